"""`census`: what one read of an input volume tells the stages before any of them runs.

The value range (the value scale, the preview's grey scale, the refusal of NaN), the
voxels at the minimum and at 0 (the ``"auto"`` mask's plateaus), the fixed sample the
lattice is found from (`volseg._lattice`) and, for integers of a narrow span, the
count of every value (the mask rules' histogram, and the lattice's exact levels). A
Dask volume's blocks are read once for all of it: these were four passes over a
stored input (range, lattice sample, plateau, histogram), 13.4 s of a 1024^3 uint8
run's start here, each decompressing every block again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._lattice import sample_stride

__all__ = ["Census", "census", "MAX_INTEGER_BINS"]

#: Integer volumes spanning fewer values than this get one histogram bin per value.
MAX_INTEGER_BINS = 2**20
#: Voxels counted at a time by `value_counts`: its offsets are 8 bytes a voxel, so the
#: whole volume's at once were 24 bytes a voxel beside it (the peak of a default run).
COUNT_SLAB = 2**20


@dataclass(frozen=True)
class Census:
    """One read of a volume (`census`).

    Attributes
    ----------
    low, high : int or float
        The minimum and maximum, as Python numbers (integers stay exact; NaN if the
        volume holds one).
    at_low : int
        Voxels equal to `low`.
    at_zero : int or None
        Voxels equal to 0 (None: not counted, `census` of an array in memory that
        is not integer).
    sample : ndarray
        ``volume[::s, ::s, ::s]`` with s = `volseg._lattice.sample_stride`.
    counts : (high - low + 1,) ndarray of intp or None
        Voxels at each integer from `low` to `high`; None for floats and for
        integers spanning `MAX_INTEGER_BINS` values or more.
    """

    low: int | float
    high: int | float
    at_low: int
    at_zero: int | None
    sample: np.ndarray
    counts: np.ndarray | None

    @property
    def value_range(self) -> tuple:
        return self.low, self.high

    def present(self) -> np.ndarray | None:
        """The distinct values of an integer volume, increasing (None without
        `counts`)."""
        if self.counts is None:
            return None
        return np.flatnonzero(self.counts).astype(np.int64) + np.int64(self.low)


def census(volume) -> Census:
    """The `Census` of `volume` ((X, Y, Z) numpy or Dask array, not empty): a Dask
    volume's blocks are each read once, on Dask's current scheduler, and joined
    pairwise (the per-value counts never all reach one place at once)."""
    stride = sample_stride(volume.shape)
    if not hasattr(volume, "dask"):
        return _finish(_part(np.asarray(volume), (0, 0, 0), stride, zeros=False),
                       volume.shape, stride)
    import dask

    starts = [np.cumsum((0, *c[:-1])) for c in volume.chunks]
    parts = []
    for index, block in np.ndenumerate(volume.to_delayed()):
        start = tuple(int(s[i]) for s, i in zip(starts, index, strict=True))
        parts.append(dask.delayed(_part)(block, start, stride, zeros=True))
    while len(parts) > 1:
        parts = [dask.delayed(_join)(*parts[i:i + 2]) if i + 1 < len(parts) else parts[i]
                 for i in range(0, len(parts), 2)]
    part, = dask.compute(parts[0])
    return _finish(part, volume.shape, stride)


def value_counts(block, low, width: int) -> np.ndarray:
    """Voxels of `block` at each integer ``low .. low + width - 1`` (intp), counted in
    slabs of `COUNT_SLAB` voxels."""
    flat = np.asarray(block).reshape(-1)
    counts = np.zeros(width, dtype=np.intp)
    for start in range(0, flat.size, COUNT_SLAB):
        part = widened(flat[start:start + COUNT_SLAB])
        counts += np.bincount((part - part.dtype.type(low)).astype(np.intp, copy=False),
                              minlength=width)
    return counts


def widened(block) -> np.ndarray:
    """An integer block in a type where ``block - low`` cannot overflow for a span
    under `MAX_INTEGER_BINS` (64-bit types as they are: the span is small)."""
    block = np.asarray(block)
    return block if block.dtype.itemsize == 8 else block.astype(np.int64)


def _part(block, start: tuple, stride: int, *, zeros: bool) -> dict:
    """One block's share: its range, voxels at its minimum (and at 0, if `zeros` or
    counted anyway), its value counts and its voxels of the sample."""
    block = np.asarray(block)
    first = [(-o) % stride for o in start]
    piece = block[first[0]::stride, first[1]::stride, first[2]::stride]
    at = tuple((o + f) // stride for o, f in zip(start, first, strict=True))
    if block.size == 0:
        return {"low": None, "pieces": [(at, piece)]}
    low, high = np.min(block).item(), np.max(block).item()
    counts = None
    if block.dtype.kind in "iu" and int(high) - int(low) < MAX_INTEGER_BINS:
        counts = value_counts(block, low, int(high) - int(low) + 1)
        at_low, at_zero = int(counts[0]), (int(counts[-low]) if low <= 0 <= high else 0)
    else:
        at_low = int(np.count_nonzero(block == low)) if low == low else 0
        at_zero = int(np.count_nonzero(block == 0)) if zeros else None
    return {"low": low, "high": high, "at_low": at_low, "at_zero": at_zero,
            "counts": counts, "integer": block.dtype.kind in "iu", "pieces": [(at, piece)]}


def _join(a: dict, b: dict) -> dict:
    """Two blocks' shares as one (NaN wins the range, as in `np.min`)."""
    if a["low"] is None or b["low"] is None:
        kept = b if a["low"] is None else a
        return {**kept, "pieces": a["pieces"] + b["pieces"]}
    # Python's min and max for integers (exact beyond 2^63), numpy's for floats (NaN).
    low, high = ((min(a["low"], b["low"]), max(a["high"], b["high"])) if a["integer"] else
                 (np.minimum(a["low"], b["low"]).item(), np.maximum(a["high"], b["high"]).item()))
    at_low = sum(p["at_low"] for p in (a, b) if p["low"] == low)
    at_zero = None if a["at_zero"] is None else a["at_zero"] + b["at_zero"]
    counts = None
    if a["counts"] is not None and b["counts"] is not None \
            and int(high) - int(low) < MAX_INTEGER_BINS:
        counts = np.zeros(int(high) - int(low) + 1, dtype=np.intp)
        for p in (a, b):
            counts[int(p["low"]) - int(low):int(p["high"]) - int(low) + 1] += p["counts"]
    return {"low": low, "high": high, "at_low": at_low, "at_zero": at_zero, "counts": counts,
            "integer": a["integer"], "pieces": a["pieces"] + b["pieces"]}


def _finish(part: dict, shape: tuple, stride: int) -> Census:
    """The `Census` of the joined shares of a volume of `shape`."""
    pieces = part["pieces"]
    sample = np.empty(tuple(-(-n // stride) for n in shape), dtype=pieces[0][1].dtype)
    for at, piece in pieces:
        sample[tuple(slice(a, a + n) for a, n in zip(at, piece.shape, strict=True))] = piece
    return Census(part["low"], part["high"], part["at_low"], part["at_zero"], sample,
                  part["counts"])
