"""One writer for a volume's output set, whatever its labels are: numpy arrays in
memory, or lazy arrays the blockwise path has already stored."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .. import _json
from .._distinct import label_type
from ..io import Frame, OutputSet, write_ngff, write_volume, write_vti, write_vts, write_zarr

__all__ = ["write_result_files", "write_segmentation"]

#: The array outputs: kind -> the paths' keys that hold it (a set has one or both).
_ARRAY_KEYS = {"labels": ("labels", "labels_nifti"), "curvature": ("curvature", "curvature_nifti")}


def write_result_files(paths: dict, result, values, info: dict, *, frame: Frame | None,
                       title: str, value_range=None) -> None:
    """Write `result`'s files into `paths` (an output set's staging paths): labels and
    curvature (NIfTI, or Zarr for ``.zarr`` paths; a path already written by the
    blockwise path's storage is kept), the ParaView image of the input, curvature and
    labels (streamed: lazy arrays stay lazy), preview, persistence plot, summary `info`.

    `values` is the volume that was segmented (for the preview) and `value_range` its
    (min, max), when known. Labels are written in the smallest unsigned type that
    holds them (what label viewers expect), the curvature as float32 in NIfTI.
    """
    from .preview import write_persistence_plot, write_preview

    frame = frame or Frame.from_spacing(result.spacing)
    k = int(result.n_regions)
    # Cast once, for every writer that takes them (NIfTI, Zarr, NGFF, ParaView); lazy
    # arrays stay lazy.
    arrays = {"labels": result.labels.astype(label_type(k), copy=False),
              "curvature": result.curvature.astype(np.float32)}
    curve = (result.report.curve, result.report.curve.n_components, result.threshold)
    # The writers run at once: ISA-L's gzip releases the GIL while it compresses (two
    # threads each writing 32 MB of float32 took 0.55-0.75 of the serial time).
    with ThreadPoolExecutor(3) as pool:
        jobs = [pool.submit(_write_array, Path(paths[key]), arrays[kind], frame, kind,
                            _description(kind, result))
                for kind, keys in _ARRAY_KEYS.items() for key in keys
                if key in paths and not Path(paths[key]).exists()]
        jobs.append(pool.submit(write_preview, paths["preview"], values, result.curvature,
                                result.labels, title=title, persistence=curve,
                                value_range=value_range, n_labels=k, measure=result.measure,
                                field=getattr(result, "field", "curvature")))
        field = getattr(result, "field", "curvature")
        if "ngff" in paths:
            jobs.append(pool.submit(write_ngff, paths["ngff"], arrays["labels"],
                                    result.curvature, frame, field))  # means in float64
        if "paraview" in paths:         # the arrays named for what they hold
            write_paraview = write_vts if str(paths["paraview"]).endswith(".vts") else write_vti
            jobs.append(pool.submit(write_paraview, paths["paraview"],
                                    {"labels": arrays["labels"], field: arrays["curvature"],
                                     "values": values}, frame))
        if "persistence" in paths:
            jobs.append(pool.submit(write_persistence_plot, paths["persistence"], *curve, k,
                                    measure=result.measure))
        for job in jobs:
            job.result()
    Path(paths["summary"]).write_text(_json.dumps(info, indent=2))


def _write_array(path: Path, array, frame, kind: str, description: str):
    if path.name.endswith(".zarr"):
        write_zarr(path, array, frame=frame)
    else:
        write_volume(path, np.asarray(array), frame=frame, labels=kind == "labels",
                     description=description)


def _description(kind: str, result) -> str:
    """A NIfTI ``descrip`` naming the run (79 characters at most)."""
    from .._version import __version__

    operator = result.operator.replace("_", "-")
    if kind == "labels":
        return (f"volseg {__version__} labels 1..{int(result.n_regions)} ({operator} "
                f"curvature, {result.measure} cut), 0 outside")
    return f"volseg {__version__} {operator} mean curvature"


def write_segmentation(outputs: OutputSet, result, values, info: dict, *, frame: Frame | None,
                       title: str) -> dict:
    """Write labels, curvature, summary and preview of `result` as one set (an entered
    `OutputSet`); `info` is the summary (its ``outputs`` entry is filled in here).
    Returns the summary."""
    info = {**info, "outputs": {kind: str(path) for kind, path in outputs.targets.items()}}
    outputs.commit(lambda paths: write_result_files(paths, result, values, info, frame=frame,
                                                    title=title))
    return info
