"""Compiled passes of the blockwise Morse build (`volseg.morse._blocks`): one block of a
3-D field at a time, with a 1-voxel halo; flat, checked arrays, no defaults.

Voxels are named by their global flat index (C order) ``gid``; "higher" is the
in-memory order, (f(u), gid u) > (f(v), gid v), so every decision a block takes is
the one the in-memory build takes. The halo holds the neighbours' values (-inf
outside the volume); a block's own -inf voxels are outside a mask (docs/design.md
section 9): no path enters them and they reach no maximum (`OUTSIDE`).
"""

import numba
import numpy as np

from .._kernels import UNROLLED, unrolled

#: `ascend`'s result for a voxel whose steepest path leaves the block: -1 - gid of the
#: first voxel outside (always on a neighbouring block's outer layer).
EXIT = -1
#: `ascend`'s result for an owned voxel outside the mask (value -inf).
OUTSIDE = np.iinfo(np.int64).min


@numba.njit(cache=True, nogil=True, inline="always")
def _gid(i, j, k, origin, shape):
    return ((origin[0] + i) * shape[1] + (origin[1] + j)) * shape[2] + (origin[2] + k)


def ascend(halo, origin, shape, offsets, result):
    """result[i, j, k] for each owned voxel: the gid of the maximum its steepest ascent
    reaches inside the block, or -1 - gid of the first voxel outside the block on it,
    or `OUTSIDE` for a voxel of value -inf (outside the mask).

    halo: (a+2, b+2, c+2) float64, C-contiguous; origin: global index of owned voxel
    (0, 0, 0); shape: the volume's shape; offsets: (m, 3) neighbour steps; result:
    (a, b, c) int64, C-contiguous.

    The halo's flat index orders its voxels as their gids do (both are C order, and
    the halo's voxels outside the volume are -inf, never chosen), so a tie is broken
    by the neighbours' flat steps and no gid is computed but an exit's or a maximum's.
    The steepest neighbours are found by a parallel kernel (`_steepest`; under the
    blockwise engine it runs on its task's one thread, and numba's parallel loop
    still ran 10-15 % faster than the plain loop on a 128^3 block), then the paths
    are followed serially (`_resolve`).
    """
    a, b, c = result.shape
    hb, hc = b + 2, c + 2
    steps, fixed = unrolled((offsets[:, 0] * hb + offsets[:, 1]) * hc + offsets[:, 2])
    up = np.empty(a * b * c, dtype=np.int64)       # local index, or -1 - gid when outside
    _steepest(halo.reshape(-1), (a, b, c), origin, shape, offsets, steps, fixed, up)
    _resolve(halo.reshape(-1), (a, b, c), origin, shape, up, result.reshape(-1))


@numba.njit(cache=True, parallel=True)
def _steepest(flat, block, origin, shape, offsets, steps, unrolled, up):
    """up[own]: the local index of the steepest neighbour inside the block, -1 - gid
    of one outside it, or `own` itself (a maximum, or outside the mask: no one climbs
    to it). `steps` padded by 0 to `UNROLLED` when `unrolled` (a loop of known length)."""
    a, b, c = block
    hb, hc = b + 2, c + 2
    for i in numba.prange(a):
        for j in range(b):
            row, halo_row = (i * b + j) * c, ((i + 1) * hb + (j + 1)) * hc + 1
            for k in range(c):
                own, h = row + k, halo_row + k
                best_v = flat[h]
                up[own] = own
                if best_v == -np.inf:
                    continue
                best_s, best_t = 0, -1
                if unrolled:
                    for t in range(UNROLLED):
                        value = flat[h + steps[t]]
                        if value >= best_v and (value > best_v or steps[t] > best_s):
                            best_v, best_s, best_t = value, steps[t], t
                else:
                    for t in range(len(steps)):
                        value = flat[h + steps[t]]
                        if value >= best_v and (value > best_v or steps[t] > best_s):
                            best_v, best_s, best_t = value, steps[t], t
                if best_t < 0:
                    continue
                bi, bj, bk = i + offsets[best_t, 0], j + offsets[best_t, 1], k + offsets[best_t, 2]
                if 0 <= bi < a and 0 <= bj < b and 0 <= bk < c:
                    up[own] = (bi * b + bj) * c + bk
                else:
                    up[own] = -1 - _gid(bi, bj, bk, origin, shape)


@numba.njit(cache=True, nogil=True)
def _resolve(flat, block, origin, shape, up, final):
    """final[own] from `up` (`_steepest`): each path followed to its maximum or exit,
    every voxel on it answered at once; `OUTSIDE` for the voxels of value -inf."""
    a, b, c = block
    hb, hc = b + 2, c + 2
    n = a * b * c
    unknown = np.iinfo(np.int64).min
    final[:] = unknown
    for v in range(n):
        x = v
        while final[x] == unknown and up[x] >= 0 and up[x] != x:
            x = up[x]
        if final[x] != unknown:
            answer = final[x]
        elif up[x] < 0:
            answer = up[x]
        else:  # a maximum of the block
            i, r = divmod(x, b * c)
            j, k = divmod(r, c)
            answer = _gid(i, j, k, origin, shape)
        y = v
        while final[y] == unknown:
            final[y] = answer
            if up[y] < 0 or up[y] == y:
                break
            y = up[y]
    for i in range(a):
        for j in range(b):
            row, halo_row = (i * b + j) * c, ((i + 1) * hb + (j + 1)) * hc + 1
            for k in range(c):
                if flat[halo_row + k] == -np.inf:
                    final[row + k] = OUTSIDE
