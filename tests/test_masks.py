"""volseg.masks: each rule on small exact volumes, the auto rule's plateau share, Otsu
against scikit-image, the refusals."""

import numpy as np
import pytest
from skimage.filters import threshold_otsu

from volseg.masks import AUTO_PLATEAU_SHARE, check_rule, foreground_mask


def test_mask_rules():
    volume = np.arange(64, dtype=float).reshape(4, 4, 4)
    assert foreground_mask(volume, "value>=60").voxels == 4
    assert foreground_mask(volume, "value < 3").voxels == 3
    assert foreground_mask(volume, "none").mask is None
    assert foreground_mask(volume, "auto").used == "none"  # no plateau
    assert foreground_mask(volume, "otsu").used.startswith("value>")
    with pytest.raises(ValueError, match="unknown `mask` rule 'bright'"):
        foreground_mask(volume, "bright")
    with pytest.raises(ValueError, match="selects no voxel"):
        foreground_mask(volume, "value>100")
    with pytest.raises(ValueError, match="boolean array of the volume's shape"):
        foreground_mask(volume, np.ones((4, 4), bool))


@pytest.mark.parametrize("plateau, used", [(32, "none"), (33, "nonzero")])
def test_auto_masks_the_minimum_plateau_only_above_half_the_volume(plateau, used):
    assert AUTO_PLATEAU_SHARE == 0.5
    volume = np.arange(1, 65, dtype=float).reshape(4, 4, 4)
    volume.ravel()[:plateau] = 0.0            # 32 of 64 voxels: exactly half
    choice = foreground_mask(volume, "auto")
    # Half is no plateau by the first rule; nor a low mode: the bright voxels fill the
    # border as much as the volume (no object inside a background).
    assert choice.used == used
    if used == "nonzero":
        assert choice.voxels == 64 - plateau
        assert np.array_equal(choice.mask, volume > 0)
    else:
        assert choice.mask is None and choice.voxels == 64


def test_nonzero_is_above_the_minimum_even_when_it_is_not_zero():
    volume = np.full((3, 3, 3), -2.0)
    volume[1, 1, 1] = 5.0
    choice = foreground_mask(volume, "nonzero")
    assert choice.voxels == 1 and choice.mask[1, 1, 1] and choice.describe()["used"] == "nonzero"


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_otsu_is_scikit_images_threshold(dtype):
    rng = np.random.default_rng(0)
    volume = np.concatenate([rng.normal(40, 5, 500), rng.normal(180, 10, 500)])
    volume = volume.clip(0, 255).astype(dtype).reshape(10, 10, 10)
    choice = foreground_mask(volume, "otsu")
    threshold = threshold_otsu(volume.ravel())
    assert np.array_equal(choice.mask, volume > threshold)
    assert choice.used == f"value>{float(threshold):g}"



@pytest.mark.parametrize("dtype, offset", [
    (np.int8, -128), (np.uint16, 65535 - 1000), (np.int32, -2**31),
    (np.int64, 2**62), (np.int64, -2**63), (np.int64, 2**63 - 1001),
    (np.uint64, 2**64 - 1001)])
@pytest.mark.parametrize("lazy", [False, True])
def test_integer_rules_do_not_move_with_the_values(dtype, offset, lazy):
    """Otsu and auto on a volume shifted to its type's ends give the unshifted masks:
    near 2^62 scikit-image asked for 2^62 bins, a uint64 near 2^64 raised IndexError,
    and float64 thresholds (2048 apart there) selected none or all of the voxels."""
    import dask.array as da

    volume, _ = _head_phantom()
    volume = volume.astype(np.int64)
    span = 100 if np.dtype(dtype).itemsize == 1 else 1000
    volume = np.clip(volume * span // max(int(volume.max()), 1), 0, span - 1)
    shifted = volume.astype(dtype) + np.dtype(dtype).type(offset)
    for rule in ("otsu", "auto"):
        expected = foreground_mask(volume, rule)
        got = foreground_mask(da.from_array(shifted, chunks=7) if lazy else shifted, rule)
        assert (got.mask is None) == (expected.mask is None), rule
        if expected.mask is not None:
            assert np.array_equal(np.asarray(got.mask), expected.mask), rule


def test_integers_spanning_more_than_a_million_values_get_256_bins():
    """Otsu on an int64 spanning 2^62 (one bin per value would be 2^62 bins) equals
    Otsu on its float64 copy, numpy and Dask alike."""
    import dask.array as da

    rng = np.random.default_rng(3)
    values = np.concatenate([rng.normal(0.2, 0.03, 600), rng.normal(0.8, 0.05, 400)])
    volume = np.round(values.clip(0, 1) * 2**62).astype(np.int64).reshape(10, 10, 10)
    expected = volume.astype(np.float64) > threshold_otsu(volume.astype(np.float64))
    for data in (volume, da.from_array(volume, chunks=4)):
        assert np.array_equal(np.asarray(foreground_mask(data, "otsu").mask), expected)

def test_rules_parse_without_data_and_a_boolean_array_is_taken_as_it_is():
    assert check_rule(" Value<=2.5 ") == ("value", ("<=", 2.5))
    assert check_rule("OTSU") == ("otsu", None)
    with pytest.raises(ValueError, match="unknown `mask` rule"):
        check_rule("value=3")
    mask = np.zeros((2, 3, 4), bool)
    mask[1, 2, 3] = True
    choice = foreground_mask(np.zeros((2, 3, 4)), mask)
    assert choice.mask is mask or np.array_equal(choice.mask, mask)
    assert choice.describe() == {"rule": "array", "used": "array", "voxels": 1}
    assert choice.phrase().endswith("mask of 1 voxels")


def _head_phantom(n=40, seed=0, noise=10.0):
    """An 8-bit 'head': a bright ellipsoid with a darker core on air, Rician noise over
    everything (the background a low mode, not a plateau)."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    r = np.sqrt((x / 0.8) ** 2 + (y / 0.65) ** 2 + (z / 0.7) ** 2)
    clean = np.where(r < 1, 160 + 40 * np.cos(6 * x) * np.sin(5 * y), 0.0)
    clean[r < 0.3] = 90
    noisy = np.hypot(clean + rng.normal(0, noise, clean.shape), rng.normal(0, noise, clean.shape))
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8), r < 1


def test_auto_finds_a_noisy_low_mode_background_and_leaves_a_full_volume_alone():
    from skimage.filters import threshold_triangle

    volume, inside = _head_phantom()
    choice = foreground_mask(volume, "auto")
    assert choice.used.startswith("low mode: value>")
    threshold = float(threshold_triangle(volume))            # scikit-image's, on the volume
    assert choice.used == f"low mode: value>{threshold:g}"
    assert np.array_equal(choice.mask, volume > threshold)
    assert (~choice.mask[~inside]).mean() > 0.99 and choice.mask[inside].mean() > 0.99
    # A field without background (a smooth simulation) keeps every voxel.
    axis = np.linspace(0, 3, 30)
    field = np.sin(axis)[:, None, None] * np.cos(axis)[None, :, None] + axis[None, None, :]
    assert foreground_mask(field, "auto").mask is None


def test_auto_masks_a_signed_maps_zeros_but_not_a_signed_field_without_them():
    rng = np.random.default_rng(1)
    stat = np.zeros((20, 20, 20), np.float32)
    stat[4:16, 4:12, 5:15] = rng.normal(0, 2, (12, 8, 10))   # 24 % of the voxels, signed
    choice = foreground_mask(stat, "auto")
    assert choice.used == "value!=0" and np.array_equal(choice.mask, stat != 0)
    assert foreground_mask(rng.normal(size=(12, 12, 12)), "auto").mask is None


def test_segment_volume_defaults_on_a_noisy_head_label_the_air_0():
    from volseg import segment_volume

    volume, inside = _head_phantom(48, seed=2)
    result = segment_volume(volume)
    # Rician noise of 10 grey levels: the noise-aware default smooths at the most.
    assert (result.measure, result.smooth_sigma) == ("hypervolume", 2.0)
    assert result.smooth_rule.startswith("auto: uint8 values, noise 1")
    labelled = result.labels > 0
    assert (~labelled[~inside]).mean() >= 0.9 and (~labelled[inside]).mean() <= 0.05
    sizes = np.bincount(result.labels[labelled])[1:] / labelled.sum()
    assert sizes.max() <= 0.5 and (sizes >= 0.01).sum() >= 10


def _ct(kind, seed=0):
    """int16 Hounsfield phantoms: a head in mostly air, or a body filling the view
    with some air around it (its soft-tissue peak then tops the histogram)."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(-1, 1, 48)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    if kind == "head":
        body = np.sqrt(x**2 + y**2 + z**2) < 0.6
    else:
        body = np.sqrt(x**2 + y**2) < 0.95
    ct = np.where(body, 40.0, -1000.0)
    ct[body & (np.sqrt(x**2 + y**2) < 0.25)] = 700.0          # bone
    return np.round(ct + rng.normal(0, 20, ct.shape)).astype(np.int16), body


def test_low_mode_masks_air_around_a_head_but_never_a_bodys_soft_tissue():
    head, inside = _ct("head")
    choice = foreground_mask(head, "auto")
    assert choice.used.startswith("low mode") and (choice.mask != inside).mean() < 0.001
    # The body's soft tissue tops the histogram, with the air a mode below it: no low
    # mode (a mask there would keep the bone only).
    body, _ = _ct("body")
    assert foreground_mask(body, "auto").mask is None


def test_low_mode_ignores_a_saturated_top_bin_and_the_shared_tooth_loses_its_air(volvis_dir):
    volume, inside = _head_phantom(40, seed=3, noise=10.0)
    saturated = volume.copy()
    saturated[inside & (np.random.default_rng(0).random(volume.shape) < 0.1)] = 255
    choice = foreground_mask(saturated, "auto")
    assert choice.used.startswith("low mode") and choice.mask[inside].mean() > 0.99
    from volseg.files import load_volume

    tooth = load_volume(str(volvis_dir / "tooth_103x94x161_uint8.raw")).data
    choice = foreground_mask(tooth, "auto")       # its air is noise about 77 of 255
    assert choice.used == "low mode: value>89" and 0.25 < choice.voxels / tooth.size < 0.32


def chest_ct(shape=(120, 120, 24), seed=0):
    """An axial chest CT slab as acquired (int16 HU): air at -1000 around the body,
    fat, soft tissue, lungs, heart, spine and the table; the body runs through the
    first and last slices, so it touches the volume's border there."""
    rng = np.random.default_rng(seed)
    x, y, z = np.meshgrid(*[np.linspace(-1, 1, n) for n in shape], indexing="ij")
    hu = np.full(shape, -1000.0)
    ring = (x / 0.85) ** 2 + (y / 0.6) ** 2
    hu[ring <= 1] = -90
    hu[ring <= 0.8] = 40
    for side in (-1, 1):
        hu[((x - side * 0.38) / 0.3) ** 2 + ((y + 0.05) / 0.38) ** 2 + (z / 2.5) ** 2 <= 1] = -850
    hu[((x + 0.05) / 0.22) ** 2 + ((y + 0.1) / 0.2) ** 2 <= 1] = 45
    hu[(x / 0.08) ** 2 + ((y - 0.45) / 0.08) ** 2 <= 1] = 700
    table = (y > 0.7) & (y < 0.8) & (np.abs(x) < 0.98)
    hu[table] = 200
    hu += rng.normal(0, 15, shape)
    return np.clip(np.round(hu), -1024, 3071).astype(np.int16), (ring <= 1) | table


def test_auto_finds_the_air_around_an_axial_ct_slab():
    """The end slices are body cross-sections: the border test reads the faces of two
    of the three axes. The segmentation's default then labels the air 0 and keeps a
    spread of regions (issue 55's chest CT)."""
    import warnings

    from volseg import segment_volume

    volume, inside = chest_ct()
    choice = foreground_mask(volume, "auto")
    assert choice.used.startswith("low mode: value>")
    air = (volume < -900) & ~inside
    assert (~choice.mask[air]).mean() > 0.99 and choice.mask[inside].mean() > 0.98
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seg = segment_volume(volume, n_regions=30)
    assert (seg.labels[air] == 0).mean() >= 0.9
    sizes = np.bincount(seg.labels[seg.labels > 0])[1:]
    assert (sizes >= 0.01 * sizes.sum()).sum() >= 10
    # Bright values on the faces of every axis: a field, no background found.
    noise = np.random.default_rng(0).normal(0, 1, (30, 30, 30))
    assert foreground_mask(noise, "auto").mask is None


def test_the_cli_says_when_the_mask_leaves_out_non_zero_voxels(tmp_path, capsys):
    from volseg.cli import main

    volume, _ = chest_ct((40, 40, 8))
    np.save(tmp_path / "chest.npy", volume)
    assert main(["segment", str(tmp_path / "chest.npy"), "-o", str(tmp_path / "o"),
                 "--regions", "5", "--no-vti"]) == 0
    err = capsys.readouterr().err
    assert "leaves out" in err and "of the non-zero voxels" in err
    fuel = np.zeros((20, 20, 20), np.uint8)               # a zero background: no line
    fuel[5:15, 5:15, 5:15] = np.random.default_rng(1).integers(1, 255, (10, 10, 10))
    np.save(tmp_path / "fuel.npy", fuel)
    assert main(["segment", str(tmp_path / "fuel.npy"), "-o", str(tmp_path / "f"),
                 "--regions", "5", "--no-vti"]) == 0
    assert "leaves out" not in capsys.readouterr().err
