"""Compiled per-face kernel for the explicit-mesh bending angles (flat, checked arrays)."""

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _project_out(vector, basis, count, d):
    """Subtract from `vector` its components along the first `count` rows of the
    orthonormal `basis` (one Gram-Schmidt step, in place)."""
    for q in range(count):
        dot = 0.0
        for c in range(d):
            dot += vector[c] * basis[q, c]
        for c in range(d):
            vector[c] -= dot * basis[q, c]


@numba.njit(cache=True, nogil=True)
def bending_kernel(vertices, face_vertices, far_vertex, unit, sa, sb, psi, measure):
    """psi = atan2(-nu_b . u_a, nu_a . nu_b) and the unnormalised |tau| * (n-1)! per face.

    vertices (V, d); face_vertices (F, n) the face's vertices; far_vertex (F,) the
    vertex of sigma_a not on the face; unit (S, d) unit simplex normals; sa, sb (F,)
    the two simplices. Writes psi and measure (F,).
    """
    n_faces, n = face_vertices.shape
    d = vertices.shape[1]
    basis = np.empty((max(n - 1, 1), d))
    e = np.empty(d)
    u = np.empty(d)
    for f in range(n_faces):
        t0 = face_vertices[f, 0]
        prod = 1.0
        for k in range(1, n):
            for c in range(d):
                e[c] = vertices[face_vertices[f, k], c] - vertices[t0, c]
            _project_out(e, basis, k - 1, d)
            r = 0.0
            for c in range(d):
                r += e[c] * e[c]
            r = math.sqrt(r)
            prod *= r
            for c in range(d):
                basis[k - 1, c] = e[c] / r
        for c in range(d):
            u[c] = vertices[far_vertex[f], c] - vertices[t0, c]
        _project_out(u, basis, n - 1, d)
        un = 0.0
        sin_part = 0.0
        cos_part = 0.0
        for c in range(d):
            un += u[c] * u[c]
            sin_part += unit[sb[f], c] * u[c]
            cos_part += unit[sa[f], c] * unit[sb[f], c]
        psi[f] = math.atan2(-sin_part / math.sqrt(un), cos_part)
        measure[f] = prod


@numba.njit(cache=True, nogil=True)
def volume_gradient_kernel(vertices, simplices, k_sum, star):
    """Accumulate |sigma| grad(phi_p) into k_sum[p] and |sigma|/(n+1) into star[p].

    grad(phi_i), i >= 1, are the rows of G^-1 E (G = E E^T, E the edge vectors);
    grad(phi_0) = -sum of the others. G^-1 E comes from Gauss-Jordan elimination
    with partial pivoting on [G | E]; |sigma| = sqrt(det G) / n!.
    """
    n_simplices, width = simplices.shape
    n = width - 1
    d = vertices.shape[1]
    edges = np.empty((n, d))
    aug = np.empty((n, n + d))
    factorial = 1.0
    for k in range(2, n + 1):
        factorial *= k
    for s in range(n_simplices):
        v0 = simplices[s, 0]
        for i in range(n):
            vi = simplices[s, i + 1]
            for c in range(d):
                edges[i, c] = vertices[vi, c] - vertices[v0, c]
        for i in range(n):
            for j in range(n):
                g = 0.0
                for c in range(d):
                    g += edges[i, c] * edges[j, c]
                aug[i, j] = g
            for c in range(d):
                aug[i, n + c] = edges[i, c]
        det = 1.0
        for col in range(n):
            pivot = col
            for r in range(col + 1, n):
                if abs(aug[r, col]) > abs(aug[pivot, col]):
                    pivot = r
            if pivot != col:
                for c in range(n + d):
                    tmp = aug[col, c]
                    aug[col, c] = aug[pivot, c]
                    aug[pivot, c] = tmp
                det = -det
            p = aug[col, col]
            det *= p
            for c in range(n + d):
                aug[col, c] /= p
            for r in range(n):
                if r != col:
                    factor = aug[r, col]
                    if factor != 0.0:
                        for c in range(n + d):
                            aug[r, c] -= factor * aug[col, c]
        volume = math.sqrt(max(det, 0.0)) / factorial
        v0 = simplices[s, 0]
        for i in range(n):
            vi = simplices[s, i + 1]
            star[vi] += volume / width
            for c in range(d):
                k_sum[vi, c] += volume * aug[i, n + c]
                k_sum[v0, c] -= volume * aug[i, n + c]
        star[v0] += volume / width
