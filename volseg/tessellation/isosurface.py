"""Isosurfaces of sampled fields on the Kuhn triangulation, any dimension
(docs/design.md section 11).

The level set ``{F = level}`` of the piecewise-linear interpolant of a field on the
Kuhn (Freudenthal) triangulation of its grid: a closed polygon for a 2-D field, a
triangle mesh for 3-D, a tetrahedral 3-manifold in R^4 for a 4-D field (x, y, z, t).

Marching simplices. A grid point is *above* when ``F >= level`` and *below* otherwise
(a value exactly at the level counts as above: a symbolic perturbation that keeps
the result a manifold; its crossing points then sit on the grid point). A d-simplex
with p + 1 points below and q + 1 above is cut in a convex polytope that is the
product of a p- and a q-simplex; its crossing points lie on the (p + 1)(q + 1) edges
joining a below point to an above point. The polytope is split by the *staircase*
rule over the simplex's points ordered by global index: one (d-1)-simplex per
monotone lattice path from (0, 0) to (p, q), the path's points ``(b_i, a_j)`` being
the crossing on edge (below point i, above point j). The rule depends only on global
indices, so two simplices sharing a face split it the same way and the result is
conforming; in 4-D it gives the tetrahedron (p or q = 0) or the triangular prism
split into three tetrahedra (p, q = 1, 2) that marching-simplices papers describe.

Orientation is decided exactly, without the crossing positions: the crossings at the
edge midpoints are a level set of the affine function that is 0 below and 1 above,
which cuts the simplex into the same combinatorial pieces with the same orientations
as any level in between, and their coordinates are half-integers. Each output simplex
is ordered so that its normal points toward lower field values (outward for a blob,
docs/design.md sections 2 and 11).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._kuhn import cube_paths

__all__ = ["Isosurface", "isosurface", "level_set"]

#: Cut cubes processed at once (bounds the temporary simplex arrays to ~100 MB in 4-D).
_CUBES_PER_CHUNK = 1 << 16


@dataclass(frozen=True)
class Isosurface:
    """A level set extracted by `isosurface`.

    Unpacks as ``vertices, simplices, boundary_faces = isosurface(...)``.

    Attributes
    ----------
    vertices : (V, d) ndarray of float64
        Crossing points in world coordinates (``origin + index * spacing``).
    simplices : (S, d) ndarray of intp
        (d-1)-simplices, consistently oriented, normals toward lower field values.
    boundary_faces : (B, d-1) ndarray of intp
        Faces of one simplex only: where the level set meets the grid's boundary
        (empty for a closed level set), vertex indices sorted ascending.
    edges : (V, 2) ndarray of int64
        The grid edge each vertex lies on: flat indices (C order) of its below and
        its above grid point.
    fraction : (V,) ndarray of float64
        Position along that edge, in (0, 1]. A vertex merged onto a grid point
        (see `snap`) has that point as both ends and fraction 1.
    """

    vertices: NDArray[np.float64]
    simplices: NDArray[np.intp]
    boundary_faces: NDArray[np.intp]
    edges: NDArray[np.int64]
    fraction: NDArray[np.float64]

    def __iter__(self):
        return iter((self.vertices, self.simplices, self.boundary_faces))


@lru_cache(maxsize=None)
def _staircase(k: int) -> dict:
    """For a simplex of k points (ordered by global index) and each above-pattern
    (bit i set: point i above), the staircase split of its cut: (C, k-1, 2) array of
    (below point, above point) per output vertex."""
    tables = {}
    for pattern in range(1, 2 ** k - 1):
        above = [i for i in range(k) if pattern >> i & 1]
        below = [i for i in range(k) if not pattern >> i & 1]
        p, q = len(below) - 1, len(above) - 1
        split = []
        for below_steps in itertools.combinations(range(p + q), p):
            i = j = 0
            simplex = [(below[0], above[0])]
            for step in range(p + q):
                if step in below_steps:
                    i += 1
                else:
                    j += 1
                simplex.append((below[i], above[j]))
            split.append(simplex)
        tables[pattern] = np.array(split, dtype=np.intp)
    return tables


def _cut(simplices: NDArray, values: NDArray, level: float, coordinates) -> tuple:
    """Cut simplices (rows sorted by global index) by the level.

    `coordinates(ids)` gives (..., d) positions used only for the orientation
    (exact for grid indices). Returns (below, above): (T, k-1) global indices of the
    edge of each output vertex, rows ordered so the normal points toward below.
    """
    k = simplices.shape[1]
    above = values[simplices] >= level
    pattern = (above.astype(np.intp) << np.arange(k)).sum(axis=1)
    below_out, above_out = [], []
    for code, table in _staircase(k).items():
        rows = simplices[pattern == code]
        if not len(rows):
            continue
        ends = rows[:, table]                       # (R, C, k-1, 2)
        ends = ends.reshape(-1, k - 1, 2)
        lower, upper = ends[..., 0], ends[..., 1]
        if coordinates is not None:
            # Orientation at the edge midpoints: det[b - m_0; m_1 - m_0; ...] > 0 with
            # b a below point of the parent, on the normal's side (the normal is
            # written first, docs/design.md section 2).
            mid = (coordinates(lower) + coordinates(upper)) * 0.5
            first_below = int(table[0, 0, 0])
            reference = np.repeat(rows[:, [first_below]], len(table), axis=0)
            rows_of = np.concatenate([coordinates(reference) - mid[:, :1],
                                      mid[:, 1:] - mid[:, :1]], axis=1)
            flip = np.linalg.det(rows_of) < 0
            lower[flip, :2] = lower[flip, 1::-1]
            upper[flip, :2] = upper[flip, 1::-1]
        below_out.append(lower)
        above_out.append(upper)
    if not below_out:
        empty = np.zeros((0, k - 1), dtype=np.int64)
        return empty, empty
    return np.concatenate(below_out), np.concatenate(above_out)


def _weld(below: NDArray, above: NDArray, values: NDArray, level: float) -> tuple:
    """Shared crossing points: one vertex per edge. Returns (edges (V, 2), simplices
    (S, k-1), fraction (V,): where the level crosses each edge, from its below end)."""
    n_points = len(values)
    keys = below.astype(np.int64) * n_points + above
    unique, inverse = np.unique(keys.ravel(), return_inverse=True)
    edges = np.column_stack([unique // n_points, unique % n_points])
    f_below, f_above = values[edges[:, 0]], values[edges[:, 1]]
    fraction = (level - f_below) / (f_above - f_below)
    return edges, inverse.reshape(keys.shape).astype(np.intp), fraction


def _check_values(field) -> NDArray[np.float64]:
    array = np.asarray(field)
    if array.dtype == object or not (np.issubdtype(array.dtype, np.number)
                                     or array.dtype == bool):
        raise ValueError(f"`field` must be a numeric array, got dtype {array.dtype}")
    array = np.ascontiguousarray(array, dtype=np.float64)
    if not np.isfinite(array).all():
        bad = np.unravel_index(int(np.flatnonzero(~np.isfinite(array))[0]), array.shape)
        raise ValueError("`field` holds NaN or infinite values (first at index "
                         f"{tuple(map(int, bad))})")
    return array


def _check_level(level) -> float:
    from .._validate import number

    return number(level, "level")


def _axis_vector(value, d: int, name: str, default: float, positive: bool) -> NDArray:
    if value is None:
        return np.full(d, default)
    vector = np.asarray(value, dtype=np.float64)
    if vector.ndim == 0:
        vector = np.full(d, float(vector))
    if vector.shape != (d,) or not np.isfinite(vector).all() or (positive and (vector <= 0).any()):
        kind = "positive finite numbers" if positive else "finite numbers"
        raise ValueError(f"`{name}` must be {d} {kind} (one per axis), got {value!r}")
    return vector


def _problem_vertices(simplices: NDArray, n_vertices: int) -> NDArray[np.intp]:
    """Vertices where a mesh is not an oriented manifold: on a face of three or more
    simplices, of a duplicated simplex, of an inconsistently oriented face, or pinched."""
    from ..mesh import faces, pinched_vertices, row_keys

    width = simplices.shape[1]
    facets = np.sort(np.concatenate([np.delete(simplices, c, axis=1) for c in range(width)]),
                     axis=1)
    _, inverse, counts = np.unique(row_keys(facets, max(n_vertices, 1)), return_inverse=True,
                                   return_counts=True)
    crowded = facets[counts[inverse] > 2]
    if len(crowded):
        return np.unique(crowded)
    mesh_faces = faces(simplices, n_vertices)
    bad = [mesh_faces.vertices[~mesh_faces.consistent].ravel(),
           pinched_vertices(simplices, n_vertices, mesh_faces)]
    return np.unique(np.concatenate(bad)).astype(np.intp)


def _moved_off(edges: NDArray, values: NDArray, level: float, points: NDArray) -> NDArray:
    """Edge fractions after moving the samples of `points` (sorted grid points) off the
    level, away from it, by a tenth of their smallest gap across the level: the level
    set of a perturbed interpolant, so a valid embedding whose crossings near those
    points sit at least a few percent of an edge from them (no flat simplex; the
    slivers are left to `relax_isosurface`)."""
    below, above = values[edges[:, 0]].copy(), values[edges[:, 1]].copy()
    gap = above - below
    eta = np.full(len(points), np.inf)
    ends = []
    for column in (0, 1):
        where = np.minimum(np.searchsorted(points, edges[:, column]), max(len(points) - 1, 0))
        hit = points[where] == edges[:, column] if len(points) else np.zeros(len(edges), bool)
        np.minimum.at(eta, where[hit], gap[hit])
        ends.append((where, hit))
    eta *= 0.1
    (where, hit), (where_up, hit_up) = ends
    below[hit] = np.minimum(below[hit], level - eta[where[hit]])
    above[hit_up] = np.maximum(above[hit_up], level + eta[where_up[hit_up]])
    return (level - below) / (above - below)


def _collapse(edges: NDArray, fraction: NDArray, simplices: NDArray, snap: float,
              values: NDArray, level: float, positions) -> tuple:
    """Merge the crossings at (or within `snap` of) a grid point into one vertex on it
    and drop the simplices that degenerate. Where a merge would leave a non-manifold
    (a critical point of the interpolant at the level) or a flat simplex, the grid
    point is instead moved off the level (`_moved_off`). `positions(edges, fraction)`
    gives vertex coordinates. Returns (edges, fraction, simplices)."""
    from ..mesh import flat_simplices

    n_vertices = len(edges)
    point = np.where(fraction >= 1.0 - snap, edges[:, 1],
                     np.where(fraction <= snap, edges[:, 0], -1))
    if not (point >= 0).any():
        return edges, fraction, simplices
    kept_apart = np.zeros(0, dtype=np.int64)
    for _ in range(8):
        apart = (point >= 0) & np.isin(point, kept_apart)
        moved = _moved_off(edges, values, level, kept_apart) if len(kept_apart) else fraction
        snapped = (point >= 0) & ~apart
        key = np.where(snapped, point, -1 - np.arange(n_vertices))
        unique, first, new_id = np.unique(key, return_index=True, return_inverse=True)
        merged = new_id.reshape(-1)[simplices]
        ordered = np.sort(merged, axis=1)
        merged = merged[(ordered[:, 1:] != ordered[:, :-1]).all(axis=1)]
        out_edges = edges[first].copy()
        out_fraction = moved[first].copy()
        grid = unique >= 0
        out_edges[grid] = unique[grid, None]
        out_fraction[grid] = 1.0
        problems = _problem_vertices(merged, len(unique)) if len(merged) else np.zeros(0, np.intp)
        if not len(problems) and len(merged):
            problems = np.unique(merged[flat_simplices(positions(out_edges, out_fraction),
                                                       merged)])
        if not len(problems):
            used = np.zeros(len(unique), dtype=bool)
            used[merged.ravel()] = True      # crossings whose simplices all degenerated
            renumber = np.cumsum(used) - 1
            return out_edges[used], out_fraction[used], renumber[merged].astype(np.intp)
        culprits = np.where(grid, unique, -1)[problems]
        culprits = culprits[culprits >= 0]
        if not len(culprits):
            break
        kept_apart = np.union1d(kept_apart, culprits)
    # No merge that keeps a manifold: move every candidate point off the level.
    return edges, _moved_off(edges, values, level, np.unique(point[point >= 0])), simplices


class TooManyCutCells(ValueError):
    """The level cuts more grid cells than `isosurface`'s `max_cut_cells`."""

    def __init__(self, cells: int, limit: int, level: float):
        super().__init__(f"the level {level:g} cuts {cells:,} grid cells, more than "
                         f"`max_cut_cells` = {limit:,}")
        self.cells, self.limit = cells, limit


def isosurface(field: ArrayLike, level: float, *, spacing=None, origin=None,
               snap: float = 1e-6, max_cut_cells: int | None = None) -> Isosurface:
    """The level set ``{F = level}`` of a field sampled on a d-D grid, as a (d-1)-manifold.

    Parameters
    ----------
    field : (N_0, ..., N_{d-1}) array_like of real, d >= 2
        Samples on a regular grid; for a time-varying volume the axes are
        (x, y, z, t).
    level : float
    spacing : float or (d,) sequence of float, optional
        Grid step per axis (default 1); for (x, y, z, t) the last entry is the time
        scale, the length one time step counts for in R^4.
    origin : (d,) sequence of float, optional
        World position of sample 0 (default 0).
    snap : float in [0, 0.5)
        Crossings within this fraction of an edge from a grid point are moved onto
        it and merged there, with the simplices that degenerate dropped. The default
        1e-6 merges the crossings on a grid point whose sample equals the level
        (common in integer data) or misses it by rounding: left apart they give
        zero-volume simplices, on which curvature is undefined. Larger values (0.1 -
        0.2) also remove the slivers of near-vertex crossings. Where a merge would
        break the manifold or leave a flat simplex (a critical point of the
        interpolant at the level), that sample is instead moved off the level by a
        tenth of its smallest gap across it, so its crossings stay apart.
    max_cut_cells : int, optional
        Refuse (`TooManyCutCells`) a level that cuts more grid cells than this,
        before any simplex is made. A cut cell is d! Kuhn simplices, each cut into
        up to C(d - 1, (d - 1) // 2) pieces (72 in 4-D); a noise field at its median
        cuts almost every cell.

    Returns
    -------
    Isosurface
        Vertices (V, d), simplices (S, d) oriented with normals toward lower values,
        boundary faces (B, d-1), and each vertex's grid edge. Empty arrays when the
        level is not crossed.

    Raises
    ------
    ValueError
        A non-numeric field, fewer than 2 axes or 2 samples per axis, NaN or
        infinite values, a non-finite level, or bad spacing / origin.

    Examples
    --------
    >>> import numpy as np
    >>> axis = np.linspace(-1, 1, 21)
    >>> x, y = np.meshgrid(axis, axis, indexing="ij")
    >>> polygon = isosurface(-(x**2 + y**2), -0.5**2, spacing=0.1, origin=(-1, -1))
    >>> polygon.simplices.shape[1], len(polygon.boundary_faces)
    (2, 0)
    """
    from ..mesh import boundary_faces

    array, level = _check_values(field), _check_level(level)
    if not 0.0 <= float(snap) < 0.5:
        raise ValueError(f"`snap` must be in [0, 0.5), got {snap!r}")
    d = array.ndim
    if d < 2 or min(array.shape) < 2:
        raise ValueError(f"`field` must have 2 or more axes with at least 2 samples each, "
                         f"got shape {array.shape}")
    spacing = _axis_vector(spacing, d, "spacing", 1.0, positive=True)
    origin = _axis_vector(origin, d, "origin", 0.0, positive=False)
    shape = array.shape
    strides = np.array([int(np.prod(shape[a + 1:])) for a in range(d)], dtype=np.int64)
    # A cube is cut when some corner is below and some corner is above.
    cube_shape = tuple(s - 1 for s in shape)
    lowest = np.full(cube_shape, np.inf)
    highest = np.full(cube_shape, -np.inf)
    for corner in itertools.product((0, 1), repeat=d):
        view = array[tuple(slice(c, c + s) for c, s in zip(corner, cube_shape, strict=True))]
        np.minimum(lowest, view, out=lowest)
        np.maximum(highest, view, out=highest)
    cut = np.flatnonzero((lowest < level) & (highest >= level))
    del lowest, highest
    if max_cut_cells is not None and len(cut) > max_cut_cells:
        raise TooManyCutCells(len(cut), int(max_cut_cells), level)
    corners = np.ravel_multi_index(np.unravel_index(cut, cube_shape), shape).astype(np.int64)
    offsets = cube_paths(d) @ strides                     # (d!, d+1), increasing along paths
    values = array.ravel()

    def coordinates(ids):
        # Unravelled flat: numpy 2.4's unravel_index is wrong for (N, 1) index arrays
        # past its 8192-element buffer (numpy issue 31980).
        flat = np.unravel_index(ids.ravel(), shape)
        return np.stack(flat, axis=-1).astype(np.float64).reshape(*ids.shape, d)

    below, above = [], []
    for start in range(0, len(corners), _CUBES_PER_CHUNK):
        chunk = corners[start:start + _CUBES_PER_CHUNK]
        simplices = (chunk[:, None, None] + offsets[None]).reshape(-1, d + 1)
        lower, upper = _cut(simplices, values, level, coordinates)
        below.append(lower)
        above.append(upper)
    if not below:
        below, above = [np.zeros((0, d), dtype=np.int64)], [np.zeros((0, d), dtype=np.int64)]
    edges, simplices, fraction = _weld(np.concatenate(below), np.concatenate(above), values,
                                       level)

    def positions(edges, fraction):
        start, end = coordinates(edges[:, 0]), coordinates(edges[:, 1])
        return origin + (start + fraction[:, None] * (end - start)) * spacing

    if len(simplices):
        edges, fraction, simplices = _collapse(edges, fraction, simplices, snap, values,
                                               level, positions)
    vertices = positions(edges, fraction)
    faces = boundary_faces(simplices) if len(simplices) else np.zeros((0, d - 1), dtype=np.intp)
    return Isosurface(vertices, simplices, faces, edges, fraction)


def level_set(vertices: ArrayLike, simplices: ArrayLike, field: ArrayLike, level: float,
              *, oriented: bool = True) -> Isosurface:
    """The level set of a vertex field on any simplicial mesh, by the same staircase rule.

    Parameters
    ----------
    vertices : (V, d) array_like of float
    simplices : (S, k) array_like of int
        Any simplices (tetrahedra of a 3-manifold in R^4 cut by the time
        coordinate, triangles of a surface cut by a height, ...).
    field : (V,) array_like of real
    level : float
    oriented : bool
        Orient the output toward lower values; needs full-dimensional simplices
        (k = d + 1). False: output in staircase order.

    Returns
    -------
    Isosurface
        Vertices interpolated along mesh edges; `edges` index `vertices`.
    """
    from ..mesh import boundary_faces, check_mesh

    vertices, simplices = check_mesh(vertices, simplices, codimension=None)
    values, level = _check_values(field).ravel(), _check_level(level)
    if np.ndim(field) != 1 or len(values) != len(vertices):
        raise ValueError(f"`field` must have one value per vertex ({len(vertices)}), got "
                         f"{len(values)}")
    k = simplices.shape[1]
    if oriented and vertices.shape[1] != k - 1:
        raise ValueError(f"an oriented level set needs full-dimensional simplices "
                         f"({vertices.shape[1] + 1} vertices each), got {k}")
    ordered = np.sort(simplices, axis=1)
    lower, upper = _cut(ordered, values, level, (lambda ids: vertices[ids]) if oriented else None)
    edges, out, fraction = _weld(lower, upper, values, level)
    start, end = vertices[edges[:, 0]], vertices[edges[:, 1]]
    points = start + fraction[:, None] * (end - start)
    faces = (boundary_faces(out) if len(out) and k > 2
             else np.zeros((0, max(k - 2, 0)), dtype=np.intp))
    return Isosurface(points, out, faces, edges, fraction)
