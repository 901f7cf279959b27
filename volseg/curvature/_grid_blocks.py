"""`grid_curvature` of a Dask array: the same kernel, block by block (DESIGN.md section 10).

Every voxel's curvature depends on its 1-ring only (the faces through it and the
tetrahedra on both sides of each lie within one step). So the volume, scaled and
padded at its own boundary exactly as in memory (one voxel, by the `boundary` rule),
is cut into its chunks with a 1-voxel halo (`map_overlap`), each block runs the
in-memory kernel over itself and keeps its interior. The value scale, a global
statistic, is computed first (one pass for min and max). Each block runs its slabs
in the parity order they have in the whole volume, so every voxel's sums are added
in the in-memory order and the result is bit-identical (tested).
"""

from __future__ import annotations

import numpy as np

from ._grid import _kernel_tables
from ._grid_kernels import grid_kernel

__all__ = ["dask_grid_curvature"]


def _pad_axis(array, axis: int, boundary: str):
    import dask.array as da

    take = lambda i: array[(slice(None),) * axis + (slice(i, i + 1 if i != -1 else None),)]  # noqa: E731
    if boundary == "linear":   # f[-1] = 2 f[0] - f[1], as np.pad(mode="reflect", reflect_type="odd")
        low, high = 2 * take(0) - take(1), 2 * take(-1) - take(-2)
    else:                      # f[-1] = f[1], as np.pad(mode="reflect")
        low, high = take(1), take(-2)
    return da.concatenate([low, array, high], axis=axis)


class _Block:
    """The per-block function. A module-level class, not a closure: a distributed
    worker unpickles it by reference to this module, so the compiled kernel is the
    module's own (a closure carries the numba dispatcher by value, and each task then
    rebuilt it and reloaded its cache: 0.8 s per block)."""

    def __init__(self, entry, h, row_starts):
        self.entry, self.h, self.row_starts = entry, np.asarray(h, dtype=np.float64), row_starts

    def __call__(self, block, block_id=None):
        # `block` is a chunk of the padded volume with its 1-voxel halo: the in-memory
        # path's padded array in miniature, already scaled.
        if not np.isfinite(block).all():
            raise ValueError("the volume holds NaN or infinite values; replace them (e.g. "
                             "numpy.nan_to_num) first")
        entry, h = self.entry, self.h
        fp = np.ascontiguousarray(block, dtype=np.float64)
        acc = np.zeros((entry.grid_channels,) + fp.shape)
        # Local slab 0 is the padded volume's cube row (first row - 1): keep the
        # in-memory parity order, so the sums (and results) are bit-identical.
        first = (self.row_starts[block_id[0]] - 1) % 2
        grid_kernel(fp, h, entry.grid_code, _kernel_tables(h), acc, first)
        return entry.grid_finish(acc, (slice(1, -1),) * 3, h)


def dask_grid_curvature(array, entry, spacing, value_scale, boundary, wrap=None):
    """`checked_grid_curvature` for a 3-D Dask array (checked: real, 3-D, >= 2 per
    axis; finiteness is checked per block). Returns a lazy float64 Dask array with the
    input's chunks. `wrap(stage, function)`, if given, wraps the per-block function
    (`volseg._resume.WorkFolder.wrap`: finished blocks kept on disk)."""
    scaled = array.astype(np.float64) * value_scale
    padded = scaled
    for axis in range(3):
        padded = _pad_axis(padded, axis, boundary)
    # Boundary 0 outside the padded array only feeds the pad ring, which is dropped.
    row_starts = np.concatenate([[0], np.cumsum(padded.chunks[0])[:-1]])
    kernel = _Block(entry, spacing, row_starts)
    if wrap is not None:
        kernel = wrap("curvature", kernel)
    out = padded.map_overlap(kernel, depth=1, boundary=0.0,
                             trim=False, dtype=np.float64, chunks=padded.chunks,
                             meta=np.zeros((0, 0, 0)))
    out = out[1:-1, 1:-1, 1:-1]
    return out.rechunk(array.chunks)

