"""The blockwise path's storage: each stage of `volseg.segment.run_stages` kept on
disk for the next, for volumes larger than memory.

`run_stages` on a Dask array is already blockwise, but every stage that reads the
curvature would compute it again. `BlockwiseStorage` makes each stage read the one
before from disk instead, inside the output set's staging folder:

0. the mask, if asked (`volseg.masks.foreground_mask` of the lazy input: one pass
   for auto and nonzero, two for otsu; each Morse pass reads it again from the
   input); then the free disk is checked (`DISK_BYTES_PER_VOXEL`);
1. the input's min and max (one pass: the value scale and the preview's grey scale);
   with smoothing, the smoothed volume, block by block into the work folder below
   (8 bytes per voxel on disk until the outputs are committed), its own min and max
   for the value scale taken as each block is kept;
2. the curvature, block by block with its halo, written to ``<stem>_curvature.zarr``
   (float64, so that the Morse stage reads exactly what it would in memory), each
   block also kept in the work folder below, uncompressed: the later stages read it
   from there (another field, the gradient or the values: the same, each block kept
   there first, then written from there);
3. the Morse hierarchy from those blocks (two passes over them with their
   halos, the ascent's per-voxel path ends kept in the work folder until the cells
   are computed from them, once; the maxima's ids, the exits and the union-find on
   the workers, in a tree of block groups; the hierarchy on this process);
4. the labels, block by block, written to ``<stem>_labels.zarr``.

The output set's writer (`volseg.outputs`) then adds the summary, the preview and,
for a small volume, the NIfTI files. Nothing is ever whole in memory but the
hierarchy (the per-maximum data and the merge events).

Every per-block result (smoothed values, curvature, ascent summaries and path ends,
cells, edges) is also kept in ``<out>/.<stem>.volseg-work``
(`volseg.blockwise.WorkFolder`, keyed by the inputs' checksum and every parameter)
until the set is committed: a killed run, rerun with the same arguments, loads its
finished blocks instead of computing them. The stages run on the
`volseg.blockwise.engine.Engine` entered by the caller, or on Dask's current
scheduler.
"""

from __future__ import annotations

import os
import shutil

import numpy as np

from .. import __version__
from .._block_hooks import BlockHooks
from .._distinct import label_type
from ..errors import OutputError
from ..fields import GIVEN
from ..io import Frame, read_zarr, write_zarr
from ..segment import Storage
from ._resume import WorkFolder

__all__ = ["BlockwiseStorage", "DEFAULT_CHUNKS", "IN_MEMORY_BYTES_PER_VOXEL",
           "DISK_BYTES_PER_VOXEL"]

# Chunk edge of the blockwise path when the command line chooses it (--memory-limit):
# 128^3 blocks are 16 MB of float64, few enough tasks (512 at 1024^3) for Dask.
DEFAULT_CHUNKS = 128
# Peak memory of the in-memory `volseg segment` per voxel, an upper bound for every input
# type: measured end to end at 512^3 (`benchmarks/bench_memory.py`) 28.8 B for a smooth
# uint8 field and 32.4 B for float32; a float64 input holds 4 bytes a voxel more again.
IN_MEMORY_BYTES_PER_VOXEL = 40
# Disk a blockwise run holds at once, bytes per voxel (its blocks are stored
# uncompressed): the work folder's curvature 8, path ends 8 and cells 4 at the end of
# the cells pass, plus 8 of smoothed values with smoothing; the outputs come on top:
# the compressed float64 curvature store (at most 8), the OME-Zarr's float32 levels (at
# most 4 x 8/7) and labels with their levels (at most 2 x 8/7 up to 65 535 regions):
# 15 (measured at 512^3, zstd level 1, staircase field: 6.7 + 3.6 + 0.05), and the
# ParaView image's uncompressed input (at most 8), curvature 4 and labels 4, and an
# oblique input's grid points (at most 24, float64).
# Less free disk than the work folder needs refuses the run before it starts; less
# than both, a warning.
DISK_BYTES_PER_VOXEL = {"work": 20, "smoothed": 8, "outputs": 15, "paraview": 16,
                        "paraview_points": 24}
#: Progress titles of the stages stored whole in the work folder.
_STORED_TITLES = {"smoothed": "smoothing", "cells": "Morse: cells per block"}


class BlockwiseStorage(Storage):
    """`run_stages` storage that writes each stage to the output set's staging files
    (`paths`) and the work folder of `folder`/`stem`, and reads it back.

    `request` is the run's `SegmentRequest` and `checksum` the input files' SHA-256
    (both key the work folder); `engine` an entered `Engine` (or None: Dask's current
    scheduler); `say` prints progress.
    """

    def __init__(self, data, request, paths, *, folder, stem, checksum, frame: Frame | None,
                 engine=None, say=lambda message: None):
        self.data, self.request, self.paths = data, request, paths
        self.folder, self.checksum, self.engine, self.say = folder, checksum, engine, say
        self.frame = frame or Frame.from_spacing(request.spacing)
        self.work_folder = folder / f".{stem}.volseg-work"
        self.work = None
        #: The blocks' edge per axis, as the messages and the summary give it ("64x64x64").
        self.chunks = "x".join(str(max(c)) for c in data.chunks)
        self._run = engine.compute if engine is not None else BlockHooks().compute
        self._persist = engine.persist if engine is not None else BlockHooks().persist

    def begin(self, choice, request=None):
        """The work folder (keyed by everything that changes a block), after the free
        disk is checked; `request` with its smoothing resolved (`run_stages`)."""
        self.request = request = request or self.request
        data = self.data
        _check_disk(self.folder, self.work_folder, data.size, request.smooth_sigma, self.say,
                    paraview="paraview" in self.paths,
                    points=str(self.paths.get("paraview", "")).endswith(".vts"))
        self.work = WorkFolder(self.work_folder, {
            "volseg": __version__, "input": self.checksum, "shape": list(data.shape),
            "chunks": [list(c) for c in data.chunks], "spacing": list(request.spacing),
            "operator": request.operator.name, "value_scale": request.value_scale,
            "padding": request.padding, "connectivity": "kuhn",
            "smooth": request.smooth_sigma, "mask": choice.used,
            "field": _field_key(request.field),
            # 3: ascent ends kept; 4: one stage sequence; 5: forests with faces;
            # 6: the ascent's blocks with their range
            "block_layout": 6})
        if self.work.resumed:
            done = ", ".join(f"{stage} {self.work.finished(stage)}" for stage in
                             ("smoothed", "curvature", "ascent", "cells", "forests"))
            self.say(f"resuming from finished blocks in {self.work.folder} ({done})")
        self.kept = set()                   # the stages whose blocks a kernel keeps
        self.block_hooks = BlockHooks(wrap=self._wrap, compute=self._run,
                                      persist=self._persist, store=self._store, reread=True,
                                      scratch=str(self.work.folder / "ends"),
                                      threads=self.engine.threads if self.engine else None)

    def _wrap(self, stage: str, function):
        """The work folder's `wrap`, noting that `stage`'s blocks are kept by it."""
        self.kept.add(stage)
        return self.work.wrap(stage, function)

    def _store(self, stage: str, blocks, *, extremes: bool = False):
        """Blocks wrapped by ``work.wrap(stage, ...)``, computed once into the work
        folder (each block saved by its wrap), then read back from it. `extremes`:
        returns also the blocks' (min, max), taken as each is kept, or None when every
        block was on disk already (a resumed run: nothing passed through)."""
        found = None
        if self.work.finished(stage) < blocks.npartitions:
            each = (blocks.map_blocks(_extremes, dtype=np.float64, chunks=(
                *((1,) * len(c) for c in blocks.chunks[:-1]), (2,) * len(blocks.chunks[-1])))
                if extremes else
                blocks.map_blocks(_nothing, dtype=bool,
                                  chunks=tuple((1,) * len(c) for c in blocks.chunks)))
            (done,) = self._run(each, stage=_STORED_TITLES.get(stage, stage))
            if extremes:
                found = float(done[..., 0::2].min()), float(done[..., 1::2].max())
        stored = self.work.array(stage, blocks.chunks, blocks.dtype)
        return (stored, found) if extremes else stored

    def smoothed(self, values):
        # Smoothed once, into the work folder: the value scale and the curvature read
        # it back, and the curvature's halos reread its blocks rather than keep them
        # (dask cannot rerun a map_overlap graph's blocks on their own).
        if not self.request.smooth_sigma:
            return values
        self.say(f"smoothing, sigma {self.request.smooth_sigma:g} voxels, block by block")
        # Their range (the value scale's) is taken as the blocks are kept: the pass
        # that read them all back for it took 2.4 s of a 1024^3 run.
        smoothed, self.smoothed_range = self._store(
            "smoothed", values.map_blocks(self.work.wrap("smoothed", _same), dtype=values.dtype),
            extremes=True)
        return smoothed

    def curvature(self, field):
        # The Morse stage and the writers read the field again and again (each pass,
        # each block's halo): from the work folder, uncompressed, rather than decoded
        # from the output's zstd chunks (a pass over a 512^3 curvature: 0.6 CPU-s
        # against 1.4). The curvature's kernel keeps its blocks there as it computes
        # them; another field (gradient, value, given) is kept there first, then written.
        if "curvature" not in self.kept:
            field = self._store("curvature", field.map_blocks(
                self.work.wrap("curvature", _same), dtype=field.dtype))
        self._write("curvature", field)
        return self.work.array("curvature", field.chunks, field.dtype)

    def labels(self, labels, n_regions: int):
        return self._written("labels", labels.astype(label_type(n_regions)))

    def _written(self, kind: str, array):
        self._write(kind, array)
        return read_zarr(self.paths[kind]).data

    def _write(self, kind: str, array):
        write_zarr(self.paths[kind], array, frame=self.frame,
                   compute=lambda x: self._run(x, stage=kind))

    def describe(self, hierarchy) -> dict:
        """The summary's ``blockwise`` entry."""
        return {"chunks": self.chunks,
                "engine": self.engine.describe() if self.engine else "dask",
                "resumed": self.work.resumed,
                "morse_phases_s": {phase: round(seconds, 4)
                                   for phase, seconds in hierarchy.timings.items()},
                "cluster_stages": list(self.engine.stages) if self.engine else []}

    def finish(self):
        """The set is committed: the finished blocks are no longer needed."""
        if self.work is not None:
            self.work.remove()


def _field_key(entry) -> str:
    """What identifies the field in the work folder's key: its name, and for a field
    the user gave, dask's token of its array (its file and chunks, or its bytes)."""
    if entry.name != GIVEN:
        return entry.name
    from dask.base import tokenize

    return f"{GIVEN}:{tokenize(entry.make(None, None, None, None, None))}"


def _check_disk(folder, work_folder, voxels: int, smooth: float, say, paraview=False,
                points=False):
    """Refuse a run whose work folder cannot fit on `folder`'s disk (an OutputError
    naming both sizes, before anything is written); warn when the outputs may not fit
    beside it. A work folder left by an earlier run counts as free: it is either
    reused or emptied."""
    per_voxel = DISK_BYTES_PER_VOXEL
    least = voxels * (per_voxel["work"] + (per_voxel["smoothed"] if smooth else 0))
    most = least + voxels * (per_voxel["outputs"] + (per_voxel["paraview"] if paraview else 0)
                             + (per_voxel["paraview_points"] if points else 0))
    free = shutil.disk_usage(folder).free + sum(
        os.path.getsize(os.path.join(top, name))
        for top, _, names in os.walk(work_folder) for name in names)
    gb = 1e9
    if free < least:
        raise OutputError(
            f"{folder}: {free / gb:.3g} GB free, but the blockwise run's work folder needs "
            f"{least / gb:.3g} GB ({least // voxels} bytes per voxel: curvature 8, path ends 8, "
            f"cells 4{', smoothed values 8' if smooth else ''}); free some space or write the "
            "outputs elsewhere (-o)")
    if free < most:
        say(f"warning: {folder}: {free / gb:.3g} GB free; the run may need up to "
            f"{most / gb:.3g} GB (work folder {least / gb:.3g} GB, outputs up to "
            f"{(most - least) / gb:.3g} GB)")


def _same(block, block_id=None):
    """A block as it is (its wrap keeps it in the work folder)."""
    return block


def _extremes(block):
    """A block's (min, max) in float64 (exact for every input type volseg smooths
    to), shaped as one element of each axis but the last, which holds the two."""
    return np.array([block.min(), block.max()], dtype=np.float64).reshape(
        (1,) * (block.ndim - 1) + (2,))


def _nothing(block):
    """One flag per block: computing a map of it runs the blocks for their side effect."""
    return np.ones((1,) * block.ndim, dtype=bool)
