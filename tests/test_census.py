"""volseg._census: one read of a volume gives what the separate passes gave (range,
plateaus, lattice sample, value counts), for numpy and for Dask arrays in awkward
blocks; the mask rules and the lattice give the same answers from it."""

import dask
import dask.array as da
import numpy as np
import pytest

import volseg._census as _census
import volseg._lattice as _lattice
from volseg._census import census
from volseg._lattice import lattice_of
from volseg.masks import foreground_mask

#: Blocks of unequal sizes, none a multiple of the sample's stride.
CHUNKS = ((9, 14, 14), (7, 7, 9), (13, 13, 13, 11))


def _volumes():
    rng = np.random.default_rng(11)
    shape = (37, 23, 50)
    plateau = rng.integers(0, 255, shape).astype(np.uint8)
    plateau[:, :, :30] = 0
    signed = rng.integers(-300, 900, shape).astype(np.int16)
    signed[rng.random(shape) < 0.6] = 0
    wide = rng.integers(-2**40, 2**40, shape).astype(np.int64)         # counts: none
    floats = rng.normal(size=shape).astype(np.float32)
    floats[rng.random(shape) < 0.3] = 0
    scaled = (rng.integers(0, 40, shape) * 257).astype(np.uint16)        # a lattice
    return {"plateau": plateau, "signed": signed, "wide": wide, "floats": floats,
            "scaled": scaled}


@pytest.fixture(autouse=True)
def small_sample(monkeypatch):
    """A sample stride of 5 on these volumes (the default samples 2^21 voxels)."""
    monkeypatch.setattr(_lattice, "SAMPLE_VOXELS", 400)


@pytest.mark.parametrize("name", list(_volumes()))
@pytest.mark.parametrize("lazy", [False, True])
def test_census_equals_the_separate_passes(name, lazy):
    volume = _volumes()[name]
    read = census(da.from_array(volume, chunks=CHUNKS) if lazy else volume)
    low, high = volume.min().item(), volume.max().item()
    assert (read.low, read.high) == (low, high)
    assert type(read.low) is type(low)
    assert read.at_low == np.count_nonzero(volume == low)
    if lazy or read.counts is not None:
        assert read.at_zero == np.count_nonzero(volume == 0)
    else:                       # in memory, counted only if a mask rule asks
        assert read.at_zero is None
    stride = _lattice.sample_stride(volume.shape)
    assert stride == 5
    np.testing.assert_array_equal(read.sample, volume[::stride, ::stride, ::stride])
    assert read.sample.dtype == volume.dtype
    if name in ("wide", "floats"):
        assert read.counts is None and read.present() is None
    else:
        expected = np.bincount((volume.astype(np.int64) - low).ravel())
        np.testing.assert_array_equal(read.counts, expected)
        np.testing.assert_array_equal(read.present(), np.unique(volume))


def test_census_of_nan_has_a_nan_range_as_numpy():
    volume = np.zeros((6, 7, 8))
    volume[5, 6, 7] = np.nan
    for data in (volume, da.from_array(volume, chunks=3)):
        read = census(data)
        assert np.isnan(read.low) and np.isnan(read.high)


def test_census_reads_each_block_once():
    volume = _volumes()["plateau"]
    reads = []

    def read_block(block):
        if block.size:                  # not Dask's probe of the output type
            reads.append(block.shape)
        return block

    lazy = da.from_array(volume, chunks=CHUNKS).map_blocks(read_block, dtype=volume.dtype)
    with dask.config.set(scheduler="synchronous"):
        census(lazy)
    assert len(reads) == np.prod([len(c) for c in CHUNKS])


@pytest.mark.parametrize("name", list(_volumes()))
def test_lattice_from_the_census_equals_the_pass(name):
    volume = _volumes()[name]
    read = census(volume)
    expected = lattice_of(volume, read.value_range)
    assert lattice_of(volume, read.value_range, sample=read.sample,
                      present=read.present()) == expected
    if name == "scaled":
        low, high = read.value_range
        assert expected == _lattice.Lattice(float(low), 257.0, (high - low) // 257 + 1)


def test_lattice_off_by_one_value_found_from_the_census():
    """A uint16 lattice of step 257 with one voxel off it, outside the sample: the
    census's distinct values find it with no pass over the voxels, as the pass does."""
    volume = _volumes()["scaled"].copy()
    volume[1, 1, 1] += 1
    read = census(volume)
    assert lattice_of(volume, read.value_range) is None

    def unread(block):
        raise AssertionError("a block was read")

    lazy = da.from_array(volume, chunks=CHUNKS).map_blocks(unread, dtype=volume.dtype)
    assert lattice_of(lazy, read.value_range, sample=read.sample,
                      present=read.present()) is None
    volume[1, 1, 1] -= 1
    read = census(volume)
    assert lattice_of(lazy, read.value_range, sample=read.sample,
                      present=read.present()).step == 257.0


@pytest.mark.parametrize("name", list(_volumes()))
@pytest.mark.parametrize("rule", ["auto", "nonzero", "otsu"])
@pytest.mark.parametrize("lazy", [False, True])
def test_masks_from_the_census_equal_the_passes(name, rule, lazy):
    volume = _volumes()[name]
    data = da.from_array(volume, chunks=CHUNKS) if lazy else volume
    read = census(data)
    plain = foreground_mask(data, rule, value_range=read.value_range)
    given = foreground_mask(data, rule, census=read)
    assert (given.rule, given.used, given.voxels) == (plain.rule, plain.used, plain.voxels)
    if plain.mask is None:
        assert given.mask is None
    else:
        np.testing.assert_array_equal(np.asarray(given.mask), np.asarray(plain.mask))


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.int64])
def test_value_counts_in_slabs_count_every_value(dtype, monkeypatch):
    """The integer histogram is counted a slab of voxels at a time (its 8-byte offsets
    were 24 bytes a voxel at once): the same counts as one bincount, any slab size."""
    rng = np.random.default_rng(5)
    volume = rng.integers(-40 if dtype != np.uint8 else 0, 200, (17, 13, 11)).astype(dtype)
    lo = int(volume.min())
    width = int(volume.max()) - lo + 1
    expected = np.bincount((volume.astype(np.int64) - lo).ravel(), minlength=width)
    for slab in (7, 1000, 2**20):
        monkeypatch.setattr(_census, "COUNT_SLAB", slab)
        np.testing.assert_array_equal(_census.value_counts(volume, lo, width), expected)
        np.testing.assert_array_equal(_census.value_counts(volume[:, ::2], lo, width),
                                      np.bincount((volume[:, ::2].astype(np.int64) - lo)
                                                  .ravel(), minlength=width))
