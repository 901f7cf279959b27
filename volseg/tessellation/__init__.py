"""Tessellations: Kuhn grids, test hypersurfaces, irregular Delaunay and diamond meshes."""

from .kuhn import KUHN_OFFSETS_3D, kuhn_cube_mesh, kuhn_grid_mesh, kuhn_simplices
from .shapes import cylinder, polygon, sphere, subdivide

__all__ = [
    "KUHN_OFFSETS_3D",
    "kuhn_simplices",
    "kuhn_grid_mesh",
    "kuhn_cube_mesh",
    "polygon",
    "sphere",
    "cylinder",
    "subdivide",
]
