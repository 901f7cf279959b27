"""The blockwise pipeline behind `volseg segment` for volumes larger than memory.

`segment_volume` takes Dask arrays too (lazy labels and curvature), but every stage
that reads the curvature would compute it again. Here each stage reads the one
before from disk instead: inside the output set's staging folder,

0. the mask, if asked (`volseg.masks.foreground_mask` of the lazy input: one pass
   for auto and nonzero, two for otsu; each Morse pass reads it again from the
   input); then the free disk is checked (`DISK_BYTES_PER_VOXEL`);
1. the input's min and max (one pass: the value scale and the preview's grey scale);
   with `smooth`, the smoothed volume, block by block into the work folder below
   (8 bytes per voxel on disk until the outputs are committed), and its own min and
   max for the value scale;
2. the curvature, block by block with its halo, written to ``<stem>_curvature.zarr``
   (float64, so that the Morse stage reads exactly what it would in memory);
3. the Morse hierarchy from that store (`descending_complex` on Dask: two passes
   over its blocks with their halos, the ascent's per-voxel path ends kept in the
   work folder below until the cells are computed from them, once, the cell graph on
   this process);
4. the labels, block by block, written to ``<stem>_labels.zarr`` (and, for a volume
   of at most `volseg.outputs.BLOCKWISE_NIFTI_VOXELS`, labels and curvature to the
   in-memory path's NIfTI files, from the stores);
5. the summary (region sizes: one pass over the labels) and the preview (three mid
   slices: read, not computed).

Nothing is ever whole in memory but the per-maximum data and the cell graph. The
set is committed only when all of it is written (`volseg.io.OutputSet`).

Every per-block result (smoothed values, curvature, ascent summaries and path ends,
cells, edges) is also kept in
``<out>/.<stem>.volseg-work`` (`volseg._resume.WorkFolder`, keyed by the inputs'
checksum and every parameter) until the set is committed: a killed run, rerun with
the same arguments, loads its finished blocks instead of computing them. The stages
run on the `volseg.engine.Engine` entered by the caller (from the command line:
threads by default, `--scheduler local` or an address for dask.distributed), or on
Dask's current scheduler.
"""

from __future__ import annotations

import os
import shutil
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["segment_to_zarr", "DEFAULT_CHUNKS", "IN_MEMORY_BYTES_PER_VOXEL"]

# Chunk edge of the blockwise path when the command line chooses it (--memory-limit):
# 128^3 blocks are 16 MB of float64, few enough tasks (512 at 1024^3) for Dask.
DEFAULT_CHUNKS = 128
# Peak memory of the in-memory `volseg segment` per voxel, measured end to end on a
# smooth uint8 field (4.98 GB at 512^3: 37 B), rounded up.
IN_MEMORY_BYTES_PER_VOXEL = 40
# Disk a blockwise run holds at once, bytes per voxel (its blocks are stored
# uncompressed): the work folder's curvature 8, path ends 8 and cells 4 at the end of
# the cells pass, plus 8 of smoothed values with `smooth`; the outputs' compressed
# curvature (5.1 measured at 512^3, at most 8) and labels (at most 2) come on top.
# Less free disk than the work folder needs refuses the run before it starts; less
# than both, a warning.
DISK_BYTES_PER_VOXEL = {"work": 20, "smoothed": 8, "outputs": 10}


def segment_to_zarr(volume, outputs, *, operator="weighted", n_regions=None, min_persistence=None,
                    value_scale=None, boundary="linear", mask=None, smooth=0.0, engine=None,
                    say=lambda message: None) -> dict:
    """Segment a lazily read `volume` (its data a 3-D Dask array) into an entered
    `OutputSet` named by ``output_names(stem, blockwise=True, voxels=...)``; returns the
    summary.
    `mask`: a `volseg.masks.foreground_mask` rule, resolved before anything is written
    (its passes over the input: the minimum and the count, or the histogram), its
    array read again from the input by each Morse pass.
    `smooth`: Gaussian sigma in voxels, as `segment_volume`'s (computed block by block,
    once, into the work folder).
    `engine`: a `volseg.engine.Engine` (entered), for its progress bars."""
    import dask

    from . import __version__, _validate
    from ._resume import WorkFolder
    from ._smoothing import gaussian
    from .curvature import default_value_scale, get_operator
    from .curvature._grid import check_boundary
    from .curvature._grid_blocks import dask_grid_curvature
    from .io import Frame, read_zarr, write_volume, write_zarr
    from .masks import foreground_mask
    from .outputs import files_sha256, summary
    from .preview import write_persistence_plot, write_preview
    from .segment import Segmentation, _cut, _cut_request

    started = time.perf_counter()
    entry = get_operator(operator)
    min_persistence, n_cut, auto = _cut_request(min_persistence, n_regions)
    data = _validate.lazy_volume_array(volume.data)
    smooth = _validate.smooth(smooth)
    spacing = volume.spacing
    frame = volume.frame or Frame.from_spacing(spacing)
    check_boundary(boundary)
    chunks = "x".join(str(max(c)) for c in data.chunks)
    run = engine.compute if engine is not None else (
        lambda *collections, stage: dask.compute(*collections))
    checksum = files_sha256(volume.files)
    if mask not in (None, "none"):
        say(f"{volume.name}: mask {mask}")
    choice = foreground_mask(data, mask)     # of the values as read, as in memory
    work_folder = outputs.folder / f".{outputs.stem}.volseg-work"
    _check_disk(outputs.folder, work_folder, data.size, smooth, say)
    result = {}

    def write(paths):
        from . import _json
        from ._morse_blocks import dask_descending_complex

        timings = {}
        start = time.perf_counter()
        # The key holds the value scale as asked: the default is a function of the
        # input and `smooth`, both in the key.
        work = WorkFolder(work_folder, {
            "volseg": __version__, "input": checksum, "shape": list(data.shape),
            "chunks": [list(c) for c in data.chunks], "spacing": list(spacing),
            "operator": entry.name, "value_scale": value_scale, "boundary": boundary,
            "connectivity": "kuhn", "smooth": smooth, "mask": choice.used,
            "block_layout": 3})   # 2: curvature blocks = input chunks; 3: ascent ends kept
        stages = ("smoothed", "curvature", "ascent", "cells", "pairs")
        if work.resumed:
            done = {stage: work.finished(stage) for stage in stages}
            say(f"{volume.name}: resuming from finished blocks in {work.folder} "
                f"({', '.join(f'{stage} {n}' for stage, n in done.items())})")

        def stored(blocks, stage, title):     # computed once into the work folder (each
            if work.finished(stage) < blocks.npartitions:       # block saved by its wrap),
                run(blocks.map_blocks(_nothing, dtype=bool,     # then read back from it
                                      chunks=tuple((1,) * len(c) for c in blocks.chunks)),
                    stage=title)
            return work.array(stage, blocks.chunks, blocks.dtype)

        # The input's range, in one pass: the preview's grey scale and, unsmoothed, the
        # value scale.
        value_range = tuple(v.item() for v in run(data.min(), data.max(), stage="value range"))
        values = gaussian(data, smooth)
        if smooth:
            # Smoothed once, into the work folder: the value scale and the curvature
            # read it back, and the curvature's halos reread its blocks rather than
            # keep them (dask cannot rerun a map_overlap graph's blocks on their own).
            say(f"{volume.name}: smoothing, sigma {smooth:g} voxels, block by block")
            values = stored(values.map_blocks(work.wrap("smoothed", _same), dtype=values.dtype),
                            "smoothed", "smoothing")
        scale = _validate.value_scale(value_scale if value_scale is not None else
                                      default_value_scale(values, spacing, value_range=(
                                          None if smooth else value_range)))
        say(f"{volume.name}: curvature ({entry.name}) of a {'x'.join(map(str, data.shape))} volume "
            f"in {chunks} blocks")
        write_zarr(paths["curvature"], dask_grid_curvature(values, entry, spacing, scale, boundary,
                                                           wrap=work.wrap, reread=True),
                   frame=frame, compute=lambda x: run(x, stage="curvature"))
        curvature = read_zarr(paths["curvature"]).data
        timings["curvature"] = time.perf_counter() - start
        start = time.perf_counter()
        say(f"{volume.name}: Morse complex, block by block")

        # The cells are stored for the edge and label passes (so their tables are freed).
        hierarchy = dask_descending_complex(curvature, mask=choice.mask, persist=lambda cells: (
                                                stored(cells, "cells", "Morse: cells per block")),
                                            wrap=work.wrap, compute=run, reread=True,
                                            ends_folder=str(work.folder / "ends"))
        timings["morse"] = time.perf_counter() - start
        labels, k, threshold, cut = _cut(hierarchy, min_persistence, n_cut, auto, timings)
        start = time.perf_counter()
        write_zarr(paths["labels"], labels.astype(np.min_scalar_type(k)), frame=frame,
                   compute=lambda x: run(x, stage="labels"))
        labels = read_zarr(paths["labels"]).data
        if "labels_nifti" in paths:     # a small volume: the in-memory path's files too
            with ThreadPoolExecutor(2) as pool:      # (zlib releases the GIL)
                jobs = [pool.submit(write_volume, paths["labels_nifti"], np.asarray(labels),
                                    frame=frame),
                        pool.submit(write_volume, paths["curvature_nifti"],
                                    np.asarray(curvature).astype(np.float32), frame=frame)]
                for job in jobs:
                    job.result()
        timings["labels"] = time.perf_counter() - start
        seg = Segmentation(labels, curvature, hierarchy, k, entry.name, threshold, scale, spacing,
                           timings, cut, choice, smooth)
        say(f"{volume.name}: {k} regions{choice.phrase()} from {len(hierarchy.maxima)} maxima; "
            "writing")
        info = summary(seg, name=volume.name, source=volume.path,
                       checksum=checksum, files=volume.files, frame=frame,
                       requested_regions=n_regions)
        info["blockwise"] = {"chunks": chunks, "engine": engine.describe() if engine else "dask",
                             "resumed": work.resumed, "morse_phases_s": {
            phase: round(seconds, 4) for phase, seconds in hierarchy.timings.items()}}
        info["timings_s"]["total"] = round(time.perf_counter() - started, 4)
        info["outputs"] = {kind: str(path) for kind, path in outputs.targets.items()}
        curve = (hierarchy.event_persistence, hierarchy.n_components, threshold)
        title = f"{volume.name}: {k} regions, {entry.name.replace('_', '-')} curvature"
        title += f", smoothed sigma {smooth:g}" if smooth else ""
        title += f", mask {choice.used} (blockwise)" if choice.mask is not None else " (blockwise)"
        write_preview(paths["preview"], data, curvature, labels, title=title, persistence=curve,
                      value_range=value_range, n_labels=k)
        if "persistence" in paths:
            write_persistence_plot(paths["persistence"], *curve, k)
        paths["summary"].write_text(_json.dumps(info, indent=2))
        result["info"], result["work"] = info, work

    outputs.commit(write)
    result["work"].remove()      # committed: the finished blocks are no longer needed
    return result["info"]


def _check_disk(folder, work_folder, voxels: int, smooth: float, say):
    """Refuse a run whose work folder cannot fit on `folder`'s disk (an OutputError
    naming both sizes, before anything is written); warn when the outputs may not fit
    beside it. A work folder left by an earlier run counts as free: it is either
    reused or emptied."""
    from .io import OutputError

    per_voxel = DISK_BYTES_PER_VOXEL
    least = voxels * (per_voxel["work"] + (per_voxel["smoothed"] if smooth else 0))
    most = least + voxels * per_voxel["outputs"]
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


def _nothing(block):
    """One flag per block: computing a map of it runs the blocks for their side effect."""
    return np.ones((1,) * block.ndim, dtype=bool)
