"""Compiled Kuhn-stencil kernels: curvature of a volume's graph without building tetrahedra.

Every cube of the grid is split the same way, so one cube's 6 tetrahedra and 12
triangles (6 inside the cube, 6 on its three low sides, paired with the neighbouring
cube's tetrahedra) describe the whole tessellation; tables built in `_grid.py` give
their vertex offsets. On a graph with upward normals a tetrahedron is fixed by its
gradient g: normal (-g, 1)/W, W = sqrt(1 + |g|^2), volume V0 W. Cube slabs along x
are processed in two passes (even, then odd slabs) so that parallel slabs never
write the same vertex.

The per-operator work of the extrinsic operators and Laplace-Beltrami is unrolled in
`_grid_stencil.py` (generated from the tables by `_stencil_codegen.py`), their face
angles by `_atan`; the intrinsic operator, not on any hot path, reads the tables at
run time here. (numba's cache keys a kernel on its own file only: after changing a
kernel it calls from another module, touch this file or clear `__pycache__`, or the
cached `grid_kernel` keeps the old callee.)
"""

import math

import numba
import numpy as np

from ._grid_stencil import laplace_beltrami_slab, unweighted_slab, weighted_slab
from ._registry import GRID_CODES

WEIGHTED, UNWEIGHTED = GRID_CODES["weighted"], GRID_CODES["unweighted"]
LAPLACE_BELTRAMI, INTRINSIC = GRID_CODES["laplace_beltrami"], GRID_CODES["intrinsic"]


@numba.njit(cache=True, nogil=True)
def _intrinsic_slab(fp, i, h, tables, acc):
    """Solid angles at the corners of one slab of cubes (x index i), summed into acc[1]."""
    offsets, path_idx, axes = tables[0], tables[1], tables[2]
    ny, nz = fp.shape[1], fp.shape[2]
    cv = np.empty(8)
    g = np.empty(3)
    e = np.empty((3, 4))
    v0 = h[0] * h[1] * h[2] / 6.0
    for j in range(ny - 1):
        for k in range(nz - 1):
            for c in range(8):
                cv[c] = fp[i + offsets[c, 0], j + offsets[c, 1], k + offsets[c, 2]]
            for t in range(6):
                for s in range(3):
                    g[axes[t, s]] = (cv[path_idx[t, s + 1]] - cv[path_idx[t, s]]) / h[axes[t, s]]
                vol = v0 * math.sqrt(1.0 + g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
                for s in range(4):
                    q = path_idx[t, s]
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
                    uv = (e[0, 0] * e[1, 0] + e[0, 1] * e[1, 1]
                          + e[0, 2] * e[1, 2] + e[0, 3] * e[1, 3])
                    uw = (e[0, 0] * e[2, 0] + e[0, 1] * e[2, 1]
                          + e[0, 2] * e[2, 2] + e[0, 3] * e[2, 3])
                    vw = (e[1, 0] * e[2, 0] + e[1, 1] * e[2, 1]
                          + e[1, 2] * e[2, 2] + e[1, 3] * e[2, 3])
                    denominator = lu * lv * lw + uv * lw + uw * lv + vw * lu
                    acc[1, i + offsets[q, 0], j + offsets[q, 1], k + offsets[q, 2]] += (
                        2.0 * math.atan2(6.0 * vol, denominator))


def grid_kernel(fp, h, operator, tables, acc, first_parity=0):
    """Accumulate per-vertex sums over the padded grid `fp` into `acc` (m, *fp.shape).

    Slabs of cubes (one x layer each) run in two parallel passes, those of parity
    `first_parity` first: a block of a larger grid passes the parity of its first slab
    in the whole grid, so every vertex gets its sums in the same order as in memory
    (the blockwise result is then bit-identical).

    acc[0]: sum psi |tau| (weighted) or sum psi (unweighted); acc[1]: sum |sigma|/4
    (or, for intrinsic, the sum of solid angles); for Laplace-Beltrami acc[2:6] the
    sum of |sigma| grad(phi_p) and acc[6:9] the x, y, z parts of the sum of
    |sigma| nu (its last part is 24 V0 at every vertex with a full star).

    Each operator has a compiled pass of its own, chosen here: a first run compiles
    only the operator it uses (one pass for all four compiled every stencil, 9 of
    the 38 CPU-s a first `volseg segment` spent compiling). Four passes of the same
    shape rather than one taking its slab function as an argument: numba caches no
    function that takes another (it compiled again on every run).
    """
    _PASSES[operator](fp, h, tables, acc, first_parity)


@numba.njit(cache=True, nogil=True, inline="always")
def _slabs(fp, turn, first_parity):
    """(the count of slabs of this turn's parity, that parity): slab i = 2 half + parity."""
    parity = (turn + first_parity) % 2   # the local parity of the global first pass
    return (fp.shape[0] - 1 - parity + 1) // 2, parity


@numba.njit(cache=True, parallel=True)
def _weighted_pass(fp, h, tables, acc, first_parity):
    fpf, flat = fp.reshape(-1), acc.reshape(acc.shape[0], -1)
    for turn in range(2):
        count, parity = _slabs(fp, turn, first_parity)
        for half in numba.prange(count):
            weighted_slab(fpf, fp.shape, 2 * half + parity, h, tables[3], flat[0], flat[1])


@numba.njit(cache=True, parallel=True)
def _unweighted_pass(fp, h, tables, acc, first_parity):
    fpf, flat = fp.reshape(-1), acc.reshape(acc.shape[0], -1)
    for turn in range(2):
        count, parity = _slabs(fp, turn, first_parity)
        for half in numba.prange(count):
            unweighted_slab(fpf, fp.shape, 2 * half + parity, h, tables[3], flat[0], flat[1])


@numba.njit(cache=True, parallel=True)
def _laplace_beltrami_pass(fp, h, tables, acc, first_parity):
    fpf, flat = fp.reshape(-1), acc.reshape(acc.shape[0], -1)
    for turn in range(2):
        count, parity = _slabs(fp, turn, first_parity)
        for half in numba.prange(count):
            laplace_beltrami_slab(fpf, fp.shape, 2 * half + parity, h, flat)


@numba.njit(cache=True, parallel=True)
def _intrinsic_pass(fp, h, tables, acc, first_parity):
    for turn in range(2):
        count, parity = _slabs(fp, turn, first_parity)
        for half in numba.prange(count):
            _intrinsic_slab(fp, 2 * half + parity, h, tables, acc)


_PASSES = {WEIGHTED: _weighted_pass, UNWEIGHTED: _unweighted_pass,
           LAPLACE_BELTRAMI: _laplace_beltrami_pass, INTRINSIC: _intrinsic_pass}
