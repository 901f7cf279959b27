"""Dask in, Dask out (DESIGN.md section 10): blockwise curvature and the blockwise
Morse build equal the in-memory ones (bit for bit, event for event) on awkward
chunkings (uneven, 2 voxels thick, one block), plateaus and exact ties, for every
operator and connectivity."""

import dask
import dask.array as da
import numpy as np
import pytest

from volseg import descending_complex, grid_curvature

from .conftest import smooth_random_field

CHUNKINGS = [(27, 40, 50), (2, 46, 33), (23, 17, 11)]


@pytest.fixture(scope="module")
def volume():
    rng = np.random.default_rng(7)
    field = smooth_random_field((41, 46, 33), rng, sigma=2.0)
    field[10:20, 10:20, 10:20] = 0.3          # a plateau
    return field


@pytest.fixture(autouse=True)
def _synchronous():
    with dask.config.set(scheduler="synchronous"):
        yield


@pytest.mark.parametrize("operator, boundary", [
    ("weighted", "linear"), ("weighted", "mirror"), ("unweighted", "linear"),
    ("laplace_beltrami", "mirror"), ("intrinsic", "linear")])
def test_blockwise_curvature_equals_in_memory(volume, operator, boundary):
    spacing = (1.0, 0.7, 1.3)
    reference = grid_curvature(volume, operator, boundary=boundary, spacing=spacing)
    for chunks in CHUNKINGS[:3]:
        lazy = grid_curvature(da.from_array(volume, chunks=chunks), operator, boundary=boundary,
                              spacing=spacing)
        assert isinstance(lazy, da.Array) and lazy.chunks == da.from_array(volume, chunks=chunks).chunks
        # Bit-identical: each block adds its sums in the in-memory order.
        assert np.array_equal(lazy.compute(), reference)


def test_blockwise_curvature_uses_the_global_value_scale(volume):
    # The default scale is a global statistic: a block with a small local range must
    # not get its own.
    scaled = volume * 1000.0
    reference = grid_curvature(scaled)
    lazy = grid_curvature(da.from_array(scaled, chunks=(16, 16, 16)))
    assert np.array_equal(lazy.compute(), reference)


def test_blockwise_curvature_refuses_nan_and_bad_shapes(volume):
    bad = volume.copy()
    bad[30, 30, 30] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        grid_curvature(da.from_array(bad, chunks=20), value_scale=1.0).compute()
    with pytest.raises(ValueError, match="3-D"):
        grid_curvature(da.zeros((4, 4), chunks=2))


def quantized(volume, step=0.05):
    return np.round(volume / step) * step     # exact ties everywhere


def assert_same_hierarchy(lazy, eager):
    for name in ("maxima", "values", "young", "elder", "target", "saddle", "saddle_value"):
        assert np.array_equal(getattr(lazy, name), getattr(eager, name)), name
    assert np.array_equal(lazy.persistence, eager.persistence)
    assert np.array_equal(lazy.cells.compute(), eager.cells)


@pytest.fixture(scope="module")
def small():
    return smooth_random_field((31, 36, 23), np.random.default_rng(8), sigma=1.5)


@pytest.mark.parametrize("connectivity, kind", [("kuhn", "smooth"), ("kuhn", "ties"), (6, "ties"),
                                                (18, "ties"), (26, "ties")])
def test_blockwise_morse_equals_in_memory(small, connectivity, kind):
    field = small if kind == "smooth" else quantized(small)
    eager = descending_complex(field, connectivity=connectivity)
    for chunks in [(17, 36, 10), (2, 36, 23), (7, 9, 8), (31, 36, 23)]:
        lazy = descending_complex(da.from_array(field, chunks=chunks), connectivity=connectivity)
        assert_same_hierarchy(lazy, eager)
        for cut in ({"n_regions": 12}, {"min_persistence": 0.05}):
            labels = lazy.segment(**cut)
            assert isinstance(labels, da.Array)
            assert np.array_equal(labels.compute(), eager.segment(**cut))


def test_blockwise_morse_on_a_curvature_field_with_plateaus(small):
    curvature = grid_curvature(quantized(small, 0.1), value_scale=5.0)   # plateaus of 0
    assert (curvature == 0).mean() > 0.05
    eager = descending_complex(curvature)
    lazy = descending_complex(da.from_array(curvature, chunks=(11, 2, 13)))
    assert_same_hierarchy(lazy, eager)


def test_blockwise_pipeline_dask_curvature_into_dask_morse(small):
    lazy = descending_complex(grid_curvature(da.from_array(small, chunks=(16, 20, 12))))
    eager = descending_complex(grid_curvature(small))
    assert_same_hierarchy(lazy, eager)


def test_blockwise_morse_refuses_what_it_cannot_do(volume):
    lazy = da.from_array(volume, chunks=20)
    with pytest.raises(ValueError, match="without a mask"):
        descending_complex(lazy, mask=np.ones(volume.shape, bool))
    with pytest.raises(ValueError, match="3-D"):
        descending_complex(da.zeros((5, 5), chunks=2))
    for value in (np.inf, -np.inf, np.nan):
        bad = volume.copy()
        bad[3, 3, 3] = value
        with pytest.raises(ValueError, match="NaN or infinite"):
            descending_complex(da.from_array(bad, chunks=20))


def test_segment_volume_of_a_dask_array_equals_in_memory(small):
    from volseg import segment_volume

    eager = segment_volume(small, n_regions=9)
    lazy = segment_volume(da.from_array(small, chunks=(11, 17, 9)), n_regions=9)
    assert isinstance(lazy.labels, da.Array) and isinstance(lazy.curvature, da.Array)
    assert np.array_equal(lazy.labels.compute(), eager.labels)
    assert np.array_equal(lazy.curvature.compute(), eager.curvature)
    assert lazy.region_table() == eager.region_table()
    assert lazy.min_persistence == eager.min_persistence and lazy.n_regions == eager.n_regions
    with pytest.raises(ValueError, match="without a mask"):
        segment_volume(da.from_array(small, chunks=10), mask="nonzero")


def test_smoothing_of_a_dask_array_equals_in_memory_bit_for_bit():
    from volseg._smoothing import gaussian

    rng = np.random.default_rng(1)
    volume = (rng.random((23, 31, 17)) * 255).astype(np.uint8)     # rough: every voxel counts
    for sigma in (0.7, 1.3):
        eager = gaussian(volume, sigma)
        # uneven chunks, chunks thinner than the filter's radius, one chunk
        for chunks in [(7, 9, 8), (2, 31, 17), (5, 3, 17), (23, 31, 17)]:
            lazy = gaussian(da.from_array(volume, chunks=chunks), sigma)
            assert lazy.chunks == da.from_array(volume, chunks=chunks).chunks
            assert np.array_equal(lazy.compute(), eager)
    assert gaussian(volume, 0) is volume


def test_segment_volume_of_a_dask_array_with_smoothing_equals_in_memory():
    from volseg import segment_volume

    rng = np.random.default_rng(5)
    volume = quantized(smooth_random_field((26, 30, 21), rng, sigma=1.5), 0.1)   # 8-bit-like
    eager = segment_volume(volume, n_regions=7, smooth=1.2)
    lazy = segment_volume(da.from_array(volume, chunks=(9, 2, 13)), n_regions=7, smooth=1.2)
    assert np.array_equal(lazy.curvature.compute(), eager.curvature)
    assert np.array_equal(lazy.labels.compute(), eager.labels)
    assert lazy.smooth == eager.smooth == 1.2 and lazy.value_scale == eager.value_scale
    unsmoothed = segment_volume(volume, n_regions=7)
    assert not np.array_equal(unsmoothed.curvature, eager.curvature)     # the option is used


@pytest.mark.parametrize("chunks", [((7, 7, 9), (17,), (2, 2, 2, 3)), ((1, 22), (5, 5, 7), (9,))])
def test_halo_equals_dask_overlap(chunks):
    """`_halo.with_halo` (shells copied, blocks freed) gives dask's overlap, block for block,
    with the blocks kept or recomputed, in 3-D and 2-D."""
    from volseg._halo import with_halo

    x = da.from_array(np.random.default_rng(0).random((23, 17, 9)), chunks=chunks)
    for array in (x, x[:, :, 4]):
        for value, fresh in ((-np.inf, False), (-1.0, True)):
            ours = with_halo(array, value, fresh=fresh)
            theirs = da.overlap.overlap(array, depth=1, boundary=value)
            assert ours.chunks == theirs.chunks
            assert np.array_equal(ours.compute(scheduler="sync"), theirs.compute(scheduler="sync"))
