"""`BlockHooks`: how a blockwise stage keeps and runs its blocks.

A leaf shared by the stages that work block by block (the grid curvature, the Morse
build) and the pipeline that gives them storage (`volseg.blockwise`). Without hooks
(None) a stage on a Dask array is plain Dask: lazy, nothing kept, Dask's current
scheduler.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["BlockHooks", "compute"]


def _unwrapped(stage: str, function: Callable) -> Callable:
    return function


def _dask_compute(*collections, stage: str):
    import dask

    return dask.compute(*collections)


def _dask_persist(*collections, stage: str, hierarchy: bool = False):
    import dask

    return dask.persist(*collections)


@dataclass(frozen=True)
class BlockHooks:
    """What a blockwise stage asks of its storage.

    Attributes
    ----------
    wrap : callable ``(stage, function) -> function``
        Wraps each per-block function, e.g. to keep finished blocks on disk and load
        them instead of computing them again (`volseg.blockwise.WorkFolder.wrap`).
    compute : callable ``(*collections, stage=name) -> results``
        Computes Dask collections (e.g. with a progress bar per stage).
    persist : callable ``(*collections, stage=name, hierarchy=False) -> collections``
        Computes Dask collections and keeps them where they were computed (on a
        cluster, its workers), for later graphs to use without the client holding them.
        ``hierarchy=True``: their tasks hold a whole hierarchy; on a cluster with a
        worker for it, every task of their graphs runs there
        (`volseg.blockwise.Engine.persist`), so their lazy inputs are persisted first.
    store : callable ``(stage, blocks) -> blocks``, optional
        Computes a lazy array once into storage and returns it read back, so later
        passes read it instead of computing it again. None: kept lazy.
    reread : bool
        The input's blocks are cheap to make again (read from a store): each is made
        again for its halo rather than kept waiting in memory for it.
    scratch : str, optional
        A folder for large per-block intermediates a later pass reads (the Morse
        ascent's path ends); None: recomputed instead.
    threads : int, optional
        The threads that run the tasks at once (a local engine's), which sets how
        finely the Morse stage splits its exchanges (`volseg.morse._blocks`); None:
        not known (a running cluster may grow), split as for a large cluster.
    """

    wrap: Callable = _unwrapped
    compute: Callable = _dask_compute
    persist: Callable = _dask_persist
    store: Callable | None = None
    reread: bool = False
    scratch: str | None = None
    threads: int | None = None


def compute(hooks: BlockHooks | None, *collections, stage: str):
    """`hooks.compute`, or Dask's own without hooks."""
    return (hooks or BlockHooks()).compute(*collections, stage=stage)
