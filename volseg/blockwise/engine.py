"""Where blockwise work runs: a local `dask.distributed` cluster, an existing one, or
Dask's threaded scheduler in this process.

    with Engine("local", workers=2, memory_limit="12GB") as engine:   # a LocalCluster
        engine.compute(lazy, stage="curvature")

- ``scheduler=None`` or ``"threads"`` (default): Dask's threaded scheduler in this
  process, `workers` threads (default: one per core). The compiled kernels release
  the GIL, and on one machine this is the fastest engine: on 2 cores a local
  cluster of 2 worker processes took 2.5x as long end to end at 256^3 (77.9 s
  against 31.6 s, benchmarks/bench_blockwise.py; the distributed scheduler's
  per-task work and the halos' transfers between processes compete with the
  kernels for the same cores).
  Each worker thread runs numba's parallel loops on one thread, so `workers` is the
  number of cores used. Memory is bounded by Dask's ordering of the blocks, not
  enforced.
- ``scheduler="local"``: a `LocalCluster` of `workers` processes, `threads_per_worker`
  threads each (default one), whose memory limits sum to `memory_limit` (default
  `default_memory_limit()`, half of this machine's RAM); Dask's worker memory manager
  then spills, pauses and restarts workers against that limit. Threads of one worker
  share its blocks without a transfer: a multi-node cluster is usually run as one
  worker of several threads per node, and on one machine one worker of 2 threads
  moves no block between processes (`docs/cluster.md` has the figures).
- ``scheduler="tcp://host:port"``: connect to a running scheduler (`EngineError`,
  a `ValueError`, when it cannot be reached within `timeout` seconds). Its workers
  must see the same file system as this process (inputs, outputs and the run's work
  folder are paths).

The Morse build joins the whole hierarchy (the maxima in order and the merge events,
about 150 bytes per maximum with the cut's temporaries) in one task, and cuts it in
another beside it (`volseg.morse.HierarchyOnWorkers`). On a cluster with a worker of
the resource `HIERARCHY_RESOURCE` those tasks run there and nowhere else (`persist`
with ``hierarchy=True``), so the block workers can be small and one worker large:
``hierarchy_memory`` adds that worker to a local cluster; on a running cluster, start
one worker with ``--resources volseg_hierarchy=1`` (`docs/cluster.md`).

A script that starts a local cluster needs the ``if __name__ == "__main__":`` guard
(its worker processes are spawned and import the script).

While the engine is entered, every Dask computation of this process runs on it (a
distributed `Client` becomes Dask's default). `compute` runs collections with a
progress bar on stderr, named by the stage, when `progress` is true.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from ..errors import EngineError  # noqa: F401 (re-exported)

__all__ = ["Engine", "EngineError", "HIERARCHY_RESOURCE", "default_memory_limit",
           "parse_bytes"]

MEMORY_SHARE = 0.5          # of physical RAM, the default budget of a local cluster
CONNECT_TIMEOUT = 10.0      # seconds to reach a running scheduler
WORKER_START_TIMEOUT = 120.0    # seconds for a local cluster's hierarchy worker to join
#: A local cluster's worker below this memory pauses for good (its interpreter, numba
#: and a block use about that much): refused up front instead.
MIN_WORKER_MEMORY = 256 * 2**20
#: The Dask worker resource of the one worker that holds a blockwise run's whole
#: hierarchy (`Engine.persist`).
HIERARCHY_RESOURCE = "volseg_hierarchy"


def _return_freed_memory():
    """Make glibc give freed memory back to the system, as dask.distributed does for
    its workers (MALLOC_TRIM_THRESHOLD_=65536): setting the trim threshold also stops
    glibc raising its mmap threshold after each large free, which otherwise keeps
    the freed blocks' memory in this process (measured on one 512^3 blockwise run,
    same code: peak RSS 2.6 GB with glibc's defaults, 1.7 GB with MALLOC_TRIM_THRESHOLD_
    and MALLOC_MMAP_THRESHOLD_ set in the environment). No effect where there is no
    mallopt."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(-1, 65536)        # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


def _one_numba_thread():
    import numba

    numba.set_num_threads(1)      # thread-local: this worker thread only


def physical_memory() -> int:
    """The physical memory of this machine, in bytes."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def default_memory_limit() -> int:
    """`MEMORY_SHARE` of this machine's physical memory, in bytes."""
    return int(MEMORY_SHARE * physical_memory())


def parse_bytes(text, option: str = "--memory-limit") -> int:
    """'12GB', '800MiB', '0.5' (a share of RAM when < 1) or a number of bytes; the
    error names `option`."""
    from dask.utils import parse_bytes as dask_bytes

    try:
        value = float(text)
    except (TypeError, ValueError):
        try:
            value = float(dask_bytes(str(text)))
        except (TypeError, ValueError):
            raise EngineError(f"{option} {text!r}: expected bytes (e.g. 12GB, 800MiB) "
                              "or a share of RAM below 1 (e.g. 0.5)") from None
    if not (value > 0 and math.isfinite(value)):            # NaN, inf, 0, negative
        raise EngineError(f"{option} must be a positive finite size, got {text!r}")
    return int(value * physical_memory()) if value < 1 else int(value)


def _answers(address: str, seconds: float) -> None:
    """Raise unless a Dask scheduler at `address` answers an identity request within
    `seconds` (a server that accepts the connection and never answers would hold
    distributed's Client, half made and already Dask's default, forever)."""
    import asyncio

    from distributed.comm import connect

    async def identity():
        comm = await connect(address, timeout=seconds)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        asyncio.run(asyncio.wait_for(identity(), seconds))
    except asyncio.TimeoutError:
        raise TimeoutError(f"no answer within {seconds:g} s") from None


class Engine:
    """A context manager: the Dask engine of a blockwise run (see the module)."""

    def __init__(self, scheduler: str | None = None, *, workers: int | None = None,
                 memory_limit=None, hierarchy_memory=None, progress: bool = False,
                 timeout: float | None = None, threads_per_worker: int = 1):
        if workers is not None and workers < 1:
            raise EngineError(f"--workers must be at least 1, got {workers}")
        if threads_per_worker < 1:
            raise EngineError(f"--threads-per-worker must be at least 1, got "
                              f"{threads_per_worker}")
        if threads_per_worker != 1 and scheduler != "local":
            raise EngineError("--threads-per-worker sets the local cluster's workers "
                              "(--scheduler local); with threads, --workers is the threads; "
                              "a running cluster's workers have their own (dask worker "
                              "--nthreads)")
        self.threads_per_worker = threads_per_worker
        self.scheduler = scheduler
        self.workers = workers or os.cpu_count() or 1
        self.memory_limit = (default_memory_limit() if memory_limit is None
                             else parse_bytes(memory_limit))
        if hierarchy_memory is not None and scheduler != "local":
            raise EngineError(
                "--hierarchy-memory adds a worker to the local cluster (--scheduler local); "
                f"on a running cluster start one worker with --resources {HIERARCHY_RESOURCE}=1")
        #: The memory of the local cluster's hierarchy worker (`persist`), or None.
        self.hierarchy_memory = (None if hierarchy_memory is None
                                 else parse_bytes(hierarchy_memory, "--hierarchy-memory"))
        if self.hierarchy_memory is not None and self.hierarchy_memory < MIN_WORKER_MEMORY:
            raise EngineError(f"--hierarchy-memory {self.hierarchy_memory / 2**20:.0f} MiB is "
                              f"less than the {MIN_WORKER_MEMORY // 2**20} MiB a worker needs")
        self._hierarchy_worker = False
        self.progress = progress
        self.timeout = CONNECT_TIMEOUT if timeout is None else timeout
        self.client = None
        self._stack = contextlib.ExitStack()
        #: Per compute on a cluster: the stage, its seconds, the bytes its workers sent
        #: (to each other and to the client), the bytes the client received and the
        #: client's peak memory so far.
        self.stages: list[dict] = []

    @property
    def threaded(self) -> bool:
        """Whether blocks run on threads of this process (no scheduler)."""
        return self.scheduler in (None, "threads")

    @property
    def threads(self) -> int | None:
        """The threads that run tasks at once: known for threads and the local cluster
        (its hierarchy worker aside), None for a running cluster (it may grow)."""
        if self.threaded:
            return self.workers
        return self.workers * self.threads_per_worker if self.scheduler == "local" else None

    def describe(self) -> str:
        """One line naming the engine and its limits, for progress and summaries."""
        if self.threaded:
            return f"Dask threads ({self.workers})"
        if self.scheduler == "local":
            extra = ("" if self.hierarchy_memory is None else
                     f", and one of {self.hierarchy_memory / 2**30:.1f} GiB for the hierarchy")
            threads = ("" if self.threads_per_worker == 1
                       else f" of {self.threads_per_worker} threads")
            return (f"local Dask cluster ({self.workers} workers{threads}, "
                    f"{self.memory_limit / self.workers / 2**30:.1f} GiB each{extra})")
        return f"Dask scheduler {self.scheduler}" + (
            " (and a worker for the hierarchy)" if self._hierarchy_worker else "")

    def __enter__(self) -> Engine:
        import dask

        try:
            if self.threaded:
                _return_freed_memory()
                # Each worker thread runs numba's parallel loops on one thread: the
                # workers are the parallelism (nested, N workers would run N x cores
                # OpenMP threads spinning against each other), and --workers 1 is one core.
                pool = self._stack.enter_context(
                    ThreadPoolExecutor(self.workers, initializer=_one_numba_thread))
                self._stack.enter_context(dask.config.set(scheduler="threads", pool=pool,
                                                          num_workers=self.workers))
            else:
                # Rechunking by tasks: the blocks' rechunks are small, and the
                # peer-to-peer shuffle logs a warning per rechunk.
                self._stack.enter_context(dask.config.set({"array.rechunk.method": "tasks"}))
                self.client = self._stack.enter_context(self._client())
                if self.hierarchy_memory is not None:
                    try:
                        self.client.wait_for_workers(self.workers + 1,
                                                     timeout=WORKER_START_TIMEOUT)
                    except TimeoutError:
                        raise EngineError("--hierarchy-memory: the local cluster's hierarchy "
                                          f"worker did not start within "
                                          f"{WORKER_START_TIMEOUT:g} s") from None
                self._hierarchy_worker = any(
                    HIERARCHY_RESOURCE in (w.get("resources") or {})
                    for w in self.client.scheduler_info()["workers"].values())
        except BaseException:
            self._stack.close()
            raise
        return self

    def __exit__(self, kind, error, traceback):
        self._stack.close()
        self.client, self._hierarchy_worker = None, False
        if kind is not None and kind.__name__ == "KilledWorker":     # outside `compute`
            raise self._over_limit(_KILLED) from None

    def check(self) -> None:
        """For a scheduler address: connect once now, so that an unreachable one is an
        `EngineError` before anything is read, whichever path the inputs take."""
        if not self.threaded and self.scheduler != "local":
            with self:
                pass

    def _client(self):
        import logging

        import dask
        from distributed import Client, LocalCluster

        # Its INFO lines (worker start, shutdown) are not volseg's progress; the
        # caller's level is back when the engine exits.
        logger = logging.getLogger("distributed")
        self._stack.callback(logger.setLevel, logger.level)
        logger.setLevel(logging.CRITICAL)
        if self.scheduler != "local":
            previous = dask.config.get("scheduler", None)
            try:
                _answers(self.scheduler, self.timeout)
                return Client(self.scheduler, timeout=f"{self.timeout}s")
            except Exception as err:  # noqa: BLE001 - any failure to connect (an echo
                # server, a tls:// address without certificates, ...) is the address's
                # The Client made itself Dask's default before it tried to connect, and
                # leaves that behind when it fails: every later compute would then ask
                # for a client that does not exist.
                dask.config.set(scheduler=previous)
                raise EngineError(f"cannot reach the Dask scheduler at {self.scheduler} "
                                  f"({type(err).__name__}: {err})") from None
        # One numba thread per worker thread: the worker threads are the parallelism
        # (nested, they oversubscribe the cores and the kernels' OpenMP threads spin
        # against each other: 2.3x slower on 2 cores).
        if self.memory_limit // self.workers < MIN_WORKER_MEMORY:
            raise EngineError(
                f"--memory-limit {self.memory_limit / 2**20:.0f} MiB over {self.workers} workers "
                f"leaves each less than the {MIN_WORKER_MEMORY // 2**20} MiB a worker needs to "
                "make progress (its process alone); give more, or fewer --workers")
        # The workers' and nanny's log lines (pausing, restarting) are not volseg's
        # either: what stops the run, `compute` says in its own line.
        cluster = LocalCluster(n_workers=self.workers,
                               threads_per_worker=self.threads_per_worker, processes=True,
                               memory_limit=self.memory_limit // self.workers,
                               dashboard_address=None, env={"NUMBA_NUM_THREADS": "1"},
                               silence_logs=logging.CRITICAL)
        self._stack.callback(cluster.close)
        if self.hierarchy_memory is not None:
            # One more worker of the same kind, its own memory, the hierarchy's resource.
            (_, spec), = cluster.new_worker_spec().items()
            spec = {**spec, "options": {**spec["options"], "memory_limit": self.hierarchy_memory,
                                        "resources": {HIERARCHY_RESOURCE: 1}}}
            cluster.worker_spec["hierarchy"] = spec
            cluster.scale(len(cluster.worker_spec))
        from ._numba_threads import NumbaThreadsFromEnvironment

        client = Client(cluster)
        client.register_plugin(NumbaThreadsFromEnvironment(), name="volseg-numba-threads")
        return client

    def compute(self, *collections, stage: str = "computing"):
        """`dask.compute(*collections)`, with a progress bar named `stage`."""
        import warnings

        import dask

        with warnings.catch_warnings():
            # Lookup tables are sent once, as their own task, on purpose; a distributed
            # client warns of any graph over 10 MB.
            warnings.filterwarnings("ignore", message="Sending large graph")
            if self.progress:
                print(f"  {stage}", file=sys.stderr, flush=True)
            if self.client is not None:
                return self._watched(collections, stage)
            if not self.progress:
                return dask.compute(*collections)
            from dask.diagnostics import ProgressBar

            with ProgressBar(out=sys.stderr, minimum=1.0):
                return dask.compute(*collections)

    def persist(self, *collections, stage: str = "computing", hierarchy: bool = False):
        """`dask.persist(*collections)` (Delayed, Dask arrays): computed now, with the
        progress of `compute`, and kept where each was computed (on a cluster, in its
        workers' memory, an array's blocks each where it was made: the client receives
        none of it) for later graphs to read.

        `hierarchy`: they hold a whole hierarchy. On a cluster with a worker of
        `HIERARCHY_RESOURCE`, every task of their graphs runs on it (persist their
        lazy inputs first, or those run there too)."""
        import dask

        if self.client is None:
            if self.progress:
                print(f"  {stage}", file=sys.stderr, flush=True)
            return dask.persist(*collections)
        return tuple(self._watched(collections, stage, gather=False, hierarchy=hierarchy))

    def _watched(self, collections, stage: str, gather: bool = True, hierarchy: bool = False):
        """The distributed compute of `compute`, stopped with one line when the
        cluster cannot go on: a task whose workers died `KilledWorker` times (over
        their memory limit), or every worker paused at its limit for `STALL_SECONDS`
        with work pending (distributed waits forever then)."""
        from concurrent.futures import CancelledError

        from distributed import KilledWorker, futures_of, progress

        start, sent = time.perf_counter(), self._sent()
        # A worker restriction given to the compute, not a `dask.annotate`: annotations
        # leak into a task's dependencies passed in containers (dask 2026.8).
        resources = {HIERARCHY_RESOURCE: 1} if hierarchy and self._hierarchy_worker else None
        if gather:
            futures = self.client.compute(list(collections), resources=resources)
        else:      # persisted: an array keeps its blocks where each was computed
            persisted = self.client.persist(list(collections), resources=resources)
            futures = futures_of(persisted)
        watchdog = _Watchdog(self.client, futures, STALL_SECONDS)
        try:
            with watchdog:
                if self.progress:
                    with contextlib.redirect_stdout(sys.stderr):
                        progress(futures, notebook=False)
                        print(file=sys.stderr)
                if gather:
                    results = tuple(self.client.gather(futures))
                else:
                    from distributed import wait

                    wait(futures)
                    for future in futures:     # raise a task's error here, as gather would
                        if future.status == "error":
                            future.result()
                    results = persisted
                self._record(stage, start, sent, results if gather else ())
                return results
        except KilledWorker:
            self.client.cancel(futures)
            raise self._over_limit(f"{stage}: {_KILLED}", hierarchy) from None
        except CancelledError:
            if watchdog.reason is None:
                raise
            raise self._over_limit(f"{stage}: {watchdog.reason}", hierarchy) from None

    def _sent(self) -> int:
        """The bytes every worker has sent so far (to other workers and to clients)."""
        try:
            return sum(self.client.run(_bytes_sent).values())
        except Exception:  # noqa: BLE001 - a worker gone: the figure is only a report
            return -1

    def _record(self, stage, start, sent, results):
        from dask.sizeof import sizeof

        after = self._sent() if sent >= 0 else -1
        self.stages.append({"stage": stage, "seconds": round(time.perf_counter() - start, 3),
                            "workers_sent_bytes": after - sent if after >= 0 else None,
                            "client_received_bytes": int(sum(sizeof(r) for r in results)),
                            "client_peak_bytes": _peak_rss()})

    def _over_limit(self, what: str, hierarchy: bool = False) -> EngineError:
        """The one line of a cluster stopped at its memory limit: `what` happened, the
        limit, and what to change (`hierarchy`: in a task that holds a whole
        hierarchy)."""
        limit = (f"{self.memory_limit / self.workers / 2**20:.0f} MiB per worker"
                 if self.scheduler == "local" else f"the cluster at {self.scheduler}")
        if self.hierarchy_memory is not None:
            limit += f", {self.hierarchy_memory / 2**20:.0f} MiB for the hierarchy"
        if hierarchy:
            where = ("--hierarchy-memory" if self.scheduler == "local"
                     else f"a worker of resource {HIERARCHY_RESOURCE}=1")
            return EngineError(f"{what} ({limit}); this task holds the whole Morse hierarchy "
                               f"(about 150 bytes per maximum) on one worker: give it one with "
                               f"that memory ({where})")
        return EngineError(f"{what} ({limit}); give more --memory-limit, fewer --workers or "
                           "smaller --chunks")


def _peak_rss() -> int:
    """The peak resident memory of this process so far, in bytes (Linux counts KiB)."""
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak * (1 if sys.platform == "darwin" else 1024))


def _bytes_sent(dask_worker) -> int:
    return int(dask_worker.transfer_outgoing_bytes_total)


#: What `KilledWorker` means here: distributed gave up on a task after its workers died.
_KILLED = "Dask workers died running the same task, over their memory limit"


#: Every worker paused at its memory limit this long, with work pending: the run stops.
STALL_SECONDS = 60.0


class _Watchdog:
    """A thread that cancels `futures` when every worker of `client` has been paused
    (at its memory limit) for `seconds` while some future is pending; `reason` says so."""

    def __init__(self, client, futures, seconds: float, interval: float = 1.0):
        import threading

        self.client, self.futures, self.seconds, self.interval = client, futures, seconds, interval
        self.reason = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="volseg-watchdog")

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()

    def _run(self):
        import time

        paused_since = None
        while not self._stop.wait(self.interval):
            try:
                workers = self.client.scheduler_info()["workers"].values()
            except Exception:  # noqa: BLE001 - the compute itself reports a lost cluster
                return
            pending = any(not f.done() for f in self.futures)
            if pending and workers and all(w.get("status") == "paused" for w in workers):
                paused_since = paused_since or time.monotonic()
                if time.monotonic() - paused_since >= self.seconds:
                    self.reason = (f"every Dask worker has been paused at its memory limit for "
                                   f"{self.seconds:g} s with work pending")
                    self.client.cancel(self.futures)
                    return
            else:
                paused_since = None
