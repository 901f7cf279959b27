"""Laplace-Beltrami (cotangent) mean curvature, any n.

Per simplex the cotangent weights are ``w_ij = -|sigma| grad(phi_i) . grad(phi_j)``,
phi the barycentric coordinates (n = 2: (cot a)/2; n = 3: (1/6) l cot theta). Because
the phi sum to one, ``sum_j w_pj (p - x_j)`` over a simplex equals ``|sigma| grad phi_p``,
the gradient of |sigma| with respect to p, so K(p) is accumulated without forming the
matrix; `cotangent_weights` forms it for those who want it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # scipy.sparse costs 0.13 s to import; only cotangent_weights needs it
    from scipy import sparse

from .. import mesh as _mesh
from ._common import edge_gram

__all__ = ["cotangent_weights"]


def _inverse(m):
    """Inverse of a stack of k x k symmetric positive definite matrices (closed form k <= 3)."""
    k = m.shape[-1]
    if k == 1:
        return 1.0 / m
    if k == 2:
        det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
        inv = np.empty_like(m)
        inv[:, 0, 0], inv[:, 1, 1] = m[:, 1, 1], m[:, 0, 0]
        inv[:, 0, 1], inv[:, 1, 0] = -m[:, 0, 1], -m[:, 1, 0]
        return inv / det[:, None, None]
    if k == 3:
        a, b, c = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
        d, e, f = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
        g, h, i = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
        co = np.stack(
            [
                np.stack([e * i - f * h, c * h - b * i, b * f - c * e], axis=1),
                np.stack([f * g - d * i, a * i - c * g, c * d - a * f], axis=1),
                np.stack([d * h - e * g, b * g - a * h, a * e - b * d], axis=1),
            ],
            axis=1,
        )
        det = a * co[:, 0, 0] + b * co[:, 1, 0] + c * co[:, 2, 0]
        return co / det[:, None, None]
    return np.linalg.inv(m)


def _gradients(vertices, simplices):
    """(S, n+1, d) gradients of the barycentric coordinates and (S,) volumes."""
    edges = _mesh._edge_vectors(vertices, simplices)
    gram = edge_gram(edges)
    n = simplices.shape[1] - 1
    volumes = np.sqrt(np.clip(_mesh._det(gram), 0, None)) / math.factorial(n)
    grads_rest = _inverse(gram) @ edges  # rows 1..n
    grad0 = -grads_rest.sum(axis=1, keepdims=True)
    return np.concatenate([grad0, grads_rest], axis=1), volumes


def cotangent_weights(vertices: ArrayLike, simplices: ArrayLike) -> sparse.csr_matrix:
    """Cotangent Laplacian of an n-manifold in any R^d, libigl's `cotmatrix` convention.

    Parameters
    ----------
    vertices : (V, d) array_like of float
    simplices : (S, n+1) array_like of int

    Returns
    -------
    (V, V) scipy.sparse.csr_matrix
        Off-diagonal entries ``w_ij`` (n = 2: (cot a + cot b)/2; n = 3:
        (1/6) sum l_kl cot theta_kl), diagonal ``-sum_j w_ij``.
    """
    vertices, simplices = _mesh.check_mesh(vertices, simplices, codimension=None)
    grads, volumes = _gradients(vertices, simplices)
    width = simplices.shape[1]
    rows, cols, vals = [], [], []
    for i in range(width):
        for j in range(width):
            if i != j:
                w = -volumes * np.einsum("ij,ij->i", grads[:, i], grads[:, j])
                rows.append(simplices[:, i])
                cols.append(simplices[:, j])
                vals.append(w)
    n_vertices = len(vertices)
    from scipy import sparse

    matrix = sparse.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(n_vertices, n_vertices),
    ).tocsr()
    return (matrix - sparse.diags(np.asarray(matrix.sum(axis=1)).ravel())).tocsr()


def laplace_beltrami(parts):
    """H = sign(K . nu_p) |K| / n with K = (1/|p|) sum_j w_pj (p - x_j)."""
    from ._mesh_kernels import volume_gradient_kernel

    vertices, simplices, raw_normals = parts.vertices, parts.simplices, parts.raw_normals
    n = simplices.shape[1] - 1
    n_vertices = len(vertices)
    k_vec = np.zeros((n_vertices, vertices.shape[1]))
    star = np.zeros(n_vertices)
    volume_gradient_kernel(vertices, simplices, k_vec, star)
    normal = _mesh.to_vertices(simplices, raw_normals, n_vertices)
    with np.errstate(invalid="ignore", divide="ignore"):
        k_vec /= star[:, None]
        sign = np.where(np.einsum("ij,ij->i", k_vec, normal) < 0, -1.0, 1.0)
        return sign * np.linalg.norm(k_vec, axis=1) / n
