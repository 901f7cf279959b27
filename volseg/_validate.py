"""The front door: checks of what a user hands to volseg, done once where it enters,
with the argument named in every message (STYLE.md section 4)."""

from __future__ import annotations

import numbers

import numpy as np
from numpy.typing import NDArray

__all__ = ["volume_array", "spacing", "value_scale", "smooth", "rounds", "is_lazy"]

# Cut parameters (n_regions, min_persistence) are checked by volseg.morse.check_cut,
# which owns them: the Morse stage stands alone.


def is_lazy(array) -> bool:
    """Whether `array` is a Dask array (a lazily computed, blockwise volume), without
    importing Dask for other inputs."""
    return type(array).__module__.startswith("dask.")


def _check_layout(data, what: str, error, ndim: int) -> None:
    """The checks that need no values: `ndim` axes, >= 2 samples each, a real type."""
    if data.ndim != ndim:
        raise error(f"{what} must be {ndim}-D, got shape {data.shape}")
    if min(data.shape) < 2:
        raise error(f"{what} needs at least 2 samples along each axis, got shape {data.shape}")
    if np.dtype(data.dtype).kind not in "biuf":
        raise error(f"{what} must hold real numbers, got dtype {data.dtype}")


def volume_array(volume, name: str = "volume", *, source=None,
                 error: type[ValueError] = ValueError, ndim: int = 3) -> NDArray:
    """A 3-D (or `ndim`-D) real, finite array with at least 2 samples per axis (not copied).

    Messages name the argument (`name`) or, for a file, start with `source`; `error`
    is the exception type raised (the readers raise `VolumeFileError`).
    """
    data = np.asarray(volume)
    kind = "volume" if ndim == 3 else "series"
    what = f"{source}: the {kind}" if source is not None else f"`{name}`"
    _check_layout(data, what, error, ndim)
    if data.dtype.kind == "f":
        bad = ~np.isfinite(data)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            axes = ", ".join("xyzt"[:ndim]) if ndim <= 4 else "index"
            raise error(f"{what} holds {int(bad.sum())} NaN or infinite values (first at "
                        f"[{axes}] = {first}); replace them (e.g. numpy.nan_to_num) first")
    return data


def lazy_volume_array(array, name: str = "volume"):
    """`volume_array`'s checks that need no data (3-D, >= 2 per axis, real) for a lazy
    (Dask) array; finiteness is checked block by block when it is computed."""
    _check_layout(array, f"`{name}`", ValueError, 3)
    return array


# Lengths of a grid step: the curvature operators multiply up to eight of them, which
# stays finite (and above the denormals) in float64 inside this range.
STEP_RANGE = (1e-30, 1e30)


def _in_step_range(array) -> bool:
    return bool(np.isfinite(array).all() and (array >= STEP_RANGE[0]).all()
                and (array <= STEP_RANGE[1]).all())


def spacing(value, default=(1.0, 1.0, 1.0)) -> tuple:
    """Three positive finite voxel sizes; a scalar means the same size on every axis."""
    if value is None:
        value = default
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 0:
        array = np.repeat(array, 3)
    if array.shape != (3,) or not _in_step_range(array):
        raise ValueError(f"`spacing` must be three numbers (dx, dy, dz) in [{STEP_RANGE[0]:g}, "
                         f"{STEP_RANGE[1]:g}] (another length unit otherwise), got {value!r}")
    return tuple(float(s) for s in array)


def step(value, name: str) -> float:
    """One grid step's length (a time step's, say), in `STEP_RANGE` like `spacing`."""
    result = number(value, name, positive=True)
    if not _in_step_range(np.float64(result)):
        raise ValueError(f"`{name}` must be a length in [{STEP_RANGE[0]:g}, {STEP_RANGE[1]:g}] "
                         f"(another length unit otherwise), got {value!r}")
    return result


def number(value, name: str, *, positive: bool = False) -> float:
    """A finite (and, with `positive`, > 0) number; the message names the argument."""
    kind = "a positive number" if positive else "a finite number"
    try:
        result = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be {kind}, got {value!r}") from None
    if not np.isfinite(result) or (positive and result <= 0):
        raise ValueError(f"`{name}` must be {kind}, got {value!r}")
    return result


def chunk_edge(value, name: str = "chunks") -> int:
    """A blockwise chunk's edge in voxels: a whole number of at least 2 (a block of
    one voxel has no interior for the halo stencils)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 2:
        raise ValueError(f"`{name}` must be a whole number of at least 2 voxels, got {value!r}")
    return int(value)


def share(value, name: str) -> float:
    """A share: a number in [0, 1); the message names the argument."""
    result = number(value, name)
    if not 0 <= result < 1:
        raise ValueError(f"`{name}` must be a share in [0, 1), got {value!r}")
    return result


def value_scale(value) -> float:
    """The scale s of the value axis: a positive finite number."""
    return number(value, "value_scale", positive=True)


def rounds(value, name: str) -> int:
    """A number of rounds: a non-negative whole number (2.0 is taken; 2.5, a bool, a
    string or a negative number is refused, naming `name`)."""
    import numbers

    whole = (isinstance(value, numbers.Real) and not isinstance(value, bool)
             and np.isfinite(value) and value == int(value) and value >= 0)
    if not whole:
        raise ValueError(f"`{name}` must be a whole number of rounds >= 0, got {value!r}")
    return int(value)


def smooth(value) -> float:
    """A Gaussian pre-smoothing sigma in voxels: a non-negative finite number."""
    try:
        sigma = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`smooth_sigma` must be a number of voxels, got {value!r}") from None
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"`smooth_sigma` must be a non-negative number of voxels, got {value!r}")
    return sigma


