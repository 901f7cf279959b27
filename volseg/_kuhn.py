"""The Kuhn (Freudenthal) split of a grid cube, in any dimension: the one place it is written.

Every cube of a grid is split into d! simplices, one per permutation (a, b, ...) of
the axes, along the path ``0 -> e_a -> e_a + e_b -> ... -> (1, ..., 1)`` from the
cube's lowest corner; the same split everywhere makes the tessellation conforming
(docs/design.md section 4). Its edges join grid points whose difference is a nonzero 0/1
vector or the negative of one. This is a leaf module (numpy only): the tessellations,
the grid curvature's stencil tables and the Morse stage's grid neighbourhood read it.
"""

from __future__ import annotations

import itertools
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

__all__ = ["axis_orders", "cube_paths", "permutation_sign", "neighbour_offsets"]


@lru_cache(maxsize=None)
def axis_orders(d: int) -> tuple[tuple[int, ...], ...]:
    """The d! axis permutations, in the order every table of volseg uses."""
    return tuple(itertools.permutations(range(d)))


def cube_paths(d: int) -> NDArray[np.intp]:
    """(d!, d+1, d) corner offsets of the cube's simplices, one path per axis order."""
    out = np.zeros((len(axis_orders(d)), d + 1, d), dtype=np.intp)
    for t, order in enumerate(axis_orders(d)):
        for s, axis in enumerate(order):
            out[t, s + 1] = out[t, s]
            out[t, s + 1, axis] += 1
    return out


def permutation_sign(perm) -> int:
    """+1 for an even permutation, -1 for an odd one."""
    sign = 1
    perm = list(perm)
    for i in range(len(perm)):
        for j in range(i + 1, len(perm)):
            if perm[i] > perm[j]:
                sign = -sign
    return sign


def neighbour_offsets(d: int) -> NDArray[np.intp]:
    """(2^(d+1) - 2, d) offsets of a vertex's Kuhn neighbours (3-D: 14, 2-D: 6, 1-D: 2)."""
    steps = [s for s in itertools.product((-1, 0, 1), repeat=d) if any(s)]
    chosen = [s for s in steps if min(s) >= 0 or max(s) <= 0]
    return np.array(chosen, dtype=np.intp).reshape(-1, d)
