"""`grid_curvature` of a Dask array: the same kernel, block by block (docs/design.md section 10).

Every voxel's curvature depends on its 1-ring only (the faces through it and the
tetrahedra on both sides of each lie within one step). So each block of the input
gets a 1-voxel halo of its neighbours' raw values (`volseg._halo`: their shells, so
no block stays in memory for its neighbours' sake, and in the input's own type: 1
byte per voxel for uint8), and then, inside its task: scaled, padded where it meets
the volume's boundary as np.pad pads the whole volume (axis by axis, by the
`padding` rule, the same arithmetic), and run through the kernel, keeping its
interior. The value scale, a global statistic, is computed first (one pass for min
and max). Each block runs its slabs in the parity order they have in the whole
volume, so every voxel's sums are added in the whole volume's order and the result is
bit-identical (tested). One task per block and stage, no padded copy of the volume,
no final rechunk. The in-memory path runs the same `BlockCurvature` on slabs of the
first axis (`_grid.checked_grid_curvature`).
"""

from __future__ import annotations

import numpy as np

from .._halo import block_starts, with_halo
from ._grid_kernels import grid_kernel
from ._grid_tables import _kernel_tables

__all__ = ["dask_grid_curvature"]


class BlockCurvature:
    """The per-block function. A module-level class, not a closure: a distributed
    worker unpickles it by reference to this module, so the compiled kernel is the
    module's own (a closure carries the numba dispatcher by value, and each task then
    rebuilt it and reloaded its cache: 0.8 s per block)."""

    def __init__(self, entry, h, value_scale, padding, starts, shape):
        self.entry, self.h = entry, np.asarray(h, dtype=np.float64)
        self.value_scale, self.padding = value_scale, padding
        self.starts, self.shape = starts, shape

    def __call__(self, block, block_id=None):
        # `block`: the raw input over this chunk and a 1-voxel halo (placeholders
        # where the halo leaves the volume).
        fp = np.ascontiguousarray(block, dtype=np.float64) * self.value_scale
        self._padded(fp, block_id)
        if not np.isfinite(fp).all():
            raise ValueError("the volume holds NaN or infinite values; replace them (e.g. "
                             "numpy.nan_to_num) first")
        return self._curvature(fp, block_id)

    def of_scaled(self, fp, block_id, out=None, room=None):
        """The curvature of a block given scaled already: `fp` float64, C order, the
        block's values times the scale (finite) and a 1-voxel halo (placeholders where
        the volume ends, padded here, in place); into `out` if given, the accumulator
        in the flat float64 `room` if given (the in-memory path's slabs reuse both)."""
        self._padded(fp, block_id)
        return self._curvature(fp, block_id, out, room)

    def _padded(self, fp, block_id) -> None:
        for axis in range(3):           # the in-memory padding, in its axis order
            start = self.starts[axis][block_id[axis]]
            stop = start + fp.shape[axis] - 2
            if self.shape[axis] == 1:   # one voxel: its value on both sides (np.pad's rule)
                _pad_one_voxel(fp, axis)
                continue
            if start == 0:
                _pad(fp, axis, 0, self.padding)
            if stop == self.shape[axis]:
                _pad(fp, axis, -1, self.padding)

    def _curvature(self, fp, block_id, out=None, room=None):
        entry, h = self.entry, self.h
        shape = (entry.grid_channels,) + fp.shape
        if room is None:
            acc = np.zeros(shape)
        else:
            acc = room[:int(np.prod(shape))].reshape(shape)
            acc.fill(0.0)
        # Local slab 0 is the padded volume's cube row (first row - 1): keep the
        # in-memory parity order, so the sums (and results) are bit-identical.
        first = self.starts[0][block_id[0]] % 2
        grid_kernel(fp, h, entry.grid_code, _kernel_tables(h), acc, first)
        return entry.grid_finish(acc, (slice(1, -1),) * 3, h, out)


def _pad_one_voxel(fp, axis: int):
    """Both halo layers of `axis`, a volume one voxel thick along it, set to that voxel."""
    moved = np.moveaxis(fp, axis, 0)
    moved[0] = moved[2] = moved[1]


def _pad(fp, axis: int, end: int, padding: str):
    """Set the halo layer at `end` (0 or -1) of `axis` from the two layers inside it:
    linear f[-1] = 2 f[0] - f[1] (np.pad reflect, odd), else mirrored f[-1] = f[1]."""
    def layer(i):
        index = [slice(None)] * 3
        index[axis] = i
        return tuple(index)
    inner, next_ = (1, 2) if end == 0 else (-2, -3)
    if padding == "linear":
        fp[layer(end)] = 2 * fp[layer(inner)] - fp[layer(next_)]
    else:
        fp[layer(end)] = fp[layer(next_)]


def dask_grid_curvature(array, entry, spacing, value_scale, padding, hooks=None):
    """`checked_grid_curvature` for a 3-D Dask array (checked: real, 3-D, >= 2 per
    axis; finiteness is checked per block). Returns a lazy float64 Dask array with the
    input's chunks. `hooks` (`volseg._block_hooks.BlockHooks`): its ``wrap`` wraps the
    per-block function (finished blocks kept on disk); with ``reread``, the input's
    blocks are cheap to make again (read from a file), so each is made again for its
    own halo (`volseg._halo`, fresh) instead of waiting in memory for it."""
    starts = [s.tolist() for s in block_starts(array.chunks)]
    kernel = BlockCurvature(entry, spacing, value_scale, padding, starts, array.shape)
    reread = False
    if hooks is not None:
        kernel, reread = hooks.wrap("curvature", kernel), hooks.reread
    return with_halo(array, 0, fresh=reread).map_blocks(
        kernel, dtype=np.float64, chunks=array.chunks, meta=np.zeros((0, 0, 0)))
