"""Seeded noise models of the paper's experiments."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["add_value_noise", "add_normal_noise"]


def add_value_noise(volume: ArrayLike, percent: float, *, seed=None,
                    reference_range=None) -> NDArray[np.float64]:
    """The volume plus Gaussian noise of sigma = `percent` % of its value range.

    Parameters
    ----------
    volume : ndarray
    percent : float
        Standard deviation as a percentage of ``reference_range`` (default the
        volume's own max - min).
    seed : int or numpy Generator, optional
        The same seed gives the same noise on any machine.

    Returns
    -------
    ndarray of float64
        A new array; the input is not modified.
    """
    data = np.asarray(volume, dtype=np.float64)
    if not np.isfinite(percent) or percent < 0:
        raise ValueError(f"noise `percent` must be a non-negative number, got {percent}")
    if reference_range is None:
        reference_range = float(data.max() - data.min())
    rng = np.random.default_rng(seed)
    return data + rng.standard_normal(data.shape) * (percent / 100.0 * reference_range)


def add_normal_noise(vertices: ArrayLike, simplices: ArrayLike, percent: float, *, seed=None,
                     movable=None) -> NDArray[np.float64]:
    """Vertices moved along their unit normals by Gaussian amounts of sigma = `percent`
    % of the mesh's mean edge length (the paper's second noise model).

    Parameters
    ----------
    vertices : (V, n+1) array_like
    simplices : (S, n+1) array_like of int
    percent : float
    seed : int or numpy Generator, optional
    movable : (V,) array_like of bool, optional
        Only these vertices move (e.g. not the boundary); default all.

    Returns
    -------
    (V, n+1) ndarray of float64, a new array.
    """
    from .mesh import edges, per_vertex_normals

    vertices = np.array(vertices, dtype=np.float64)
    simplices = np.asarray(simplices)
    if not np.isfinite(percent) or percent < 0:
        raise ValueError(f"noise `percent` must be a non-negative number, got {percent}")
    pairs = edges(simplices)
    mean_edge = float(np.linalg.norm(vertices[pairs[:, 0]] - vertices[pairs[:, 1]], axis=1).mean())
    normals = per_vertex_normals(vertices, simplices)
    rng = np.random.default_rng(seed)
    amount = rng.standard_normal(len(vertices)) * (percent / 100.0 * mean_edge)
    if movable is not None:
        amount = np.where(np.asarray(movable, dtype=bool), amount, 0.0)
    return vertices + np.nan_to_num(normals) * amount[:, None]
