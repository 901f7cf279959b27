"""The first run's compilation, said when it happens: numba compiles this install's
kernels on their first call (about 30-50 s on 2 cores, in silence otherwise) and
loads them from its cache on every later run.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["FIRST_RUN_NOTE", "noting_compilation"]

#: Measured on this project's 2-core machine: a fresh cache's first `volseg demo` took
#: 36 s, the second 2.0 (benchmarks/bench_first_run.py; 41 s before each operator got
#: a compiled pass of its own), rounded to a range for slower machines.
FIRST_RUN_NOTE = ("compiling the numba kernels (first run after an install only, about "
                  "25-45 s; cached for every later run)")


@contextmanager
def noting_compilation(say):
    """Inside the block, `say` `FIRST_RUN_NOTE` once when numba starts compiling a
    kernel in this process: a cache miss, not a load from the cache (numba's
    ``numba:compile`` event fires only then). A cluster's worker processes compile in
    silence."""
    from numba.core import event

    class Note(event.Listener):
        said = False

        def on_start(self, ev):
            if not self.said:
                self.said = True
                say(FIRST_RUN_NOTE)

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", Note()):
        yield
