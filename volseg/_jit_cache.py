"""Whether numba has this install's kernels cached: the first run after an install
compiles them (about 30 s on 2 cores, in silence otherwise), every later run loads them.
"""

from __future__ import annotations

import os

__all__ = ["uncompiled", "first_run_note"]

#: Measured on this project's 2-core machine: a clean worktree's first `volseg demo`
#: took 29.9 s, the second 3.0 s (benchmarks/bench_first_run.py), rounded.
FIRST_RUN_SECONDS = 30


def uncompiled(kernels) -> list[str]:
    """The names of the cached numba `kernels` that have no cache index on disk yet
    (each will be compiled when first called). Kernels without caching, and a numba
    whose cache layout is not the one read here, count as compiled."""
    missing = []
    for kernel in kernels:
        try:
            index = kernel._cache._cache_file._index_path
        except AttributeError:           # not a cached dispatcher (or another numba)
            continue
        if not os.path.exists(index):
            missing.append(f"{kernel.__module__}.{kernel.__name__}")
    return missing


def first_run_note(kernels) -> str | None:
    """One line before the first run's compilation when one of `kernels` (the entry
    kernels of a command: `volseg.curvature.entry_kernels`, ...) is not cached yet;
    None otherwise."""
    if not uncompiled(kernels):
        return None
    return (f"compiling the numba kernels (first run after an install only, about "
            f"{FIRST_RUN_SECONDS} s; cached for every later run)")
