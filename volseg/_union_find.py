"""Union-find, compiled: the one `find_root` of the Morse kernels and the mesh's
star test (a leaf: numba and numpy only)."""

import numba

__all__ = ["find_root"]


@numba.njit(cache=True, nogil=True, inline="always")
def find_root(parent, x):
    """The root of `x` in the forest `parent`, halving the path on the way."""
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x
