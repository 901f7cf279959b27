"""Intrinsic distortion: angle deficit (n = 2), solid-angle deficit (n = 3)."""

from __future__ import annotations

import numpy as np


def _angle(u, v):
    """Accurate angle between rows of u and v (Kahan's half-angle form)."""
    un = u / np.linalg.norm(u, axis=1, keepdims=True)
    vn = v / np.linalg.norm(v, axis=1, keepdims=True)
    return 2.0 * np.arctan2(np.linalg.norm(un - vn, axis=1), np.linalg.norm(un + vn, axis=1))


def _solid_angle(u, v, w, volumes):
    """Solid angle spanned by edge vectors u, v, w (rows); sqrt(det G) = 6 |sigma|."""
    lu, lv, lw = (np.linalg.norm(x, axis=1) for x in (u, v, w))
    dot = lambda a, b: np.einsum("ij,ij->i", a, b)  # noqa: E731
    denominator = lu * lv * lw + dot(u, v) * lw + dot(u, w) * lv + dot(v, w) * lu
    return 2.0 * np.arctan2(6.0 * volumes, denominator)


def intrinsic_distortion(parts):
    """2 pi minus the angles at p (n = 2), 4 pi minus the solid angles (n = 3)."""
    vertices, simplices, volumes = parts.vertices, parts.simplices, parts.volumes
    n = simplices.shape[1] - 1
    n_vertices = len(vertices)
    total = np.zeros(n_vertices)
    width = n + 1
    for c in range(width):
        others = [simplices[:, (c + k) % width] for k in range(1, width)]
        apex = vertices[simplices[:, c]]
        edges = [vertices[o] - apex for o in others]
        if n == 2:
            angle = _angle(*edges)
        else:
            angle = _solid_angle(*edges, volumes)
        total += np.bincount(simplices[:, c], weights=angle, minlength=n_vertices)
    full = 2.0 * np.pi if n == 2 else 4.0 * np.pi
    return full - total
