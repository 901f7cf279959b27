"""`SizedByArrays`: a task result's size as the numpy arrays it holds count it.

A Dask worker accounts its memory, and the scheduler prices moving a result, by
`dask.sizeof.sizeof`, which for an object of our own falls back to `sys.getsizeof`:
about 100 bytes for a hierarchy's bucket of 2 million maxima (80 MB). The workers
then counted most of the Morse stage's results as unmanaged memory (which they
cannot spill), and the scheduler placed their readers as if moving them cost nothing.
"""

from __future__ import annotations

import sys

import numpy as np

__all__ = ["SizedByArrays", "held_bytes"]


def held_bytes(value) -> int:
    """The bytes `value` holds: a numpy array's buffer, a tuple's, list's or dict's
    items, an object's own `__sizeof__` (so nested `SizedByArrays` count theirs)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, tuple | list):
        return sys.getsizeof(value) + sum(held_bytes(v) for v in value)
    if isinstance(value, dict):
        return sys.getsizeof(value) + sum(held_bytes(v) for v in value.values())
    return sys.getsizeof(value)


class SizedByArrays:
    """Mixin: ``sys.getsizeof(self)`` (and so dask's `sizeof`) counts the arrays in
    the object's attributes (its ``__dict__`` or ``__slots__``)."""

    __slots__ = ()

    def __sizeof__(self) -> int:
        names = vars(self) if hasattr(self, "__dict__") else {
            n: getattr(self, n) for n in type(self).__slots__ if hasattr(self, n)}
        return object.__sizeof__(self) + sum(held_bytes(v) for v in names.values())
