"""`grid_curvature`: the four operators on the implicit Kuhn tessellation of a volume."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _buffers, _validate
from .._buffers import margin_owner, with_room
from ._registry import get_operator

__all__ = ["grid_curvature", "default_value_scale", "checked_grid_curvature", "check_padding"]

#: The padding rules beyond the volume's border (`_grid_blocks._pad`): linear
#: extrapolation (np.pad's odd reflection) or a mirror (np.pad's reflection).
PADDINGS = ("linear", "mirror")


def default_value_scale(volume: ArrayLike, spacing=(1.0, 1.0, 1.0), *,
                        value_range=None) -> float:
    """The value scale s that makes a volume's graph as tall as it is wide.

    ``s = L / (max f - min f)`` with L the longest side of the grid in spacing
    units, so the graph in R^4 spans L along every axis, values included: the shape
    of the paper's test surfaces on [-1, 1]^3. Curvature then does not depend on the
    units of the data (scaling f by c leaves the result unchanged), and it stays in
    the non-linear regime where it differs from a plain Laplacian (tiny s makes
    H -> -Laplacian(f) s / 3). A constant volume gets s = 1.
    `value_range`: (min f, max f) when the caller has them already (no pass over the
    volume then).
    """
    if value_range is not None:
        lo, hi = (float(v) for v in value_range)
        data = volume
    elif _validate.is_lazy(volume):   # one pass over the blocks for both statistics
        import dask

        lo, hi = (float(v) for v in dask.compute(volume.min(), volume.max()))
        data = volume
    else:
        data = np.asarray(volume)
        lo, hi = float(np.min(data)), float(np.max(data))
    spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,))
    extent = float(np.max((np.array(data.shape) - 1) * spacing))
    span = hi - lo
    return extent / span if span > 0 else 1.0


def grid_curvature(
    volume: ArrayLike,
    operator: str = "weighted",
    *,
    spacing=None,
    value_scale: float | None = None,
    padding: str = "linear",
) -> NDArray[np.float64]:
    """Curvature of a volume's graph in R^4, on the implicit Kuhn tessellation.

    Vertex (i, j, k) is ``(i dx, j dy, k dz, s f[i, j, k])`` (docs/design.md section 2);
    the tessellation is the Kuhn split of every grid cube (section 4), oriented with
    upward normals. At interior voxels the result equals
    ``vertex_curvature(*kuhn_grid_mesh(volume, spacing, value_scale), operator)`` to
    rounding, without building a single tetrahedron.

    Parameters
    ----------
    volume : (X, Y, Z) array_like of real, or `volseg.Volume`
        Indexed [x, y, z]; must be finite.
    operator : {'weighted', 'unweighted', 'laplace_beltrami', 'intrinsic'}
    spacing : (3,) sequence of float, optional
        Grid spacing (dx, dy, dz); default the Volume's spacing, or 1.
    value_scale : float, optional
        s; default `default_value_scale` (the graph as tall as it is wide).
    padding : {'linear', 'mirror'}
        How boundary voxels get a complete star: the volume is padded by one voxel,
        continued linearly (``f[-1] = 2 f[0] - f[1]``: a plane stays flat up to the
        boundary, and the boundary adds no curvature across itself) or mirrored
        (``f[-1] = f[1]``: zero normal derivative, as for a symmetric field).

    Returns
    -------
    (X, Y, Z) ndarray of float64
        Finite at every voxel. For a Dask array in, a lazy Dask array with its
        chunks, computed block by block with a 1-voxel halo (the value scale is
        computed first, in one pass); equal to the in-memory result to rounding.

    Examples
    --------
    >>> import numpy as np
    >>> x, y, z = np.meshgrid(*[np.linspace(-1, 1, 33)] * 3, indexing="ij")
    >>> h = grid_curvature(-0.4 * (x**2 + y**2 + z**2), spacing=(1 / 16,) * 3, value_scale=1.0)
    >>> round(float(h[16, 16, 16]), 2)  # the peak of -0.4|x|^2: H = +0.8
    0.8
    """
    entry = get_operator(operator)
    check_padding(padding)
    h = _validate.spacing(spacing, getattr(volume, "spacing", (1.0, 1.0, 1.0)))
    lazy = _validate.is_lazy(getattr(volume, "data", volume))
    data = (_validate.lazy_volume_array(getattr(volume, "data", volume)) if lazy
            else _validate.volume_array(volume))
    if value_scale is None:
        value_scale = default_value_scale(data, h)
    scale = _validate.value_scale(value_scale)
    return checked_grid_curvature(data, entry, h, scale, padding)


def check_padding(padding: str) -> str:
    """`padding` if it is a padding rule of `grid_curvature`, else a ValueError."""
    if padding not in PADDINGS:
        raise ValueError(f"unknown `padding` {padding!r}; choose one of {', '.join(PADDINGS)}")
    return padding


def checked_grid_curvature(data, entry, spacing, value_scale, padding, *,
                           block_hooks=None, owned=False) -> NDArray[np.float64]:
    """`grid_curvature` of arguments already checked by `volseg._validate` (a 3-D real
    array, finite unless lazy, an `Operator` entry, three positive spacings, a positive
    scale, a padding rule). A Dask array goes block by block (`_grid_blocks`), with
    the blockwise path's `block_hooks` (`volseg._block_hooks.BlockHooks`) if given.

    `owned`: `data` may be overwritten (the stages' smoothed copy). When it is the
    interior of a float64 buffer with a 1-voxel margin (`volseg._smoothing.gaussian`),
    that buffer takes the result.

    In memory the volume goes through the kernel in slabs along its first axis, each
    with a 1-voxel halo, exactly as the blockwise path's blocks (`_grid_blocks`):
    the same sums in the same order, so the same numbers as the whole padded volume
    at once (tested), and the stage holds the input, the result and one slab's work
    arrays, not a padded float64 copy and an accumulator of 2-9 channels beside them
    (24 bytes a voxel for the weighted operator). The result starts a buffer with
    room for it padded by one voxel (the owned buffer: each slab is read before the
    result reaches it; else a new one, its tail untouched), where the Morse build
    pads it in place (`volseg._buffers.room_to_pad`)."""
    if _validate.is_lazy(data):
        from ._grid_blocks import dask_grid_curvature

        return dask_grid_curvature(data, entry, spacing, value_scale, padding, block_hooks)
    from ._grid_blocks import BlockCurvature

    owner = margin_owner(data) if owned else None
    out = with_room(data.shape) if owner is None else \
        owner.reshape(-1)[:data.size].reshape(data.shape)
    nx = data.shape[0]
    thick = _buffers.slab_thickness(data.shape)
    starts = [list(range(0, nx, thick)), [0], [0]]
    kernel = BlockCurvature(entry, spacing, value_scale, padding, starts, data.shape)
    # One slab's and one accumulator's memory, reused by every slab.
    plane = (data.shape[1] + 2) * (data.shape[2] + 2)
    slab_room = np.empty((thick + 2) * plane)
    acc_room = np.empty(entry.grid_channels * (thick + 2) * plane)
    for k, x0 in enumerate(starts[0]):
        x1 = min(x0 + thick, nx)
        fp = _scaled_slab(data, x0, x1, value_scale, slab_room)
        # Written behind every row a later slab reads (in an owned buffer).
        kernel.of_scaled(fp, (k, 0, 0), out[x0:x1], acc_room)
    return out


def _scaled_slab(data, x0: int, x1: int, value_scale: float, room):
    """Rows x0..x1 of `data` in float64 times `value_scale`, with a 1-voxel halo of
    their neighbours' on the first axis (zeros where the volume ends there, and on the
    other axes: the block kernel pads those), in the flat float64 `room`."""
    nx, ny, nz = data.shape
    lo, hi = max(x0 - 1, 0), min(x1 + 1, nx)
    block = room[:(x1 - x0 + 2) * (ny + 2) * (nz + 2)].reshape(x1 - x0 + 2, ny + 2, nz + 2)
    block.fill(0.0)
    inner = block[lo - x0 + 1:hi - x0 + 1, 1:-1, 1:-1]
    inner[...] = data[lo:hi]
    inner *= value_scale
    return block
