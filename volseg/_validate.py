"""The front door: checks of what a user hands to volseg, done once where it enters,
with the argument named in every message (STYLE.md section 4)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["volume_array", "spacing", "smooth"]

# Cut parameters (n_regions, min_persistence) are checked by volseg.morse.check_cut,
# which owns them: the Morse stage stands alone.


def volume_array(volume, name: str = "volume") -> NDArray:
    """A 3-D real, finite array with at least 2 samples per axis (not copied)."""
    data = np.asarray(volume)
    if data.ndim != 3:
        raise ValueError(f"`{name}` must be 3-D, got shape {data.shape}")
    if min(data.shape) < 2:
        raise ValueError(f"`{name}` needs at least 2 samples along each axis, got shape {data.shape}")
    if data.dtype.kind not in "biuf":
        raise ValueError(f"`{name}` must hold real numbers, got dtype {data.dtype}")
    if data.dtype.kind == "f" and not np.isfinite(data).all():
        raise ValueError(f"`{name}` holds {int((~np.isfinite(data)).sum())} non-finite values")
    return data


def spacing(value, default=(1.0, 1.0, 1.0)) -> tuple:
    """Three positive finite voxel sizes; a scalar means the same size on every axis."""
    if value is None:
        value = default
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 0:
        array = np.repeat(array, 3)
    if array.shape != (3,) or not (np.isfinite(array).all() and (array > 0).all()):
        raise ValueError(f"`spacing` must be three positive numbers (dx, dy, dz), got {value!r}")
    return tuple(float(s) for s in array)



def smooth(value) -> float:
    """A Gaussian pre-smoothing sigma in voxels: a non-negative finite number."""
    try:
        sigma = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`smooth` must be a number of voxels, got {value!r}") from None
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"`smooth` must be a non-negative number of voxels, got {value!r}")
    return sigma
