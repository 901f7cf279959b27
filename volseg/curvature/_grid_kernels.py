"""Compiled Kuhn-stencil kernel: curvature of a volume's graph without building tetrahedra.

Every cube of the grid is split the same way, so one cube's 6 tetrahedra and 12
triangles (6 inside the cube, 6 on its three low sides, paired with the neighbouring
cube's tetrahedra) describe the whole tessellation; tables built in `_grid.py` give
their vertex offsets. On a graph with upward normals a tetrahedron is fixed by its
gradient g: normal (-g, 1)/W, W = sqrt(1 + |g|^2), volume V0 W. Cube slabs along x
are processed in two passes (even, then odd slabs) so that parallel slabs never
write the same vertex.
"""

import math

import numba
import numpy as np

from ._registry import GRID_CODES

WEIGHTED, UNWEIGHTED = GRID_CODES["weighted"], GRID_CODES["unweighted"]
LAPLACE_BELTRAMI, INTRINSIC = GRID_CODES["laplace_beltrami"], GRID_CODES["intrinsic"]


@numba.njit(cache=True, nogil=True)
def _slab(fp, i, h, operator, tables, lb_b, acc):
    """One slab of cubes (x index i). `tables` come from `_grid._tables` (see there)."""
    offsets, path_idx, axes, face_idx, face_side, face_ub, face_vb, face_cross2, face_tets = tables
    nx, ny, nz = fp.shape
    cv = np.empty(11)
    grads = np.empty((12, 3))
    w = np.empty(12)
    valid = np.empty(12, dtype=np.bool_)
    v0 = h[0] * h[1] * h[2] / 6.0
    e = np.empty((3, 4))
    for j in range(ny - 1):
        for k in range(nz - 1):
            for c in range(11):
                ox, oy, oz = offsets[c, 0], offsets[c, 1], offsets[c, 2]
                a, b, cc = i + ox, j + oy, k + oz
                if a < 0 or b < 0 or cc < 0:
                    cv[c] = 0.0
                else:
                    cv[c] = fp[a, b, cc]
            for t in range(12):
                valid[t] = True
                if t >= 6:
                    c = axes[t, 0]  # the neighbour cube lies below along its first axis
                    if (c == 0 and i == 0) or (c == 1 and j == 0) or (c == 2 and k == 0):
                        valid[t] = False
                        continue
                for s in range(3):
                    grads[t, axes[t, s]] = (cv[path_idx[t, s + 1]] - cv[path_idx[t, s]]) / h[axes[t, s]]
                if t < 6:
                    gx, gy, gz = grads[t, 0], grads[t, 1], grads[t, 2]
                    w[t] = math.sqrt(1.0 + gx * gx + gy * gy + gz * gz)
            # Faces: bending angle, weighted by area for the weighted operator.
            if operator == WEIGHTED or operator == UNWEIGHTED:
                for fi in range(12):
                    ta = face_tets[fi, 0]
                    tb = face_tets[fi, 1]
                    if not valid[tb]:
                        continue
                    ga0, ga1, ga2 = grads[ta, 0], grads[ta, 1], grads[ta, 2]
                    gb0, gb1, gb2 = grads[tb, 0], grads[tb, 1], grads[tb, 2]
                    dgx, dgy, dgz = gb0 - ga0, gb1 - ga1, gb2 - ga2
                    cx = ga1 * gb2 - ga2 * gb1
                    cy = ga2 * gb0 - ga0 * gb2
                    cz = ga0 * gb1 - ga1 * gb0
                    sin_part = math.sqrt(dgx * dgx + dgy * dgy + dgz * dgz + cx * cx + cy * cy + cz * cz)
                    cos_part = 1.0 + ga0 * gb0 + ga1 * gb1 + ga2 * gb2
                    psi = math.atan2(sin_part, cos_part)
                    if dgx * face_side[fi, 0] + dgy * face_side[fi, 1] + dgz * face_side[fi, 2] > 0.0:
                        psi = -psi
                    p0 = face_idx[fi, 0]
                    if operator == WEIGHTED:
                        # |u ^ v|^2 = |u_b x v_b|^2 + |du v_b - dv u_b|^2 for u = (u_b, du).
                        du = cv[face_idx[fi, 1]] - cv[p0]
                        dv = cv[face_idx[fi, 2]] - cv[p0]
                        mx = du * face_vb[fi, 0] - dv * face_ub[fi, 0]
                        my = du * face_vb[fi, 1] - dv * face_ub[fi, 1]
                        mz = du * face_vb[fi, 2] - dv * face_ub[fi, 2]
                        psi *= 0.5 * math.sqrt(face_cross2[fi] + mx * mx + my * my + mz * mz)
                    for s in range(3):
                        q = face_idx[fi, s]
                        acc[0, i + offsets[q, 0], j + offsets[q, 1], k + offsets[q, 2]] += psi
            # Tetrahedra: barycentric volume, volume gradients, solid angles.
            for t in range(6):
                vol = v0 * w[t]
                for s in range(4):
                    q = path_idx[t, s]
                    a, b, c = i + offsets[q, 0], j + offsets[q, 1], k + offsets[q, 2]
                    if operator != INTRINSIC:
                        acc[1, a, b, c] += 0.25 * vol
                    if operator == LAPLACE_BELTRAMI:
                        bx, by, bz = lb_b[t, s, 0], lb_b[t, s, 1], lb_b[t, s, 2]
                        gb = (grads[t, 0] * bx + grads[t, 1] * by + grads[t, 2] * bz) / (w[t] * w[t])
                        acc[2, a, b, c] += vol * (bx - grads[t, 0] * gb)
                        acc[3, a, b, c] += vol * (by - grads[t, 1] * gb)
                        acc[4, a, b, c] += vol * (bz - grads[t, 2] * gb)
                        acc[5, a, b, c] += vol * gb
                        acc[6, a, b, c] -= v0 * grads[t, 0]
                        acc[7, a, b, c] -= v0 * grads[t, 1]
                        acc[8, a, b, c] -= v0 * grads[t, 2]
                    elif operator == INTRINSIC:
                        r = 0
                        for o in range(4):
                            if o == s:
                                continue
                            qo = path_idx[t, o]
                            e[r, 0] = (offsets[qo, 0] - offsets[q, 0]) * h[0]
                            e[r, 1] = (offsets[qo, 1] - offsets[q, 1]) * h[1]
                            e[r, 2] = (offsets[qo, 2] - offsets[q, 2]) * h[2]
                            e[r, 3] = cv[qo] - cv[q]
                            r += 1
                        lu = math.sqrt(e[0, 0] ** 2 + e[0, 1] ** 2 + e[0, 2] ** 2 + e[0, 3] ** 2)
                        lv = math.sqrt(e[1, 0] ** 2 + e[1, 1] ** 2 + e[1, 2] ** 2 + e[1, 3] ** 2)
                        lw = math.sqrt(e[2, 0] ** 2 + e[2, 1] ** 2 + e[2, 2] ** 2 + e[2, 3] ** 2)
                        uv = e[0, 0] * e[1, 0] + e[0, 1] * e[1, 1] + e[0, 2] * e[1, 2] + e[0, 3] * e[1, 3]
                        uw = e[0, 0] * e[2, 0] + e[0, 1] * e[2, 1] + e[0, 2] * e[2, 2] + e[0, 3] * e[2, 3]
                        vw = e[1, 0] * e[2, 0] + e[1, 1] * e[2, 1] + e[1, 2] * e[2, 2] + e[1, 3] * e[2, 3]
                        denominator = lu * lv * lw + uv * lw + uw * lv + vw * lu
                        acc[1, a, b, c] += 2.0 * math.atan2(6.0 * vol, denominator)


@numba.njit(cache=True, parallel=True)
def grid_kernel(fp, h, operator, tables, lb_b, acc):
    """Accumulate per-vertex sums over the padded grid `fp` into `acc` (m, *fp.shape).

    acc[0]: sum psi |tau| (weighted) or sum psi (unweighted); acc[1]: sum |sigma|/4
    (or, for intrinsic, the sum of solid angles); for Laplace-Beltrami acc[2:6] the
    sum of |sigma| grad(phi_p) and acc[6:9] the x, y, z parts of the sum of
    |sigma| nu (its last part is 24 V0 at every vertex with a full star).
    """
    n_slabs = fp.shape[0] - 1
    for parity in range(2):
        for half in numba.prange((n_slabs - parity + 1) // 2):
            _slab(fp, 2 * half + parity, h, operator, tables, lb_b, acc)
