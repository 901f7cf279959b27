"""The floor of the weighted grid curvature: only the arithmetic no kernel can avoid.

Per cube: the 11 values, 12 tetrahedron gradients, the 12 bending angles times their
triangles' areas (`volseg.curvature._atan.angle_times_root`: one square root and the
rational for a small angle), 6 tetrahedron volumes (one square root each); no tables,
no scatter, no accumulator: a per-slab sum keeps the
compiler from dropping the work. A kernel that also stores its results cannot be
faster than this one; `bench_kernels.py` reports the fraction of its speed reached.
"""

import math

import numba
import numpy as np

from volseg.curvature._atan import angle_times_root


@numba.njit(cache=True, nogil=True)
def _floor_slab(fp, i, h):
    ny, nz = fp.shape[1], fp.shape[2]
    hx, hy, hz = 1.0 / h[0], 1.0 / h[1], 1.0 / h[2]
    total = 0.0
    for j in range(ny - 1):
        for k in range(nz - 1):
            f000 = fp[i, j, k]
            f001 = fp[i, j, k + 1]
            f010 = fp[i, j + 1, k]
            f011 = fp[i, j + 1, k + 1]
            f100 = fp[i + 1, j, k]
            f101 = fp[i + 1, j, k + 1]
            f110 = fp[i + 1, j + 1, k]
            f111 = fp[i + 1, j + 1, k + 1]
            for t in range(12):  # 12 faces: two gradients, an angle, an area
                a = (f100 - f000) * hx + t * 1e-3
                b = (f110 - f100) * hy
                c = (f111 - f110) * hz
                d = (f001 - f000) * hz
                e = (f011 - f001) * hy
                g = (f111 - f011 + f101 - f010) * hx
                dx, dy, dz = a - g, b - e, c - d
                cx = b * d - c * e
                cy = c * g - a * d
                cz = a * e - b * g
                s2 = dx * dx + dy * dy + dz * dz + cx * cx + cy * cy + cz * cz
                total += angle_times_root(s2, 1.0 + a * g + b * e + c * d, 1.0 + a * a + d * d)
            for t in range(6):  # 6 volumes
                total += math.sqrt(1.0 + (f100 - f000) ** 2 + (f010 - f000) ** 2 + t)
    return total


@numba.njit(cache=True, parallel=True)
def floor_kernel(fp, h):
    n = fp.shape[0] - 1
    out = np.zeros(n)
    for i in numba.prange(n):
        out[i] = _floor_slab(fp, i, h)
    return out.sum()
