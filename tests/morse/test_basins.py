"""The watershed measures (``area``, ``volume``; docs/design.md sections 12-13): each
event's saliency against its definition (the superlevel-set components found by a
breadth-first search), the cut's invariants, blockwise equal to in memory, and the
masked gradient they are meant for."""

import os
import subprocess
import sys
import warnings
from collections import deque

import dask.array as da
import numpy as np
import pytest

from volseg import segment_volume
from volseg.fields import gradient_magnitude
from volseg.morse import descending_complex, grid_offsets


def _side(h, f, start, level, saddle, allowed):
    """The vertices higher than the saddle (value, index) reachable from `start`."""
    shape = f.shape
    offsets = [np.array(o) for o in grid_offsets(f.ndim)]
    seen, todo = {start}, deque([start])
    while todo:
        v = todo.popleft()
        for o in offsets:
            u = tuple(np.add(v, o))
            if any(c < 0 or c >= n for c, n in zip(u, shape, strict=True)):
                continue
            flat = np.ravel_multi_index(u, shape)
            if u not in seen and allowed[u] and (f[u], flat) > (level, saddle):
                seen.add(u)
                todo.append(u)
    return seen


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_saliency_is_the_smaller_side_at_the_saddle(seed):
    """Each side at event e: the superlevel-set components (above the saddle, in the
    simulation-of-simplicity order) of the maxima that earlier events joined to it,
    with the saddle vertex on its own cell's side. A vertex that is the saddle of
    several events joins its components one event at a time, as a binary partition
    tree does."""
    rng = np.random.default_rng(seed)
    f = rng.random((9, 8))
    mask = np.ones(f.shape, bool)
    mask[:2, :3] = False
    h = descending_complex(f, mask=mask)
    cells = np.asarray(h.cells)
    area, volume = h.extinction("area"), h.extinction("volume")
    assert len(area) == len(h.young) > 3
    group = {m: {m} for m in range(len(h.maxima))}
    for e in range(len(h.young)):
        s, saddle = h.saddle_value[e], int(h.saddle[e])
        where = np.unravel_index(saddle, f.shape)
        sides = []
        for cell in (h.source[e], h.target[e]):
            side = set()
            for m in group[cell]:
                side |= _side(h, f, np.unravel_index(int(h.maxima[m]), f.shape), s, saddle,
                              mask)
            assert where not in side
            own = int(cells[where]) in group[cell]
            sides.append((len(side) + own, sum(f[v] - s for v in side)))
        assert area[e] == min(a for a, _ in sides)
        assert volume[e] == pytest.approx(min(v for _, v in sides), rel=1e-6, abs=1e-6)
        joined = group[h.source[e]] | group[h.target[e]]
        for m in joined:
            group[m] = joined


def test_cuts_are_nested_connected_and_counted():
    rng = np.random.default_rng(5)
    f = rng.random((12, 11, 10))
    h = descending_complex(f)
    for measure in ("area", "volume"):
        previous = None
        for k in (40, 17, 6, 1):
            labels = h.segment(n_regions=k, measure=measure)
            assert len(np.unique(labels)) == k
            for region in range(1, k + 1):               # every region connected
                from scipy import ndimage

                _, parts = ndimage.label(labels == region, np.ones((3, 3, 3)))
                assert parts == 1
            if previous is not None:                     # a coarser cut joins regions
                pairs = np.unique(np.stack([previous.ravel(), labels.ravel()]), axis=1)
                assert len(np.unique(pairs[0])) == pairs.shape[1]
            previous = labels
        t = h.threshold_for(9, measure)
        assert len(np.unique(h.segment(measure=measure, threshold=t))) == 9


def test_blockwise_equals_in_memory_on_uneven_chunks():
    rng = np.random.default_rng(3)
    f = rng.random((19, 13, 11))
    mask = rng.random(f.shape) > 0.15
    h = descending_complex(f, mask=mask)
    lazy = descending_complex(da.from_array(f, chunks=(7, 5, 6)),
                              mask=da.from_array(mask, chunks=(7, 5, 6)))
    for measure in ("area", "volume"):
        np.testing.assert_array_equal(h.extinction(measure), lazy.extinction(measure))
        np.testing.assert_array_equal(h.segment(n_regions=9, measure=measure),
                                      np.asarray(lazy.segment(n_regions=9, measure=measure)))


def test_in_memory_vertices_in_chunks_are_ordered_by_rank(rng, monkeypatch):
    """`records` on a grid, ranked chunk by chunk (chunks of 1, 7 and 1000 vertices):
    the vertices inside the mask ordered by rank (the count of events with a saddle
    above them), increasing within a rank, as int32, read in the hierarchy's own cells
    and field (not copies); the cells' areas and the fixed point's range are those of
    the field inside the mask; the extinctions are those of the whole field at once
    and of the sweep over one record per vertex (`Basins`, as the blocks give it)."""
    from volseg.morse import _basins, _measures

    f = np.round(rng.random((9, 8, 7)) * 40) / 8               # ties at saddles
    mask = rng.random(f.shape) > 0.2
    h = descending_complex(f, mask=mask)
    cells, field = h.cells.ravel(), h._field.ravel()
    inside = np.flatnonzero(cells >= 0)
    rank = np.array([np.sum(h.saddle_value > v) for v in field[inside]])
    want_order = inside[np.argsort(rank, kind="stable")]
    want_start = np.concatenate([[0], np.cumsum(np.bincount(rank, minlength=len(h.young) + 1))])
    low, high = field[inside].min(), field[inside].max()
    steps = np.floor((field[inside] - low) / _measures.unit_of(low, high)).astype(np.int64)
    one_each = _basins.Basins(cells[inside], rank.astype(np.int32),
                              np.ones(len(rank), np.int64), steps, low,
                              _measures.unit_of(low, high), 1.0)
    extinctions = None
    for chunk in (1, 7, 1000):
        monkeypatch.setattr(_basins, "RECORD_CHUNK", chunk)
        got = _basins.records(h.cells, h._field, h.saddle_value, None, _measures.unit_of,
                              _measures.scale_of)
        assert isinstance(got, _basins.RankedVertices) and got.order.dtype == np.int32
        assert np.shares_memory(got.cells, h.cells) and np.shares_memory(got.field, h._field)
        np.testing.assert_array_equal(got.order, want_order)
        np.testing.assert_array_equal(got.start, want_start)
        np.testing.assert_array_equal(got.values, np.bincount(cells[inside]))
        assert (got.low, got.unit) == (low, _measures.unit_of(low, high))
        for volume in (False, True):
            np.testing.assert_array_equal(
                _basins.saliency(got, h.source, h.target, h.saddle_value, len(h.maxima),
                                 volume),
                _basins.saliency(one_each, h.source, h.target, h.saddle_value,
                                 len(h.maxima), volume))
        fresh = descending_complex(f, mask=mask)
        now = [fresh.extinction(m) for m in ("area", "volume")]
        if extinctions is not None:
            for a, b in zip(now, extinctions, strict=True):
                np.testing.assert_array_equal(a, b)
        extinctions = now


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_counting_sort_leaves_out_negative_keys(rng, dtype):
    """The counting sort both sweeps and the leaves use: indices by key, increasing
    within a key (a stable argsort of the keys kept), keys below 0 left out of the
    order and the starts; `key_counts` counts each key the same way."""
    from volseg.morse import _kernels

    keys = rng.integers(-3, 6, size=500).astype(dtype)
    kept = np.flatnonzero(keys >= 0)
    start = _kernels.key_starts(keys, 7)
    order = np.full(start[-1], -9, dtype=np.int32)
    _kernels.by_key(keys, start, order)
    np.testing.assert_array_equal(order, kept[np.argsort(keys[kept], kind="stable")])
    counts = np.bincount(keys[kept], minlength=7)
    np.testing.assert_array_equal(start, np.concatenate([[0], np.cumsum(counts)]))
    np.testing.assert_array_equal(_kernels.key_counts(keys, 7), counts)
    again = np.empty_like(order)
    np.testing.assert_array_equal(_kernels.counting_sort(keys, 7, again), start)
    np.testing.assert_array_equal(again, order)


def test_records_with_a_weight_per_vertex_are_weighted_values(rng, monkeypatch):
    """With one weight per vertex (a mesh's dual areas) a record is a vertex inside
    the mask: its cell, its rank, its weight as the count and weight x value as the
    sum (floats, no fixed point), chunk by chunk; an area extinction with all weights
    2 is twice the grid's, and with weights 1 the same."""
    from volseg.morse import _basins, _measures

    f = np.round(rng.random((8, 7, 6)) * 40) / 8
    mask = rng.random(f.shape) > 0.2
    h = descending_complex(f, mask=mask)
    cells, field = h.cells.ravel(), h._field.ravel()
    inside = cells >= 0
    weight = rng.random(f.size) + 0.5
    want_rank = np.array([np.sum(h.saddle_value > v) for v in field[inside]])
    for chunk in (1, 5, 1000):
        monkeypatch.setattr(_basins, "RECORD_CHUNK", chunk)
        got = _basins.records(h.cells, h._field, h.saddle_value, weight,
                              _measures.unit_of, _measures.scale_of)
        np.testing.assert_array_equal(got.cell, cells[inside])
        np.testing.assert_array_equal(got.rank, want_rank)
        np.testing.assert_array_equal(got.count, weight[inside])
        np.testing.assert_array_equal(got.sums, weight[inside] * field[inside])
    grid = h.extinction("area")
    np.testing.assert_array_equal(h.with_vertex_weight(np.ones(f.size)).extinction("area"),
                                  grid)
    np.testing.assert_array_equal(
        h.with_vertex_weight(np.full(f.size, 2.0)).extinction("area"), 2 * grid)


def test_an_interrupt_in_the_records_cancels_the_chunks_not_started(monkeypatch):
    """The records' chunks run on threads; an interrupt raised in one stops the rest
    from starting (the pool is not drained first: at 512^3 that is seconds)."""
    import itertools
    import time

    from volseg.morse import _basins, _measures

    h = descending_complex(np.random.default_rng(1).random((10, 6, 5)))
    calls, order = [], itertools.count()

    def interrupted(*args):
        first = next(order) == 0                # atomic: one thread gets 0
        calls.append(1)
        time.sleep(0.02)
        if first:
            raise KeyboardInterrupt

    monkeypatch.setattr(_basins, "RECORD_CHUNK", 5)             # 60 chunks
    monkeypatch.setattr(_basins, "_ranks_into", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _basins.records(h.cells, h._field, h.saddle_value, None, _measures.unit_of,
                        _measures.scale_of)
    assert len(calls) < 20, len(calls)


def test_released_records_are_made_again_for_the_next_cut():
    """`release_vertex_records` (the pipeline's, once its cut is made) lets the
    watershed records go; cuts by either watershed measure afterwards equal a fresh
    hierarchy's."""
    from volseg.morse._hierarchy import _base_key

    rng = np.random.default_rng(6)
    f = rng.random((11, 9, 8))
    h = descending_complex(f)
    first = h.segment(n_regions=7, measure="volume")
    assert _base_key("volume") in h._pruned
    h.release_vertex_records()
    assert _base_key("area") not in h._pruned
    fresh = descending_complex(f)
    np.testing.assert_array_equal(h.segment(n_regions=7, measure="volume"), first)
    np.testing.assert_array_equal(h.segment(n_regions=5, measure="area"),
                                  fresh.segment(n_regions=5, measure="area"))
    result = segment_volume((f * 200).astype(np.uint8), field="gradient", n_regions=4,
                            mask=None)
    assert _base_key("volume") not in result.hierarchy._pruned
    np.testing.assert_array_equal(result.recut(n_regions=4).labels, result.labels)


SWEEP_SIGNATURES = """
import dask.array as da
import numpy as np
from volseg.morse import _basins, descending_complex
f = np.random.default_rng(3).random((19, 13, 11))
mask = f > 0.1
a = descending_complex(f, mask=mask).extinction("volume")
b = descending_complex(da.from_array(f, chunks=(7, 5, 6)),
                       mask=da.from_array(mask, chunks=(7, 5, 6))).extinction("volume")
assert np.array_equal(a, b)
kernels = (_basins._sweep, _basins._sweep_vertices, _basins._joined_at, _basins._rank)
print(*(len(k.signatures) for k in kernels), [k.signatures for k in kernels])
"""


def test_the_sweeps_compile_once_and_share_their_join(tmp_path):
    """The blocks' joined records give `_sweep` cells and ranks of one type
    (`_basins._index`, as a mesh's records) and the in-memory grid's ranked vertices
    go to `_sweep_vertices`: each compiles once, and the event join both call and the
    rank both records paths take compile once for the two (counted in a new process
    on an empty numba cache)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    run = subprocess.run([sys.executable, "-c", SWEEP_SIGNATURES], capture_output=True,
                         text=True, env=env)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("1 1 1 1 "), run.stdout


def test_segment_volume_blockwise_equal_for_every_field():
    rng = np.random.default_rng(4)
    x, y, z = np.meshgrid(*[np.arange(n) for n in (30, 26, 22)], indexing="ij")
    volume = 60 + 100 * (((x - 10) ** 2 + (y - 12) ** 2 + (z - 11) ** 2) < 49) \
        + 60 * (((x - 20) ** 2 + (y - 13) ** 2 + (z - 10) ** 2) < 36)
    volume = np.clip(volume + rng.normal(0, 6, volume.shape), 0, 255).astype(np.uint8)
    volume[:3] = 0                                         # a background slab: a mask
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for field in ("gradient", "value", "curvature"):
            for measure in ("area", "volume"):
                a = segment_volume(volume, field=field, measure=measure, n_regions=7)
                b = segment_volume(da.from_array(volume, chunks=(11, 9, 13)), field=field,
                                   measure=measure, n_regions=7)
                np.testing.assert_array_equal(a.labels, np.asarray(b.labels))


def test_gradient_default_measure_finds_the_parts():
    """Touching flat-topped spheres on a graded background: the gradient's basins by
    volume (the field's default) give the parts."""
    rng = np.random.default_rng(0)
    x, y, z = np.meshgrid(*[np.arange(n, dtype=float) for n in (40, 36, 30)], indexing="ij")
    truth = np.zeros(x.shape, int)
    volume = 40 + 1.0 * x
    for label, (c, r, level) in enumerate([((12, 14, 15), 8, 160), ((25, 14, 15), 6, 220),
                                           ((19, 25, 15), 7, 110)], 1):
        inside = (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 <= r * r
        volume, truth = np.where(inside, level, volume), np.where(inside, label, truth)
    volume = np.clip(np.round(volume + rng.normal(0, 5, x.shape)), 0, 255).astype(np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seg = segment_volume(volume, field="gradient", n_regions=4, mask="none")
    assert seg.measure == "volume"
    from volseg.metrics import adjusted_rand_index

    assert adjusted_rand_index(truth.ravel(), seg.labels.ravel()) > 0.8


def test_masked_gradient_never_reaches_outside():
    rng = np.random.default_rng(2)
    values = rng.random((9, 8, 7))
    mask = rng.random(values.shape) > 0.3
    out = gradient_magnitude(values, (1.0, 2.0, 0.5), mask)
    changed = values.copy()
    changed[~mask] = rng.random(int((~mask).sum())) * 100     # outside: anything
    np.testing.assert_array_equal(out, gradient_magnitude(changed, (1.0, 2.0, 0.5), mask))
    np.testing.assert_array_equal(gradient_magnitude(values, (1.0, 2.0, 0.5)),
                                  gradient_magnitude(values, (1.0, 2.0, 0.5),
                                                     np.ones(values.shape, bool)))
    lazy = gradient_magnitude(da.from_array(values, chunks=(4, 3, 5)), (1.0, 2.0, 0.5),
                              da.from_array(mask, chunks=(4, 3, 5)))
    np.testing.assert_array_equal(out, lazy.compute())
    line = np.array([[[0.0, 1.0, 3.0, 9.0]]])              # one-sided at the mask's edge
    inside = np.array([[[True, True, True, False]]])
    np.testing.assert_array_equal(gradient_magnitude(line, (1, 1, 1), inside)[0, 0],
                                  [1.0, 1.5, 2.0, 0.0])


def test_a_degenerate_volume_cut_falls_back_to_area_and_says_so(volvis_dir):
    """By volume, the tooth (one homogeneous object in its masked air) is one basin of
    two thirds of it and specks along the mask's rim: degenerate. The gradient's
    default then cuts by area, and the report records why (issue 55: the tooth keeps
    its spread with --field gradient). An asked measure, or a threshold, is never
    replaced; blockwise gives the same labels and the same rule."""
    from volseg.io import read_volume
    from volseg.metrics import region_spread

    volume = read_volume(next(volvis_dir.glob("tooth_*.raw"))).data
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        by_volume = segment_volume(volume, field="gradient", measure="volume")
        default = segment_volume(volume, field="gradient")
        lazy = segment_volume(da.from_array(volume, chunks=(47, 53, 61)), field="gradient")
    assert region_spread(np.bincount(by_volume.labels.ravel())[1:])["degenerate"]
    assert by_volume.measure == "volume" and "measure_rule" not in by_volume.cut
    assert default.measure == "area"
    assert default.cut["measure_rule"].startswith("area: by volume the cut was degenerate")
    spread = region_spread(np.bincount(default.labels.ravel())[1:])
    assert spread["largest_share"] <= 0.5 and spread["regions_at_least_1_percent"] >= 10
    np.testing.assert_array_equal(default.labels, np.asarray(lazy.labels))
    assert lazy.cut["measure_rule"] == default.cut["measure_rule"]
    threshold = by_volume.hierarchy.threshold_for(30, "volume")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        by_threshold = segment_volume(volume, field="gradient", threshold=threshold)
    assert by_threshold.measure == "volume"
