"""Compiled kernel: a cubic B-spline and its exact gradient at many points, any dimension.

`value_and_gradient` takes flat, checked arrays and has no defaults (the public side
is `mesh_quality._Spline`). The coefficients are those of a field padded by
`PAD` samples per side, so the 4^d support of any point inside the original grid
lies inside the array and no boundary rule is needed here.
"""

from __future__ import annotations

import numba
import numpy as np

PAD = 3


@numba.njit(cache=True)
def _weights(u):
    """Lowest support index, cubic B-spline weights and their derivatives at u."""
    cell = np.floor(u)
    t = u - cell
    s = 1.0 - t
    weights = (s * s * s / 6.0, (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0,
               (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) / 6.0, t * t * t / 6.0)
    slopes = (-0.5 * s * s, 0.5 * (3.0 * t * t - 4.0 * t), 0.5 * (-3.0 * t * t + 2.0 * t + 1.0),
              0.5 * t * t)
    return np.int64(cell) - 1, weights, slopes


@numba.njit(cache=True, parallel=True, nogil=True)
def value_and_gradient_4d(coefficients, strides, upper, index, inverse_spacing, value, gradient):
    """`value_and_gradient` for d = 4, contracting one axis at a time and carrying the
    partial derivatives along (about 800 multiply-adds per point instead of 256 x 20)."""
    for p in numba.prange(index.shape[0]):
        c0, w0, s0 = _weights(min(max(index[p, 0], 0.0), upper[0]) + PAD)
        c1, w1, s1 = _weights(min(max(index[p, 1], 0.0), upper[1]) + PAD)
        c2, w2, s2 = _weights(min(max(index[p, 2], 0.0), upper[2]) + PAD)
        c3, w3, s3 = _weights(min(max(index[p, 3], 0.0), upper[3]) + PAD)
        base = c0 * strides[0] + c1 * strides[1] + c2 * strides[2] + c3 * strides[3]
        v0 = g0 = g1 = g2 = g3 = 0.0
        for i in range(4):
            v1 = a1 = b1 = c1 = 0.0
            for j in range(4):
                v2 = b2 = c2 = 0.0
                for k in range(4):
                    offset = base + i * strides[0] + j * strides[1] + k * strides[2]
                    v3 = c3 = 0.0
                    for m in range(4):
                        c = coefficients[offset + m * strides[3]]
                        v3 += w3[m] * c
                        c3 += s3[m] * c
                    v2 += w2[k] * v3
                    b2 += s2[k] * v3
                    c2 += w2[k] * c3
                v1 += w1[j] * v2
                a1 += s1[j] * v2
                b1 += w1[j] * b2
                c1 += w1[j] * c2
            v0 += w0[i] * v1
            g0 += s0[i] * v1
            g1 += w0[i] * a1
            g2 += w0[i] * b1
            g3 += w0[i] * c1
        value[p] = v0
        gradient[p, 0] = g0 * inverse_spacing[0]
        gradient[p, 1] = g1 * inverse_spacing[1]
        gradient[p, 2] = g2 * inverse_spacing[2]
        gradient[p, 3] = g3 * inverse_spacing[3]


@numba.njit(cache=True, parallel=True, nogil=True)
def value_and_gradient(coefficients, strides, upper, index, inverse_spacing, value, gradient):
    """coefficients: flat float64 (padded field's spline coefficients); strides: (d,)
    int64 element strides; upper: (d,) largest allowed index (original grid units);
    index: (P, d) points in original grid units (clamped into [0, upper]);
    inverse_spacing: (d,); value: (P,) out; gradient: (P, d) out, world units."""
    n_points, d = index.shape
    combos = 4 ** d
    for p in numba.prange(n_points):
        weight = np.empty((d, 4))
        slope = np.empty((d, 4))
        digit = np.empty(d, dtype=np.int64)
        base = 0
        for a in range(d):
            u = min(max(index[p, a], 0.0), upper[a]) + PAD
            first, w, sl = _weights(u)
            for j in range(4):
                weight[a, j] = w[j]
                slope[a, j] = sl[j]
            base += first * strides[a]
        total = 0.0
        partial = np.zeros(d)
        for combo in range(combos):
            rest = combo
            offset = base
            for a in range(d - 1, -1, -1):
                digit[a] = rest % 4
                rest //= 4
                offset += digit[a] * strides[a]
            c = coefficients[offset]
            w = 1.0
            for a in range(d):
                w *= weight[a, digit[a]]
            total += c * w
            for a in range(d):   # the product with axis a's weight replaced by its slope
                q = c * slope[a, digit[a]]
                for b in range(d):
                    if b != a:
                        q *= weight[b, digit[b]]
                partial[a] += q
        value[p] = total
        for a in range(d):
            gradient[p, a] = partial[a] * inverse_spacing[a]
