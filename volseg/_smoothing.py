"""Gaussian pre-smoothing of a volume (`segment_volume(smooth_sigma=sigma)`), for numpy and
Dask arrays alike.

In memory it is scipy's `gaussian_filter` of the float64 values, 'nearest' at the
volume's boundary. On a Dask array each block is filtered with a halo of the
filter's radius (scipy's: ``int(4 sigma + 0.5)``) taken from its neighbours, or
repeated from the boundary voxel where the volume ends, and trimmed: every owned
voxel sees the values it sees in memory through the same sums, so the result is
equal bit for bit (tested), for any chunking; chunks thinner than the radius are
merged for the filter and cut back to the input's chunks after it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["gaussian", "noise_sigma"]

#: `noise_sigma` reads at most about this many 2x2x2 cells (a lattice of them).
NOISE_SAMPLE_CELLS = 2_000_000

#: Float types scipy's filters read as they are (integers are read as they are too).
_READ_AS_IS = (np.dtype(np.float32), np.dtype(np.float64))

#: scipy.ndimage.gaussian_filter's default truncation, in standard deviations.
TRUNCATE = 4.0


def gaussian(data, sigma: float, *, margin: int = 0):
    """`data` (numpy or Dask, any dimension) smoothed by a Gaussian of `sigma` voxels,
    as float64; `sigma` 0 returns it unchanged. `margin`: a numpy result is the
    interior of a buffer `margin` voxels wider on every side (its margin unset), for a
    stage that pads it in place (`volseg.curvature.checked_grid_curvature`)."""
    if not sigma:
        return data
    if not hasattr(data, "map_overlap"):
        data = np.asarray(data)
        buffer = np.empty(tuple(n + 2 * margin for n in data.shape))
        out = buffer[tuple(slice(margin, n + margin) for n in data.shape)] if margin else buffer
        return _filter(data, sigma, out)
    radius = int(TRUNCATE * float(sigma) + 0.5)
    chunks = data.chunks
    # An axis shorter than the halo is one block (Dask cannot cut a halo deeper than
    # the array); a block that spans its axis needs no halo there: the filter's own
    # 'nearest' edge is what the padding would give.
    short = {axis: -1 for axis, n in enumerate(data.shape) if n <= radius}
    if short:
        data = data.rechunk(short)
    depth = {axis: 0 if len(c) == 1 else radius for axis, c in enumerate(data.chunks)}
    # The halos are cut from the input as it is (1 byte per voxel for uint8, not 8):
    # each block becomes float64 inside the filter, the same values.
    out = data.map_overlap(_filter, depth=depth, boundary="nearest", dtype=np.float64,
                           sigma=sigma)
    return out if out.chunks == chunks else out.rechunk(chunks)


def _filter(block, sigma, out=None):
    """scipy's `gaussian_filter` of the values in float64, 'nearest' at the edges (the
    whole volume in memory, or a block with its halo), into `out` if given. The block is
    passed as it is: scipy reads each line into float64 itself, so an integer volume
    needs no float64 copy beside the result (the same numbers: tested)."""
    from scipy.ndimage import gaussian_filter

    block = np.asarray(block)
    if block.dtype.kind not in "iu" and block.dtype not in _READ_AS_IS:
        block = block.astype(np.float64)          # float16 and others scipy refuses
    if out is None:
        out = np.empty(block.shape)
    gaussian_filter(block, sigma, output=out, mode="nearest", truncate=TRUNCATE)
    return out


def noise_sigma(data, mask=None) -> float:
    """The standard deviation of white noise in `data` (3-D, numpy or Dask), by
    Donoho's estimator: the median absolute finest-scale Haar diagonal coefficient
    over 0.6745 (the estimate of scikit-image's `estimate_sigma`, which needs
    PyWavelets). The coefficient of a 2x2x2 cell is its 8 values with alternating
    signs over sqrt(8): smooth structure cancels, noise stays. Only cells wholly
    inside `mask`, on a lattice of at most `NOISE_SAMPLE_CELLS` cells, are read; the
    same cells for numpy and Dask, so the same estimate. 0 when no cell is inside."""
    cells = [n // 2 for n in data.shape]
    step = max(1, int(np.ceil((np.prod(cells, dtype=float) / NOISE_SAMPLE_CELLS) ** (1 / 3))))
    corners = [(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]

    def corner(array, offset):
        return array[tuple(slice(o, 2 * c, 2 * step) for o, c in zip(offset, cells, strict=True))]

    parts = [corner(data, o) for o in corners]
    inside = None if mask is None else [corner(mask, o) for o in corners]
    if hasattr(data, "map_overlap"):
        import dask

        parts, inside = dask.compute(parts, inside)
    detail = sum((-1) ** sum(o) * np.asarray(p, dtype=np.float64)
                 for o, p in zip(corners, parts, strict=True)) / np.sqrt(8.0)
    if inside is not None:
        detail = detail[np.logical_and.reduce([np.asarray(m) for m in inside])]
    return float(np.median(np.abs(detail)) / 0.6745) if detail.size else 0.0
