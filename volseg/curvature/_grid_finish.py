"""Finishing steps of the grid path: per-vertex curvature from the kernel's sums.

Each function takes the accumulator ``acc`` (channels x padded grid), the slice of
the unpadded voxels, the spacing and optionally the (X, Y, Z) float64 array to write
into, and returns the (X, Y, Z) curvature. What each
channel holds is documented in `_grid_kernels.grid_kernel`.
"""

from __future__ import annotations

import numpy as np


def weighted(acc, inner, h, out=None):
    # sum psi |tau| / (n^2 |p|) with n = 3 and |p| = acc[1] (a quarter of each star volume);
    # in place, so that the peak stays at the accumulator plus the output
    star = acc[1][inner]
    star *= 9.0
    return np.divide(acc[0][inner], star, out=out)


def unweighted(acc, inner, h, out=None):
    if out is None:
        return acc[0][inner].copy()
    out[...] = acc[0][inner]
    return out


def intrinsic(acc, inner, h, out=None):
    return np.subtract(4.0 * np.pi, acc[1][inner], out=out)


def laplace_beltrami(acc, inner, h, out=None):
    # K = acc[2:6] / |p| in place; the normal's last part is 24 V0 everywhere.
    star = acc[1][inner]
    k = acc[2:6][(slice(None),) + inner]
    k /= star
    dot = k[3] * (4.0 * h.prod())
    for c in range(3):
        dot += k[c] * acc[6 + c][inner]
    norm = np.sqrt(np.einsum("c...,c...->...", k, k), out=out)
    norm /= 3.0
    norm[dot < 0] *= -1.0
    return norm
