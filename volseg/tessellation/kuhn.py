"""Kuhn (Freudenthal) tessellations of regular grids, any dimension (docs/design.md section 4)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._kuhn import axis_orders, cube_paths, permutation_sign

__all__ = ["kuhn_simplices", "kuhn_grid_mesh", "kuhn_cube_mesh"]

def kuhn_simplices(shape, *, periodic=(), upward: bool = True) -> NDArray[np.intp]:
    """Simplices of the Kuhn split of every cell of a grid of `shape` points.

    Each cell with lowest corner c is split into d! simplices, one per permutation
    (a, b, ...) of the axes: ``c -> c + e_a -> c + e_a + e_b -> ... -> c + 1``.
    Vertex indices are ``np.ravel_multi_index(point, shape)``.

    Parameters
    ----------
    shape : tuple of int
        Points per axis (d axes).
    periodic : iterable of int
        Axes that wrap around (the cell after the last point joins it to the first).
    upward : bool
        True: order each simplex so that the graph of a function over the grid, as
        a d-manifold in R^(d+1), has normals with positive last component. False:
        every simplex has a positive determinant in the grid's own coordinates.
        Either way the tessellation is consistently oriented.

    Returns
    -------
    (d! * cells, d+1) ndarray of intp
    """
    shape = tuple(int(s) for s in shape)
    d = len(shape)
    periodic = set(periodic)
    cells_per_axis = [s if a in periodic else s - 1 for a, s in enumerate(shape)]
    corners = np.stack(
        np.meshgrid(*[np.arange(c) for c in cells_per_axis], indexing="ij"), axis=-1
    ).reshape(-1, d)
    out = []
    for perm, path in zip(axis_orders(d), cube_paths(d), strict=True):
        points = [corners + p for p in path]
        for a in periodic:
            for p in points:
                p[:, a] %= shape[a]
        index = np.stack([np.ravel_multi_index(tuple(p.T), shape) for p in points], axis=1)
        # Base orientation is sign(perm); the graph normal's last component has sign
        # (-1)^d sign(perm) (cofactor convention, docs/design.md section 2).
        wanted = (-1) ** d if upward else 1
        if wanted * permutation_sign(perm) < 0:
            index[:, [0, 1]] = index[:, [1, 0]]
        out.append(index)
    return np.concatenate(out, axis=0).astype(np.intp)


def kuhn_grid_mesh(
    volume: ArrayLike, *, spacing=(1.0, 1.0, 1.0), value_scale: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """The graph of a volume as an explicit tetrahedral 3-manifold in R^4.

    Parameters
    ----------
    volume : (X, Y, Z) array_like
        Indexed [x, y, z].
    spacing : (3,) sequence of float
    value_scale : float
        Vertex (i, j, k) maps to ``(i dx, j dy, k dz, value_scale * f[i, j, k])``.

    Returns
    -------
    vertices : (X*Y*Z, 4) ndarray of float
        Vertex index = ``np.ravel_multi_index((i, j, k), shape)``.
    tetrahedra : (6 (X-1)(Y-1)(Z-1), 4) ndarray of intp
        Kuhn tetrahedra oriented with upward normals.
    """
    volume = np.asarray(volume, dtype=np.float64)
    if volume.ndim != 3:
        raise ValueError(f"`volume` must be 3-D, got shape {volume.shape}")
    spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,))
    grid = np.stack(np.meshgrid(*[np.arange(s) for s in volume.shape], indexing="ij"), axis=-1)
    vertices = np.concatenate(
        [grid.reshape(-1, 3) * spacing, value_scale * volume.reshape(-1, 1)], axis=1
    )
    return vertices, kuhn_simplices(volume.shape)


def kuhn_cube_mesh(resolution: int, function=None):
    """Kuhn grid of ``resolution^3`` samples on [-1, 1]^3, optionally lifted by a function.

    Parameters
    ----------
    resolution : int
        Samples per axis (>= 2).
    function : callable, optional
        ``function(x, y, z)`` giving the value coordinate; 0 if omitted.

    Returns
    -------
    vertices : (resolution^3, 4) ndarray of float
    tetrahedra : (6 (resolution-1)^3, 4) ndarray of intp
    """
    axis = np.linspace(-1.0, 1.0, resolution)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    values = np.zeros_like(x) if function is None else function(x, y, z)
    h = 2.0 / (resolution - 1)
    vertices, tetrahedra = kuhn_grid_mesh(values, spacing=(h, h, h))
    vertices[:, :3] -= 1.0
    return vertices, tetrahedra
