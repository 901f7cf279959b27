"""Time-varying volumes as 3-manifolds in R^4: isosurface, curvature, segmentation, slices.

The paper's conclusion names the next step after graphs of volumes: hypersurfaces
that are not graphs, "such as isosurfaces of time-varying scalar fields". Here the
level set ``{F(x, y, z, t) = level}`` of a series is extracted on the 4-D Kuhn
triangulation (`volseg.tessellation.isosurface`, with the time step counting
`time_scale` in R^4), relaxed so that its curvature means something
(`relax_isosurface`, vertices on edges inside a time step kept in it), and segmented
by the descending Morse complex of its mean curvature (`segment_mesh`). A region is
a feature followed through time: its cross-sections at each step are the slices.

The slice at step k is exact, not resampled: the 4-D triangulation restricted to the
hyperplane t = k is the 3-D Kuhn triangulation of that step, so the faces of the
tetrahedral mesh whose vertices all lie on edges inside step k are the isosurface of
that step, carrying the 4-D curvature and labels on the same vertices.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .mesh import unique_rows
from .segment import Segmentation, segment_mesh
from .tessellation.isosurface import Isosurface, TooManyCutCells, isosurface
from .tessellation.mesh_quality import quality, relax_isosurface

__all__ = ["SpaceTimeSegmentation", "TimeSlice", "segment_series", "time_slices"]

#: Relaxation rounds by default (docs/design.md section 11: 10 rounds take the S^3 median
#: of H r from +10 % to within 1 % at 17^4 samples).
DEFAULT_RELAX = 10
#: Memory of `segment_series` per grid cell the level cuts, the bound `memory_limit`
#: is checked against before the surface is made: 72 tetrahedra (the most a 4-cube
#: gives) at the 0.85 KB per tetrahedron the whole run peaked at (measured on random
#: and smooth 4-D fields: 46 KB per cut cell at 53 tetrahedra, 27 KB at 33).
BYTES_PER_CUT_CELL = 64_000


@dataclass
class TimeSlice:
    """The isosurface at one time step, as faces of the space-time mesh.

    Attributes
    ----------
    step : int
    vertex : (P,) ndarray of intp
        Indices of its points among the space-time mesh's vertices.
    triangles : (T, 3) ndarray of intp
        Indices into `vertex`.
    """

    step: int
    vertex: NDArray[np.intp]
    triangles: NDArray[np.intp]


@dataclass
class SpaceTimeSegmentation:
    """The result of `segment_series`.

    Attributes
    ----------
    surface : Isosurface
        The (relaxed) tetrahedral 3-manifold in R^4, vertices (x, y, z, t * time_scale).
    segmentation : Segmentation
        Curvature, labels (1..k; 0 for vertices left out) and hierarchy per vertex.
    level : float
    spacing : (4,) tuple of float
        Grid step of x, y, z and of time (the time scale).
    shape : (4,) tuple of int
        The series' shape (X, Y, Z, T).
    relax : int
        Relaxation rounds used.
    quality : dict
        Dihedral-angle statistics ``{"raw": ..., "relaxed": ...}`` (`quality`).
    timings : dict
    """

    surface: Isosurface
    segmentation: Segmentation
    level: float
    spacing: tuple
    shape: tuple
    relax: int
    quality: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    def slices(self) -> list[TimeSlice]:
        """The isosurface of every time step (empty ones included)."""
        return time_slices(self.surface, self.shape)


def time_slices(surface: Isosurface, shape) -> list[TimeSlice]:
    """Cut a space-time isosurface of a field of `shape` (X, Y, Z, T) at every step.

    A vertex lies in step k when both ends of its grid edge are at time k; a face of
    the mesh whose three vertices lie in step k is part of that step's isosurface
    (module docstring), each face once.
    """
    steps = int(shape[-1])
    at = surface.edges % steps                       # t index of each end (t is the last axis)
    layer = np.where(at[:, 0] == at[:, 1], at[:, 0], -1)
    tets = surface.simplices
    faces = np.concatenate([tets[:, list(c)] for c in itertools.combinations(range(4), 3)])
    where = layer[faces]
    faces = faces[(where[:, 0] >= 0) & (where[:, 0] == where[:, 1]) & (where[:, 0] == where[:, 2])]
    faces = unique_rows(np.sort(faces, axis=1))
    face_layer = layer[faces[:, 0]]
    out = []
    for step in range(steps):
        mine = faces[face_layer == step]
        vertex, local = np.unique(mine, return_inverse=True)
        out.append(TimeSlice(step, vertex.astype(np.intp), local.reshape(-1, 3).astype(np.intp)))
    return out


def segment_series(
    field: ArrayLike,
    level: float,
    *,
    spacing=(1.0, 1.0, 1.0),
    time_scale: float = 1.0,
    relax: int = DEFAULT_RELAX,
    snap: float = 1e-6,
    operator: str = "weighted",
    n_regions: int | str | None = None,
    min_persistence: float | None = None,
    boundary: str = "partial",
    smooth_rounds: int = 0,
    memory_limit: int | None = None,
) -> SpaceTimeSegmentation:
    """Segment the space-time isosurface of a time-varying volume.

    Parameters
    ----------
    field : (X, Y, Z, T) array_like of real
        The series, indexed [x, y, z, t].
    level : float
        The isosurface value; normals point toward lower values (outward for
        blobs brighter than `level`).
    spacing : (3,) sequence of float
        Voxel size.
    time_scale : float
        The length one time step counts for in R^4, in the units of `spacing`.
        It sets how strongly motion bends the hypersurface: a feature moving v
        voxels per step tilts it by atan(v / time_scale).
    relax : int
        Rounds of `relax_isosurface` (0: the raw marching mesh).
    snap : float
        Passed to `isosurface`.
    operator, n_regions, min_persistence, boundary, smooth_rounds
        Passed to `segment_mesh`.
    memory_limit : int, optional
        Bytes the run may use: a level that cuts more grid cells than fit at
        `BYTES_PER_CUT_CELL` each is refused before the surface is made.

    Returns
    -------
    SpaceTimeSegmentation

    Raises
    ------
    ValueError
        Not 4-D, fewer than 2 samples per axis, NaN values, a level the field
        does not cross, bad spacing or time scale, and what `segment_mesh` refuses.
    """
    from . import _validate

    data = _validate.volume_array(field, "field", ndim=4)
    spacing = _validate.spacing(spacing)
    time_scale = _validate.step(time_scale, "time_scale")
    relax = _validate.rounds(relax, "relax")
    steps = (*spacing, time_scale)
    timings = {}
    start = time.perf_counter()
    limit = None if memory_limit is None else max(int(memory_limit) // BYTES_PER_CUT_CELL, 1)
    try:
        surface = isosurface(data, level, spacing=steps, snap=snap, max_cut_cells=limit)
    except TooManyCutCells as err:
        raise ValueError(
            f"the level {level:g} cuts {err.cells:,} grid cells of the series: its surface "
            f"would need about {err.cells * BYTES_PER_CUT_CELL / 1e9:.3g} GB, over the memory "
            f"limit of {memory_limit / 1e9:.3g} GB; choose a level the series crosses less "
            "often (a noisy series crosses its median everywhere) or a larger limit "
            "(--memory-limit)") from None
    if not len(surface.simplices):
        lo, hi = float(np.min(data)), float(np.max(data))
        raise ValueError(f"the level {level:g} is not crossed: the series ranges over "
                         f"[{lo:g}, {hi:g}]; choose a level strictly inside it")
    timings["isosurface"] = time.perf_counter() - start
    grades = {"raw": quality(surface.vertices, surface.simplices)}
    if relax:
        start = time.perf_counter()
        surface = relax_isosurface(surface, data, level, spacing=steps, iterations=relax,
                                   layer_axis=3)
        timings["relax"] = time.perf_counter() - start
        grades["relaxed"] = quality(surface.vertices, surface.simplices)
    # Space-time features are smooth and few: the paper's persistence cut (with the
    # hypervolume default the demo's two drifting blobs are not followed; not studied).
    result = segment_mesh(surface.vertices, surface.simplices, operator=operator,
                          n_regions=n_regions, min_persistence=min_persistence,
                          boundary=boundary, smooth_rounds=smooth_rounds,
                          measure="persistence")
    timings.update(result.timings)
    return SpaceTimeSegmentation(surface, result, float(level), steps, data.shape, relax,
                                 grades, timings)
