import numpy as np
import pytest

from volseg import Volume, segment_mesh, segment_volume
from volseg.datasets import demo_volume


def test_segment_volume_defaults_to_30_regions_and_accepts_volume_or_array():
    data = demo_volume(32)
    result = segment_volume(data)
    assert result.n_regions == 30 and result.labels.shape == data.shape
    assert (result.measure, result.smooth_sigma, result.mask.used) == (
        "hypervolume", 1.0, "nonzero")   # the defaults for 8-bit data with a zero plateau
    again = segment_volume(Volume(data, spacing=(1.0, 1.0, 1.0)))
    np.testing.assert_array_equal(again.labels, result.labels)
    recut = result.hierarchy.segment(n_regions=10)
    assert recut.max() == 10          # with a mask: regions 1..k, 0 outside
    # Regions are 1..k (0 for voxels outside the mask); region 1 has the top maximum.
    assert result.labels.min() == 0 and result.labels.max() == 30
    assert ((result.labels == 0) == (data == 0)).all()
    assert result.labels[np.unravel_index(result.region_maxima()[0], data.shape)] == 1
    plain = segment_volume(data, mask=None, smooth_sigma=0, measure="persistence")
    assert plain.labels.min() == 1 and plain.labels.max() == 30


def test_blob_centres_are_curvature_maxima():
    # Three separated Gaussian blobs: with 4 regions (3 blobs + background) each blob
    # centre lies in its own region.
    axis = np.linspace(-1, 1, 33)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    centres = [(-0.5, -0.5, 0), (0.5, -0.4, 0.3), (0, 0.5, -0.4)]
    f = sum(np.exp(-((x - a) ** 2 + (y - b) ** 2 + (z - c) ** 2) / 0.04) for a, b, c in centres)
    labels = segment_volume(f, n_regions=4, measure="persistence", mask=None).labels
    index = [tuple(np.round((np.array(c) + 1) * 16).astype(int)) for c in centres]
    assert len({labels[i] for i in index}) == 3


def test_segment_errors():
    with pytest.raises(ValueError, match="not both"):
        segment_volume(np.zeros((4, 4, 4)), n_regions=2, min_persistence=1.0)
    with pytest.raises(ValueError, match="unknown `operator`"):
        segment_volume(np.zeros((4, 4, 4)), operator="nope")


@pytest.mark.parametrize("kwargs, message", [
    ({"spacing": (1.0, 2.0)}, "`spacing` must be three numbers"),
    ({"spacing": (1.0, -1.0, 1.0)}, "`spacing` must be three numbers"),
    ({"n_regions": 2.5}, "`n_regions` must be an integer"),
    ({"min_persistence": -0.1}, "`min_persistence` must be a non-negative number"),
])
def test_bad_arguments_name_themselves(kwargs, message):
    with pytest.raises(ValueError, match=message):
        segment_volume(np.random.default_rng(0).random((6, 6, 6)), **kwargs)
    with pytest.raises(ValueError, match="`volume` must be 3-D"):
        segment_volume(np.zeros((6, 6)))


# ---------------------------------------------------------------- masks and smoothing (issue 13)


def _two_blobs(n=24, background=0.0):
    axis = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    f = sum(np.exp(-((x - a) ** 2 + y**2 + z**2) / 0.03) for a in (-0.5, 0.5))
    return np.where(f > 0.05, np.round(200 * f), background)


def test_zero_background_and_two_blobs_give_exactly_two_foreground_regions():
    volume = _two_blobs()
    result = segment_volume(volume, mask="auto", min_persistence=0.05)
    assert result.mask.used == "nonzero"
    assert ((result.labels == 0) == (volume == 0)).all()
    assert sorted(np.unique(result.labels)) == [0, 1, 2]
    left, right = result.labels[6, 12, 12], result.labels[17, 12, 12]
    assert {left, right} == {1, 2}
    # Unmasked, the empty plateau is carved into the regions (index tie-breaking).
    assert segment_volume(volume, min_persistence=0.05, mask=None).labels.min() == 1


def test_each_mask_component_gets_a_region_and_counts_are_foreground_regions():
    volume = _two_blobs()
    # Whole numbers in floats are quantised data (smoothed by default): sigma 0 keeps
    # the blobs' own maxima for the count of 4.
    with pytest.warns(UserWarning, match="2 connected components"):
        result = segment_volume(volume, mask="nonzero", n_regions=1, smooth_sigma=0)
    assert result.n_regions == 2 and result.hierarchy.n_components == 2
    assert segment_volume(volume, mask="nonzero", n_regions=4, smooth_sigma=0).n_regions == 4


def test_smooth_zero_is_bit_identical_and_smoothing_removes_the_checkerboard():
    data = demo_volume(32)
    plain = segment_volume(data, smooth_sigma=0)
    np.testing.assert_array_equal(segment_volume(data, smooth_sigma=0.0).curvature,
                                  plain.curvature)
    smoothed = segment_volume(data, smooth_sigma=1.0)

    def total_variation(h):
        return sum(np.abs(np.diff(h, axis=a)).sum() for a in range(3)) / np.abs(h).sum()

    # 8-bit steps make the curvature flicker from voxel to voxel; sigma 1 calms it.
    assert total_variation(smoothed.curvature) < 0.5 * total_variation(plain.curvature)
    with pytest.raises(ValueError, match="`smooth_sigma` must be a non-negative number"):
        segment_volume(data, smooth_sigma=-1)


@pytest.mark.parametrize("dtype", [np.uint8, np.float64])
@pytest.mark.parametrize("field", ["curvature", "gradient", "value"])
def test_smoothing_in_place_leaves_the_callers_volume_and_equals_a_plain_run(dtype, field):
    """The curvature overwrites the stages' own smoothed copy (scaled, padded, then the
    result): never the caller's array, and the same numbers as the curvature of that
    smoothed volume computed on its own (a float64 input as well as an 8-bit one)."""
    from volseg._smoothing import gaussian
    from volseg.curvature import grid_curvature

    data = demo_volume(24).astype(dtype)
    before = data.copy()
    result = segment_volume(data, smooth_sigma=1.0, field=field, mask=None, n_regions=2)
    np.testing.assert_array_equal(data, before)
    if field == "curvature":
        expected = grid_curvature(gaussian(data, 1.0), value_scale=result.value_scale)
        np.testing.assert_array_equal(result.curvature, expected)
        assert result.curvature.flags.c_contiguous and result.curvature.dtype == np.float64


def test_regions_auto_takes_a_gap_only_where_it_stands_out():
    """`auto` on a power law's curve gives the default count, saying so with the
    evidence; a planted gap four times the law's step plus the significance is taken.
    The criterion is checked against its definition: each log gap over the step of a
    power law fitted (log-log) to the window."""
    from volseg.morse._hierarchy import gap_factor, widest_gap_count

    ranks = np.arange(1, 60, dtype=float)
    law = 100.0 * ranks ** -1.3                          # a power law: nothing stands out
    assert widest_gap_count(law, len(law), 1, (20, 40), 60, fallback=30) == 30
    assert widest_gap_count(law, len(law), 1, (20, 40), 60) == 20   # the widest: the edge
    planted = law.copy()
    planted[25:] *= np.exp(-1.3 * np.log(26 / 25) * (gap_factor(21) + 4))
    assert widest_gap_count(planted, len(planted), 1, (20, 40), 60, fallback=30) == 26
    result = segment_volume(demo_volume(32), n_regions="auto", measure="persistence",
                            mask=None, smooth_sigma=0)
    evidence = result.cut["auto_evidence"]
    p = np.sort(result.hierarchy.event_persistence)[::-1]
    counts = np.arange(20, 41)
    gaps = np.log(p[counts - 2]) - np.log(p[counts - 1])
    slope = -np.polyfit(np.log(np.arange(19, 41)), np.log(p[18:40]), 1)[0]
    ratio = gaps / (slope * np.log(counts / (counts - 1)))
    assert evidence["n_regions"] == counts[np.argmax(ratio)]
    assert evidence["ratio"] == pytest.approx(ratio.max())
    stands_out = evidence["ratio"] >= evidence["needed"]
    assert result.n_regions == (evidence["n_regions"] if stands_out else 30)


@pytest.mark.parametrize("rounds", [2.5, -1, True, "3"])
def test_mesh_smoothing_rounds_must_be_whole(rounds):
    from volseg.tessellation import sphere

    v, s = sphere(dim=2, radius=1.0, subdivisions=1)
    with pytest.raises(ValueError, match="`smooth_rounds` must be a whole number"):
        segment_mesh(v, s, smooth_rounds=rounds)


def _two_bump_sphere(n):
    from volseg.tessellation import isosurface

    axis = np.linspace(-1, 1, n)
    p = np.stack(np.meshgrid(axis, axis, axis, axis, indexing="ij"), -1)
    bump = sum(np.exp(-((p - c) ** 2).sum(-1) / (2 * 0.3**2))
               for c in ([0.6, 0, 0, 0], [-0.6, 0, 0, 0]))
    iso = isosurface(-(p**2).sum(-1) + 0.12 * bump, -0.36, spacing=2 / (n - 1),
                     origin=(-1, -1, -1, -1))
    return iso.vertices, iso.simplices


@pytest.mark.slow
@pytest.mark.parametrize("n", [25, 33])
def test_segment_mesh_defaults_split_two_low_bumps_of_a_raw_marching_3_sphere(n):
    # 25^4 and 33^4 samples (72 k, 173 k vertices): by persistence (even smoothed) one
    # region holds both bumps at 33^4 and the other is a speck, by hypervolume at 25^4
    # (98.8 %); the default measure (volume, the watershed hierarchy) splits them.
    vertices, simplices = _two_bump_sphere(n)
    tips = (np.argmax(vertices[:, 0]), np.argmin(vertices[:, 0]))
    result = segment_mesh(vertices, simplices, n_regions=2)
    assert result.measure == "volume" and result.smooth_rounds == 10
    labels = result.labels
    assert labels[tips[0]] != labels[tips[1]]
    assert (np.bincount(labels)[1:] / len(labels)).min() > 0.1
    if n == 33:                        # where the height alone keeps them together
        by_height = segment_mesh(vertices, simplices, n_regions=2,
                                 measure="persistence").labels
        assert by_height[tips[0]] == by_height[tips[1]]


def test_segment_mesh_sizes_are_vertex_volumes():
    from volseg.mesh import vertex_volumes

    vertices, simplices = _two_bump_sphere(13)
    result = segment_mesh(vertices, simplices, n_regions=4, measure="size")
    np.testing.assert_allclose(result.hierarchy.cell_measure("size").sum(),
                               vertex_volumes(vertices, simplices).sum())
    assert result.n_regions == 4 and result.threshold > 0


def test_noise_estimate_is_the_noise_and_the_same_for_dask():
    import dask.array as da

    from volseg._smoothing import noise_sigma

    rng = np.random.default_rng(2)
    axis = np.linspace(0, 4, 96)
    smooth = 50 * np.sin(axis)[:, None, None] * np.cos(axis)[None, :, None] + 10 * axis
    for sigma in (0.5, 3.0, 12.0):
        noisy = smooth + rng.normal(0, sigma, smooth.shape)
        assert abs(noise_sigma(noisy) / sigma - 1) < 0.05
    mask = rng.random(smooth.shape) > 0.2
    noisy = np.round(smooth + rng.normal(0, 4, smooth.shape)).astype(np.int16)
    assert noise_sigma(da.from_array(noisy, chunks=(17, 40, 23)),
                       da.from_array(mask, chunks=31)) == noise_sigma(noisy, mask)


def test_auto_smoothing_follows_the_type_and_the_noise():
    from volseg.segment import auto_smoothing

    rng = np.random.default_rng(0)
    clean = demo_volume(32)
    assert auto_smoothing(clean)[0] == 1.0                     # 8-bit steps only
    noisy = np.clip(clean + rng.normal(0, 12, clean.shape), 0, 255).astype(np.uint8)
    assert 1.5 < auto_smoothing(noisy)[0] <= 2.0                # grey-level noise of 12
    assert auto_smoothing(clean.astype(np.float32))[0] == 0.0   # floats: none
    assert auto_smoothing(clean.astype(np.int32))[0] == 0.0
    # A given sigma wins; the rule read the file's type, not the noise's.
    assert segment_volume(clean, smooth_sigma=0).smooth_rule == "given"
    result = segment_volume(clean)
    assert result.smooth_sigma == 1.0 and result.smooth_rule.startswith("auto: uint8")


@pytest.mark.parametrize("dtype, offset", [(np.int64, 2**62), (np.int64, -2**63 + 7),
                                           (np.uint64, 2**64 - 400)])
@pytest.mark.parametrize("lazy", [False, True])
def test_integers_beyond_2_to_53_segment_as_their_offsets(dtype, offset, lazy):
    """A 64-bit volume near 2^62 is the same field as the unshifted one (the curvature
    sees differences): in float64 its values were 1024 apart, labels differed and the
    curvature by 1.3. Now the labels and curvature equal the unshifted run's."""
    import dask.array as da

    rng = np.random.default_rng(4)
    volume = np.asarray(demo_volume(16).data, dtype=np.float64)[:, 1:, 2:]
    volume = volume + rng.normal(0, 2, volume.shape)
    volume = np.round(volume).clip(0, 250).astype(np.int64)
    shifted = volume.astype(dtype) + np.dtype(dtype).type(offset)
    expected = segment_volume(volume, n_regions=4)
    got = segment_volume(da.from_array(shifted, chunks=5) if lazy else shifted, n_regions=4)
    np.testing.assert_array_equal(np.asarray(got.labels), expected.labels)
    np.testing.assert_allclose(np.asarray(got.curvature), expected.curvature, atol=1e-12)


def test_recut_equals_a_fresh_segmentation_and_reuses_a_buffer():
    """`Segmentation.recut` is the cut `segment_volume` makes with the same count or
    threshold (labels, count, cut record, threshold), nothing recomputed; with `out`
    the labels are written into it; `region` agrees with the region table."""
    from volseg.datasets import demo_volume

    data = demo_volume(28)
    base = segment_volume(data, n_regions=9)
    buffer = base.labels.copy()
    for k in (2, 5, 9, 14):
        fresh = segment_volume(data, n_regions=k)
        cut = base.recut(k)
        assert np.array_equal(cut.labels, fresh.labels) and cut.n_regions == fresh.n_regions
        assert cut.cut == fresh.cut and cut.threshold == fresh.threshold
        into = base.recut(k, out=buffer)
        assert into.labels is buffer and np.array_equal(buffer, fresh.labels)
        by_threshold = base.recut(threshold=cut.threshold)
        assert np.array_equal(by_threshold.labels, fresh.labels)
        table = fresh.region_table()
        for label in (1, k):
            region = cut.region(label)
            assert region["size"] == table[label - 1]["size"]
            assert region["maximum"] == table[label - 1]["maximum"]
    assert base.region(1)["persistence"] == np.inf
    with pytest.raises(ValueError, match="region 1..9"):
        base.region(10)
    with pytest.raises(ValueError, match="`out`"):
        base.recut(3, out=np.zeros(5, np.int32))
    # A smaller integer type (a viewer's texture) holds the same labels, or is refused.
    small = np.zeros(data.shape, np.uint8)
    assert np.array_equal(base.recut(9, out=small).labels, base.recut(9).labels)
    with pytest.raises(ValueError, match="cannot hold label 300"):
        base.hierarchy.relabel(np.arange(300), out=np.zeros(base.labels.shape, np.uint8))


def test_a_nibabel_image_segments_as_the_command_line_segments_its_file(tmp_path, capsys):
    """`segment_volume(nib.load(f))` keeps the file's anisotropic voxels and scaling, and
    equals `volseg segment f`; the bare array (every voxel a unit cube) does not."""
    import json

    import nibabel as nib

    from volseg.cli import main

    data = np.asarray(demo_volume(24).data, dtype=np.int16)
    affine = np.diag([0.7, 0.7, 3.0, 1.0])
    image = nib.Nifti1Image(data, affine)
    image.header.set_xyzt_units("mm")
    image.header.set_slope_inter(0.5, 10.0)
    path = tmp_path / "aniso.nii.gz"
    nib.save(image, path)
    loaded = nib.load(path)
    result = segment_volume(loaded, n_regions=8)
    assert result.spacing == (pytest.approx(0.7), pytest.approx(0.7), pytest.approx(3.0))
    assert main(["segment", str(path), "-o", str(tmp_path / "o"), "-q", "--regions", "8"]) == 0
    written = np.asarray(nib.load(tmp_path / "o" / "aniso_labels.nii.gz").dataobj)
    np.testing.assert_array_equal(written, result.labels)
    bare = segment_volume(loaded.get_fdata(), n_regions=8)
    assert bare.spacing == (1.0, 1.0, 1.0) and (bare.labels != result.labels).any()
    capsys.readouterr()
    assert json.dumps(result.spacing)
