import numpy as np
import pytest
from numpy.testing import assert_allclose

from tests.conftest import smooth_random_field
from volseg import Volume, tessellation
from volseg.curvature import REGISTRY, default_value_scale, grid_curvature, vertex_curvature

ALL = list(REGISTRY)
INNER = (slice(1, -1),) * 3


@pytest.mark.parametrize("operator", ALL)
@pytest.mark.parametrize("spacing, scale", [((1, 1, 1), 1.0), ((0.7, 1.0, 1.3), 0.4)])
@pytest.mark.parametrize("rough", [False, True])
def test_grid_equals_explicit_mesh_at_interior_voxels(operator, spacing, scale, rough, rng):
    # Rough: white noise, so that many faces bend by more than 33 degrees (obtuse too)
    # and the kernels' angles take their reduced branch (`_atan`).
    f = (10 * rng.standard_normal((9, 10, 11)) if rough
         else 3 * smooth_random_field((9, 10, 11), rng, sigma=1.5))
    v, t = tessellation.kuhn_grid_mesh(f, spacing=spacing, value_scale=scale)
    mesh_h = vertex_curvature(v, t, operator).reshape(f.shape)[INNER]
    grid_h = grid_curvature(f, operator, spacing=spacing, value_scale=scale)[INNER]
    assert_allclose(grid_h, mesh_h, rtol=1e-10, atol=1e-10 * np.abs(mesh_h).max())


@pytest.mark.parametrize("operator", ALL)
@pytest.mark.parametrize("boundary", ["linear", "mirror"])
def test_every_voxel_is_finite(operator, boundary, rng):
    f = smooth_random_field((6, 7, 5), rng)
    assert np.isfinite(grid_curvature(f, operator, padding=boundary)).all()


@pytest.mark.parametrize("operator", ALL)
def test_linear_padding_keeps_a_plane_flat_up_to_the_boundary(operator):
    x, y, z = np.meshgrid(*[np.arange(6.0)] * 3, indexing="ij")
    h = grid_curvature(0.3 * x - 0.2 * y + 0.7 * z + 2, operator, value_scale=1.0)
    assert_allclose(h, 0, atol=1e-12)


def test_mirror_padding_treats_the_boundary_as_a_symmetry_plane():
    # A field symmetric about x = 0, cut there: mirror padding at x = 0 reproduces
    # the full field's values on the cut plane.
    x, y, z = np.meshgrid(np.arange(-6.0, 7), np.arange(7.0), np.arange(7.0), indexing="ij")
    f = np.exp(-0.05 * (x**2 + (y - 3) ** 2 + (z - 3) ** 2))
    full = grid_curvature(f, spacing=(1, 1, 1), value_scale=4.0, padding="mirror")
    half = grid_curvature(f[6:], spacing=(1, 1, 1), value_scale=4.0, padding="mirror")
    # Not identical: the Kuhn split is not mirror-symmetric. Close on the cut plane.
    assert_allclose(half[0, 1:-1, 1:-1], full[6, 1:-1, 1:-1], rtol=0.15, atol=0.01)


def test_peak_is_positive_h_matches_exact_value():
    x, y, z = np.meshgrid(*[np.linspace(-1, 1, 33)] * 3, indexing="ij")
    h = grid_curvature(-0.4 * (x**2 + y**2 + z**2), spacing=(1 / 16,) * 3, value_scale=1.0)
    assert_allclose(h[16, 16, 16], 0.8, rtol=1e-2)


def test_default_value_scale_makes_the_result_unit_free(rng):
    f = smooth_random_field((8, 8, 8), rng)
    assert_allclose(grid_curvature(1000 * f + 7), grid_curvature(f), rtol=1e-9, atol=1e-12)
    assert default_value_scale(np.zeros((3, 3, 3))) == 1.0
    assert_allclose(default_value_scale(np.array([[[0, 2]] * 2] * 2)), 0.5)


def test_volume_spacing_is_used(rng):
    f = smooth_random_field((6, 6, 6), rng)
    volume = Volume(f, spacing=(2.0, 1.0, 0.5))
    assert_allclose(grid_curvature(volume), grid_curvature(f, spacing=(2.0, 1.0, 0.5)))


def test_grid_errors():
    with pytest.raises(ValueError, match="must be 3-D"):
        grid_curvature(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="at least 2 samples"):
        grid_curvature(np.zeros((4, 4, 1)))
    with pytest.raises(ValueError, match="NaN or infinite values"):
        grid_curvature(np.full((3, 3, 3), np.inf))
    with pytest.raises(ValueError, match="`spacing` must be three numbers"):
        grid_curvature(np.zeros((3, 3, 3)), spacing=(1, 0, 1))
    with pytest.raises(ValueError, match="`value_scale` must be a positive"):
        grid_curvature(np.zeros((3, 3, 3)), value_scale=-1)
    with pytest.raises(ValueError, match="unknown `padding`"):
        grid_curvature(np.zeros((3, 3, 3)), padding="wrap")


def test_the_generated_stencil_is_what_the_tables_give():
    """`_grid_stencil.py` is generated from the cube tables; a stale file would silently
    compute another tessellation's curvature."""
    from pathlib import Path

    from volseg.curvature import _stencil_codegen

    committed = Path(_stencil_codegen.__file__).with_name("_grid_stencil.py").read_text()
    assert committed == _stencil_codegen.source(), \
        "run python -m volseg.curvature._stencil_codegen"


@pytest.mark.parametrize("layout", ["F", "strided", "float32"])
def test_memory_layout_does_not_change_the_result(layout, rng):
    """Raw files are read as Fortran-ordered views; the kernels need C order inside."""
    field = rng.random((9, 7, 8))
    expected = grid_curvature(field, "weighted")
    if layout == "F":
        other = np.asfortranarray(field)
    elif layout == "strided":
        other = np.repeat(field, 2, axis=1)[:, ::2]
    else:
        other, expected = field.astype(np.float32), grid_curvature(field.astype(np.float32))
    assert np.array_equal(grid_curvature(other, "weighted"), expected)


#: The padding rules as np.pad's arguments: the reference the slabs are held to.
NP_PAD = {"linear": {"mode": "reflect", "reflect_type": "odd"}, "mirror": {"mode": "reflect"}}


def _whole_volume_at_once(volume, operator, padding, scale, h):
    """The curvature as the in-memory path computed it before its slabs: the whole
    volume scaled, padded by np.pad and run through the kernel at once."""
    from volseg.curvature import get_operator
    from volseg.curvature._grid_kernels import grid_kernel
    from volseg.curvature._grid_tables import _kernel_tables

    entry, h = get_operator(operator), np.asarray(h, dtype=np.float64)
    fp = np.pad(volume.astype(np.float64) * scale, 1, **NP_PAD[padding])
    acc = np.zeros((entry.grid_channels,) + fp.shape)
    grid_kernel(fp, h, entry.grid_code, _kernel_tables(h), acc)
    return entry.grid_finish(acc, INNER, h)


@pytest.mark.parametrize("shape", [(6, 7, 5), (1, 4, 3), (2, 1, 5), (3, 2, 1), (7, 1, 1)])
@pytest.mark.parametrize("padding", ["linear", "mirror"])
def test_slabs_give_the_whole_volumes_curvature_bit_for_bit(shape, padding, rng, monkeypatch):
    """The in-memory curvature, slab by slab with halos, equals the whole volume's at
    once for every operator and slab thickness (1 voxel up), one-voxel axes, both
    paddings, anisotropic spacing, integer and float inputs; the result starts a
    buffer with room for it padded."""
    from volseg import _buffers
    from volseg._buffers import room_to_pad
    from volseg.curvature import checked_grid_curvature, get_operator

    h = (1.0, 0.7, 1.3)
    f = rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 3, shape)
    for volume in (f, (50 * rng.random(shape)).astype(np.uint8)):
        for operator in ALL:
            want = _whole_volume_at_once(volume, operator, padding, 0.37, h)
            for thick in range(1, shape[0] + 1):
                monkeypatch.setattr(_buffers, "MIN_SLAB", thick)
                got = checked_grid_curvature(volume, get_operator(operator), h, 0.37, padding)
                assert got.tobytes() == want.tobytes(), (operator, thick, volume.dtype)
                assert room_to_pad(got) is not None


@pytest.mark.parametrize("operator", ALL)
@pytest.mark.parametrize("padding", ["linear", "mirror"])
def test_an_owned_smoothed_buffer_gives_the_same_curvature(operator, padding, rng,
                                                          monkeypatch):
    """Curvature of the stages' smoothed copy, read slab by slab and overwritten by the
    result in its own buffer (`owned`), equals the one of a copy, bit for bit, for
    any slab thickness (each slab is read before the result reaches its rows); a view
    that is not a margin buffer's interior is copied as before."""
    from volseg import _buffers
    from volseg._smoothing import gaussian
    from volseg.curvature import checked_grid_curvature, get_operator

    volume = (255 * rng.random((13, 11, 9))).astype(np.uint8)
    entry, h = get_operator(operator), (0.7, 1.0, 1.3)
    expected = _whole_volume_at_once(gaussian(volume, 1.0), operator, padding, 0.3, h)
    for thick in (1, 2, 3, 5, 13):
        monkeypatch.setattr(_buffers, "MIN_SLAB", thick)
        owned = gaussian(volume, 1.0, margin=1)
        assert owned.base.shape == (15, 13, 11)
        result = checked_grid_curvature(owned, entry, h, 0.3, padding, owned=True)
        assert result.tobytes() == expected.tobytes(), thick
        assert result.flags.c_contiguous and np.shares_memory(result, owned.base)
    other = np.zeros((13, 11, 9, 2))[..., 0]                  # strided, no margin
    other[...] = gaussian(volume, 1.0)
    assert np.array_equal(checked_grid_curvature(other, entry, h, 0.3, padding, owned=True),
                          expected)


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint64, np.float16, np.float32])
def test_smoothing_reads_any_type_as_its_float64_copy_would(dtype, rng):
    """scipy's filter is given the volume as it is (no float64 copy beside the result):
    the numbers of the filter of its float64 copy, with or without a margin."""
    from scipy.ndimage import gaussian_filter

    from volseg._smoothing import gaussian

    volume = (200 * rng.random((12, 9, 14))).astype(dtype)
    expected = gaussian_filter(volume.astype(np.float64), 1.3, mode="nearest", truncate=4.0)
    for margin in (0, 1):
        assert np.array_equal(gaussian(volume, 1.3, margin=margin), expected)
