"""Tessellations: Kuhn grids, test hypersurfaces, irregular Delaunay and diamond meshes,
isosurfaces of sampled fields in any dimension."""

from .diamond import DiamondMesh, decode, diamond_mesh
from .irregular import IrregularMesh, irregular_cube_mesh, lift, orient_upward
from .isosurface import Isosurface, isosurface, level_set
from .kuhn import kuhn_cube_mesh, kuhn_grid_mesh, kuhn_simplices
from .mesh_quality import dihedral_angles, quality, relax_isosurface
from .shapes import cylinder, polygon, sphere, subdivide

__all__ = [
    "kuhn_simplices",
    "kuhn_grid_mesh",
    "kuhn_cube_mesh",
    "polygon",
    "sphere",
    "cylinder",
    "subdivide",
    "irregular_cube_mesh",
    "IrregularMesh",
    "lift",
    "orient_upward",
    "diamond_mesh",
    "DiamondMesh",
    "decode",
    "isosurface",
    "Isosurface",
    "level_set",
    "relax_isosurface",
    "dihedral_angles",
    "quality",
]
