"""The measure pruning decided in groups (`_prune_groups`) against the sequential
pruning and its definition: every partition into leaves, every tree of groups, ties,
zeros, lone cells, several components; and on hierarchies of fields with plateaus,
masks and every connectivity."""

import os
import subprocess
import sys

import numpy as np
import pytest

from volseg.morse import descending_complex
from volseg.morse._group_tree import block_tree
from volseg.morse._prune import prune
from volseg.morse._prune_groups import grid_leaves, grouped_prune

from .test_measures import _pruning_by_definition


def _random_forest(rng, n_max):
    """(source, target) of a random forest on n_max cells in a random sweep order."""
    edges = [(int(rng.integers(0, i)), i) for i in range(1, n_max) if rng.random() < 0.85]
    rng.shuffle(edges)
    names = rng.permutation(n_max)
    source = np.array([names[a if rng.random() < 0.5 else b] for a, b in edges], np.int64)
    target = np.array([names[a] + names[b] - s for (a, b), s in zip(edges, source, strict=True)],
                      np.int64)
    return source, target


def _sequential(source, target, base):
    order = np.empty(len(source), np.int64)
    extinction = np.empty(len(source), np.int64)
    prune(source, target, len(base), base, order, extinction)
    return order, extinction


def test_grouped_pruning_equals_its_definition_for_any_leaves_and_tree():
    """Bit for bit on random forests, each cell put in a random leaf of a random block
    grid (so most regions have neighbours outside their leaf), measures that tie
    often, zeros included."""
    rng = np.random.default_rng(29)
    for trial in range(400):
        n_max = int(rng.integers(1, 8 if trial < 300 else 80))
        source, target = _random_forest(rng, n_max)
        base = rng.integers(0, (2, 4, 1000)[trial % 3], n_max).astype(np.int64)
        grid = tuple(int(n) for n in rng.integers(1, 4, 3))
        leaf_of = rng.integers(0, int(np.prod(grid)), n_max)
        order, extinction = grouped_prune(source, target, base, leaf_of, block_tree(grid))
        want_order, want = _pruning_by_definition(source.tolist(), target.tolist(), n_max, base)
        assert order.tolist() == want_order, trial
        assert extinction.tolist() == [want[e] for e in range(len(source))], trial


def test_a_region_beside_a_frozen_one_waits_for_it():
    """Leaf 0 holds f (3), r (5) and n (9), leaf 1 holds x (1). f may not merge in
    leaf 0 (x, outside, may weigh less) and freezes; r comes after f and its highest
    edge leads to f: merging r there would prune it with 5, where the sequential
    pruning first merges x into f (4), then f across that edge (extinction 4)."""
    f, r, n, x = 0, 1, 2, 3
    source, target = np.array([f, r, f]), np.array([r, n, x])      # in sweep order
    base = np.array([3, 5, 9, 1], np.int64)
    order, extinction = grouped_prune(source, target, base, np.array([0, 0, 0, 1]),
                                      block_tree((2, 1, 1)))
    assert order.tolist() == [2, 0, 1]
    assert extinction.tolist() == [4, 9, 1]
    assert (order.tolist(), extinction.tolist()) == tuple(
        a.tolist() for a in _sequential(source, target, base))


@pytest.mark.parametrize("connectivity", ["kuhn", 6, 26])
@pytest.mark.parametrize("edge", [2, 3, 5])
def test_grouped_pruning_of_a_field_equals_the_sequential_one(connectivity, edge):
    """Hierarchies of noisy fields with plateaus (a few levels) and a mask, cut into
    leaves of edge^3 voxels: the same order and extinctions as one sequential pruning
    of the fixed-point measures, and `MorseHierarchy` reports those."""
    rng = np.random.default_rng(edge)
    field = np.round(rng.random((11, 9, 8)) * 5)
    mask = rng.random(field.shape) > 0.1
    h = descending_complex(field, connectivity=connectivity, mask=mask)
    for measure in ("size", "hypervolume"):
        base = h._cell_base(measure)
        leaf_of, tree = grid_leaves(h.maxima, h.shape, edge)
        assert len(np.unique(leaf_of)) > 4
        order, extinction = grouped_prune(h.source, h.target, base.sums, leaf_of, tree)
        want_order, want = _sequential(h.source, h.target, base.sums)
        assert np.array_equal(order, want_order)
        assert np.array_equal(extinction, want)
        got_order, got, values = h._pruning(measure)
        assert np.array_equal(got_order, want_order)
        assert np.array_equal(got, want.astype(np.float64) * base.scale)
        assert np.array_equal(values, base.values)


def test_fixed_point_keys_order_ties_exactly_where_float_sums_do_not():
    """Cells A (1 step of 0.1), B (5), C (6), D (100); edges A-B (highest), B-D, C-D.
    A merges into B first: the union weighs 6 steps, as C does, and C (the larger id)
    goes next. In floats the union weighs 0.1 + 0.5 = 0.6 < 6 * 0.1 and would go
    first: the order would hang on the order of additions, which the groups
    do not keep. The grouped and sequential prunings add integers and agree."""
    from volseg.morse._measures import Fixed

    fixed = Fixed(np.array([1, 5, 6, 100], np.int64), 0.1)
    source, target = np.array([0, 1, 2]), np.array([1, 3, 3])
    want_order = [0, 2, 1]
    assert _sequential(source, target, fixed.sums)[0].tolist() == want_order
    for leaf_of in ([0, 0, 0, 0], [0, 1, 1, 0], [0, 1, 0, 1]):
        order, _ = grouped_prune(source, target, fixed.sums, np.array(leaf_of),
                                 block_tree((2, 1, 1)))
        assert order.tolist() == want_order
    floats = np.empty(3, np.int64)
    prune(source, target, 4, fixed.values, floats, np.empty(3))
    assert floats.tolist() == [0, 1, 2]                # why the keys are integers


HEAP_HELPERS = """
import numpy as np
from volseg.morse import _prune
from volseg.morse._group_tree import block_tree
from volseg.morse._prune_groups import grouped_prune
for kind in (np.int32, np.int64):
    source, target = np.array([0, 1, 0], kind), np.array([1, 2, 3], kind)
    base = np.array([3, 5, 9, 1], np.int64)
    order, extinction = np.empty(3, np.int64), np.empty(3, np.int64)
    _prune.prune(source, target, 4, base, order, extinction)
    grouped_prune(source, target, base, np.array([0, 0, 1, 1]), block_tree((2, 1, 1)))
helpers = (_prune._sift_down, _prune._sift_up, _prune._pop)
print([len(f.signatures) for f in helpers], [f.signatures for f in helpers])
"""


def test_the_heap_helpers_compile_once(tmp_path):
    """Every call of the pruning's heap helpers passes int64 slots (`_prune._remove`
    says why), so each is compiled once whatever the events' and regions' integer
    types (the keys' type, int64 sizes or float64 hypervolumes, is another
    specialisation; int64 here): a call with an int32 slot would compile another
    copy, 0.3-0.5 CPU-s more on every first run. Counted in a new process on an
    empty numba cache (a kernel loaded from the cache does not compile its callees)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    run = subprocess.run([sys.executable, "-c", HEAP_HELPERS], capture_output=True,
                         text=True, env=env)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("[1, 1, 1] "), run.stdout
