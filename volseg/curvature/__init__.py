"""Discrete curvature of simplicial n-manifolds in R^(n+1) and of volumes on grids.

- `vertex_curvature`: the four operators on an explicit mesh, any n;
- `grid_curvature`: the same operators on the implicit Kuhn tessellation of a
  volume's graph in R^4, as compiled stencils;
- the pieces: `bending_angles`, `cotangent_weights`, and from `volseg.mesh`
  `vertex_volumes` and `per_vertex_normals`.
"""

from ._common import MeshParts
from ._extrinsic import bending_angles
from ._laplace import cotangent_weights
from ._registry import (
    OPERATORS,
    REGISTRY,
    Operator,
    cli_choices,
    get_operator,
    normalize_operator,
)
from ._vertex import vertex_curvature

__all__ = [
    "OPERATORS",
    "REGISTRY",
    "Operator",
    "MeshParts",
    "get_operator",
    "cli_choices",
    "normalize_operator",
    "vertex_curvature",
    "grid_curvature",
    "default_value_scale",
    "checked_grid_curvature",
    "check_padding",
    "bending_angles",
    "cotangent_weights",
]


def __getattr__(name):  # the grid path pulls in numba: load it on first use
    if name in ("grid_curvature", "default_value_scale", "checked_grid_curvature",
                "check_padding"):
        from . import _grid

        return getattr(_grid, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
