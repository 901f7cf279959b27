"""The scalar field the Morse complex is built on: a registry (docs/design.md section 13).

Every field runs through the same machinery (the hierarchy, every measure, the
blockwise path, the outputs); an entry says how the field is made from the (smoothed)
volume, whether the complex is built on it or on its negative, and which cut measure
suits it:

- ``curvature``: the paper's mean curvature of the volume's graph in R^4; regions are
  territories around curvature peaks;
- ``gradient``: the gradient magnitude |grad f| (central differences with the voxel
  spacing, one-sided at the border) of the volume normalised to its range; the complex
  is built on -|grad f|, so regions are the basins of the gradient, bounded by edges:
  a watershed hierarchy (by dynamics, area or volume as in higra);
- ``value``: the volume itself, normalised to its range; regions are bright blobs (on a
  map of both signs, |f|: bright and dark blobs alike).

A field the user computed (an array of the volume's shape) is given as
``segment_volume(field=array)``; the complex is built on it as it is.

Examples
--------
>>> from volseg.fields import FIELD_REGISTRY, get_field
>>> list(FIELD_REGISTRY)
['curvature', 'gradient', 'value']
>>> get_field("edges").name, get_field("gradient").sign
('gradient', -1.0)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import _buffers, _validate
from ._registry import Registry

__all__ = ["Field", "FIELD_REGISTRY", "FIELDS", "get_field", "field_entry", "given",
           "for_morse", "gradient_magnitude", "normalised", "GIVEN"]


@dataclass(frozen=True)
class Field:
    """A field the Morse complex can be built on.

    `make(values, span, request, scale, hooks, mask, owned)` gives the field as a user
    sees it (numpy in, numpy out; Dask in, lazy Dask out, equal to numpy's exactly);
    `owned`: `values` are the stages' own copy (the smoothed volume, the interior of a
    buffer with a 1-voxel margin: `volseg._smoothing.gaussian`), which `make` may
    overwrite (the curvature scales and pads it in place: 8 bytes a voxel less); the
    complex is built on ``sign * field``. `halo`: the voxels of halo a block needs.
    `needs_scale`: the field reads the graph's value scale (the curvature). `measure`:
    the cut measure by default (`volseg.morse.MEASURE_REGISTRY`), chosen by measurement
    (docs/guide/useful-regions.md); `fallback`: the measure a count cut by that default
    falls back to when its cut is degenerate (`volseg.metrics.region_spread`), or None.
    """

    name: str
    label: str
    aliases: tuple[str, ...]
    make: Callable
    sign: float
    halo: int
    needs_scale: bool
    measure: str
    summary: str
    fallback: str | None = None


def normalised(values, span):
    """`values` minus their minimum over their range (the input's (min, max) `span`):
    0..1, the same for every exactly scaled or offset copy of a volume."""
    low, width = _low_width(span)
    if _validate.is_lazy(values):
        return values.map_blocks(_normalised_block, low, width, dtype=np.float64)
    return _normalised_block(np.asarray(values), low, width)


def _low_width(span) -> tuple[float, float]:
    low, high = (float(v) for v in span)
    return low, high - low if high > low else 1.0


def _normalised_block(block, low, width, out=None):
    """(block - low) / width in float64, into `out` if given (`block` itself, in
    place, if it is `out`)."""
    if out is None:
        out = np.empty(np.shape(block))
    if out is not block:
        out[...] = block
    out -= low
    out /= width
    return out


def gradient_magnitude(values, spacing, mask=None, span=None):
    """(X, Y, Z) |grad f| of `values` with the voxel `spacing` (of the values
    `normalised` over `span` first, if given): central differences inside,
    one-sided at the volume's border (as `numpy.gradient`). With a `mask`, a
    difference never reaches outside it: one-sided at the mask's border, 0 for a voxel
    with no masked neighbour along an axis, so the mask's edge (a skull-stripped
    brain's rim, a CT's air) makes no basin walls of its own. A Dask array block by
    block with a one-voxel halo (none past the border), equal to numpy's exactly; a
    numpy array slab by slab so (a slab's temporaries, not the volume's)."""
    spacing = tuple(float(s) for s in spacing)
    if _validate.is_lazy(values):
        if span is not None:
            values = normalised(values, span)
        if mask is None:
            return values.map_overlap(_gradient_block, depth=1, boundary="none",
                                      dtype=np.float64, spacing=spacing)
        import dask.array as da

        mask = da.asarray(mask).rechunk(values.chunks)
        return da.map_overlap(_gradient_block, values, mask, depth=1, boundary="none",
                              dtype=np.float64, spacing=spacing)
    return _gradient_in_slabs(np.asarray(values), spacing,
                              None if mask is None else np.asarray(mask, bool),
                              None if span is None else _low_width(span))


def _gradient_in_slabs(values, spacing, mask, normalise=None):
    """`_gradient_block` of a numpy volume, slab by slab along its first axis, each with
    a one-voxel halo (none past the border) as the Dask path's blocks: the same
    numbers, with one slab's temporaries (several float64 arrays of its size) instead
    of the volume's. `normalise`: (low, width), applied to each slab first. The result
    starts a buffer with room for the Morse build's padding (`volseg._buffers`)."""
    out = _buffers.with_room(values.shape)
    nx = values.shape[0]
    thick = _buffers.slab_thickness(values.shape)
    for x0 in range(0, nx, thick):
        x1 = min(x0 + thick, nx)
        lo, hi = max(x0 - 1, 0), min(x1 + 1, nx)
        block = _normalised_block(values[lo:hi], *normalise) if normalise \
            else np.asarray(values[lo:hi], dtype=np.float64)
        out[x0:x1] = _gradient_block(block, None if mask is None else mask[lo:hi],
                                     spacing=spacing)[x0 - lo:x1 - lo]
    return out


def _gradient_block(block, mask=None, *, spacing):
    block = np.asarray(block, dtype=np.float64)
    inside = np.ones(block.shape, bool) if mask is None else np.asarray(mask, bool)
    squares = np.zeros(block.shape)
    for axis, step in enumerate(spacing):
        n = block.shape[axis]
        if n < 2:
            continue

        def part(start, stop, a=axis):
            return (slice(None),) * a + (slice(start, stop),)

        pair = inside[part(1, None)] & inside[part(None, -1)]      # (i, i + 1) both in
        forward = np.zeros(block.shape)
        forward[part(None, -1)] = np.where(pair, (block[part(1, None)]
                                                  - block[part(None, -1)]) / step, 0.0)
        after = np.zeros(block.shape, bool)
        after[part(None, -1)] = pair
        before = np.zeros(block.shape, bool)
        before[part(1, None)] = pair
        backward = np.zeros(block.shape)
        backward[part(1, None)] = forward[part(None, -1)]
        central = np.zeros(block.shape)
        central[part(1, -1)] = (block[part(2, None)] - block[part(None, -2)]) / (2.0 * step)
        squares += np.where(after & before, central,
                            np.where(after, forward, np.where(before, backward, 0.0))) ** 2
    return np.sqrt(squares)


def _curvature(values, span, request, scale, hooks, mask=None, owned=False):
    from .curvature import checked_grid_curvature

    return checked_grid_curvature(values, request.operator, request.spacing, scale,
                                  request.padding, block_hooks=hooks, owned=owned)


def _gradient(values, span, request, scale, hooks, mask=None, owned=False):
    return gradient_magnitude(values, request.spacing, mask, span)


def _value(values, span, request, scale, hooks, mask=None, owned=False):
    low, high = (float(v) for v in span)
    signed = low < 0 < high                 # a signed map: bright and dark blobs
    if signed:
        span = (0.0, max(-low, high))
    if _validate.is_lazy(values):
        return normalised(abs(values) if signed else values, span)
    # In a buffer with room for the Morse build's padding: the same numbers as
    # `normalised` (|f| taken in float64, where it cannot overflow an integer type).
    out = _buffers.with_room(values.shape)
    out[...] = values
    if signed:
        np.abs(out, out=out)
    return _normalised_block(out, *_low_width(span), out=out)


FIELD_REGISTRY = Registry("field", [
    Field("curvature", "curvature", ("mean-curvature",), _curvature, 1.0, 1, True,
          "hypervolume", "mean curvature of the graph in R^4: territories around peaks"),
    Field("gradient", "gradient magnitude", ("edges", "watershed"), _gradient, -1.0, 1,
          False, "volume", "basins of |grad f|: regions bounded by edges", "area"),
    Field("value", "value", ("intensity", "blobs"), _value, 1.0, 0, False, "hypervolume",
          "the values: regions around bright blobs (|f| on a signed map)"),
])
#: The registered fields' names.
FIELDS = tuple(FIELD_REGISTRY)
#: What a field given as an array is called in summaries.
GIVEN = "given"


def get_field(field: str | Field) -> Field:
    """The registry entry of a field name or alias."""
    return FIELD_REGISTRY[field]


def given(array) -> Field:
    """The entry of a field the user computed: the complex built on `array` itself."""
    def make(values, span, request, scale, hooks, mask=None, owned=False):
        return array

    return Field(GIVEN, "given field", (), make, 1.0, 0, False, "hypervolume",
                 "a field given as an array of the volume's shape")


def field_entry(field) -> Field:
    """The entry of `field`: a registered name or alias, an entry, or an array (`given`)."""
    if isinstance(field, str | Field):
        return get_field(field)
    if not (_validate.is_lazy(field) or hasattr(field, "__array__")
            or isinstance(field, list | tuple)):
        raise ValueError(f"`field` must be one of {', '.join(FIELDS)} or an array of the "
                         f"volume's shape, got {type(field).__name__}")
    return given(field if _validate.is_lazy(field) else np.asarray(field))


def for_morse(entry: Field, field):
    """The array the complex is built on: ``entry.sign * field``, lazily for Dask; a
    numpy negation in a buffer with room for the Morse build's padding."""
    if entry.sign > 0:
        return field
    if _validate.is_lazy(field):
        return -field
    return np.negative(field, out=_buffers.with_room(field.shape))
