"""The field the complex is built on (docs/design.md section 13): curvature, gradient,
value or the user's own, through one machinery: blockwise equal to in memory for every
field and measure, the gradient exact at block faces and at the border."""

import json

import dask.array as da
import numpy as np
import pytest

from volseg import segment_volume
from volseg.cli import main
from volseg.fields import FIELDS, get_field, gradient_magnitude

from .conftest import smooth_random_field


def _phantom(rng, shape=(23, 19, 17)):
    """Touching flat-topped spheres on a graded, noisy background, as 8-bit."""
    x, y, z = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    volume = 40 + 2.0 * x
    for centre, radius, level in (((7, 9, 8), 6, 140), ((15, 9, 8), 5, 200), ((11, 3, 12), 4, 90)):
        inside = sum((c - a) ** 2 for c, a in zip((x, y, z), centre, strict=True)) <= radius**2
        volume = np.where(inside, level, volume)
    return np.clip(np.round(volume + rng.normal(0, 4, shape)), 0, 255).astype(np.uint8)


def test_the_gradient_is_numpys_and_the_same_block_by_block(rng):
    values = smooth_random_field((13, 11, 9), rng)
    spacing = (0.5, 1.0, 2.0)
    expected = np.sqrt(sum(g**2 for g in np.gradient(values, *spacing)))
    np.testing.assert_array_equal(gradient_magnitude(values, spacing), expected)
    lazy = gradient_magnitude(da.from_array(values, chunks=(5, 4, 3)), spacing)
    np.testing.assert_array_equal(lazy.compute(), expected)      # bit for bit
    ramp = np.broadcast_to(3.0 * np.arange(6.0)[:, None, None], (6, 5, 4))
    np.testing.assert_allclose(gradient_magnitude(ramp, (1.5, 1, 1)), 2.0)  # border too


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("measure", ["persistence", "size", "hypervolume"])
def test_dask_in_uneven_chunks_equals_numpy_for_every_field_and_measure(rng, field, measure):
    volume = _phantom(rng)
    options = {"field": field, "measure": measure, "n_regions": 6, "mask": "otsu",
               "smooth_sigma": 0.7}
    expected = segment_volume(volume, **options)
    lazy = segment_volume(da.from_array(volume, chunks=(7, 6, 5)), **options)
    assert expected.field == lazy.field == field
    np.testing.assert_array_equal(np.asarray(lazy.labels), expected.labels)
    np.testing.assert_allclose(np.asarray(lazy.curvature), expected.curvature, rtol=0,
                               atol=1e-12)


def test_the_gradient_follows_edges_the_curvature_does_not(rng):
    """On small touching flat-topped spheres on a larger graded background, the
    gradient's basins find the spheres: its adjusted Rand index against the truth beats
    the curvature's. Cut by hypervolume (the sum of each basin's own pond): by volume,
    the field's default, the background's wide shallow basins outweigh small objects
    (0.27 here; docs/guide/useful-regions.md)."""
    from volseg.metrics import adjusted_rand_index

    volume = _phantom(rng, (30, 22, 20))
    x, y, z = np.meshgrid(*[np.arange(n) for n in volume.shape], indexing="ij")
    truth = np.zeros(volume.shape, int)
    for label, (centre, radius) in enumerate((((7, 9, 8), 6), ((15, 9, 8), 5),
                                              ((11, 3, 12), 4)), 1):
        inside = sum((c - a) ** 2 for c, a in zip((x, y, z), centre, strict=True)) <= radius**2
        truth[inside] = label
    score = {field: adjusted_rand_index(truth, segment_volume(
        volume, field=field, mask=None, n_regions=4, measure="hypervolume").labels)
             for field in ("curvature", "gradient")}
    assert score["gradient"] > 0.8 and score["gradient"] > score["curvature"] + 0.2, score


def test_a_given_field_is_cut_as_it_is(rng):
    volume = _phantom(rng)
    own = -np.asarray(gradient_magnitude(volume.astype(float), (1, 1, 1)))
    result = segment_volume(volume, field=own, n_regions=5, mask=None, smooth_sigma=0)
    assert result.field == "given" and result.n_regions == 5
    np.testing.assert_array_equal(result.curvature, own)
    with pytest.raises(ValueError, match="`field` must have the volume's shape"):
        segment_volume(volume, field=own[1:])
    with pytest.raises(ValueError, match="unknown `field` 'edgy'"):
        segment_volume(volume, field="edgy")


def test_the_cli_writes_the_field_it_used_and_says_so(tmp_path, capsys, rng):
    source = tmp_path / "p.npy"
    np.save(source, _phantom(rng))
    assert main(["segment", str(source), "-o", str(tmp_path / "o"), "-q", "--json",
                 "--field", "gradient", "--regions", "4", "--mask", "none"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["field"] == "gradient" and summary["n_regions"] == 4
    assert (tmp_path / "o" / "p_gradient.nii.gz").exists()
    assert not (tmp_path / "o" / "p_curvature.nii.gz").exists()
    # The ParaView image's array and the OME-Zarr image are named for the field.
    import zarr
    from vtkmodules.vtkIOXML import vtkXMLImageDataReader

    reader = vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "o" / "p_volumes.vti"))
    reader.Update()
    data = reader.GetOutput().GetPointData()
    names = {data.GetArray(i).GetName() for i in range(data.GetNumberOfArrays())}
    assert names == {"labels", "gradient", "values"}
    from volseg.io.zarr_store import multiscales_of

    attrs = zarr.open_group(str(tmp_path / "o" / "p_segmentation.ome.zarr"), mode="r").attrs
    assert multiscales_of(attrs.asdict())[0]["name"] == "gradient"
    assert main(["segment", str(source), "-o", str(tmp_path / "b"), "-q", "--json",
                 "--field", "gradient", "--regions", "4", "--mask", "none", "--chunks", "8"]) == 0
    blockwise = json.loads(capsys.readouterr().out)
    assert [r["size"] for r in blockwise["regions"]] == [r["size"] for r in summary["regions"]]
    assert main(["segment", str(source), "-o", str(tmp_path / "x"), "--field", "edgy"]) == 2
    assert "edgy" in capsys.readouterr().err


def test_every_field_is_a_registry_entry():
    for name in FIELDS:
        entry = get_field(name)
        assert entry.name == name and entry.sign in (1.0, -1.0) and entry.halo in (0, 1)


@pytest.mark.parametrize("shape", [(7, 5, 4), (2, 3, 4), (1, 4, 3), (6, 1, 1)])
def test_the_in_memory_gradient_in_slabs_is_the_whole_volumes(shape, rng, monkeypatch):
    """The numpy gradient, slab by slab with halos, equals `_gradient_block` of the whole
    volume at once, bit for bit, for every slab thickness (1 voxel up), with and without
    a mask, normalised per slab or not (as a Dask array's blocks are); the result has
    room for the Morse padding."""
    from volseg import _buffers, fields
    from volseg._buffers import room_to_pad

    spacing = (0.7, 1.0, 1.3)
    values = (rng.random(shape) * 300).astype(np.float32)
    span = (float(values.min()) - 2.5, float(values.max()))
    for mask in (None, rng.random(shape) > 0.3):
        whole = fields._gradient_block(values.astype(np.float64), mask, spacing=spacing)
        low, high = span
        normal = fields._gradient_block((values.astype(np.float64) - low) / (high - low),
                                        mask, spacing=spacing)
        lazy = gradient_magnitude(da.from_array(values, chunks=(3, 2, 2)), spacing,
                                  mask, span)
        assert np.asarray(lazy).tobytes() == normal.tobytes()
        for thick in range(1, shape[0] + 1):
            monkeypatch.setattr(_buffers, "MIN_SLAB", thick)
            got = gradient_magnitude(values, spacing, mask)
            assert got.tobytes() == whole.tobytes(), thick
            assert room_to_pad(got) is not None
            got = gradient_magnitude(values, spacing, mask, span)
            assert got.tobytes() == normal.tobytes(), thick


def test_the_value_field_and_the_negated_gradient_have_room_to_pad(rng):
    """The value field (|f| on a signed map) is `normalised`'s numbers in a buffer with
    room for the Morse padding, and so is the gradient's negation: the Morse build pads
    them in place; an int8 -128 is 128 in |f| (not numpy's int8 overflow)."""
    from volseg import fields
    from volseg._buffers import room_to_pad

    entry = get_field("value")
    for values, span in ((rng.random((5, 4, 3)) * 7 - 2, (-2.0, 5.0)),
                         (rng.random((5, 4, 3)).astype(np.float32) + 1, (1.0, 2.0)),
                         (rng.integers(0, 9, (5, 4, 3)).astype(np.uint16), (0, 8))):
        low, high = span
        signed = low < 0 < high
        v = np.abs(values.astype(np.float64)) if signed else values.astype(np.float64)
        lo, hi = (0.0, max(-low, high)) if signed else span
        want = (v - lo) / (hi - lo)
        assert fields.normalised(v, (lo, hi)).tobytes() == want.tobytes()
        got = entry.make(values, span, None, None, None)
        assert got.tobytes() == want.tobytes() and room_to_pad(got) is not None
    ints = np.array([-128, -1, 0, 127], np.int8).reshape(4, 1, 1)
    np.testing.assert_array_equal(entry.make(ints, (-128, 127), None, None, None).ravel(),
                                  [1.0, 1 / 128, 0.0, 127 / 128])
    gradient = get_field("gradient")
    field = gradient_magnitude(rng.random((5, 4, 3)), (1, 1, 1))
    negated = fields.for_morse(gradient, field)
    assert negated.tobytes() == (-field).tobytes() and room_to_pad(negated) is not None
    assert fields.for_morse(get_field("curvature"), field) is field


@pytest.mark.parametrize("field", ["gradient", "value"])
def test_the_pipelines_gradient_and_value_are_built_in_their_own_buffers(field, rng,
                                                                          monkeypatch):
    """`segment_volume` by the gradient or the value builds the complex in the field's
    own buffer (no padded copy): the copy's path is never taken, and the labels are
    those of the Morse stage on a copy of the field."""
    from volseg.morse import _build, descending_complex

    volume = _phantom(rng)
    want = segment_volume(volume, field=field, n_regions=2, mask="otsu")
    with monkeypatch.context() as patched:
        patched.setattr(_build, "_neighbourhood", None)
        got = segment_volume(volume, field=field, n_regions=2, mask="otsu")
    np.testing.assert_array_equal(got.labels, want.labels)
    sign = get_field(field).sign
    copied = descending_complex(sign * want.curvature.copy(), mask=want.mask.mask)
    np.testing.assert_array_equal(copied.persistence, got.hierarchy.persistence)


def test_the_pipelines_gradient_comes_back_bit_for_bit_after_its_negation(rng):
    """The pipeline lets the gradient go while the Morse stage reads its negation, and
    gives it back as the negation's negation: the gradient magnitude exactly, zeros
    +0.0 (no sign bit), and the hierarchy's field is its negation."""
    from volseg.fields import normalised

    volume = _phantom(rng)
    volume[:4] = 90                                       # flat: zero gradient
    result = segment_volume(volume, field="gradient", mask=None, smooth_sigma=0,
                            n_regions=3, spacing=(0.5, 1.0, 2.0))
    span = (float(volume.min()), float(volume.max()))
    want = gradient_magnitude(normalised(volume, span), (0.5, 1.0, 2.0))
    assert (want == 0).any()
    assert result.curvature.tobytes() == want.tobytes()
    assert not np.signbit(result.curvature).any()
    assert result.hierarchy._field.tobytes() == (-want).tobytes()


@pytest.mark.parametrize("field", ["gradient", "curvature"])
def test_stages_without_the_hierarchy_give_the_same_field_and_labels(field, rng):
    """`run_stages(keep_hierarchy=False)` (the files' run in memory) returns no
    hierarchy, and the same field bit for bit (the gradient negated back in the Morse
    stage's own buffer, +0.0 for its zeros) and the same labels as with it."""
    from volseg.segment import SegmentRequest, run_stages

    volume = _phantom(rng)
    volume[:4] = 90                                       # flat: zero gradient
    request = SegmentRequest.checked(field=field, mask=None, n_regions=3, dtype=volume.dtype)
    kept, _ = run_stages(volume.copy(), request)
    alone, _ = run_stages(volume.copy(), request, keep_hierarchy=False)
    assert kept.hierarchy is not None and alone.hierarchy is None
    assert alone.curvature.tobytes() == kept.curvature.tobytes()
    assert not np.signbit(alone.curvature).any() or field == "curvature"
    np.testing.assert_array_equal(alone.labels, kept.labels)
