"""The names of a segmentation's files, its summary and its title.

``<stem>_labels.nii.gz`` and ``<stem>_curvature.nii.gz`` carry the input's
voxel-to-world frame (affine and NIfTI codes); ``<stem>_volumes.vti`` holds the input,
curvature and labels for ParaView; ``<stem>_summary.json`` is strict JSON (non-finite
numbers are null); ``<stem>_preview.png`` shows mid slices.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .._version import __version__
from ..io import Frame
from ..morse import get_measure
from ..morse.cuts import LISTED_PERSISTENCES

__all__ = ["OUTPUT_SUFFIXES", "BLOCKWISE_NIFTI_VOXELS", "PARAVIEW_SUFFIX",
           "PARAVIEW_GRID_SUFFIX", "PARAVIEW_VOXELS",
           "NGFF_SUFFIX", "output_names", "all_output_names", "files_sha256", "summary",
           "result_summary", "input_summary", "result_title", "degenerate_cut_warning"]

OUTPUT_SUFFIXES = {"labels": "_labels.nii.gz", "curvature": "_curvature.nii.gz",
                   "summary": "_summary.json", "preview": "_preview.png"}


#: The blockwise path's labels and curvature: chunked Zarr stores, never whole in memory.
BLOCKWISE_SUFFIXES = {"labels": "_labels.zarr", "curvature": "_curvature.zarr"}
#: Up to this many voxels the blockwise path also writes the NIfTI files of the
#: in-memory path (``labels_nifti``, ``curvature_nifti``), each read whole from its
#: store: at 256^3 that is 134 MB for the float64 curvature and its float32 copy.
BLOCKWISE_NIFTI_VOXELS = 256**3


#: Curvature and labels as an OME-Zarr image with its labels, for napari, neuroglancer
#: and every NGFF viewer (`volseg.io.write_ngff`).
NGFF_SUFFIX = "_segmentation.ome.zarr"
#: The input, curvature and labels in one VTK image for ParaView (`volseg.io.write_vti`).
PARAVIEW_SUFFIX = "_volumes.vti"
#: The same as a structured grid with every point's world position, for an oblique or
#: flipped input (`volseg.io.write_vts`): ParaView's Contour ignores an image's Direction.
PARAVIEW_GRID_SUFFIX = "_volumes.vts"
#: Up to this many voxels every run writes the ParaView image (about 9 bytes per voxel
#: for 8-bit input: 150 MB at 256^3); above it only on request (``--vti``).
PARAVIEW_VOXELS = 256**3


def output_names(stem: str, persistence_plot: bool = False, blockwise: bool = False,
                 voxels: int | None = None, paraview: bool | None = None,
                 field: str = "curvature", axis_aligned: bool = True) -> dict:
    """Kind -> file name of the outputs of `stem` (with ``<stem>_persistence.png``
    when `persistence_plot`; labels and curvature as ``.zarr`` when `blockwise`, and
    also as NIfTI when the volume's `voxels` are given and at most
    `BLOCKWISE_NIFTI_VOXELS`; the OME-Zarr image ``<stem>_segmentation.ome.zarr``; the ParaView
    image ``<stem>_volumes.vti`` when `paraview`, or by default when `voxels` are
    unknown or at most `PARAVIEW_VOXELS`; ``<stem>_volumes.vts`` instead when the
    input's frame is not `axis_aligned`)."""
    names = {kind: stem + suffix.replace("curvature", field)
             for kind, suffix in OUTPUT_SUFFIXES.items()}
    names["ngff"] = stem + NGFF_SUFFIX
    if paraview or (paraview is None and (voxels is None or voxels <= PARAVIEW_VOXELS)):
        names["paraview"] = stem + (PARAVIEW_SUFFIX if axis_aligned else PARAVIEW_GRID_SUFFIX)
    if blockwise:
        if voxels is not None and voxels <= BLOCKWISE_NIFTI_VOXELS:
            names.update({f"{kind}_nifti": stem + OUTPUT_SUFFIXES[kind].replace("curvature", field)
                          for kind in BLOCKWISE_SUFFIXES})
        names.update({kind: stem + suffix.replace("curvature", field)
                      for kind, suffix in BLOCKWISE_SUFFIXES.items()})
    if persistence_plot:
        names["persistence"] = f"{stem}_persistence.png"
    return names


def all_output_names(stem: str, fields=("curvature",)) -> set:
    """Every file name a set of `stem` can have, whatever its options (each of
    `fields`, in memory or blockwise, with the persistence plot and the ParaView image):
    what a new set of the stem replaces, so no file of an older run stays beside it."""
    names = set()
    for field in fields:
        names |= set(output_names(stem, persistence_plot=True, blockwise=True, voxels=1,
                                  paraview=True, field=field).values())
        names |= set(output_names(stem, persistence_plot=True, paraview=True,
                                  field=field, axis_aligned=False).values())
    return names


def input_files(paths) -> list[Path]:
    """Every file of an input's `paths`: a Zarr store is a folder, its files in name
    order, but for an OME-Zarr image's ``labels/`` (derived images, never read as the
    image: adding labels, ``--labels-into-input``, leaves its checksum as it was)."""
    files = []
    for path in map(Path, paths):
        if not path.is_dir():
            files.append(path)
            continue
        files += sorted(p for p in path.rglob("*") if p.is_file()
                        and p.relative_to(path).parts[0] != "labels")
    return files


def files_sha256(paths) -> str | None:
    """SHA-256 of the bytes of `paths` read one after another (a detached header and its
    data file: every byte the reader used). None for no files."""
    paths = list(paths)
    if not paths:
        return None
    digest = hashlib.sha256()
    for path in input_files(paths):
        with open(path, "rb") as handle:
            for block in iter(lambda h=handle: h.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def _auto_phrase(cut: dict, measure: str) -> str:
    """How ``--regions auto`` chose its count, with the evidence it read."""
    evidence = cut.get("auto_evidence") or {}
    if evidence.get("n_regions") is None:
        return "auto: fewer maxima than the 20-40 window; all of them"
    ratio, needed = evidence["ratio"], evidence["needed"]
    if evidence["n_regions"] == cut["n_regions"] and ratio >= needed:
        return (f"auto: the {measure} gap at {evidence['n_regions']} regions stands out: "
                f"{ratio:.2f}x the step of a power law fitted to the 20-40 window, "
                f"{needed:.2f}x needed")
    return (f"auto: no {measure} gap stands out for 20-40 regions (the most, at "
            f"{evidence['n_regions']}, is {ratio:.2f}x a power law's step, "
            f"{needed:.2f}x needed): the default count")


def result_summary(result) -> dict:
    """The part of a summary every `Segmentation` has, volume or mesh: operator, cut,
    persistence, regions and their spread (`volseg.metrics.region_spread`), timings."""
    from ..metrics import region_spread

    regions = result.region_table()
    measure = result.measure
    return {
        "field": getattr(result, "field", "curvature"),
        "operator": result.operator,
        "n_regions": result.n_regions,
        "cut": _auto_phrase(result.cut, measure) if result.cut.get("auto")
        else (f"{measure} threshold" if result.cut.get("threshold") is not None
              else "region count"),
        "measure": measure,
        "measure_rule": result.cut.get("measure_rule", "as asked"),
        "threshold": result.threshold,
        "min_persistence": result.min_persistence,
        "min_component": result.cut.get("min_component", 0.0),
        "n_maxima": int(result.report.n_maxima),
        "persistence": {
            "components": result.report.n_components,
            "events": int(result.report.n_events),
            f"largest_{LISTED_PERSISTENCES}": result.report.largest_persistences.tolist(),
        },
        "regions": regions,
        "spread": region_spread([r["size"] for r in regions]),
        "timings_s": {k: round(v, 4) for k, v in result.timings.items()},
    }


def input_summary(name, source=None, checksum=None, files=()) -> dict:
    """Where the input came from: name or path, every file read, their SHA-256."""
    return {
        "volseg_version": __version__,
        "input": str(source) if source else name,
        "input_files": [str(f) for f in files],
        "input_sha256": checksum,
    }


#: What the summary says of an oblique or flipped input's OME-Zarr image.
NGFF_NOT_PLACED = ("axis-aligned: the input's frame rotates or flips its axes, which "
                   "NGFF 0.5 (scale and translation only) cannot hold; the OME-Zarr "
                   "image's voxel (i, j, k) sits at origin + spacing x (i, j, k), not where "
                   "the scan is. The NIfTI outputs carry the full affine, and the ParaView "
                   "file (.vts) every voxel's world position")


def ngff_placement(frame) -> str:
    """``"exact"`` when the OME-Zarr image can sit where the input is, else why not."""
    return "exact" if frame is None or frame.axis_aligned else NGFF_NOT_PLACED


def summary(result, *, name, source=None, checksum=None, files=(), frame: Frame | None = None,
            noise=None, seed=None, requested_regions=None) -> dict:
    """The summary dictionary of a `Segmentation` of a volume (strict-JSON ready)."""
    common = result_summary(result)
    out = {
        **input_summary(name, source, checksum, files),
        "shape": list(result.labels.shape),
        "spacing": list(result.spacing),
        "affine": (frame.affine if frame is not None else np.diag([*result.spacing, 1.0])).tolist(),
        "ome_zarr_placement": ngff_placement(frame),
        "operator": common.pop("operator"),
        "value_scale": result.value_scale,
        "noise_percent": noise or 0.0,
        "seed": seed if noise else None,
        "smooth_sigma_voxels": result.smooth_sigma,
        "smooth_rule": result.smooth_rule,
        "padding": result.padding,
        "mask": result.mask.describe(),
        "labels": "0 outside the mask, regions 1..k",
        "n_regions": common.pop("n_regions"),
        "requested_regions": requested_regions,
        **common,
    }
    return out


def result_title(name: str, result, *, blockwise: bool = False, spread=None) -> str:
    """The preview's title of a volume's `Segmentation`: regions, operator, smoothing,
    mask, path; with a degenerate `spread` (`volseg.metrics.region_spread`), that too."""
    field = getattr(result, "field", "curvature")
    what = (f"{result.operator.replace('_', '-')} curvature" if field == "curvature"
            else f"the {field} field")
    title = f"{name}: {result.n_regions} regions, {what}"
    if result.smooth_sigma:
        title += f", smoothed sigma {result.smooth_sigma:g}"
    if result.mask is not None and result.mask.mask is not None:
        title += f", mask {result.mask.used}"
    title += " (blockwise)" if blockwise else ""
    if spread is not None and spread["degenerate"]:
        title += (f"; degenerate cut: the largest region holds "
                  f"{100 * spread['largest_share']:.1f} %")
    return title


def degenerate_cut_warning(name: str, result, spread: dict, dtype) -> str | None:
    """One line for a degenerate cut (None otherwise): the spread, the likely cause and
    the option that fixes it."""
    if not spread["degenerate"]:
        return None
    what = (f"{name}: the largest of {result.n_regions} regions holds "
            f"{100 * spread['largest_share']:.1f} % of the labelled voxels and only "
            f"{spread['regions_at_least_1_percent']} hold 1 % or more")
    if not get_measure(result.measure).pruned:
        fix = ("the most persistent curvature peaks are voxel-sized spikes; try --measure "
               "hypervolume (or size)" + (", --smooth 1" if result.smooth_sigma == 0 else ""))
    elif result.smooth_sigma == 0 and np.dtype(dtype).kind in "biu":
        fix = ("on integer data the quantization steps dominate the curvature; "
               "try --smooth 1 or 2")
    elif result.smooth_sigma == 0:
        fix = "noise or voxel-scale detail dominates the curvature; try --smooth 1"
    else:
        fix = (f"try a larger --smooth than {result.smooth_sigma:g}, or --mask to leave "
               "the background out")
    return f"{what}: {fix}"
