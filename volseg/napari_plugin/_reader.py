"""The napari reader: volseg's output sets, its OME-Zarr output, and every input
volseg segments, each through volseg's own checked readers (a malformed file is
refused with its one-line message, as at the command line)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..errors import MissingChunksError, VolsegError, VolsegWarning
from ..io.ngff import ome_levels
from ..io.readers import is_tiff_folder
from ..outputs import BLOCKWISE_SUFFIXES, NGFF_SUFFIX, OUTPUT_SUFFIXES
from ._layers import frame_kwargs, to_layer

__all__ = ["napari_get_reader", "read", "open_in", "demo_layers"]

_SUMMARY = OUTPUT_SUFFIXES["summary"]
#: The name of the labels image inside volseg's OME-Zarr output.
NGFF_LABELS = "labels/regions"


def napari_get_reader(path):
    """The reader of `path` (one path, or a list of one), or None when volseg cannot
    read it (napari then asks the next plugin)."""
    if isinstance(path, (list, tuple)):
        if len(path) != 1:
            return None
        path = path[0]
    path = Path(path)
    if path.name.endswith(_SUMMARY):
        return read if _is_volseg_summary(path) else None
    if path.is_dir() and not path.name.lower().endswith(".zarr") and not is_tiff_folder(path):
        return None
    return read


def read(path) -> list[tuple]:
    """Layer data of `path`: an output set (by its ``_summary.json``): the curvature as
    an image and the labels as labels, both placed by the input's frame; volseg's
    OME-Zarr output: the same, as multiscale layers; any input: one image layer that
    carries its `Volume` (what the segmentation widget segments)."""
    path = Path(path[0] if isinstance(path, (list, tuple)) else path)
    if path.name.endswith(_SUMMARY):
        return _output_set(path)
    if path.name.endswith(NGFF_SUFFIX) and (path / NGFF_LABELS).is_dir():
        return _ngff_output(path)
    volume = _load(path)
    if path.name.endswith((OUTPUT_SUFFIXES["labels"], BLOCKWISE_SUFFIXES["labels"])):
        # One of volseg's label maps opened on its own: a labels layer, not an image.
        return [_result_layer(to_layer(volume.data), volume.name, "labels",
                              frame_kwargs(volume.frame))]
    return [_input_layer(volume)]


def open_in(viewer, path) -> list:
    """Open `path` in `viewer` with volseg's reader, whatever its name (the reader's
    patterns claim only what no other napari reader opens: summaries, .raw, .dat,
    .nrrd, .nhdr); returns the layers added."""
    from napari.layers import Layer

    return [viewer.add_layer(Layer.create(*layer)) for layer in read(path)]


def demo_layers() -> list[tuple]:
    """The sample data: volseg's built-in demo volume."""
    from ..datasets import demo_volume
    from ..io import Volume

    return [_input_layer(Volume(demo_volume(), name="demo", source="built-in synthetic"))]


def _load(path: Path, **options):
    """volseg's reader; a Zarr store whose writer skipped chunks of the fill value (Zarr's
    and ome-zarr-py's default) is read with them as the fill value, and napari shows a
    warning saying so (the CLI refuses it unless ``--fill-missing-chunks``)."""
    from ..blockwise.engine import default_memory_limit
    from ..files import load_for_budget

    try:
        try:
            return load_for_budget(str(path), default_memory_limit(), **options)
        except MissingChunksError as err:
            volume = load_for_budget(str(path), default_memory_limit(), **options,
                                     fill_missing_chunks=True)
            warnings.warn(f"{err}: read them as the fill value, as every Zarr reader does "
                          "(volseg segment needs --fill-missing-chunks for this store)",
                          VolsegWarning, stacklevel=2)
            return volume
    except VolsegError as err:
        raise ValueError(str(err)) from None     # napari shows a reader's error as one line


def _input_layer(volume) -> tuple:
    return (to_layer(volume.data),
            {"name": volume.name, "metadata": {"volseg_volume": volume},
             **frame_kwargs(volume.frame)}, "image")


#: A summary larger than this is not one of volseg's (they are a few kB to a few MB).
SUMMARY_BYTES = 64 * 2**20


def _summary_of(path: Path) -> dict | None:
    """The summary at `path`, or None when it is not one of volseg's: only a regular
    file of sane size is opened (a FIFO or a device would block the viewer)."""
    try:
        if not path.is_file() or path.stat().st_size > SUMMARY_BYTES:
            return None
        with open(path, encoding="utf-8") as file:
            info = json.load(file)
    except (OSError, ValueError):
        return None
    if isinstance(info, dict) and "volseg_version" in info and "n_regions" in info:
        return info
    return None


def _is_volseg_summary(path: Path) -> bool:
    return _summary_of(path) is not None


def _output_set(summary: Path) -> list[tuple]:
    """The curvature and labels beside `summary`: the Zarr stores of a blockwise run,
    else the NIfTI files; read as one run wrote them, never halfway through another
    run's commit of the stem (`volseg.io.output_set.read_set`; a Zarr store is read
    lazily, later, as napari shows it)."""
    from ..io.output_set import read_set

    stem = summary.name[: -len(_SUMMARY)]
    try:
        return read_set(summary, stem, lambda: _set_layers(summary, stem))
    except VolsegError as err:
        raise ValueError(str(err)) from None


def _set_layers(summary: Path, stem: str) -> list[tuple]:
    info = _summary_of(summary)
    if info is None:
        raise ValueError(f"{summary}: not a volseg summary (a regular JSON file with "
                         "volseg_version and n_regions)")
    field = info.get("field", "curvature")
    layers = []
    for kind, layer_type in (("curvature", "image"), ("labels", "labels")):
        zarr = summary.parent / (stem + BLOCKWISE_SUFFIXES[kind].replace("curvature", field))
        nifti = summary.parent / (stem + OUTPUT_SUFFIXES[kind].replace("curvature", field))
        if not (zarr.exists() or nifti.exists()):
            raise ValueError(f"{summary}: its {'labels' if kind == 'labels' else field} file "
                             f"{nifti.name} is missing beside it (moved or deleted?)")
        volume = _load(zarr if zarr.exists() else nifti)
        name = f"{stem} {'labels' if kind == 'labels' else field}"
        layers.append(_result_layer(to_layer(volume.data), name, layer_type,
                                    frame_kwargs(volume.frame)))
    return layers


def _ngff_output(path: Path) -> list[tuple]:
    """volseg's OME-Zarr output as multiscale layers (every level read lazily)."""
    stem = path.name[: -len(NGFF_SUFFIX)]
    layers = []
    for sub, kind, layer_type in (("", "curvature", "image"), (NGFF_LABELS, "labels", "labels")):
        levels = [_load(path / sub, ome_level=level)
                  for level in range(max(ome_levels(path / sub), 1))]
        data = [to_layer(level.data) for level in levels]
        layers.append(_result_layer(data if len(data) > 1 else data[0], f"{stem} {kind}",
                                    layer_type, frame_kwargs(levels[0].frame)))
    return layers


#: The curvature's contrast limits are percentiles of at most about this many voxels.
CONTRAST_SAMPLE = 64**3


def _result_layer(data, name: str, layer_type: str, placement: dict) -> tuple:
    kwargs = {"name": name, **placement}
    if layer_type == "image":
        kwargs["colormap"] = "magma"
        sample = data[-1] if isinstance(data, list) else data
        step = max(1, int(np.ceil((np.prod(sample.shape) / CONTRAST_SAMPLE) ** (1 / 3))))
        low, high = np.percentile(np.asarray(sample[::step, ::step, ::step]), [1, 99])
        kwargs["contrast_limits"] = (float(low), float(high)) if high > low else None
    return (data, kwargs, layer_type)
