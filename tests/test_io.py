import gzip

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from volseg import io
from volseg.io import read_volume, write_volume


def xyz_volume(shape=(5, 4, 3), dtype=np.uint16):
    return (np.arange(np.prod(shape)).reshape(shape) * 7 % 251).astype(dtype)


def raw_bytes(data, order="<"):
    return np.ascontiguousarray(data.transpose(2, 1, 0)).astype(data.dtype.newbyteorder(order)).tobytes()


@pytest.mark.parametrize("dtype", ["uint8", "uint16", "int16", "float32", "float64"])
def test_raw_from_name_is_x_fastest(tmp_path, dtype):
    data = xyz_volume(dtype=dtype)
    path = tmp_path / f"thing_5x4x3_{dtype}.raw"
    path.write_bytes(raw_bytes(data))
    volume = read_volume(path)
    assert volume.shape == (5, 4, 3) and volume.name == "thing"
    assert_array_equal(np.asarray(volume), data)
    # The byte offset of voxel (x, y, z) is x + X (y + Y z).
    flat = np.frombuffer(path.read_bytes(), dtype=dtype)
    assert volume.data[3, 2, 1] == flat[3 + 5 * (2 + 4 * 1)]


def test_raw_big_endian_and_explicit_shape(tmp_path):
    data = xyz_volume()
    path = tmp_path / "scan.bin"
    path.write_bytes(raw_bytes(data, ">"))
    volume = read_volume(path, shape=(5, 4, 3), dtype="uint16", byte_order="big")
    assert_array_equal(volume.data, data)


def test_dat_text_header_and_binary_header(tmp_path):
    data = xyz_volume(dtype=np.uint8)
    (tmp_path / "blob.raw").write_bytes(raw_bytes(data))
    (tmp_path / "blob.dat").write_text(
        "ObjectFileName: blob.raw\nTaggedFileName: ---\nResolution: 5 4 3\n"
        "SliceThickness: 1 1 2.5\nFormat: UCHAR\nObjectModel: I\n"
    )
    volume = read_volume(tmp_path / "blob.dat")
    assert_array_equal(volume.data, data)
    assert volume.spacing == (1.0, 1.0, 2.5)
    data16 = xyz_volume(dtype=np.uint16)
    (tmp_path / "old.dat").write_bytes(np.array([5, 4, 3], "<u2").tobytes() + raw_bytes(data16))
    assert_array_equal(read_volume(tmp_path / "old.dat").data, data16)


@pytest.mark.parametrize("encoding", ["raw", "gzip"])
def test_nrrd_attached_and_detached(tmp_path, encoding):
    data = xyz_volume(dtype=np.int16)
    payload = raw_bytes(data)
    if encoding == "gzip":
        payload = gzip.compress(payload)
    header = (f"NRRD0004\n# comment\ntype: short\ndimension: 3\nsizes: 5 4 3\n"
              f"spacings: 0.5 1 2\nendian: little\nencoding: {encoding}\n")
    (tmp_path / "a.nrrd").write_bytes(header.encode() + b"\n" + payload)
    volume = read_volume(tmp_path / "a.nrrd")
    assert_array_equal(volume.data, data)
    assert volume.spacing == (0.5, 1.0, 2.0)
    (tmp_path / "b.raw.data").write_bytes(payload)
    (tmp_path / "b.nhdr").write_text(header + "data file: b.raw.data\n")
    assert_array_equal(read_volume(tmp_path / "b.nhdr").data, data)


def test_nifti_and_npy_and_writers_round_trip(tmp_path):
    data = xyz_volume(dtype=np.int32)
    for name in ["l.nii.gz", "l.nii", "l.npy", "l.nrrd"]:
        write_volume(tmp_path / name, data, spacing=(0.5, 1.0, 2.0))
        volume = read_volume(tmp_path / name)
        assert_array_equal(volume.data, data)
        if name != "l.npy":
            assert volume.spacing == (0.5, 1.0, 2.0)
    write_volume(tmp_path / "l_5x4x3_int32.raw", data)
    assert_array_equal(read_volume(tmp_path / "l_5x4x3_int32.raw").data, data)
    assert not list(tmp_path.glob(".*part*"))  # no temporary files left behind


@pytest.mark.parametrize("name, shape", [("fuel", (64, 64, 64)), ("neghip", (64, 64, 64)),
                                         ("silicium", (98, 34, 34))])
def test_real_volvis_files(volvis_dir, name, shape):
    path = next(volvis_dir.glob(f"{name}_*.raw"))
    volume = read_volume(path)
    assert volume.shape == shape and volume.dtype == np.uint8 and volume.name == name
    raw = np.frombuffer(path.read_bytes(), np.uint8)
    rng = np.random.default_rng(0)
    for _ in range(20):
        x, y, z = (int(rng.integers(s)) for s in shape)
        assert volume.data[x, y, z] == raw[x + shape[0] * (y + shape[1] * z)]
    assert volume.data.max() == 255


def test_silicium_neighbours_are_smooth_along_every_axis(volvis_dir):
    # With x = 98 fastest, neighbouring voxels differ by ~10 along every axis
    # (shared/data/volvis/README.md); a wrong axis order gives ~50.
    data = read_volume(volvis_dir / "silicium_98x34x34_uint8.raw").data.astype(float)
    for axis in range(3):
        assert np.abs(np.diff(data, axis=axis)).mean() < 15


def test_errors_name_the_file_and_the_problem(tmp_path):
    short = tmp_path / "v_4x4x4_uint8.raw"
    short.write_bytes(bytes(10))
    with pytest.raises(ValueError, match=r"v_4x4x4_uint8.raw: expected 64 bytes .* found 10"):
        read_volume(short)
    with pytest.raises(FileNotFoundError, match="missing.raw: no such file"):
        read_volume(tmp_path / "missing.raw")
    nameless = tmp_path / "scan.raw"
    nameless.write_bytes(bytes(8))
    with pytest.raises(ValueError, match="no shape available.*--shape X Y Z"):
        read_volume(nameless)
    with pytest.raises(ValueError, match="unknown dtype 'uint12'"):
        read_volume(nameless, shape=(2, 2, 2), dtype="uint12")
    with pytest.raises(ValueError, match="at least 2 samples along each axis"):
        read_volume(nameless, shape=(8, 1, 1))
    bad = np.zeros((3, 3, 3), np.float32)
    bad[1, 2, 0] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(ValueError, match=r"1 voxels are NaN or infinite \(first at \[x, y, z\] = \(1, 2, 0\)\)"):
        read_volume(tmp_path / "nan.npy")
    np.save(tmp_path / "flat.npy", np.zeros((3, 3)))
    with pytest.raises(ValueError, match="must be 3-D"):
        read_volume(tmp_path / "flat.npy")
    with pytest.raises(ValueError, match="unknown output format"):
        write_volume(tmp_path / "x.tif", np.zeros((2, 2, 2)))
    assert not list(tmp_path.glob("x.tif*")) and not list(tmp_path.glob(".x.tif*"))
    assert io.DTYPES["uint8"] == "u1"
