import contextlib
import warnings

import networkx as nx
import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy import ndimage, sparse

from tests.conftest import smooth_random_field
from volseg.morse import descending_complex, grid_offsets


def test_two_peaks_in_1d_by_hand():
    f = np.array([0.0, 3.0, 1.0, 2.0, 0.5])
    h = descending_complex(f)
    assert h.maxima.tolist() == [1, 3]
    assert h.persistence.tolist() == [np.inf, 1.0]  # 2 - 1 at the saddle x = 2
    assert h.saddle.tolist() == [2] and h.saddle_value.tolist() == [1.0]
    # The saddle vertex climbs to its highest neighbour (3.0 at x = 1).
    assert_array_equal(h.segment(), [1, 1, 1, 2, 2])
    assert_array_equal(h.segment(min_persistence=1.0), [1, 1, 1, 2, 2])
    assert_array_equal(h.segment(min_persistence=1.01), [1, 1, 1, 1, 1])


def test_plateau_ties_break_by_index():
    # Equal values: the higher index is higher (simulation of simplicity).
    f = np.array([1.0, 1.0, 1.0, 0.0, 1.0])
    h = descending_complex(f)
    assert h.maxima.tolist() == [4, 2]
    # Vertex 3 (value 0) climbs to its highest neighbour: 4, equal in value to 2 but higher.
    assert_array_equal(h.segment(), [2, 2, 2, 1, 1])
    assert h.persistence.tolist() == [np.inf, 1.0]


def test_2d_known_saddle():
    # Two bumps on a 4-connected grid joined through the saddle at (2, 2).
    y, x = np.mgrid[0:5, 0:7]
    f = np.exp(-((x - 1) ** 2 + (y - 2) ** 2)) + 0.8 * np.exp(-((x - 5) ** 2 + (y - 2) ** 2))
    h = descending_complex(f, connectivity=4)
    tops = [np.unravel_index(m, f.shape) for m in h.maxima]
    assert tops == [(2, 1), (2, 5)]
    saddle = np.unravel_index(h.saddle[0], f.shape)
    assert saddle == (2, 3)
    assert np.isclose(h.persistence[1], f[2, 5] - f[2, 3])
    graph = h.region_adjacency()
    assert graph.number_of_nodes() == 2 and np.isclose(graph.edges[1, 2]["saddle"], f[2, 3])


@pytest.mark.parametrize("shape", [(40,), (17, 19), (11, 12, 13)])
def test_region_count_law_and_monotone_and_connected(shape, rng):
    f = smooth_random_field(shape, rng, sigma=1.2)
    h = descending_complex(f)
    p = h.persistence
    previous = np.inf
    structure = np.zeros((3,) * len(shape), bool)
    for step in grid_offsets(len(shape), "kuhn"):
        structure[tuple(step + 1)] = True
    structure[(1,) * len(shape)] = True
    for t in np.r_[0, np.quantile(p[np.isfinite(p)], [0.1, 0.5, 0.9]), p[np.isfinite(p)].max() + 1]:
        labels = h.segment(min_persistence=t)
        k = labels.max()
        assert k == 1 + np.sum(np.isfinite(p) & (p >= t))
        assert k <= previous
        previous = k
        assert labels.min() == 1 and len(np.unique(labels)) == k  # every voxel labelled
        for region in range(1, k + 1):
            _, parts = ndimage.label(labels == region, structure=structure)
            assert parts == 1, (t, region)
        tops = [f.ravel()[np.flatnonzero(labels.ravel() == r)].max() for r in range(1, k + 1)]
        assert tops == sorted(tops, reverse=True)  # ordered by decreasing maximum


def test_n_regions_is_exact_and_warns_when_too_many(rng):
    f = smooth_random_field((20, 20, 20), rng, sigma=1.5)
    h = descending_complex(f)
    for k in [1, 2, 7, len(h.maxima)]:
        assert h.segment(n_regions=k).max() == k
        assert h.segment(min_persistence=h.threshold_for(k)).max() == k
    with pytest.warns(UserWarning, match="only"):
        labels = h.segment(n_regions=len(h.maxima) + 5)
    assert labels.max() == len(h.maxima)


def test_persistence_equals_gudhi_cubical_on_6_connected_grids(rng):
    gudhi = pytest.importorskip("gudhi")
    for shape in [(12, 13, 14), (30, 31)]:
        f = smooth_random_field(shape, rng, sigma=1.5)
        h = descending_complex(f, connectivity=6 if len(shape) == 3 else 4)
        cubical = gudhi.CubicalComplex(vertices=-f)
        cubical.compute_persistence()
        pairs = cubical.persistence_intervals_in_dimension(0)
        expected = np.sort(pairs[:, 1] - pairs[:, 0])
        assert_array_equal(len(expected), len(h.maxima))
        np.testing.assert_allclose(np.sort(h.persistence), expected, rtol=1e-12)


def test_grid_and_explicit_adjacency_give_the_same_partition(rng):
    f = smooth_random_field((9, 10, 11), rng, sigma=1.2)
    offsets = grid_offsets(3, "kuhn")
    index = np.arange(f.size).reshape(f.shape)
    edges = []
    for step in offsets:
        src = tuple(slice(max(-s, 0), n - max(s, 0)) for s, n in zip(step, f.shape, strict=True))
        dst = tuple(slice(max(s, 0), n - max(-s, 0)) for s, n in zip(step, f.shape, strict=True))
        edges.append(np.c_[index[src].ravel(), index[dst].ravel()])
    edges = np.concatenate(edges)
    grid = descending_complex(f)
    matrix = sparse.coo_matrix((np.ones(len(edges)), edges.T), shape=(f.size, f.size))
    graph = nx.Graph()
    graph.add_nodes_from(range(f.size))
    graph.add_edges_from(edges.tolist())
    for adjacency in [edges, matrix, graph]:
        other = descending_complex(f.ravel(), adjacency=adjacency)
        assert_array_equal(other.maxima, grid.maxima)
        np.testing.assert_array_equal(other.persistence, grid.persistence)
        for k in [1, 5, len(grid.maxima)]:
            assert_array_equal(other.segment(n_regions=k).reshape(f.shape),
                               grid.segment(n_regions=k))


def test_networkx_node_order_is_documented_order():
    graph = nx.path_graph(["a", "b", "c", "d"])
    h = descending_complex(np.array([0.0, 2.0, 1.0, 3.0]), adjacency=graph)
    assert h.maxima.tolist() == [3, 1]


def test_disconnected_graph_keeps_one_region_per_component():
    h = descending_complex(np.array([1.0, 2.0, 5.0, 4.0]), adjacency=np.array([[0, 1], [2, 3]]))
    assert h.n_components == 2
    with pytest.warns(UserWarning, match="connected components"):
        assert h.segment(n_regions=1).max() == 2


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match="NaN or infinite values \\(first at index \\[1\\]\\)"):
        descending_complex(np.array([0.0, np.nan, 1.0]))
    with pytest.raises(ValueError, match="outside the field"):
        descending_complex(np.zeros(3), adjacency=np.array([[0, 3]]))
    with pytest.raises(ValueError, match="3 vertices"):
        descending_complex(np.zeros(3), adjacency=sparse.eye(4))
    with pytest.raises(ValueError, match="must be 1-D"):
        descending_complex(np.zeros((2, 2)), adjacency=np.array([[0, 1]]))
    with pytest.raises(ValueError, match="not available in 3-D"):
        descending_complex(np.zeros((3, 3, 3)), connectivity=8)
    h = descending_complex(np.array([0.0, 1.0, 0.0, 2.0]))
    with pytest.raises(ValueError, match="`n_regions` must be at least 1"):
        h.segment(n_regions=0)
    with pytest.raises(ValueError, match="not both"):
        h.segment(min_persistence=1, n_regions=1)
    with pytest.raises(ValueError, match="real numbers"):
        descending_complex(np.array(["a", "b"]))


def _reference_persistence(values, edges):
    """Elder-rule vertex sweep in plain Python: sorted (birth - death) of dying maxima."""
    n = len(values)
    neighbours = [[] for _ in range(n)]
    for a, b in edges:
        neighbours[a].append(b)
        neighbours[b].append(a)
    key = lambda v: (values[v], v)  # noqa: E731
    parent = list(range(n))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    seen, peak, deaths = set(), {}, []
    for v in sorted(range(n), key=key, reverse=True):
        seen.add(v)
        peak[v] = v
        for u in neighbours[v]:
            if u not in seen:
                continue
            ru, rv = find(u), find(v)
            if ru == rv:
                continue
            young, old = (ru, rv) if key(peak[ru]) < key(peak[rv]) else (rv, ru)
            if peak[young] != v:
                deaths.append(values[peak[young]] - values[v])
            parent[young] = old
    return sorted(deaths)


def test_dense_cross_cell_edges_match_a_reference_sweep():
    # 60 high vertices, each of 100 low ones joined to a random half of them: low
    # vertices fall into many cells and each touches 30, so the cell pairs outnumber
    # the edge pass's first allocation (one per two vertices) and its rerun is used.
    rng = np.random.default_rng(3)
    values = np.concatenate([1 + rng.random(60), rng.random(100)])
    edges = np.array([(a, b) for b in range(60, 160) for a in rng.permutation(60)[:30]])
    hierarchy = descending_complex(values, adjacency=edges)
    assert len(hierarchy.maxima) == 60
    got = np.sort(hierarchy.values[hierarchy.young] - hierarchy.saddle_value)
    np.testing.assert_allclose(got, _reference_persistence(values, edges.tolist()))


# ---------------------------------------------------------------- adjacency is structure (issue 11)


@pytest.mark.parametrize("weight", [0.5, 128, 256, -1.0, 1e-300])
def test_weighted_sparse_adjacency_is_read_as_structure(weight):
    from scipy import sparse

    field = np.array([0.0, 3.0, 1.0, 2.0, 0.5])
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    reference = descending_complex(field, adjacency=edges)
    matrix = sparse.coo_array((np.full(4, weight), (edges[:, 0], edges[:, 1])), shape=(5, 5))
    for m in (matrix, matrix.tocsr(), sparse.csr_matrix(matrix)):
        result = descending_complex(field, adjacency=m)
        assert_array_equal(result.segment(), reference.segment())
        assert_array_equal(result.persistence, reference.persistence)


def test_duplicate_entries_that_sum_to_zero_are_still_an_edge():
    from scipy import sparse

    field = np.array([0.0, 3.0, 1.0])
    matrix = sparse.coo_array(([1.0, -1.0, 1.0], ([0, 0, 1], [1, 1, 2])), shape=(3, 3))
    assert len(descending_complex(field, adjacency=matrix).maxima) == 1


def test_dense_square_adjacency_is_refused_as_ambiguous():
    with pytest.raises(ValueError, match=r"dense 2 x 2 array: pass .*csr_array"):
        descending_complex(np.array([1.0, 2.0]), adjacency=np.array([[0, 1], [1, 0]]))


@pytest.mark.parametrize("call, message", [
    (lambda h: h.segment(n_regions=2.5), "`n_regions` must be an integer"),
    (lambda h: h.segment(n_regions=True), "`n_regions` must be an integer"),
    (lambda h: h.segment(min_persistence=-1), "non-negative"),
    (lambda h: h.segment(min_persistence=float("nan")), "non-negative"),
    (lambda h: h.threshold_for(0), "at least 1"),
    (lambda h: h.region_adjacency(np.zeros((3, 3), int)), r"field's shape \(4, 4, 4\)"),
])
def test_cut_arguments_are_checked_with_their_names(call, message):
    hierarchy = descending_complex(np.random.default_rng(0).random((4, 4, 4)))
    with pytest.raises(ValueError, match=message):
        call(hierarchy)


# ---------------------------------------------------------------- masks (issue 13)


def _restricted_adjacency(mask, connectivity="kuhn"):
    """Edges of the grid connectivity between masked voxels, in compact ids (the
    masked voxels in flat order)."""
    compact = np.full(mask.size, -1)
    compact[np.flatnonzero(mask)] = np.arange(mask.sum())
    compact = compact.reshape(mask.shape)
    rows, cols = [], []
    for step in grid_offsets(mask.ndim, connectivity):
        if tuple(step) <= (0,) * mask.ndim:
            continue
        src = tuple(slice(max(-s, 0), n - max(s, 0)) for s, n in zip(step, mask.shape, strict=True))
        dst = tuple(slice(max(s, 0), n - max(-s, 0)) for s, n in zip(step, mask.shape, strict=True))
        both = mask[src] & mask[dst]
        rows.append(compact[src][both])
        cols.append(compact[dst][both])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    return sparse.coo_array((np.ones(len(rows)), (rows, cols)), shape=(mask.sum(),) * 2)


@pytest.mark.parametrize("connectivity", ["kuhn", 6, 26])
@pytest.mark.parametrize("kind", ["smooth", "ties", "two-components"])
def test_masked_grid_equals_the_explicit_restricted_graph(connectivity, kind):
    rng = np.random.default_rng(5)
    field = smooth_random_field((18, 15, 12), rng)
    if kind == "ties":
        field = np.round(field * 4) / 4  # plateaus and exact ties everywhere
    mask = field > np.quantile(field, 0.45)
    if kind == "two-components":
        mask[8:10] = False
    field = np.where(mask, field, np.nan)  # values outside the mask are never read
    grid = descending_complex(field, mask=mask, connectivity=connectivity)
    graph = descending_complex(field[mask], adjacency=_restricted_adjacency(mask, connectivity))
    where = np.flatnonzero(mask)
    assert_array_equal(grid.maxima, where[graph.maxima])
    assert_array_equal(grid.persistence, graph.persistence)
    assert_array_equal(grid.saddle, where[graph.saddle])
    assert grid.n_components == graph.n_components
    # Five regions from fewer maxima, or from more components, is all there is, with a
    # warning saying so (the "ties" field at 26 has 2 maxima; "two-components" 6).
    warns = len(grid.maxima) < 5 or grid.n_components > 5
    for cut in [{}, {"n_regions": 5}, {"min_persistence": 0.05}]:
        def expected(cut=cut):
            if warns and cut.get("n_regions"):
                return pytest.warns(UserWarning, match="asked for 5 regions")
            return contextlib.nullcontext()

        with expected():
            labels = grid.segment(**cut)
        with expected():
            other = graph.segment(**cut)
        assert (labels[~mask] == 0).all()
        assert_array_equal(labels[mask], other)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # the same warning, asserted above
        labels = grid.segment(n_regions=5)
    adjacency = grid.region_adjacency(labels)
    assert sorted(adjacency.nodes) == list(range(1, labels.max() + 1))



@pytest.mark.parametrize("masked", [False, True])
def test_region_adjacency_of_sparse_and_huge_labels(rng, masked):
    """Labels {0, 7, 2^40} give the graph of {0, 1, 2} relabelled: no empty node per
    unused label (there was one per gap, with maximum -1), and no 2^40-entry count."""
    import networkx as nx

    field = rng.random((7, 6, 5))
    mask = np.ones(field.shape, bool)
    mask[:2] = False
    h = descending_complex(field, mask=mask if masked else None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        labels = h.segment(n_regions=3).astype(np.int64)
    names = {0: 0, 1: 7, 2: 2**40, 3: 2**40 + 5}
    sparse = np.vectorize(names.get, otypes=[np.int64])(labels)
    compact, spread = h.region_adjacency(labels), h.region_adjacency(sparse)
    assert sorted(spread.nodes) == sorted(names[n] for n in compact.nodes)
    relabelled = nx.relabel_nodes(compact, names)
    assert dict(spread.nodes(data=True)) == dict(relabelled.nodes(data=True))
    assert {frozenset(e): d for *e, d in spread.edges(data=True)} == \
        {frozenset(e): d for *e, d in relabelled.edges(data=True)}
    assert all(d["size"] > 0 and d["maximum"] >= 0 for _, d in spread.nodes(data=True))

def test_mask_errors():
    field = np.zeros((4, 4, 4))
    with pytest.raises(ValueError, match="boolean array of the field's shape"):
        descending_complex(field, mask=np.ones((4, 4), bool))
    with pytest.raises(ValueError, match="selects no vertex"):
        descending_complex(field, mask=np.zeros((4, 4, 4), bool))


def test_memory_layout_does_not_change_the_hierarchy(rng):
    """Fortran-ordered and strided fields (a raw volume is read as a transposed view)
    give the same hierarchy; they used to be walked with the wrong strides (a crash)."""
    field = rng.random((9, 7, 8))
    expected = descending_complex(field)
    for other in (np.asfortranarray(field), field.T.copy().T, field[:, ::-1][:, ::-1],
                  np.repeat(field, 2, axis=2)[:, :, ::2]):
        result = descending_complex(other)
        for name in ("cells", "maxima", "young", "elder", "target", "saddle"):
            assert np.array_equal(getattr(result, name), getattr(expected, name)), name


def test_events_do_not_depend_on_how_edges_were_found(rng):
    """Several edges can share a saddle vertex (it touches three or more cells); which
    merges first decides the events' targets. The order is by (value, vertex, cell
    pair), so the same hierarchy comes out of any chunking (the blockwise path needs
    this) and of the reversed field, up to the index map."""
    from volseg.morse import _edges as morse

    field = rng.integers(0, 4, (23, 19, 21)).astype(float)  # many ties
    expected = descending_complex(field)
    for size in (1 << 8, 1 << 12):
        original = morse._CHUNK_VERTICES
        morse._CHUNK_VERTICES = size
        try:
            result = descending_complex(field)
        finally:
            morse._CHUNK_VERTICES = original
        for name in ("young", "elder", "target", "saddle"):
            assert np.array_equal(getattr(result, name), getattr(expected, name)), (size, name)


def test_region_count_cut_keeps_the_events_a_full_sort_would():
    # `_all_but_most_persistent` selects in linear time what np.lexsort((young, -p))
    # ranks first: the most persistent events, ties to the older young maximum.
    from volseg.morse._hierarchy import _all_but_most_persistent

    rng = np.random.default_rng(0)
    for _ in range(200):
        n = int(rng.integers(0, 40))
        p = np.round(rng.random(n) * rng.integers(1, 5)) / 4          # many exact ties
        young = (rng.permutation(n) + 1).astype(np.int32)
        for keep in range(n + 2):
            expected = np.ones(n, dtype=bool)
            expected[np.lexsort((young, -p))[:keep]] = False
            assert np.array_equal(_all_but_most_persistent(p, young, keep), expected)


def test_integers_beyond_2_53_are_refused_not_rounded_into_one_plateau():
    """int64 maxima 1 apart above 2^53 would be one float64 value (issue 57, #6)."""
    import pytest

    big = np.int64(2**60)
    field = np.array([0, big, big - 2, big - 1, 0], dtype=np.int64)
    with pytest.raises(ValueError, match="beyond 2\\^53"):
        descending_complex(field)
    small = np.array([0, 2**53, 2**53 - 2, 2**53 - 1, 0], dtype=np.int64)
    assert len(descending_complex(small).maxima) == 2


def test_region_tops_are_each_regions_first_maximum_without_a_sort():
    """`region_tops` (a cut's highest maximum per region, O(M)) equals the first index of
    each region, on real cuts with dropped components (-1) and on any numbering."""
    from volseg.morse.cuts import region_tops

    rng = np.random.default_rng(3)
    field = rng.random((14, 13, 12))
    mask = field > 0.2
    hierarchy = descending_complex(field, mask=mask)
    for k in (1, 4, 40):
        for min_component in (0.0, 0.01):
            region = hierarchy.region_of_maximum(n_regions=k, min_component=min_component)
            count = int(region.max()) + 1
            ids, first = np.unique(region, return_index=True)
            assert np.array_equal(region_tops(region, count), first[ids >= 0])
    shuffled = np.array([2, 2, 0, -1, 1, 0, 2])           # not numbered in first order
    assert np.array_equal(region_tops(shuffled, 3), [2, 4, 0])
    assert len(region_tops(np.array([], dtype=np.int64), 0)) == 0


_HIERARCHY_ARRAYS = ("cells", "maxima", "values", "young", "elder", "target", "source",
                     "saddle", "saddle_value", "persistence")


def _in_a_padded_buffer(values, extra=0):
    """`values` (3-D float64) copied to the start of a flat buffer with room for them
    padded by one voxel (and `extra` more values), as `volseg.curvature` leaves them."""
    room = int(np.prod([n + 2 for n in values.shape])) + extra
    buffer = np.full(room, 7.5)
    field = buffer[:values.size].reshape(values.shape)
    field[...] = values
    return field


@pytest.mark.parametrize("shape", [(6, 5, 7), (1, 4, 3), (5, 1, 1), (1, 1, 1), (3, 8, 2)])
def test_a_build_in_the_fields_buffer_equals_the_build_on_a_copy(shape, rng, monkeypatch):
    """`overwrite_field`: the same hierarchy as on a copy, ties and plateaus, with and
    without a mask (NaN outside it), every connectivity; the field holds its own
    values again afterwards, bit for bit (NaN and -0.0 included)."""
    from volseg.morse import _build

    for trial in range(12):
        values = rng.integers(0, 4, shape).astype(np.float64)
        values[rng.random(shape) < 0.1] = -0.0
        mask = None if trial % 3 == 0 else rng.random(shape) < (0.7, 1.0)[trial % 3 - 1]
        if mask is not None:
            mask.flat[0] = True
            values[~mask] = np.nan
        connectivity = ("kuhn", 6, 18, 26)[trial % 4]
        field = _in_a_padded_buffer(values, extra=trial)
        want = descending_complex(values.copy(), mask=mask, connectivity=connectivity)
        with monkeypatch.context() as patched:      # not the copy's path
            patched.setattr(_build, "_neighbourhood", None)
            got = descending_complex(field, mask=mask, connectivity=connectivity,
                                     overwrite_field=True)
        for name in _HIERARCHY_ARRAYS:
            assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
        assert_array_equal(got.segment(min_persistence=1.0), want.segment(min_persistence=1.0))
        assert field.tobytes() == values.tobytes(), trial
        assert got._field is field


def test_a_build_in_the_fields_buffer_gives_it_back_when_it_fails(rng, monkeypatch):
    """An error (an interrupt) inside the build leaves the field as it was."""
    from volseg.morse import _build

    values = smooth_random_field((9, 8, 7), rng)
    mask = values > np.median(values)
    field = _in_a_padded_buffer(values)

    def failing(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(_build, "_merge_events", failing)
    with pytest.raises(KeyboardInterrupt):
        descending_complex(field, mask=mask, overwrite_field=True)
    assert field.tobytes() == values.tobytes()


@pytest.mark.parametrize("after_the_move", [False, True])
def test_an_interrupt_during_the_move_gives_the_field_back(after_the_move, rng,
                                                           monkeypatch):
    """A KeyboardInterrupt after any number of slabs moved to their padded places,
    raised before or after the slab it interrupts has moved: the field as it was."""
    from volseg.morse._graph import PaddedInPlace

    values = smooth_random_field((7, 4, 5), rng)
    values[0, 0, :2] = -0.0, np.nan
    mask = np.isfinite(values)
    move_up = PaddedInPlace._move_up
    for moved in range(len(values)):
        calls = []

        def interrupted(self, x, moved=moved, calls=calls):
            if len(calls) == moved:
                if after_the_move:
                    move_up(self, x)
                raise KeyboardInterrupt
            calls.append(x)
            move_up(self, x)

        field = _in_a_padded_buffer(values)
        with monkeypatch.context() as patched:
            patched.setattr(PaddedInPlace, "_move_up", interrupted)
            with pytest.raises(KeyboardInterrupt):
                descending_complex(field, mask=mask, overwrite_field=True)
        assert field.tobytes() == values.tobytes(), moved


def test_a_field_without_room_is_copied_not_overwritten(rng):
    """`overwrite_field` on fields it cannot use (no room, another type, order or
    dimension, a view inside a buffer): the copy's build, the field untouched."""
    values = smooth_random_field((6, 7, 5), rng)
    short = np.full(values.size + 10, 3.0)
    cases = [values.copy(), values.astype(np.float32), np.asfortranarray(values),
             values.reshape(42, 5).copy(), short[:values.size].reshape(values.shape),
             _in_a_padded_buffer(np.pad(values, 1))[1:-1, 1:-1, 1:-1]]
    for case in cases:
        case[...] = values.reshape(case.shape)
        before = case.tobytes()
        want = descending_complex(case.copy())
        got = descending_complex(case, overwrite_field=True)
        assert_array_equal(got.persistence, want.persistence)
        assert case.tobytes() == before
    assert np.all(short[values.size:] == 3.0)


def test_the_pipelines_field_is_built_in_its_own_buffer():
    """`segment_volume` leaves its curvature where the Morse build pads it in place
    (8 bytes a voxel less at the Morse stage's peak), for a smoothed integer volume
    (the smoothing's buffer) and a float one (the curvature's own)."""
    from volseg import segment_volume
    from volseg._buffers import room_to_pad

    rng = np.random.default_rng(3)
    for volume in (rng.integers(0, 255, (12, 10, 9)).astype(np.uint8),
                   smooth_random_field((12, 10, 9), rng).astype(np.float32)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")        # fewer maxima than asked, say
            result = segment_volume(volume, n_regions=3)
        assert room_to_pad(result.curvature) is not None, volume.dtype
