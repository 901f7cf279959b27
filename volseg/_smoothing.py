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

__all__ = ["gaussian"]

#: scipy.ndimage.gaussian_filter's default truncation, in standard deviations.
TRUNCATE = 4.0


def gaussian(data, sigma: float):
    """`data` (numpy or Dask, any dimension) smoothed by a Gaussian of `sigma` voxels,
    as float64; `sigma` 0 returns it unchanged."""
    if not sigma:
        return data
    if not hasattr(data, "map_overlap"):
        return _filter(data, sigma)
    radius = int(TRUNCATE * float(sigma) + 0.5)
    chunks = data.chunks
    # The halos are cut from the input as it is (1 byte per voxel for uint8, not 8):
    # each block becomes float64 inside the filter, the same values.
    out = data.map_overlap(_filter, depth=radius, boundary="nearest", dtype=np.float64,
                           sigma=sigma)
    return out if out.chunks == chunks else out.rechunk(chunks)


def _filter(block, sigma):
    """scipy's `gaussian_filter` of the float64 values, 'nearest' at the edges (the
    whole volume in memory, or a block with its halo)."""
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(np.asarray(block, dtype=np.float64), sigma, mode="nearest",
                           truncate=TRUNCATE)
