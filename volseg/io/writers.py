"""`write_volume`: labels and curvature to NIfTI, NRRD, .npy or raw, atomically, with
the input's voxel-to-world frame."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._atomic import temporary_beside
from .readers import NRRD_TYPES
from .volume import Frame

__all__ = ["write_volume", "atomic_path"]

_NRRD_NAMES = {code: name for name, code in NRRD_TYPES.items()
               if "_" not in name and " " not in name}


#: A temporary file beside a path (kept under this name for callers of volseg.io).
atomic_path = temporary_beside


#: NIfTI's names of the length units it has (others are written as 'unknown').
_NIFTI_UNITS = {"meter": "meter", "millimeter": "mm", "micrometer": "micron"}


def _nifti(path: Path, data, frame: Frame, compressed: bool, labels: bool, description):
    import nibabel

    image = nibabel.Nifti1Image(data, frame.affine)
    header = image.header
    header.set_sform(frame.affine, frame.sform_code)
    header.set_qform(frame.affine if frame.qform is None else frame.qform, frame.qform_code)
    header.set_xyzt_units(_NIFTI_UNITS.get(frame.unit, "unknown"))
    if labels:                  # a label map: viewers pick a lookup table, not a grey ramp
        header.set_intent("label")
    if data.size:               # the display range: 0..k for labels, the values' range
        if data.dtype.kind == "f":                  # over the finite values, no copy
            finite = np.isfinite(data)
            low = np.min(data, where=finite, initial=np.inf)
            high = np.max(data, where=finite, initial=-np.inf)
        else:
            low, high = data.min(), data.max()
        if np.isfinite(low) and np.isfinite(high):
            header["cal_min"], header["cal_max"] = (0 if labels else low), high
    if description:
        header["descrip"] = description.encode("ascii", "replace")[:79]
    # Into a temporary name, then moved; gzip by ISA-L (`_gzip_writer`), not nibabel's.
    named = path.with_name(path.name + (".nii.gz" if compressed else ".nii"))
    try:
        with open(named, "wb") as raw, (_gzip_writer(raw) if compressed else raw) as out:
            image.to_file_map({"image": nibabel.FileHolder(fileobj=out)})
        os.replace(named, path)
    finally:
        named.unlink(missing_ok=True)


def _gzip_writer(raw):
    """A gzip stream into the open file `raw`, compressed by ISA-L at level 1 (a standard
    gzip member, read by every gzip reader): 17x less CPU than zlib's level 1, which
    nibabel uses, for the same size on float data; no time stamp and no file name (a
    temporary one) in its header, so equal volumes give equal files."""
    from isal import igzip

    return igzip.IGzipFile(filename="", fileobj=raw, mode="wb", compresslevel=1, mtime=0)


#: NRRD's usual spellings (3D Slicer writes "mm"); others by their full name.
_NRRD_UNITS = {"millimeter": "mm", "micrometer": "um", "nanometer": "nm", "meter": "m"}


def _nrrd(path: Path, data, frame: Frame):
    code = data.dtype.str[1:]
    if code not in _NRRD_NAMES:
        raise ValueError(f"{path}: NRRD cannot hold {data.dtype}")
    columns = frame.affine[:3, :3].T
    directions = " ".join("(" + ",".join(f"{v:.17g}" for v in c) + ")" for c in columns)
    origin = "(" + ",".join(f"{v:.17g}" for v in frame.affine[:3, 3]) + ")"
    quoted = f'"{_NRRD_UNITS.get(frame.unit, frame.unit)}"'
    units = f"space units: {quoted} {quoted} {quoted}\n" if frame.unit else ""
    header = (
        f"NRRD0005\ntype: {_NRRD_NAMES[code]}\ndimension: 3\n"
        f"space: right-anterior-superior\nsizes: {' '.join(map(str, data.shape))}\n"
        f"space directions: {directions}\nspace origin: {origin}\n{units}"
        f"endian: little\nencoding: raw\n\n"
    )
    with open(path, "wb") as handle:
        handle.write(header.encode())
        handle.write(np.ascontiguousarray(data.transpose(2, 1, 0)).astype(
            data.dtype.newbyteorder("<")).tobytes())


def write_volume(path, data, *, spacing=(1.0, 1.0, 1.0), frame: Frame | None = None,
                 labels: bool = False, description: str | None = None) -> Path:
    """Write a label or curvature volume, atomically (temporary file, then rename).

    Parameters
    ----------
    path : str or Path
        The format follows the extension: ``.nii.gz`` / ``.nii`` (NIfTI),
        ``.nrrd`` (with space directions and origin, RAS+), ``.npy``, ``.raw``
        (x fastest, native little-endian, no header).
    data : (X, Y, Z) array_like
        A boolean array (a mask) is written as uint8 0 / 1.
    spacing : (3,) sequence of float
        Voxel sizes, for an axis-aligned frame when `frame` is not given.
    frame : Frame, optional
        The voxel-to-world frame, normally the input's (``volume.frame``): NIfTI
        outputs get its affine, qform, codes and length unit unchanged.
    labels : bool
        `data` is a label map: NIfTI's label intent and display range 0..k.
    description : str, optional
        NIfTI's ``descrip`` (79 ASCII characters at most: the rest is cut).
    """
    path = Path(path)
    data = np.asarray(data)
    if data.dtype == bool:        # a mask: as 0 / 1 bytes (NIfTI and NRRD have no bool type)
        data = data.astype(np.uint8)
    frame = frame or Frame.from_spacing(spacing)
    name = path.name.lower()
    if not name.endswith((".nii", ".nii.gz", ".npy", ".nrrd", ".raw")):
        raise ValueError(f"{path}: unknown output format; use .nii.gz, .nii, .npy, .nrrd or .raw")
    tmp = atomic_path(path)
    try:
        if name.endswith((".nii", ".nii.gz")):
            _nifti(tmp, data, frame, compressed=name.endswith(".gz"), labels=labels,
                   description=description)
        elif name.endswith(".npy"):
            with open(tmp, "wb") as handle:
                np.save(handle, data)
        elif name.endswith(".nrrd"):
            _nrrd(tmp, data, frame)
        else:
            with open(tmp, "wb") as handle:
                handle.write(np.ascontiguousarray(data.transpose(2, 1, 0)).tobytes())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
