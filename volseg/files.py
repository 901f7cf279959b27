"""Files in, output sets out: what ``volseg segment`` and ``volseg isosurface`` do, as
library calls.

- `segment_files`: read and check every input, lock and check every output set,
  then segment and write each (the command line's ``segment``);
- `segment_to_files`: one volume into an entered `volseg.io.OutputSet`, in memory or,
  for a lazily read volume, through the blockwise storage (`volseg.blockwise`): the
  same stage sequence (`volseg.segment.run_stages`) and the same writer
  (`volseg.outputs.write_result_files`) either way;
- `series_to_files`, `segment_series_files`: the space-time isosurface of a series;
- `load_volume`, `load_for_budget`, `chunked`: inputs as the command line reads them.

Every refusal is a `volseg.errors.VolsegError` (a ValueError) naming the file, the
field or the argument.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
import warnings
from contextlib import ExitStack
from functools import partial
from pathlib import Path

import numpy as np

from . import _validate
from ._atomic import file_identity
from ._distinct import label_type
from ._jit_cache import noting_compilation
from ._responsive import responsive
from .errors import UsageError, VolsegWarning
from .fields import FIELDS, GIVEN, field_entry
from .io import Frame, OutputSet
from .outputs import (
    all_output_names,
    degenerate_cut_warning,
    files_sha256,
    input_files,
    output_names,
    result_title,
    summary,
    write_result_files,
)
from .segment import InMemory, SegmentRequest, input_range, run_stages

__all__ = ["segment_files", "segment_to_files", "series_to_files", "segment_series_files",
           "load_volume", "load_for_budget", "chunked", "output_sets", "check_out_dir"]


def _quiet(message):
    """The default `say`: no progress."""


def load_volume(name, shape=None, dtype=None, allow_external_data=False, chunks=None,
                channel=None, ome_level=None, fill_missing_chunks=False):
    """The `Volume` of a volume file or a named dataset (`volseg.datasets.resolve`); lazy
    (a Dask array of `chunks`) when `chunks` is given; `channel` and resolution
    `ome_level` of an OME-Zarr image; `fill_missing_chunks` of a Zarr store
    (`volseg.io.read_volume`)."""
    from .datasets import resolve
    from .io import read_volume

    return read_volume(resolve(name), shape=shape, dtype=dtype,
                       allow_external_data=allow_external_data, chunks=chunks, channel=channel,
                       ome_level=ome_level, fill_missing_chunks=fill_missing_chunks)


def load_for_budget(name, budget: int, *, shape=None, dtype=None, allow_external_data=False,
                    chunks=None, channel=None, ome_level=None, fill_missing_chunks=False,
                    say=_quiet):
    """`load_volume`, lazily (the blockwise path, `DEFAULT_CHUNKS`) when `chunks` is not
    given but the in-memory path would need more than `budget` bytes
    (`IN_MEMORY_BYTES_PER_VOXEL` per voxel). The file size bounds the voxel count from
    above, so small files are read as before; compressed files are not estimated
    (their size says too little)."""
    from .blockwise import DEFAULT_CHUNKS, IN_MEMORY_BYTES_PER_VOXEL
    from .datasets import resolve

    options = {"shape": shape, "dtype": dtype, "allow_external_data": allow_external_data,
               "channel": channel, "ome_level": ome_level,
               "fill_missing_chunks": fill_missing_chunks}
    if chunks is not None:
        return chunked(load_volume(name, **options, chunks=chunks), chunks)
    path = resolve(name)       # a dataset name is verified once, here
    _refuse_compressed_over_budget(path, budget)
    try:
        size = path.stat().st_size if path.is_file() else 0
    except OSError:
        size = 0      # read_volume names the problem
    if size * IN_MEMORY_BYTES_PER_VOXEL > budget and not path.name.lower().endswith(".gz"):
        volume = load_volume(str(path), **options, chunks=DEFAULT_CHUNKS)
        need = int(np.prod(volume.shape)) * IN_MEMORY_BYTES_PER_VOXEL
        if need > budget:
            say(f"{volume.name}: about {need / 2**30:.3g} GiB in memory exceeds the memory limit "
                f"of {budget / 2**30:.3g} GiB: segmenting block by block in {DEFAULT_CHUNKS}^3 "
                "chunks (--chunks N to choose, --memory-limit to change the limit)")
            return volume
    return load_volume(str(path), **options)


def _refuse_compressed_over_budget(path, budget: int) -> None:
    """A compressed volume is decompressed whole: refuse one whose in-memory run would
    exceed `budget` (it cannot go block by block)."""
    from .blockwise import IN_MEMORY_BYTES_PER_VOXEL
    from .io import VolumeFileError
    from .io.readers import compressed_shape

    shape = compressed_shape(path)
    if shape is None:
        return
    need = int(np.prod(shape, dtype=np.float64)) * IN_MEMORY_BYTES_PER_VOXEL
    if need > budget:
        raise VolumeFileError(
            f"{path}: a compressed volume of shape {shape} is read whole and needs about "
            f"{need / 2**30:.3g} GiB, above the memory limit of {budget / 2**30:.3g} GiB; "
            "decompress it (gunzip, or NRRD 'encoding: raw') or convert it to Zarr to segment "
            "it block by block, or raise --memory-limit")


def chunked(volume, size: int):
    """A lazily read `volume` with its data in `size`^3 chunks (`size` checked by
    `volseg.segment.SegmentRequest`): the one place chunks are applied, a Zarr store's
    own chunks rechunked too."""
    from .io import Volume

    if any(size > n for n in volume.shape):
        raise UsageError(f"--chunks {size} is larger than the volume {volume.path or volume.name} "
                         f"along an axis (shape {volume.shape}); use at most {min(volume.shape)}")
    return Volume(volume.data.rechunk(size), frame=volume.frame, name=volume.name,
                  source=volume.source, path=volume.path, files=volume.files)


def _tagged(say, tag: str):
    return lambda message: say(tag + message)


def _is_lazy(volume) -> bool:
    return _validate.is_lazy(volume.data)


def check_out_dir(out_dir) -> Path:
    """`out_dir`, created if needed; a UsageError when it cannot be created or written."""
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UsageError(f"{out_dir}: cannot create the output folder ({err.strerror})") from None
    if not os.access(out_dir, os.W_OK):
        raise UsageError(f"{out_dir}: the output folder is not writable")
    return out_dir


def _refuse_noise_when_lazy(volumes, noise):
    """What the blockwise path cannot do, refused before anything is written."""
    if noise and any(_is_lazy(v) for v in volumes):
        raise UsageError("--noise needs the volume in memory; drop --chunks")


def output_sets(volumes, out_dir, *, force=False, wait=False, persistence_plot=False,
                paraview=None, field="curvature") -> list:
    """One `OutputSet` per volume (not yet entered); two inputs with one stem are
    refused before anything is computed."""
    seen = {}
    for volume in volumes:
        if volume.name in seen:
            raise UsageError(
                f"{seen[volume.name]} and {volume.path or volume.name} would both write "
                f"{Path(out_dir) / volume.name}_*; segment them into different folders")
        seen[volume.name] = volume.path or volume.name
    name = field_entry(field).name
    fields = (*FIELDS, GIVEN)
    return [OutputSet(out_dir, v.name, output_names(v.name, persistence_plot, _is_lazy(v),
                                                    int(np.prod(v.shape)), paraview, name,
                                                    v.frame.axis_aligned),
                      force=force, wait=wait, owns=all_output_names(v.name, fields))
            for v in volumes]


def segment_files(volumes, out_dir, *, force=False, wait=False, persistence_plot=False,
                  paraview=None, engine=None, say=_quiet, **options) -> list[dict]:
    """Lock and check every output set, then segment and write each volume.

    Parameters
    ----------
    volumes : list of Volume
        As read (`load_volume`, `load_for_budget`); lazy ones take the blockwise path.
    out_dir : path
    force, wait, persistence_plot
        Overwrite existing sets; wait for another writer's lock; also write the
        persistence curve alone.
    paraview : bool, optional
        Write the ParaView image ``<name>_volumes.vti`` (True), or not (False);
        default: up to `volseg.outputs.PARAVIEW_VOXELS` voxels.
    engine : volseg.blockwise.engine.Engine, optional
        Entered here, after the sets are locked, when a volume is lazy.
    **options
        Of `segment_to_files`.

    Returns
    -------
    list of dict
        The summaries, in input order.
    """
    _refuse_noise_when_lazy(volumes, options.get("noise"))
    _check_labels_into_input(volumes, options.get("labels_into_input"), force)
    out_dir = check_out_dir(out_dir)
    sets = output_sets(volumes, out_dir, force=force, wait=wait,
                       persistence_plot=persistence_plot, paraview=paraview,
                       field=options.get("field", "curvature"))
    summaries = []
    with ExitStack() as stack:
        stack.enter_context(noting_compilation(say))
        for outputs in sets:
            stack.enter_context(outputs)
            for line in outputs.recovered:
                say(f"{outputs.folder}: {line}")
        if engine is not None and any(_is_lazy(v) for v in volumes):
            # Started (or reached) after the outputs are locked and checked, before
            # anything is computed: an unreachable scheduler writes nothing.
            stack.enter_context(engine)
            say(f"blockwise engine: {engine.describe()}")
        for number, (volume, outputs) in enumerate(zip(volumes, sets, strict=True), 1):
            step = say if len(volumes) == 1 else _tagged(say, f"[{number}/{len(volumes)}] ")
            info = segment_to_files(volume, outputs, engine=engine, say=step, **options)
            summaries.append(info)
            step(f"{volume.name}: wrote "
                 f"{', '.join(Path(p).name for p in info['outputs'].values())}")
    return summaries


def _check_labels_into_input(volumes, name, force) -> None:
    """`labels_into_input` only for OME-Zarr inputs, refused before anything is
    computed (a name that is not a plain group name, an existing labels image without
    `force`)."""
    if name is None:
        return
    from .io.ngff import is_ome_image, recover_labels

    if not name or not all(c.isalnum() or c in "-_." for c in name) or name.startswith("."):
        raise UsageError(f"--labels-into-input: {name!r} is not a labels image name (letters, "
                         "digits, '-', '_', '.')")
    if name.lower() in ZARR_RESERVED:
        raise UsageError(f"--labels-into-input: {name!r} is a name Zarr keeps for its own "
                         "metadata; choose another")
    for volume in volumes:
        if volume.path is None or not is_ome_image(volume.path):
            raise UsageError(f"--labels-into-input: {volume.path or volume.name} is not an "
                             "OME-Zarr image (labels are added only to one)")
        _check_labels_group(Path(volume.path))
        recover_labels(volume.path, name)      # what a killed run left, undone first
        target = Path(volume.path) / "labels" / name
        if target.exists() and not target.is_dir():
            raise UsageError(f"--labels-into-input: {target} is a file, not a labels image; "
                             "move it away first (--force replaces only a labels image)")
        if target.exists() and not force:
            raise UsageError(f"--labels-into-input: {target} exists; give --force to replace "
                             "it")


#: Names a Zarr store keeps for its metadata: never a labels image's name.
ZARR_RESERVED = ("zarr.json", ".zattrs", ".zgroup", ".zarray", ".zmetadata")


def _check_labels_group(image: Path) -> None:
    """Refuse, before anything is computed, an image whose labels cannot be added: not
    writable, ``labels`` a file, or ``labels``'s metadata not JSON."""
    import json

    labels = image / "labels"
    where = labels if labels.exists() else image
    if labels.exists() and not labels.is_dir():
        raise UsageError(f"--labels-into-input: {labels} is a file, not the image's labels "
                         "group")
    if not os.access(where, os.W_OK | os.X_OK):
        raise UsageError(f"--labels-into-input: {where} is not writable")
    for meta in ("zarr.json", ".zattrs"):
        if (labels / meta).is_file():
            try:
                json.loads((labels / meta).read_text(encoding="utf-8"))
            except (OSError, ValueError) as err:
                raise UsageError(f"--labels-into-input: {labels / meta} is not readable "
                                 f"JSON ({type(err).__name__}); repair or remove it") from None


def segment_to_files(volume, outputs, *, operator="weighted", n_regions=None,
                     min_persistence=None, value_scale=None, noise=None, seed=0, mask=None,
                     smooth_sigma=None, padding="linear", measure=None, threshold=None,
                     min_component=None, labels_into_input=None, ome_level=None, engine=None,
                     field="curvature", say=_quiet) -> dict:
    """Segment `volume` and write its output set (an entered `OutputSet` named by
    `output_names`); returns the summary. A lazily read volume (its data a Dask
    array) takes the blockwise path: each stage stored in the set's staging files and
    a work folder that lets a killed run resume (`volseg.blockwise`). `noise`: percent
    Gaussian noise of the value range (`volseg.noise.add_value_noise`), in memory only.
    `labels_into_input`: also add the committed labels to the OME-Zarr input image (of
    level `ome_level`) as ``labels/<labels_into_input>`` (`volseg.io.write_labels_into`).
    """
    started = time.perf_counter()
    lazy = _is_lazy(volume)
    _refuse_noise_when_lazy([volume], noise)
    if lazy:
        data = _validate.lazy_volume_array(volume.data)
        dtype = data.dtype
    else:
        from .noise import add_value_noise

        data = np.asarray(volume)
        dtype = data.dtype       # the smoothing rule reads the file's type, not the noise's
        if noise:
            data = add_value_noise(data, noise, seed=seed)
    request = SegmentRequest.checked(
        operator=operator, min_persistence=min_persistence, n_regions=n_regions,
        value_scale=value_scale, spacing=volume.spacing, padding=padding, mask=mask,
        smooth_sigma=smooth_sigma, measure=measure, threshold=threshold,
        min_component=min_component, dtype=dtype, field=field)
    read_as = _file_states(volume.files)      # before the checksum reads them
    name, checksum = volume.name, files_sha256(volume.files)
    done = {}

    def write(paths):
        storage = _storage(volume, data, request, paths, outputs, checksum, engine, say)
        if lazy:       # removed with the commit, or by the next run that finishes it
            outputs.discard = [*outputs.discard, storage.work_folder]
        blocks = f" in {storage.chunks} blocks" if lazy else ""
        what = (f"curvature ({request.operator.name})" if request.field.needs_scale
                else request.field.label)
        say(f"{name}: {what} and Morse complex of a "
            f"{'x'.join(map(str, data.shape))} volume{blocks}")
        try:
            # In memory the stages are long compiled calls: run where an interrupt of
            # the main thread is not kept waiting by them (a blockwise run waits in
            # Dask's scheduler loop, which is interruptible already).
            stages = _stages_saying_warnings if lazy else partial(responsive,
                                                                  _stages_saying_warnings)
            # In memory the files need the cut alone (`keep_hierarchy`); a blockwise
            # run's hierarchy describes its work folder.
            result, value_range = stages(data, request, storage, name, say,
                                         str(volume.path or name), lazy)
        except ValueError:     # the input refused: no work worth resuming
            if lazy:
                shutil.rmtree(storage.work_folder, ignore_errors=True)
            raise
        blockwise = storage.describe(result.hierarchy) if lazy else None
        # The files need the cut, not the hierarchy: its cells (4 bytes a voxel) go
        # before the writers' casts, the peak of the writing; so do the int32 labels,
        # once cast to the type they are written in.
        result = dataclasses.replace(result, hierarchy=None, labels=result.labels.astype(
            label_type(result.n_regions), copy=False))
        info = _write_result(paths, volume, result, data, value_range, outputs,
                             checksum=checksum, noise=noise, seed=seed,
                             requested_regions=n_regions, started=started, say=say,
                             blockwise=blockwise)
        _unchanged(volume.files, read_as)     # else nothing is committed
        done["info"], done["storage"] = info, storage

    outputs.commit(write)
    done["storage"].finish()
    if labels_into_input is not None:
        _labels_into_input(volume, outputs, labels_into_input, ome_level, say)
    return done["info"]


def _labels_into_input(volume, outputs, name, level, say) -> None:
    """The committed labels (read back from the set) added to the OME-Zarr input."""
    from .io import read_volume
    from .io.ngff import write_labels_into

    labels = read_volume(outputs.targets["labels"]).data
    target = write_labels_into(volume.path, labels, name=name, level=level or 0, force=True)
    say(f"{volume.name}: added the labels to the input image as {target}")


def result_to_files(volume, result, out_dir, *, force=False, wait=False,
                    persistence_plot=False, paraview=None, say=_quiet) -> dict:
    """Write a `Segmentation` of `volume` already made as its output set in `out_dir`.

    The result comes from `segment_volume`, or is cut again with `Segmentation.recut`;
    written are the files, checks
    and summary `volseg segment` writes for the same cut, nothing recomputed. Returns
    the summary. (The napari plugin's "write outputs".)"""
    out_dir = check_out_dir(out_dir)
    started = time.perf_counter()
    read_as = _file_states(volume.files)
    checksum = files_sha256(volume.files)
    data = volume.data if _is_lazy(volume) else np.asarray(volume)
    outputs, = output_sets([volume], out_dir, force=force, wait=wait,
                           persistence_plot=persistence_plot, paraview=paraview)
    done = {}

    def write(paths):
        done["info"] = _write_result(paths, volume, result, data, input_range(data), outputs,
                                     checksum=checksum, requested_regions=result.n_regions,
                                     started=started, say=say, blockwise=None)
        _unchanged(volume.files, read_as)

    with outputs:
        outputs.commit(write)
    return done["info"]


#: The share of a volume's non-zero voxels a mask may leave out without a line of its own.
LEFT_OUT_SAID = 0.05


def _say_left_out(say, name, mask, data) -> None:
    """A line when the mask leaves out more than `LEFT_OUT_SAID` of the non-zero voxels
    (a CT's air, a noisy background): not only the summary says so."""
    if mask.mask is None or mask.voxels > (1 - LEFT_OUT_SAID) * mask.mask.size:
        return
    out, nonzero = mask.left_out(data)
    if nonzero and out > LEFT_OUT_SAID * nonzero:
        say(f"{name}: the mask ({mask.used}) leaves out {out / nonzero:.1%} of the non-zero "
            "voxels; --mask none segments every voxel, --mask 'value>T' sets the threshold")


def _write_result(paths, volume, result, data, value_range, outputs, *, checksum, started,
                  say, blockwise=None, noise=None, seed=0, requested_regions=None) -> dict:
    """The summary and files of `result` into an output set's staging `paths`."""
    name = volume.name
    frame = volume.frame or Frame.from_spacing(result.spacing)
    say(f"{name}: {result.n_regions} regions{result.mask.phrase()} from "
        f"{result.report.n_maxima} maxima; writing")
    _say_left_out(say, name, result.mask, data)
    if "ngff" in paths and not frame.axis_aligned:
        say(f"{name}: the OME-Zarr image is placed axis-aligned (NGFF 0.5 holds no rotation "
            "or flip); the NIfTI outputs and the .vti carry the input's full affine")
    if result.cut.get("fell_back"):
        say(f"{name}: cut by {result.cut['measure_rule']}")
    info = summary(result, name=name, source=volume.path, checksum=checksum,
                   files=volume.files, frame=frame, noise=noise, seed=seed,
                   requested_regions=requested_regions)
    if blockwise is not None:
        info["blockwise"] = blockwise
    info["timings_s"]["total"] = round(time.perf_counter() - started, 4)
    info["outputs"] = {kind: str(path) for kind, path in outputs.targets.items()}
    warning = degenerate_cut_warning(name, result, info["spread"], data.dtype)
    if warning:
        warnings.warn(warning, VolsegWarning, stacklevel=2)
    write_result_files(paths, result, data, info, frame=frame,
                       title=result_title(name, result, blockwise=blockwise is not None,
                                          spread=info["spread"]),
                       value_range=value_range)
    return info


def _stages_saying_warnings(data, request, storage, name, say, source, keep_hierarchy):
    """`run_stages`, its warnings (fewer maxima than asked, ...) given again as
    `VolsegWarning`s naming the input (the command line prints each as one line, even
    with -q)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        out = run_stages(data, request, storage, source=source,
                         keep_hierarchy=keep_hierarchy)
    for warning in caught:
        if issubclass(warning.category, UserWarning):
            warnings.warn(f"{name}: {warning.message}", VolsegWarning, stacklevel=2)
        else:
            warnings.warn_explicit(warning.message, warning.category, warning.filename,
                                   warning.lineno)
    return out


def _file_states(paths) -> dict:
    """Every file of an input (a store's files included) by its `file_identity`."""
    return {str(file): file_identity(os.stat(file)) for file in input_files(paths)}


def _unchanged(paths, before: dict) -> None:
    """Refuse an input whose files changed while the run read them (the labels would
    be of neither version, the checksum of the old one)."""
    after = _file_states(paths)
    if after != before:
        changed = sorted(set(after) ^ set(before)) or sorted(
            f for f in after if after[f] != before[f])
        from .io import VolumeFileError

        raise VolumeFileError(f"{changed[0]}: changed while volseg read it (size or "
                              "modification time); nothing was written. Run again once "
                              "it is complete")


def _storage(volume, data, request, paths, outputs, checksum, engine, say):
    if not _is_lazy(volume):
        return InMemory(say=lambda message: say(f"{volume.name}: {message}"))
    from .blockwise import BlockwiseStorage

    if request.mask not in (None, "none"):
        say(f"{volume.name}: mask {request.mask}")
    return BlockwiseStorage(data, request, paths, folder=outputs.folder, stem=outputs.stem,
                            checksum=checksum, frame=volume.frame, engine=engine,
                            say=lambda message: say(f"{volume.name}: {message}"))


def series_to_files(series, level, outputs, *, time_scale=1.0, relax=10, operator="weighted",
                    n_regions=None, min_persistence=None, boundary="partial", smooth_rounds=10,
                    memory_limit=None, say=_quiet) -> dict:
    """Segment the space-time isosurface of `series` and write its output set (an
    entered `OutputSet` named by `volseg.outputs.spacetime.series_output_names`);
    returns the summary."""
    from .outputs.spacetime import series_summary, write_series_segmentation
    from .spacetime import segment_series

    started = time.perf_counter()
    say(f"{series.name}: isosurface at {level:g} of a {'x'.join(map(str, series.shape))} "
        f"series, {relax} relaxation rounds, {operator} curvature, Morse complex")
    try:
        result = segment_series(series.data, level, spacing=series.spacing,
                                time_scale=time_scale, relax=relax, operator=operator,
                                n_regions=n_regions, min_persistence=min_persistence,
                                boundary=boundary, smooth_rounds=smooth_rounds,
                                memory_limit=memory_limit)
    except ValueError as err:           # what the series' values refuse, named by its file
        raise ValueError(f"{series.files[0] if series.files else series.name}: {err}") from None
    slices = result.slices()
    seg = result.segmentation
    say(f"{series.name}: {len(result.surface.vertices)} vertices, "
        f"{len(result.surface.simplices)} tetrahedra; {seg.n_regions} regions from "
        f"{seg.report.n_maxima} maxima; writing")
    info = series_summary(result, slices, name=series.name,
                          source=series.files[0] if series.files else None,
                          checksum=files_sha256(series.files), files=series.files)
    info["timings_s"]["total"] = round(time.perf_counter() - started, 4)
    title = (f"{series.name}: isosurface {level:g} in space-time, {seg.n_regions} regions "
             f"({seg.operator.replace('_', '-')} curvature)")
    info["time_step"], info["time_unit"] = series.time_step, series.time_unit
    info["time_offset"] = series.time_offset
    return write_series_segmentation(outputs, result, slices, info, title=title,
                                     frame=series.frame, time_step=series.time_step,
                                     time_offset=series.time_offset)


def segment_series_files(series, level, out_dir, *, force=False, wait=False, say=_quiet,
                         **options) -> dict:
    """Lock and check the output set ``<name>_iso_*`` of `series` in `out_dir`, then
    `series_to_files`; returns the summary."""
    from .outputs.spacetime import series_output_names

    out_dir = check_out_dir(out_dir)
    names = series_output_names(series.name, series.shape[-1])
    with OutputSet(out_dir, f"{series.name}_iso", names, force=force, wait=wait) as outputs:
        for line in outputs.recovered:
            say(f"{outputs.folder}: {line}")
        info = series_to_files(series, level, outputs, say=say, **options)
    say(f"{series.name}: wrote {Path(info['outputs']['mesh']).name}, "
        f"{Path(info['outputs']['pvd']).name} (+{series.shape[-1]} .vtu), "
        f"{Path(info['outputs']['summary']).name}, {Path(info['outputs']['preview']).name}")
    return info
