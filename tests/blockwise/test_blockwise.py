"""Dask in, Dask out (docs/design.md section 10): blockwise curvature and the blockwise
Morse build equal the in-memory ones (bit for bit, event for event) on awkward
chunkings (uneven, 2 voxels thick, one block), plateaus and exact ties, for every
operator and connectivity."""

import dask
import dask.array as da
import numpy as np
import pytest

from volseg import descending_complex, grid_curvature, segment_volume

from ..conftest import smooth_random_field

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
    reference = grid_curvature(volume, operator, padding=boundary, spacing=spacing)
    for chunks in CHUNKINGS[:3]:
        lazy = grid_curvature(da.from_array(volume, chunks=chunks), operator, padding=boundary,
                              spacing=spacing)
        assert isinstance(lazy, da.Array)
        assert lazy.chunks == da.from_array(volume, chunks=chunks).chunks
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
    for name in ("maxima", "values", "young", "elder", "target", "source", "saddle",
                 "saddle_value"):
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


@pytest.mark.parametrize("kind", ["smooth", "ties"])
def test_blockwise_morse_with_a_mask_equals_in_memory(small, kind):
    # docs/design.md section 9 on blocks: a mask of several components (a lone voxel, a
    # slab, blobs), chunks that cut through them, values outside the mask NaN (ignored).
    field = small if kind == "smooth" else quantized(small)
    rng = np.random.default_rng(11)
    mask = smooth_random_field(small.shape, rng, sigma=2.0) > 0.1
    mask[3, 3, 3], mask[2:4, 2:4, 2:5] = True, False
    mask[3, 3, 3], mask[20:22] = True, True
    field = np.where(mask, field, np.nan)
    eager = descending_complex(field, mask=mask)
    assert eager.n_components > 2
    for chunks, mask_chunks in [((17, 36, 10), (5, 5, 5)), ((2, 36, 23), (31, 36, 23)),
                                ((7, 9, 8), (7, 9, 8))]:
        lazy = descending_complex(da.from_array(field, chunks=chunks),
                                  mask=da.from_array(mask, chunks=mask_chunks))
        assert_same_hierarchy(lazy, eager)
        for cut in ({"n_regions": eager.n_components + 9}, {"min_persistence": 0.05}):
            labels = lazy.segment(**cut).compute()
            assert np.array_equal(labels, eager.segment(**cut))
            assert (labels[~mask] == 0).all() and (labels[mask] > 0).all()
    # a numpy mask works too, and an all-outside block (chunks of 2 along x) is fine
    lazy = descending_complex(da.from_array(field, chunks=(2, 36, 23)), mask=mask)
    assert_same_hierarchy(lazy, eager)


def test_blockwise_morse_refuses_a_bad_mask(small):
    lazy = da.from_array(small, chunks=10)
    with pytest.raises(ValueError, match="boolean array of the field's shape"):
        descending_complex(lazy, mask=np.ones((3, 3, 3), bool))
    with pytest.raises(ValueError, match="selects no vertex"):
        descending_complex(lazy, mask=np.zeros(small.shape, bool))
    bad = small.copy()
    bad[4, 4, 4] = np.inf
    with pytest.raises(ValueError, match="inside the mask"):
        descending_complex(da.from_array(bad, chunks=10), mask=np.ones(small.shape, bool))


def test_blockwise_morse_refuses_what_it_cannot_do(volume):
    with pytest.raises(ValueError, match="3-D"):
        descending_complex(da.zeros((5, 5), chunks=2))
    for value in (np.inf, -np.inf, np.nan):
        bad = volume.copy()
        bad[3, 3, 3] = value
        with pytest.raises(ValueError, match="NaN or infinite"):
            descending_complex(da.from_array(bad, chunks=20))


def test_segment_volume_of_a_dask_array_equals_in_memory(small):
    eager = segment_volume(small, n_regions=9)
    lazy = segment_volume(da.from_array(small, chunks=(11, 17, 9)), n_regions=9)
    assert isinstance(lazy.labels, da.Array) and isinstance(lazy.curvature, da.Array)
    assert np.array_equal(lazy.labels.compute(), eager.labels)
    assert np.array_equal(lazy.curvature.compute(), eager.curvature)
    assert lazy.region_table() == eager.region_table()
    assert lazy.min_persistence == eager.min_persistence and lazy.n_regions == eager.n_regions


@pytest.mark.parametrize("rule", ["auto", "otsu", "value>=0.2", "nonzero"])
def test_segment_volume_of_a_dask_array_with_a_mask_equals_in_memory(small, rule):
    # An empty background as fuel's (most voxels exactly at the minimum): auto masks it.
    volume = np.round(np.clip(small - 0.02, 0, None) * 400).astype(np.uint8)
    assert (volume == 0).mean() > 0.5
    eager = segment_volume(volume, n_regions=24, mask=rule)   # more than the components
    lazy = segment_volume(da.from_array(volume, chunks=(11, 17, 9)), n_regions=24, mask=rule)
    assert eager.n_regions == 24
    assert lazy.mask.describe() == eager.mask.describe()
    assert eager.mask.used != "none"
    assert np.array_equal(lazy.mask.mask.compute(), eager.mask.mask)
    assert np.array_equal(lazy.labels.compute(), eager.labels)
    assert lazy.region_table() == eager.region_table()


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
    eager = segment_volume(volume, n_regions=7, smooth_sigma=1.2)
    lazy = segment_volume(da.from_array(volume, chunks=(9, 2, 13)), n_regions=7, smooth_sigma=1.2)
    assert np.array_equal(lazy.curvature.compute(), eager.curvature)
    assert np.array_equal(lazy.labels.compute(), eager.labels)
    assert lazy.smooth_sigma == eager.smooth_sigma == 1.2 and lazy.value_scale == eager.value_scale
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


def test_a_fresh_copy_reads_nothing_of_the_original():
    """`_halo.fresh_copy` of sliced, transposed, cast arrays (dask's `Task` objects,
    whose keys `dask.graph_manipulation.clone` left as they were): the same values,
    no key shared, every dependency inside the copy; their halos equal dask's."""
    from dask._task_spec import GraphNode

    from volseg._halo import fresh_copy, with_halo

    x = da.from_array(np.random.default_rng(3).random((2, 12, 10, 9)), chunks=(1, 5, 4, 5))
    for array in (x[1], x[0].transpose(2, 1, 0), (x[0] * 100).astype(np.int32),
                  x[:, 2:9].sum(axis=0)):
        copy = fresh_copy(array)
        graph, original = dict(copy.__dask_graph__()), dict(array.__dask_graph__())
        assert not set(graph) & set(original)
        for value in graph.values():
            if isinstance(value, GraphNode):
                assert value.dependencies <= set(graph)
        assert np.array_equal(copy.compute(scheduler="sync"), array.compute(scheduler="sync"))
        assert np.array_equal(with_halo(array, -1, fresh=True).compute(scheduler="sync"),
                              da.overlap.overlap(array, depth=1, boundary=-1).compute())


@pytest.mark.parametrize("chunks", [((7, 7, 9), (17,), (2, 2, 2, 3)), ((1, 22), (5, 5, 7), (9,))])
def test_halos_of_one_block_made_together_equal_dask_overlap(chunks):
    """`_halo.with_halos`: each block's halos of two arrays, in one task, are dask's
    overlap of each, kept or recomputed, in 3-D and 2-D."""
    from volseg._halo import with_halos

    x = da.from_array(np.random.default_rng(0).random((23, 17, 9)), chunks=chunks)
    for array in (x, x[:, :, 4]):
        cells = (array * 100).astype(np.int32)
        both = with_halos([array, cells], [-np.inf, -1], [False, True]).compute(scheduler="sync")
        theirs = [da.overlap.overlap(a, depth=1, boundary=v)
                  for a, v in ((array, -np.inf), (cells, -1))]
        assert both.shape == array.numblocks
        for index in np.ndindex(*array.numblocks):
            for ours, overlap in zip(both[index], theirs, strict=True):
                assert ours.dtype == overlap.dtype
                assert np.array_equal(ours, overlap.blocks[index].compute(scheduler="sync"))


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32, np.float64])
def test_mask_rules_of_a_dask_volume_equal_in_memory(dtype):
    from volseg.masks import foreground_mask

    rng = np.random.default_rng(5)
    noise = (rng.gamma(2.0, 30.0, (23, 31, 17)) - (50 if dtype == np.int16 else 0)).astype(dtype)
    # A plateau over rows :10 only (the blocks of rows 16.. do not hold the minimum:
    # the one-pass count must skip their minima), then over rows :20 (auto masks).
    for rows in (10, 20):
        volume = noise.copy()
        volume[:, :rows] = volume.min()
        lazy = da.from_array(volume, chunks=(7, 16, 5))
        for rule in ("auto", "otsu", "nonzero", "value>40", "value<=3", "none", volume > 60):
            eager = foreground_mask(volume, rule)
            got = foreground_mask(lazy, rule)
            assert got.describe() == eager.describe(), rule
            if eager.mask is None:
                assert got.mask is None
            else:
                assert isinstance(got.mask, da.Array)
                assert np.array_equal(got.mask.compute(), eager.mask)
                assert got.voxels == eager.voxels == int(eager.mask.sum()), rule
    assert foreground_mask(lazy, "auto").used == "nonzero"
    with pytest.raises(ValueError, match="selects no voxel"):
        foreground_mask(lazy, "value>1e9")
    with pytest.raises(ValueError, match="boolean array"):
        foreground_mask(lazy, da.ones((3, 3, 3), dtype=bool))


def test_the_stage_sequence_with_blockwise_storage_equals_in_memory(tmp_path, small):
    """`run_stages` with `BlockwiseStorage` (what `volseg segment` does for a lazy
    volume), called directly: every stage stored and read back, the same result as
    the in-memory storage, and the work folder holds every block of each stage."""
    from volseg.blockwise import BlockwiseStorage
    from volseg.outputs import output_names
    from volseg.segment import SegmentRequest, run_stages

    volume = np.round((small - small.min()) * 40).astype(np.uint8)       # 8-bit steps
    request = SegmentRequest.checked(n_regions=5, mask="auto", smooth_sigma=0.8)
    eager, eager_range = run_stages(volume, request)
    lazy = da.from_array(volume, chunks=(7, 6, 5))
    paths = {kind: tmp_path / name for kind, name in output_names(
        "v", blockwise=True, voxels=volume.size).items()}
    said = []
    storage = BlockwiseStorage(lazy, request, paths, folder=tmp_path, stem="v", checksum="x",
                               frame=None, say=said.append)
    result, value_range = run_stages(lazy, request, storage)
    assert value_range == eager_range and result.value_scale == eager.value_scale
    assert np.array_equal(np.asarray(result.labels), eager.labels)
    assert np.array_equal(np.asarray(result.curvature), eager.curvature)
    assert paths["labels"].exists() and paths["curvature"].exists()   # stored as it went
    for stage in ("smoothed", "curvature", "ascent", "cells", "forests"):
        assert storage.work.finished(stage) == lazy.npartitions, stage
    assert set(result.timings) == set(eager.timings) == {"curvature", "morse", "cut", "labels"}
    assert any("smoothing" in line for line in said)
    storage.finish()
    assert not storage.work.folder.exists()


@pytest.mark.parametrize("field", ["curvature", "gradient", "value"])
def test_the_stages_after_the_field_read_it_from_the_work_folder(tmp_path, small, field):
    """The field's blocks, kept in the work folder (the curvature's as its kernel
    computed them, another field's before it is written), are what the Morse stage,
    the cut and the writers read (uncompressed), not the output's zstd chunks: with
    the output removed right after it is written, the result is still the in-memory
    one."""
    import shutil

    from volseg.blockwise import BlockwiseStorage
    from volseg.outputs import output_names
    from volseg.segment import SegmentRequest, run_stages

    class Removing(BlockwiseStorage):
        def curvature(self, field):
            kept = super().curvature(field)
            shutil.rmtree(self.paths["curvature"])
            return kept

    volume = np.round((small - small.min()) * 40).astype(np.uint8)
    request = SegmentRequest.checked(n_regions=5, mask=None, smooth_sigma=0, field=field)
    eager, _ = run_stages(volume, request)
    lazy = da.from_array(volume, chunks=(7, 6, 5))
    paths = {kind: tmp_path / name for kind, name in output_names(
        "v", blockwise=True, voxels=volume.size).items()}
    storage = Removing(lazy, request, paths, folder=tmp_path, stem="v", checksum="x",
                       frame=None)
    result, _ = run_stages(lazy, request, storage)
    assert storage.work.finished("curvature") == lazy.npartitions
    assert np.array_equal(np.asarray(result.labels), eager.labels)
    assert np.array_equal(np.asarray(result.curvature), eager.curvature)
    storage.finish()
