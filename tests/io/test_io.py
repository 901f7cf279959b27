import gzip
import os

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from volseg import io
from volseg.io import read_volume, write_volume


def xyz_volume(shape=(5, 4, 3), dtype=np.uint16):
    return (np.arange(np.prod(shape)).reshape(shape) * 7 % 251).astype(dtype)


def raw_bytes(data, order="<"):
    swapped = data.dtype.newbyteorder(order)
    return np.ascontiguousarray(data.transpose(2, 1, 0)).astype(swapped).tobytes()


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
    with pytest.raises(ValueError, match=r"holds 1 NaN or infinite values \(first at \[x, y, z\] "
                                         r"= \(1, 2, 0\)\)"):
        read_volume(tmp_path / "nan.npy")
    np.save(tmp_path / "flat.npy", np.zeros((3, 3)))
    with pytest.raises(ValueError, match="must be 3-D"):
        read_volume(tmp_path / "flat.npy")
    with pytest.raises(ValueError, match="unknown output format"):
        write_volume(tmp_path / "x.tif", np.zeros((2, 2, 2)))
    assert not list(tmp_path.glob("x.tif*")) and not list(tmp_path.glob(".x.tif*"))
    assert io.DTYPES["uint8"] == "u1"


# ---------------------------------------------------------------- frames (issue 11)

ROTATED = np.array([[0.0, -2.0, 0.0, 10.0],   # voxel x -> world y (scaled 1.5)
                    [1.5, 0.0, 0.0, -3.0],    # voxel y -> world -x (scaled 2)
                    [0.0, 0.0, -4.0, 7.0],    # voxel z flipped
                    [0.0, 0.0, 0.0, 1.0]])


def test_nifti_frame_and_codes_survive_a_round_trip(tmp_path):
    import nibabel

    data = xyz_volume(dtype=np.int16)
    image = nibabel.Nifti1Image(data, ROTATED)
    image.header.set_sform(ROTATED, 4)
    image.header.set_qform(ROTATED, 1)
    nibabel.save(image, tmp_path / "scan.nii.gz")
    volume = read_volume(tmp_path / "scan.nii.gz")
    assert_array_equal(volume.data, data)
    np.testing.assert_allclose(volume.affine, ROTATED)
    assert (volume.frame.sform_code, volume.frame.qform_code) == (4, 1)
    assert volume.spacing == (1.5, 2.0, 4.0)  # lengths of the affine's columns
    write_volume(tmp_path / "out.nii.gz", data, frame=volume.frame)
    back = nibabel.load(tmp_path / "out.nii.gz")
    np.testing.assert_allclose(back.affine, ROTATED)
    assert int(back.header["sform_code"]) == 4 and int(back.header["qform_code"]) == 1
    np.testing.assert_allclose(back.header.get_qform(), ROTATED, atol=1e-6)


def test_nrrd_space_directions_become_ras_and_round_trip(tmp_path):
    data = xyz_volume(dtype=np.uint8)
    header = ("NRRD0004\ntype: uchar\ndimension: 3\nspace: left-posterior-superior\n"
              "sizes: 5 4 3\nspace directions: (0,-1.5,0) (2,0,0) (0,0,-4)\n"
              "space origin: (-10,3,7)\nendian: little\nencoding: raw\n\n")
    (tmp_path / "s.nrrd").write_bytes(header.encode() + raw_bytes(data))
    volume = read_volume(tmp_path / "s.nrrd")
    np.testing.assert_allclose(volume.affine, ROTATED)  # LPS -> RAS flips x and y
    write_volume(tmp_path / "back.nrrd", data, frame=volume.frame)
    again = read_volume(tmp_path / "back.nrrd")
    np.testing.assert_allclose(again.affine, ROTATED)
    assert_array_equal(again.data, data)


# ---------------------------------------------------------------- confinement (issue 11)


def test_detached_headers_read_only_their_own_folder(tmp_path):
    from volseg.io import VolumeFileError

    secret = tmp_path / "secret_5x4x3_uint8.raw"
    secret.write_bytes(raw_bytes(xyz_volume(dtype=np.uint8)))
    inner = tmp_path / "inner"
    inner.mkdir()
    for data_name in [str(secret), "../secret_5x4x3_uint8.raw"]:
        (inner / "h.nhdr").write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 5 4 3\n"
                                      f"encoding: raw\ndata file: {data_name}\n")
        (inner / "h.dat").write_text(f"ObjectFileName: {data_name}\nResolution: 5 4 3\n")
        for header in ["h.nhdr", "h.dat"]:
            with pytest.raises(VolumeFileError, match=r"h\.(nhdr|dat): its .* outside the "
                                                      r"header's folder"):
                read_volume(inner / header)
            volume = read_volume(inner / header, allow_external_data=True)
            assert volume.files == (inner / header, inner / data_name)
    (inner / "link.raw").symlink_to(secret)  # a link out of the folder is outside too
    (inner / "l.nhdr").write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 5 4 3\n"
                                  "encoding: raw\ndata file: link.raw\n")
    with pytest.raises(VolumeFileError, match="outside"):
        read_volume(inner / "l.nhdr")


# ---------------------------------------------------------------- hostile sizes (issue 11)


def test_devices_pipes_and_folders_are_refused_without_opening(tmp_path):
    from volseg.io import VolumeFileError

    with pytest.raises(VolumeFileError, match="/dev/zero: is a character device"):
        read_volume("/dev/zero", shape=(12, 10, 8))
    fifo = tmp_path / "pipe_4x4x4_uint8.raw"
    os.mkfifo(fifo)
    with pytest.raises(VolumeFileError, match="is a named pipe"):
        read_volume(fifo)  # opening it would block forever
    with pytest.raises(VolumeFileError, match="is a folder"):
        read_volume(tmp_path)
    with pytest.raises(VolumeFileError, match="cannot be read"):
        read_volume(tmp_path / ("x" * 300 + ".raw"))


def _huge_nifti_gz(path):
    """A 69-byte-scale .nii.gz whose header declares 2000^3 float64 voxels."""
    import nibabel

    header = nibabel.Nifti1Header()
    header.set_data_shape((2000, 2000, 2000))
    header.set_data_dtype(np.float64)
    header["vox_offset"] = 352
    raw = header.binaryblock + b"\0" * 4
    path.write_bytes(gzip.compress(raw))


def test_declared_sizes_are_checked_before_allocating(tmp_path):
    import resource
    import tracemalloc

    from volseg.io import VolumeFileError

    _huge_nifti_gz(tmp_path / "huge.nii.gz")
    nrrd_bomb = tmp_path / "bomb.nrrd"  # declares 4 KB, decompresses to 200 MB
    nrrd_bomb.write_bytes(b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 16 16 16\n"
                          b"encoding: gzip\n\n" + gzip.compress(bytes(200 << 20)))
    raw = tmp_path / "tiny_4000x4000x4000_float64.raw"
    raw.write_bytes(bytes(100))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for path, message in [(tmp_path / "huge.nii.gz", "expected 64000000352 bytes after "
                           "decompression, found 352"),
                          (nrrd_bomb, "hold more than the 4096 bytes"),
                          (raw, "expected 512000000000 bytes")]:
        # The work is bounded by what is allocated (numpy and bytes are traced), not
        # timed: refusing must not decompress or allocate the declared size.
        tracemalloc.start()
        try:
            with pytest.raises(VolumeFileError, match=message):
                read_volume(path)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 20 << 20, (path.name, peak)
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 100


@pytest.mark.parametrize("header, field", [
    ("sizes: 5 x 3", "'sizes' field"),
    ("sizes: 5 4 3\nspacings: 1 nan 1", "'spacings' field"),
    ("sizes: 5 4 3\nbyte skip: lots", "'byte skip' field"),
    ("sizes: 5 4 3\nspace directions: (1,0) (0,1,0) (0,0,1)", "'space directions' field"),
    ("sizes: 5 4 3\nendian: middle", "'endian' field"),
    ("sizes: 5 4 3\nspace directions: (1,0,0) (2,0,0) (0,0,1)", "singular"),
])
def test_nrrd_fields_that_do_not_parse_are_named(tmp_path, header, field):
    from volseg.io import VolumeFileError

    path = tmp_path / "f.nrrd"
    path.write_bytes(f"NRRD0004\ntype: uchar\ndimension: 3\n{header}\nencoding: raw\n\n".encode()
                     + bytes(60))
    with pytest.raises(VolumeFileError, match=rf"f\.nrrd: .*{field}"):
        read_volume(path)


def test_npy_headers_that_do_not_parse_are_volume_file_errors(tmp_path):
    from volseg.io import VolumeFileError

    good = tmp_path / "g.npy"
    np.save(good, np.zeros((3, 3, 3), np.float32))
    text = good.read_bytes()
    for n, broken in enumerate([text.replace(b"'descr'", b"'descr\""),
                                text.replace(b"(3, 3, 3)", b"(3, 3, -3)"),
                                text.replace(b"<f4", b"|O8"), text[:40]]):
        (tmp_path / f"b{n}.npy").write_bytes(broken)
        with pytest.raises(VolumeFileError, match=rf"b{n}\.npy"):
            read_volume(tmp_path / f"b{n}.npy")


# ---------------------------------------------------------------- output sets (issue 11)

_KILL_MID_COMMIT = """
import os, sys
from pathlib import Path
import volseg.io.output_set as output_set
folder = Path(sys.argv[1])
real, calls = os.replace, []
def dying(src, dst):
    calls.append(dst)
    if len(calls) == {after}:
        os._exit(9)  # as SIGKILL: no cleanup runs
    return real(src, dst)
with output_set.OutputSet(folder, "s", {{"a": "s_a.txt", "b": "s_b.txt", "c": "s_c.txt"}},
                          force=True) as out:
    output_set.os.replace = dying
    out.commit(lambda paths: [p.write_text("new " + p.name) for p in paths.values()])
"""


@pytest.mark.parametrize("after", [2, 4, 6])  # journal only / old moved aside / one placed
def test_a_commit_killed_between_renames_is_completed_by_the_next_writer(tmp_path, after):
    import subprocess
    import sys

    from volseg.io import OutputSet

    for name in ["s_a.txt", "s_b.txt", "s_c.txt"]:
        (tmp_path / name).write_text("old " + name)
    run = subprocess.run([sys.executable, "-c", _KILL_MID_COMMIT.format(after=after),
                          str(tmp_path)])
    assert run.returncode == 9
    with OutputSet(tmp_path, "s", {"a": "s_a.txt"}, force=True) as out:
        assert out.recovered and "completed an interrupted commit" in out.recovered[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s_a.txt", "s_b.txt", "s_c.txt"]
    assert {p.read_text() for p in tmp_path.iterdir()} == {f"new s_{k}.txt" for k in "abc"}


def test_output_set_refuses_existing_files_and_removes_its_staging(tmp_path):
    from volseg.io import OutputError, OutputSet

    names = {"a": "s_a.txt", "b": "s_b.txt"}
    with OutputSet(tmp_path, "s", names) as out:
        assert out.commit(lambda p: [f.write_text("1") for f in p.values()]) == {
            "a": tmp_path / "s_a.txt", "b": tmp_path / "s_b.txt"}
    with pytest.raises(OutputError, match="s_a.txt exists .* use --force"):
        OutputSet(tmp_path, "s", names).acquire()
    with OutputSet(tmp_path, "s", names, force=True) as out, \
            pytest.raises(RuntimeError, match="s_b"):
        out.commit(lambda p: p["a"].write_text("2"))  # a writer that forgot a file
    assert (tmp_path / "s_a.txt").read_text() == "1"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s_a.txt", "s_b.txt"]


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd"])
def test_the_length_unit_survives_a_write_and_a_read(tmp_path, suffix):
    """The input's unit reaches the outputs (NIfTI xyzt_units, NRRD space units); an
    unknown unit stays unknown, not a hard-coded mm."""
    from volseg.io import Frame, read_volume, write_volume

    data = np.arange(60, dtype=np.uint8).reshape(5, 4, 3)
    for unit in ("micrometer", "millimeter", None):
        frame = Frame.from_spacing((0.5, 0.25, 2.0), unit=unit)
        path = write_volume(tmp_path / f"v{suffix}", data, frame=frame)
        back = read_volume(path)
        assert back.frame.unit == unit and back.spacing == (0.5, 0.25, 2.0)
    with pytest.raises(ValueError, match="`unit` must be one of"):
        Frame.from_spacing((1, 1, 1), unit="furlong")


def test_vti_streams_lazy_arrays_a_slab_at_a_time(tmp_path, monkeypatch):
    """A Dask array is written in z-slabs (here one slice each, so the order of the
    slabs is exercised) and reads back as the numpy one; bad arrays are named."""
    import dask.array as da

    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    from volseg.io import Frame, vtk_image, write_vti

    monkeypatch.setattr(vtk_image, "SLAB_BYTES", 1)
    data = np.random.default_rng(2).normal(size=(6, 5, 4))
    mask = data > 0
    write_vti(tmp_path / "a.vti", {"v": da.from_array(data, chunks=(2, 3, 1)), "m": mask},
              Frame.from_spacing((1.0, 2.0, 3.0)))
    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "a.vti"))
    reader.Update()
    points = reader.GetOutput().GetPointData()
    back = vtk_to_numpy(points.GetArray("v")).reshape(4, 5, 6).transpose(2, 1, 0)
    np.testing.assert_array_equal(back, data)
    np.testing.assert_array_equal(
        vtk_to_numpy(points.GetArray("m")).reshape(4, 5, 6).transpose(2, 1, 0), mask)
    assert reader.GetOutput().GetSpacing() == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="one shape"):
        write_vti(tmp_path / "b.vti", {"a": data, "b": data[1:]}, Frame.from_spacing((1, 1, 1)))
    with pytest.raises(ValueError, match="cannot hold complex128"):
        write_vti(tmp_path / "b.vti", {"a": data.astype(complex)}, Frame.from_spacing((1, 1, 1)))
    assert not (tmp_path / "b.vti").exists()


def test_vts_writes_every_points_world_position_slab_by_slab(tmp_path, monkeypatch):
    """`write_vts` (an oblique scan's ParaView file): the points are the frame's world
    positions, x fastest, whatever the slab size; float32 when that is within 1e-3 of
    the smallest voxel size, float64 far from the origin; the unit as field data."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    from volseg.io import Frame, vtk_image, write_vts

    monkeypatch.setattr(vtk_image, "SLAB_BYTES", 1)
    data = np.random.default_rng(4).normal(size=(6, 5, 4)).astype(np.float32)
    angle = np.deg2rad(25)
    affine = np.eye(4)
    affine[:3, :3] = np.array([[np.cos(angle), -np.sin(angle), 0],
                               [np.sin(angle), np.cos(angle), 0], [0, 0, -1]]) @ np.diag(
        [0.5, 0.25, 2.0])
    for origin, kind in (([3.0, -2.0, 1.0], np.float32), ([1e6, 0.0, 0.0], np.float64)):
        affine[:3, 3] = origin
        path = write_vts(tmp_path / "a.vts", {"v": data}, Frame(affine, unit="micrometer"))
        reader = vtk.vtkXMLStructuredGridReader()
        reader.SetFileName(str(path))
        reader.Update()
        grid = reader.GetOutput()
        points = vtk_to_numpy(grid.GetPoints().GetData())
        assert points.dtype == kind
        i, j, k = np.meshgrid(*map(np.arange, data.shape), indexing="ij")
        index = np.stack([i, j, k, np.ones_like(i)], -1).transpose(2, 1, 0, 3).reshape(-1, 4)
        np.testing.assert_allclose(points, (index @ affine.T)[:, :3], atol=1e-4)
        back = vtk_to_numpy(grid.GetPointData().GetArray("v")).reshape(4, 5, 6)
        np.testing.assert_array_equal(back.transpose(2, 1, 0), data)
        assert grid.GetFieldData().GetAbstractArray("unit").GetValue(0) == "micrometer"


def test_frames_agree_unless_both_carry_geometry_that_differs():
    """`Frame.agrees_with`, the rule `volseg compare` applies: a file without geometry
    (unit-less voxels of 1 at the origin) agrees with any grid; a unit only one frame
    says is ignored; otherwise voxel sizes, origin and axes must match."""
    Frame = io.Frame
    plain = Frame.from_spacing((1.0, 1.0, 1.0))
    scan = Frame.from_spacing((0.5, 0.5, 2.0), unit="millimeter")
    assert plain.agrees_with(scan) and scan.agrees_with(plain)
    assert scan.agrees_with(scan.with_unit(None))
    assert not scan.agrees_with(Frame.from_spacing((0.5, 0.5, 2.5), unit="millimeter"))
    assert not scan.agrees_with(scan.with_unit("micrometer"))
    shifted = np.diag([0.5, 0.5, 2.0, 1.0])
    shifted[:3, 3] = (1.0, 0.0, 0.0)
    assert not scan.agrees_with(Frame(shifted, unit="millimeter"))


def test_nifti_gzip_is_standard_and_reproducible(tmp_path):
    """The .nii.gz outputs (gzip by ISA-L): a standard gzip stream (Python's gzip and
    nibabel read it back exactly), with no time stamp, so the same volume written twice
    gives the same bytes."""
    import gzip

    import nibabel

    data = np.random.default_rng(3).random((9, 8, 7)).astype(np.float32)
    first, second = tmp_path / "a.nii.gz", tmp_path / "b.nii.gz"
    write_volume(first, data)
    write_volume(second, data)
    assert first.read_bytes() == second.read_bytes()
    raw = gzip.decompress(first.read_bytes())
    assert len(raw) == 352 + data.nbytes               # NIfTI-1 header, extension flag
    assert_array_equal(np.asarray(nibabel.load(first).dataobj), data)
