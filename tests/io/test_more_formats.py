"""MetaImage and TIFF stacks (issue 28): read with their frames through SimpleITK and
tifffile, equal to what was written; bad files exit 2 with one line, bounded."""

import numpy as np
import pytest

from volseg.cli import main
from volseg.io import VolumeFileError, read_volume

sitk = pytest.importorskip("SimpleITK")
tifffile = pytest.importorskip("tifffile")

DATA = np.random.default_rng(0).integers(0, 4000, (9, 8, 7)).astype(np.int16)   # x, y, z


def _metaimage(path, data=DATA):
    image = sitk.GetImageFromArray(data.transpose(2, 1, 0))     # ITK takes (z, y, x)
    image.SetSpacing((0.5, 0.75, 2.0))
    image.SetOrigin((10.0, -20.0, 5.0))
    image.SetDirection((0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    sitk.WriteImage(image, str(path))
    return image


@pytest.mark.parametrize("suffix", [".mha", ".mhd"])
def test_metaimage_reads_its_voxels_and_its_frame(tmp_path, suffix):
    image = _metaimage(tmp_path / f"ct{suffix}")
    volume = read_volume(tmp_path / f"ct{suffix}")
    np.testing.assert_array_equal(np.asarray(volume.data), DATA)
    assert volume.name == "ct" and volume.spacing == pytest.approx((0.5, 0.75, 2.0))
    for index in [(0, 0, 0), (8, 7, 6), (3, 1, 4)]:
        lps = image.TransformIndexToPhysicalPoint(index)
        ras = (volume.frame.affine @ [*index, 1])[:3]
        np.testing.assert_allclose(ras, [-lps[0], -lps[1], lps[2]], atol=1e-12)
    assert len(volume.files) == (1 if suffix == ".mha" else 2)


def test_tiff_stack_file_and_folder_of_slices(tmp_path):
    zyx = DATA.transpose(2, 1, 0).astype(np.uint16)
    tifffile.imwrite(tmp_path / "stack.tif", zyx, imagej=True,
                     resolution=(1 / 0.25, 1 / 0.25), metadata={"spacing": 1.5, "unit": "um"})
    volume = read_volume(tmp_path / "stack.tif")
    np.testing.assert_array_equal(np.asarray(volume.data), DATA.astype(np.uint16))
    assert volume.spacing == pytest.approx((0.25, 0.25, 1.5))
    assert volume.frame.unit == "micrometer"
    folder = tmp_path / "slices"
    folder.mkdir()
    for z, plane in enumerate(zyx):
        tifffile.imwrite(folder / f"slice_{z:03d}.tif", plane)
    volume = read_volume(folder)
    np.testing.assert_array_equal(np.asarray(volume.data), DATA.astype(np.uint16))
    assert volume.name == "slices" and volume.spacing == (1.0, 1.0, 1.0)
    assert main(["segment", str(folder), "-o", str(tmp_path / "o"), "-q", "--regions", "2"]) == 0
    assert (tmp_path / "o" / "slices_labels.nii.gz").exists()


def _bad_cases(tmp_path):
    _metaimage(tmp_path / "good.mha")
    raw = (tmp_path / "good.mha").read_bytes()
    (tmp_path / "cut.mha").write_bytes(raw[:-100])
    (tmp_path / "huge.mha").write_bytes(raw.replace(b"DimSize = 9 8 7", b"DimSize = 90000 80000 7"))
    (tmp_path / "two.mha").write_bytes(
        b"ObjectType = Image\nNDims = 2\nDimSize = 4 4\nElementType = MET_UCHAR\n"
        b"ElementDataFile = LOCAL\n" + bytes(16))
    (tmp_path / "far.mhd").write_bytes(
        b"ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
        b"ElementDataFile = ../elsewhere.raw\n")
    (tmp_path.parent / "elsewhere.raw").write_bytes(bytes(8))
    (tmp_path / "junk.tif").write_bytes(b"II*\x00garbage" * 10)
    tifffile.imwrite(tmp_path / "rgb.tif", np.zeros((3, 4, 5, 3), np.uint8))
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    tifffile.imwrite(mixed / "a.tif", np.zeros((4, 5), np.uint8))
    tifffile.imwrite(mixed / "b.tif", np.zeros((5, 5), np.uint8))
    return {"cut.mha": "holds", "huge.mha": "declares", "two.mha": "2-D MetaImage",
            "far.mhd": "outside its folder", "junk.tif": "not a readable TIFF",
            "rgb.tif": "single-channel z stack", "mixed": "cannot reshape"}


def test_bad_metaimage_and_tiff_files_exit_2_with_one_line(tmp_path, capsys):
    import resource

    for name, message in _bad_cases(tmp_path).items():
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        with pytest.raises(VolumeFileError, match=message):
            read_volume(tmp_path / name)
        assert (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak) / 1024 < 256, name
        assert main(["segment", str(tmp_path / name), "-o", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and str(tmp_path / name) in err, err
        assert main(["info", str(tmp_path / name)]) == 2
        capsys.readouterr()


def test_volseg_info_on_metaimage_and_tiff(tmp_path, capsys):
    _metaimage(tmp_path / "ct.mha")
    tifffile.imwrite(tmp_path / "s.tif", DATA.transpose(2, 1, 0).astype(np.uint16))
    for name in ("ct.mha", "s.tif"):
        assert main(["info", str(tmp_path / name)]) == 0
        out = capsys.readouterr().out
        assert "shape (x, y, z): (9, 8, 7)" in out and name in out
