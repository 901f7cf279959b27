"""`vertex_curvature`: the four operators on an explicit simplicial mesh."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import mesh as _mesh
from ._common import MeshParts, check_nondegenerate, require_consistent, require_manifold
from ._registry import get_operator

_BOUNDARY = ("nan", "partial")


def vertex_curvature(
    vertices: ArrayLike,
    simplices: ArrayLike,
    operator: str = "weighted",
    *,
    boundary: str = "nan",
) -> NDArray[np.float64]:
    """Discrete curvature at each vertex of an oriented n-manifold in R^(n+1).

    Parameters
    ----------
    vertices : (V, n+1) array_like of float
    simplices : (S, n+1) array_like of int
        Consistently oriented n-simplices, indices into `vertices` (docs/design.md
        section 2); a graph of a function should have upward normals.
    operator : {'weighted', 'unweighted', 'laplace_beltrami', 'intrinsic'}
        ``'weighted'``: the paper's mean-curvature estimate
        ``H(p) = sum psi |tau| / (n^2 |p|)``; ``'unweighted'``: extrinsic distortion
        ``D(p) = sum psi`` in radians; ``'laplace_beltrami'``: cotangent mean
        curvature ``sign(K . nu) |K| / n`` (any n); ``'intrinsic'``: ``2 pi`` minus
        the angles (n = 2) or ``4 pi`` minus the solid angles (n = 3) at p.
    boundary : {'nan', 'partial'}
        What boundary vertices (on a face of only one simplex) get: NaN, or the
        operator evaluated over their incomplete star.

    Returns
    -------
    (V,) ndarray of float
        +1/r on a round sphere with outward normals (weighted, Laplace-Beltrami);
        positive on a peak of a graph with upward normals. Vertices in no simplex
        are NaN.

    Raises
    ------
    ValueError
        Wrong shapes, indices out of range, an empty mesh, a face shared by three
        or more simplices, a pinched vertex (its star in several pieces), zero-volume
        simplices, inconsistent orientation (for the oriented operators), or an
        operator undefined for this n.

    Examples
    --------
    >>> import numpy as np
    >>> t = 2 * np.pi * np.arange(64) / 64
    >>> circle = np.c_[np.cos(t), np.sin(t)] * 2.0
    >>> edges = np.c_[np.arange(64), (np.arange(64) + 1) % 64]
    >>> round(float(vertex_curvature(circle, edges).mean()), 3)  # 1/r
    0.5
    """
    entry = get_operator(operator)
    if boundary not in _BOUNDARY:
        raise ValueError(f"unknown `boundary` {boundary!r}; choose one of {', '.join(_BOUNDARY)}")
    vertices, simplices = _mesh.check_mesh(vertices, simplices)
    n = simplices.shape[1] - 1
    if entry.dimensions is not None and n not in entry.dimensions:
        allowed = " and ".join(f"n = {d}" for d in entry.dimensions)
        raise ValueError(f"the {entry.name!r} operator is defined for {allowed}, got n = {n}")
    faces = _mesh.faces(simplices, len(vertices))
    require_manifold(simplices, faces, len(vertices))
    edges = _mesh._edge_vectors(vertices, simplices)
    raw = _mesh._cofactor_normals(edges)
    volumes = np.linalg.norm(raw, axis=1) / math.factorial(n)
    check_nondegenerate(edges, simplices, volumes)
    del edges
    if entry.oriented:
        require_consistent(faces)
    result = entry.mesh(MeshParts(vertices, simplices, faces, raw, volumes))
    used = np.zeros(len(vertices), dtype=bool)
    used[simplices.ravel()] = True
    result[~used] = np.nan
    if boundary == "nan":
        result[faces.vertices[~faces.interior].ravel()] = np.nan
    return result
