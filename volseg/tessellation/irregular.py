"""Irregular tetrahedral meshes of [-1, 1]^3 (the paper's non-grid tessellations).

Random interior samples with a minimum distance, a boundary sampled uniformly (the 8
corners, random points along the 12 edges and on the 6 faces), Delaunay
(scipy.spatial, Qhull), then Laplacian smoothing of the interior vertices with the
Delaunay neighbours and a final Delaunay of the smoothed points (so no tetrahedron
is inverted). Everything is seeded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .mesh_quality import _tetrahedron_angles

__all__ = ["IrregularMesh", "irregular_cube_mesh", "orient_upward", "lift", "delaunay_tetrahedra"]


@dataclass
class IrregularMesh:
    """Points in [-1, 1]^3 and their tetrahedra (upward-oriented, see `orient_upward`).

    Attributes
    ----------
    points : (V, 3) ndarray of float
    tetrahedra : (T, 4) ndarray of intp
    boundary : (V,) ndarray of bool
        Points on the cube's surface (never moved by smoothing).
    min_dihedral : (T,) ndarray of float
        Smallest dihedral angle of each tetrahedron, degrees.
    slivers : int
        Tetrahedra with a dihedral angle below `sliver_degrees`.
    """

    points: NDArray[np.float64]
    tetrahedra: NDArray[np.intp]
    boundary: NDArray[np.bool_]
    min_dihedral: NDArray[np.float64]
    slivers: int


def orient_upward(points: NDArray, tetrahedra: NDArray) -> NDArray[np.intp]:
    """Order each tetrahedron so that a graph over it, in R^4, has upward normals.

    That is a negative determinant of (p1 - p0, p2 - p0, p3 - p0): the convention
    of `kuhn_simplices(upward=True)` for d = 3 (normal sign (-1)^d det).
    """
    tetrahedra = np.array(tetrahedra, dtype=np.intp)
    p = np.asarray(points, dtype=np.float64)[tetrahedra]
    det = np.linalg.det(p[:, 1:] - p[:, :1])
    flip = det > 0
    tetrahedra[flip, 0], tetrahedra[flip, 1] = tetrahedra[flip, 1], tetrahedra[flip, 0].copy()
    return tetrahedra


def lift(points: NDArray, function) -> NDArray[np.float64]:
    """(V, 4) vertices (x, y, z, f(x, y, z)) of a graph over `points`."""
    points = np.asarray(points, dtype=np.float64)
    values = function(points[:, 0], points[:, 1], points[:, 2])
    return np.column_stack([points, values])


def _dart_throw(rng, n, radius, existing, sampler, max_rounds=100):
    """Up to `n` points from `sampler(k)`, each at least `radius` from the others and
    from `existing`: batches of candidates, conflicts resolved greedily in order."""
    from scipy.spatial import cKDTree

    accepted = np.zeros((0, existing.shape[1]))
    for _ in range(max_rounds):
        need = n - len(accepted)
        if need <= 0:
            break
        candidates = sampler(2 * need + 16)
        others = np.vstack([existing, accepted])
        if len(others):
            candidates = candidates[cKDTree(others).query(candidates)[0] >= radius]
        pairs = cKDTree(candidates).query_pairs(radius, output_type="ndarray")
        drop = np.zeros(len(candidates), dtype=bool)
        for i, j in pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]:
            if not drop[i]:
                drop[j] = True
        accepted = np.vstack([accepted, candidates[~drop][:need]])
    return accepted


def irregular_cube_mesh(n_vertices: int, *, seed=0, min_distance: float = 0.5,
                        smoothing_iterations: int = 100,
                        sliver_degrees: float = 5.0) -> IrregularMesh:
    """A seeded irregular tetrahedralization of [-1, 1]^3 with about `n_vertices` points.

    Parameters
    ----------
    n_vertices : int
        Target vertex count (>= 27); boundary and interior shares follow a grid of
        the same size, m^3 with m = round(n^(1/3)).
    seed : int
    min_distance : float
        Minimum distance between samples, as a fraction of the grid spacing
        h = 2 / (m - 1) of a regular grid with the same count.
    smoothing_iterations : int
        Laplacian smoothing steps of the interior points (the paper: 100).
    sliver_degrees : float
        A tetrahedron with a dihedral angle below this counts as a sliver.

    Returns
    -------
    IrregularMesh
    """
    if n_vertices < 27:
        raise ValueError(f"`n_vertices` must be at least 27, got {n_vertices}")
    rng = np.random.default_rng(seed)
    m = max(3, int(round(n_vertices ** (1 / 3))))
    h = 2.0 / (m - 1)
    radius = min_distance * h
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    edges = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        for s in (-1, 1):
            for t in (-1, 1):
                along = np.sort(rng.uniform(-1, 1, m - 2))
                points = np.zeros((m - 2, 3))
                points[:, axis] = along
                points[:, others[0]], points[:, others[1]] = s, t
                edges.append(points)
    boundary_points = np.vstack([corners, *edges])
    for axis in range(3):
        for s in (-1.0, 1.0):
            def face_sampler(k, axis=axis, s=s):
                points = rng.uniform(-1, 1, (k, 3))
                points[:, axis] = s
                return points
            face = _dart_throw(rng, (m - 2) ** 2, radius, boundary_points, face_sampler)
            boundary_points = np.vstack([boundary_points, face])
    interior = _dart_throw(rng, max(n_vertices - len(boundary_points), 1), radius,
                           boundary_points,
                           lambda k: rng.uniform(-1 + radius, 1 - radius, (k, 3)))
    points = np.vstack([boundary_points, interior])
    boundary = np.zeros(len(points), dtype=bool)
    boundary[: len(boundary_points)] = True
    tetrahedra = delaunay_tetrahedra(points)
    if smoothing_iterations:
        points = _laplacian_smooth(points, tetrahedra, boundary, smoothing_iterations)
        tetrahedra = delaunay_tetrahedra(points)
    tetrahedra = orient_upward(points, tetrahedra)
    min_dihedral = _tetrahedron_angles(points, tetrahedra).min(axis=1)
    return IrregularMesh(points, tetrahedra, boundary, min_dihedral,
                         int(np.sum(min_dihedral < sliver_degrees)))


def delaunay_tetrahedra(points: NDArray) -> NDArray[np.intp]:
    """(T, 4) Delaunay tetrahedra of (P, 3) points (scipy's Qhull) minus the flat ones
    Qhull leaves on coplanar boundary points; not oriented (see `orient_upward`)."""
    from scipy.spatial import Delaunay

    tetrahedra = Delaunay(points).simplices.astype(np.intp)
    p = points[tetrahedra]
    volume = np.abs(np.linalg.det(p[:, 1:] - p[:, :1])) / 6
    return tetrahedra[volume > 1e-12 * np.median(volume)]


def _laplacian_smooth(points, tetrahedra, fixed, iterations):
    """Move each free point to the mean of its edge neighbours, `iterations` times."""
    from ..mesh import vertex_adjacency

    adjacency = vertex_adjacency(tetrahedra, len(points))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    free = ~fixed
    points = points.copy()
    for _ in range(iterations):
        mean = adjacency @ points / degree[:, None]
        points[free] = mean[free]
    return points
