"""The local cluster's worker plugin that makes numba take the worker's environment."""

from __future__ import annotations

from distributed import WorkerPlugin

__all__ = ["NumbaThreadsFromEnvironment"]


class NumbaThreadsFromEnvironment(WorkerPlugin):
    """A worker plugin: numba's configuration read again once the worker has its
    environment (``NUMBA_NUM_THREADS=1``), before any task launches numba's threads.

    A script that imports volseg at its top imports numba in each spawned worker (as
    ``__mp_main__``) before the nanny sets the worker's environment: numba then keeps
    the default (one thread per core), launches that many threads at the first
    parallel kernel, and the next compilation, which reads the environment, fails
    ("Cannot set NUMBA_NUM_THREADS to a different value once the threads have been
    launched"). ``python -m volseg`` imports nothing there."""

    def setup(self, worker):
        from numba.core import config

        config.reload_config()
