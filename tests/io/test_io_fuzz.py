"""Hostile files: random bytes and mutated valid files raise only VolumeFileError, or
read as a valid finite 3-D volume, within 2 s (hypothesis' deadline) and 256 MB of
new peak memory per file."""

import gzip
import io as _bytes_io
import os
import resource

import nibabel
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from volseg.io import VolumeFileError, read_volume

DATA = (np.arange(6 * 5 * 4).reshape(6, 5, 4) % 251).astype(np.uint16)
RAW = np.ascontiguousarray(DATA.transpose(2, 1, 0)).tobytes()
NRRD_HEAD = ("NRRD0004\ntype: ushort\ndimension: 3\nsizes: 6 5 4\nspacings: 1 2 0.5\n"
             "endian: little\nencoding: {encoding}\n")


def _nifti(compressed: bool) -> bytes:
    image = nibabel.Nifti1Image(DATA, np.diag([1.0, 2.0, 0.5, 1.0]))
    raw = image.to_bytes()
    return gzip.compress(raw) if compressed else raw


def _npy() -> bytes:
    buffer = _bytes_io.BytesIO()
    np.save(buffer, DATA)
    return buffer.getvalue()


def _mha() -> bytes:
    import tempfile

    import SimpleITK as sitk

    with tempfile.TemporaryDirectory() as folder:
        sitk.WriteImage(sitk.GetImageFromArray(DATA.transpose(2, 1, 0)), f"{folder}/m.mha")
        with open(f"{folder}/m.mha", "rb") as handle:
            return handle.read()


def _tiff() -> bytes:
    import tifffile

    buffer = _bytes_io.BytesIO()
    tifffile.imwrite(buffer, DATA.transpose(2, 1, 0), photometric="minisblack")
    return buffer.getvalue()


# name -> {file name: bytes}; the first file is the one read.
VALID = {
    "raw": {"v_6x5x4_uint16.raw": RAW},
    "dat-text": {"v.dat": b"ObjectFileName: v.raw\nResolution: 6 5 4\nSliceThickness: 1 2 0.5\n"
                          b"Format: USHORT\n", "v.raw": RAW},
    "dat-binary": {"b.dat": np.array([6, 5, 4], "<u2").tobytes() + RAW},
    "nrrd": {"a.nrrd": NRRD_HEAD.format(encoding="raw").encode() + b"\n" + RAW},
    "nrrd-gzip": {"g.nrrd": NRRD_HEAD.format(encoding="gzip").encode() + b"\n"
                  + gzip.compress(RAW)},
    "nhdr": {"d.nhdr": NRRD_HEAD.format(encoding="raw").encode() + b"data file: d.raw\n",
             "d.raw": RAW},
    "npy": {"n.npy": _npy()},
    "nii": {"i.nii": _nifti(False)},
    "nii-gz": {"z.nii.gz": _nifti(True)},
    "mha": {"m.mha": _mha()},
    "tiff": {"s.tif": _tiff()},
}

mutations = st.lists(
    st.one_of(
        st.tuples(st.just("flip"), st.integers(0, 10_000), st.integers(0, 255)),
        st.tuples(st.just("cut"), st.integers(0, 10_000), st.just(0)),
        st.tuples(st.just("insert"), st.integers(0, 10_000), st.integers(0, 255)),
        st.tuples(st.just("digits"), st.integers(0, 10_000), st.integers(0, 9)),
    ),
    min_size=1, max_size=6,
)


def _mutate(data: bytes, steps) -> bytes:
    data = bytearray(data)
    for kind, position, value in steps:
        if not data:
            break
        at = position % len(data)
        if kind == "flip":
            data[at] = value
        elif kind == "cut":
            del data[at:]
        elif kind == "insert":
            data[at:at] = bytes([value])
        else:  # a digit where a digit was: sizes and offsets change, the text still parses
            digits = [i for i, c in enumerate(data) if 48 <= c <= 57]
            if digits:
                data[digits[position % len(digits)]] = 48 + value
    return bytes(data)


def _check_outcome(folder, files):
    for name, content in files.items():
        (folder / name).write_bytes(content)
    first = folder / next(iter(files))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:
        volume = read_volume(first)
    except VolumeFileError as err:
        # The message names the file that is wrong (the header, or the data it names).
        assert any(str(folder / name) in str(err) for name in files), str(err)
        return
    finally:  # the process's high-water mark: a reader allocating a declared size shows here
        assert (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak) / 1024 < 256
    data = np.asarray(volume)
    assert data.ndim == 3 and min(data.shape) >= 2
    assert data.dtype.kind in "uif"
    if data.dtype.kind == "f":
        assert np.isfinite(data).all()
    assert all(s > 0 for s in volume.spacing)


FUZZ = settings(max_examples=int(os.environ.get("VOLSEG_FUZZ_EXAMPLES", 150)), deadline=2000,
                derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.mark.parametrize("kind", sorted(VALID))
def test_valid_files_read(tmp_path, kind):
    for name, content in VALID[kind].items():
        (tmp_path / name).write_bytes(content)
    volume = read_volume(tmp_path / next(iter(VALID[kind])))
    np.testing.assert_array_equal(np.asarray(volume), DATA)


@pytest.mark.parametrize("kind", sorted(VALID))
@FUZZ
@given(steps=mutations)
def test_mutated_files_fail_only_as_volume_file_errors(tmp_path_factory, kind, steps):
    folder = tmp_path_factory.mktemp(kind)
    files = dict(VALID[kind])
    first = next(iter(files))
    files[first] = _mutate(files[first], steps)
    _check_outcome(folder, files)


@pytest.mark.parametrize("name", ["r_6x5x4_uint16.raw", "t.dat", "x.nrrd", "y.nhdr", "w.npy",
                                  "u.nii", "k.nii.gz", "c.mha", "p.tif"])
@FUZZ
@given(content=st.binary(max_size=4096))
def test_random_bytes_fail_only_as_volume_file_errors(tmp_path_factory, name, content):
    _check_outcome(tmp_path_factory.mktemp("random"), {name: content})

