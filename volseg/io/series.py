"""Time series of volumes: one 4-D file (x, y, z, t) or several 3-D files in time order.

The readers are those of `read_volume` (bounded, every field checked); a series adds
only that every step has the same shape, grid (spacing, origin, axes, unit) and type.
"""

from __future__ import annotations

import glob
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .. import _validate
from ._files import regular_file_size
from .readers import _read_nifti, _read_npy, read_volume
from .volume import Frame, VolumeFileError

__all__ = ["Series", "read_series", "SERIES_SUFFIXES"]

#: Files that may hold a whole (x, y, z, t) series.
SERIES_SUFFIXES = (".npy", ".nii", ".nii.gz")


@dataclass
class Series:
    """A time-varying volume.

    Attributes
    ----------
    data : (X, Y, Z, T) ndarray
        Indexed [x, y, z, t].
    spacing : (3,) tuple of float
        Voxel size (of the first step; every step must agree).
    name : str
        Output stem.
    files : tuple of Path
        Every file read, in time order.
    frame : Frame
        Voxel-to-world frame of the first step.
    time_step : float
        The time between two steps, in `time_unit` (a 4-D NIfTI's pixdim[4]; 1
        when the input does not say).
    time_unit : str or None
        ``"second"``, ``"millisecond"`` or ``"microsecond"`` (NIfTI's time units),
        None when unknown.
    time_offset : float
        The time of the first step, in `time_unit` (a 4-D NIfTI's toffset; 0 when the
        input does not say).
    """

    data: NDArray
    spacing: tuple
    name: str
    files: tuple = field(default_factory=tuple)
    frame: Frame | None = None
    time_step: float = 1.0
    time_unit: str | None = None
    time_offset: float = 0.0

    @property
    def shape(self) -> tuple:
        """The series' (X, Y, Z, T) shape."""
        return self.data.shape


def _expand(inputs) -> list[Path]:
    paths = []
    for item in inputs:
        text = str(item)
        if any(c in text for c in "*?[") and not Path(text).exists():
            matched = sorted(glob.glob(text))
            if not matched:
                raise FileNotFoundError(2, "no file matches this pattern", text)
            paths.extend(Path(m) for m in matched)
        else:
            paths.append(Path(text))
    return paths


#: NIfTI's time units as their full names.
_NIFTI_TIME_UNITS = {"sec": "second", "msec": "millisecond", "usec": "microsecond"}


def _nifti_time(path: Path) -> tuple:
    """(time step, unit, offset) of a 4-D NIfTI: pixdim[4], the xyzt_units time code
    and toffset; a step that is not a positive finite number is 1 (unknown), an offset
    that is not finite 0."""
    import nibabel

    header = nibabel.load(path).header
    zooms = header.get_zooms()
    step = float(zooms[3]) if len(zooms) > 3 else 1.0
    unit = _NIFTI_TIME_UNITS.get(header.get_xyzt_units()[1])
    offset = float(header["toffset"]) if "toffset" in header else 0.0
    offset = offset if np.isfinite(offset) else 0.0
    return (step, unit, offset) if np.isfinite(step) and step > 0 else (1.0, None, offset)


def _zarr_series(path: Path) -> Series:
    """A 4-D Zarr array (x, y, z, t), read whole (the isosurface needs all of it)."""
    import zarr

    try:
        array = zarr.open(str(path), mode="r")
    except Exception as err:  # noqa: BLE001 - any failure to open is the store's
        raise VolumeFileError(f"{path}: not a readable Zarr store ({type(err).__name__}: "
                              f"{err})") from None
    if not hasattr(array, "nchunks") or array.ndim != 4:
        raise VolumeFileError(f"{path}: the series must be one 4-D Zarr array (x, y, z, t), got "
                              f"{'a group' if not hasattr(array, 'ndim') else f'{array.ndim}-D'}")
    if array.nchunks_initialized < array.nchunks:
        raise VolumeFileError(f"{path}: {array.nchunks - array.nchunks_initialized} of "
                              f"{array.nchunks} chunks are missing")
    try:
        data = array[...]
    except Exception as err:  # noqa: BLE001 - codec errors have no common type
        raise VolumeFileError(f"{path}: a chunk is unreadable ({type(err).__name__}: "
                              f"{err})") from None
    data = _validate.volume_array(data, source=path, error=VolumeFileError, ndim=4)
    spacing = tuple(dict(array.attrs).get("volseg", {}).get("spacing", (1.0, 1.0, 1.0)))[:3]
    name = path.name[:-5] if path.name.endswith(".zarr") else path.name
    return Series(data, spacing, name, (path,), Frame.from_spacing(spacing))


def read_series(inputs, *, allow_external_data: bool = False) -> Series:
    """Read a time series.

    Parameters
    ----------
    inputs : path, or sequence of paths or glob patterns
        One ``.npy`` / ``.nii`` / ``.nii.gz`` file or Zarr array holding an (x, y, z, t)
        array, or
        two or more 3-D volumes (any format `read_volume` reads) in time order; a
        glob pattern expands to its matches sorted by name.

    Returns
    -------
    Series

    Raises
    ------
    VolumeFileError
        A file `read_volume` refuses, a single file that is not 4-D, steps of
        different shapes, grids or types, fewer than 2 time steps.
    FileNotFoundError
        A missing file or a pattern that matches nothing.
    """
    if isinstance(inputs, (str, Path)):
        inputs = [inputs]
    paths = _expand(inputs)
    if len(paths) == 1:
        path = paths[0]
        from .zarr_store import is_zarr

        if is_zarr(path):
            return _zarr_series(path)
        regular_file_size(path)
        lower = path.name.lower()
        if not lower.endswith(SERIES_SUFFIXES):
            raise VolumeFileError(f"{path}: one file must hold the whole series as an (x, y, z, t) "
                                  f"array ({', '.join(SERIES_SUFFIXES)}); or give one 3-D volume "
                                  "per time step")
        reader = _read_npy if lower.endswith(".npy") else _read_nifti
        try:
            data, frame, name, _, files = reader(path, None, None, None, allow_external_data)
        except MemoryError:
            raise VolumeFileError(f"{path}: the declared size does not fit in this machine's "
                                  "memory") from None
        data = _validate.volume_array(data, source=path, error=VolumeFileError, ndim=4)
        frame = frame or Frame.from_spacing((1.0, 1.0, 1.0))
        step, unit, offset = (_nifti_time(path) if not lower.endswith(".npy")
                              else (1.0, None, 0.0))
        return Series(data, tuple(frame.spacing), name, tuple(files), frame, step, unit,
                      offset)
    steps = [read_volume(p, allow_external_data=allow_external_data) for p in paths]
    first = steps[0]
    for path, step in zip(paths[1:], steps[1:], strict=True):
        if step.shape != first.shape:
            raise VolumeFileError(f"{path}: time step of shape {step.shape}, but {paths[0]} is "
                                  f"{first.shape}; every step must have the same shape")
        if not np.allclose(step.spacing, first.spacing):
            raise VolumeFileError(f"{path}: spacing {step.spacing} differs from {paths[0]}'s "
                                  f"{first.spacing}")
        if not first.frame.same_grid(step.frame):
            raise VolumeFileError(f"{path}: its voxels sit elsewhere than {paths[0]}'s "
                                  "(origin, axes or unit differ); every step must share "
                                  "one grid")
        if step.dtype != first.dtype:
            # Stacked, float 0..1 and uint8 0..255 steps would be one field on one scale.
            raise VolumeFileError(f"{path}: a time step of type {step.dtype}, but {paths[0]} "
                                  f"is {first.dtype}; every step must have the same type "
                                  "(and scale): convert the steps to one first")
    data = np.stack([np.asarray(s.data) for s in steps], axis=-1)
    files = tuple(f for s in steps for f in s.files)
    return Series(data, tuple(first.spacing), first.name, files, first.frame)
