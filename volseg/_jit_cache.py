"""The first run's compilation, said when it happens: numba compiles this install's
kernels on their first call (about 20-35 s on 2 cores, in silence otherwise) and
loads them from its cache on every later run.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["FIRST_RUN_NOTE", "noting_compilation"]

#: Measured on this project's 2-core machine: a fresh cache's first `volseg demo` took
#: 24.9-25.5 s, the second 2.4 (benchmarks/bench_first_run.py, 2026-12-06; 30.6-37.3 s
#: before the angle's slow path became a call), rounded to a range for slower machines.
FIRST_RUN_NOTE = ("compiling the numba kernels (first run after an install only, about "
                  "20-35 s; cached for every later run)")


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
