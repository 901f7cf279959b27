"""Quantised volumes seen as the integers they are (docs/design.md section 13).

An 8-bit scan saved as uint8, as uint16 times 257, as float32 divided by 255, as int16
minus 128 or as float64 times 1e-6 plus 7 is one volume: its values lie on a lattice
``low + step * k`` with k = 0 .. levels - 1. `lattice_of` finds that lattice (from a
fixed sample, then checked on every voxel) and `on_lattice` maps the volume to its
integers k as float64, exactly: every copy then gives the same numbers to every
stage, so the same labels, with no near-tie that rounding could break differently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Lattice", "MAX_LEVELS", "lattice_of", "on_lattice", "sample_stride"]

#: A volume of at most this many levels on a lattice is quantised (16-bit data and
#: narrower); more levels are a continuous field (simulations, float maps).
MAX_LEVELS = 2**16
#: Voxels of the sample the step is read from (a fixed stride: the same voxels for
#: every copy of a volume, numpy or Dask).
SAMPLE_VOXELS = 2**21
#: How far from an integer (in steps) a value may lie and still be on the lattice:
#: float32's rounding of k / 255 is a few 1e-6 steps off, anything else far more.
TOLERANCE = 1e-3
#: Voxels checked at a time in memory (32 MB of float64 temporaries).
SLAB = 2**22


@dataclass(frozen=True)
class Lattice:
    """Values ``low + step * k``, k = 0 .. `levels` - 1."""

    low: float
    step: float
    levels: int

    def describe(self) -> str:
        """The lattice as the summary's smoothing rule says it."""
        return f"{self.levels} levels of {self.step:.6g} from {self.low:.6g}"


def sample_stride(shape) -> int:
    """The stride s of the sample ``data[::s, ::s, ::s]`` of a volume of `shape`: about
    `SAMPLE_VOXELS` voxels."""
    return max(1, int(np.ceil((np.prod(shape, dtype=float) / SAMPLE_VOXELS) ** (1 / 3))))


def _sample(data) -> np.ndarray:
    stride = sample_stride(data.shape)
    sample = data[::stride, ::stride, ::stride]
    return np.asarray(sample.compute() if hasattr(sample, "compute") else sample)


def lattice_of(data, value_range, *, sample=None, present=None) -> Lattice | None:
    """The lattice `data` lies on (`value_range` its (min, max)), or None: more than
    `MAX_LEVELS` levels, or values off every lattice the sample suggests.

    `sample`: ``data[::s, ::s, ::s]`` (`sample_stride`), when the caller read it
    already; `present`: every distinct value of `data`, when known (an integer
    volume's `volseg._census.Census.present`): the check of every voxel is then a
    check of those values, the same answer with no pass over `data`."""
    low, high = (float(v) for v in value_range)
    if not high > low or data.dtype == bool:
        return None
    levels = np.unique(_sample(data) if sample is None else sample)
    if len(levels) > MAX_LEVELS or len(levels) < 2:
        return None
    offsets = levels.astype(np.float64) - low
    if data.dtype.kind in "iu":
        step = float(np.gcd.reduce((levels.astype(np.int64) - levels.astype(np.int64)[0])))
    else:
        step = float(np.min(np.diff(offsets)))
    count = round((high - low) / step)
    if not 1 <= count < MAX_LEVELS:
        return None
    step = (high - low) / count                   # the span's own step, not one gap's
    if not _on(offsets, step):
        return None
    if data.dtype.kind in "iu" and step == 1:
        return Lattice(low, step, count + 1)      # every integer is on it: no pass
    if present is not None:
        worst = _worst(present, low, step).max()
    elif hasattr(data, "map_blocks"):
        import dask

        off = data.map_blocks(_worst, low, step, dtype=np.float64, chunks=(1, 1, 1)).max()
        worst, = dask.compute(off)
    else:
        flat = np.asarray(data).reshape(-1)       # in slabs: no float64 copy of it all
        worst = max(_worst(flat[i:i + SLAB], low, step).max()
                    for i in range(0, flat.size, SLAB))
    return Lattice(low, step, count + 1) if worst <= TOLERANCE else None


def _on(offsets, step) -> bool:
    k = offsets / step
    return bool(np.all(np.abs(k - np.round(k)) <= TOLERANCE))


def _worst(block, low, step) -> np.ndarray:
    k = (block.astype(np.float64) - low) / step
    worst = np.max(np.abs(k - np.round(k))) if k.size else 0.0
    return np.full((1,) * block.ndim, worst)


def on_lattice(data, lattice: Lattice):
    """`data` as its lattice integers k, float64 (numpy or Dask, lazily)."""

    def integers(block):
        return np.round((block.astype(np.float64) - lattice.low) / lattice.step)

    if hasattr(data, "map_blocks"):
        return data.map_blocks(integers, dtype=np.float64)
    return integers(np.asarray(data))
