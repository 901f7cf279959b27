"""A volume is its values up to an exact affine map: the same scan saved as uint8, as
uint16 x 257, as float32 / 255, as int16 - 128 or as float64 x 1e-6 + 7 gets the same
mask, the same smoothing and the same labels (docs/design.md section 13)."""

import numpy as np
import pytest

from volseg import read_volume, segment_volume
from volseg._lattice import lattice_of, on_lattice


def _copies(values):
    return {"x257 uint16": values.astype(np.uint16) * 257,
            "/255 float32": (values / np.float32(255)).astype(np.float32),
            "-128 int16": values.astype(np.int16) - 128,
            "x1e-6+7 float64": values * 1e-6 + 7}


@pytest.mark.parametrize("name", ["nucleon_41x41x41_uint8.raw", "silicium_98x34x34_uint8.raw"])
@pytest.mark.parametrize("smooth", [None, 0])
def test_exactly_scaled_and_offset_copies_get_the_same_labels(volvis_dir, name, smooth):
    values = np.asarray(read_volume(volvis_dir / name).data)
    expected = segment_volume(values, smooth_sigma=smooth)
    for copy, data in _copies(values).items():
        result = segment_volume(data, smooth_sigma=smooth)
        assert result.smooth_sigma == expected.smooth_sigma, copy
        assert result.mask.voxels == expected.mask.voxels, copy
        differ = int((result.labels != expected.labels).sum())
        assert differ == 0, f"{copy}: {differ} voxels differ"


def test_the_lattice_is_found_exactly_or_not_at_all(rng):
    k = rng.integers(0, 200, (20, 9, 7))
    lattice = lattice_of(k * 0.25 - 3.0, (k.min() * 0.25 - 3.0, k.max() * 0.25 - 3.0))
    assert lattice.step == 0.25 and lattice.levels == k.max() - k.min() + 1
    assert np.array_equal(on_lattice(k * 0.25 - 3.0, lattice), k - k.min())
    continuous = rng.random((20, 9, 7))                          # a simulation's floats
    assert lattice_of(continuous, (continuous.min(), continuous.max())) is None
    one_off = (k * 0.25).astype(np.float64)
    one_off[3, 4, 5] += 0.1                                     # one voxel off the lattice
    assert lattice_of(one_off, (one_off.min(), one_off.max())) is None


def test_a_dask_volume_finds_the_same_lattice(rng):
    import dask.array as da

    k = rng.integers(0, 300, (30, 20, 10)).astype(np.float32) / 255
    span = (float(k.min()), float(k.max()))
    lazy = lattice_of(da.from_array(k, chunks=(7, 9, 4)), span)
    assert lazy == lattice_of(k, span) and lazy is not None
