"""Float64 buffers with room, where one stage leaves an array that the next pads in
place (a leaf: numpy only).

Two layouts, each with its test:

- the interior of a buffer one voxel wider on every side (`margin_owner`): the
  smoothing leaves its result so, and the curvature then scales and pads it in place;
- the start of a buffer with room for the array padded by one voxel (`with_room`,
  `room_to_pad`): the fields leave themselves so, and the Morse build moves the values
  to their padded places in that buffer (`volseg.morse._graph.PaddedInPlace`).

Work on such arrays goes slab by slab along the first axis (`slab_thickness`), so
that a stage holds its input, its result and one slab's temporaries.

Anything else (a view, a user's array, another type or order) gets None: the caller
copies, and never writes into memory it does not own.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["padded_size", "with_room", "room_to_pad", "margin_owner", "slab_thickness"]


def padded_size(shape) -> int:
    """The number of voxels of `shape` padded by one voxel on every side."""
    return int(np.prod([n + 2 for n in shape]))


def _owner(array):
    """The C-contiguous float64 array that owns `array`'s memory (its base, owning its
    own), when `array` is float64 too; else None."""
    owner = array.base
    if (array.dtype != np.float64 or not isinstance(owner, np.ndarray)
            or owner.base is not None or owner.dtype != np.float64
            or not owner.flags.c_contiguous):
        return None
    return owner


def _address(array) -> int:
    return array.__array_interface__["data"][0]


def with_room(shape) -> NDArray[np.float64]:
    """A new, unset float64 array of `shape` at the start of a buffer with room for it
    padded by one voxel (`room_to_pad` finds that buffer)."""
    return np.empty(padded_size(shape))[:int(np.prod(shape))].reshape(shape)


def room_to_pad(values) -> NDArray[np.float64] | None:
    """The flat float64 buffer that `values` (a 3-D C-ordered float64 array) starts,
    when it holds `values` padded by one voxel on every side; else None."""
    owner = _owner(values)
    if (owner is None or values.ndim != 3 or not values.flags.c_contiguous
            or owner.size < padded_size(values.shape) or _address(owner) != _address(values)):
        return None
    return owner.reshape(-1)


def margin_owner(data) -> NDArray[np.float64] | None:
    """The buffer whose interior (inside a 1-voxel margin) `data` is, or None."""
    owner = _owner(data)
    if owner is None or owner.shape != tuple(n + 2 for n in data.shape):
        return None
    inner = owner[(slice(1, -1),) * owner.ndim]
    return owner if _address(inner) == _address(data) and inner.strides == data.strides \
        else None


#: In-memory slabs hold about 1/SLABS of the volume each, at least MIN_SLAB voxels thick:
#: each slab's 1-voxel halo adds at most 1/32 to its work (curvature at 384^3, one
#: process, alternating: within 5 % of the whole volume at once, host noise 20 %).
SLABS, MIN_SLAB = 8, 64


def slab_thickness(shape) -> int:
    """The thickness (first axis) of the slabs in-memory stages work in."""
    return max(MIN_SLAB, -(-shape[0] // SLABS))
