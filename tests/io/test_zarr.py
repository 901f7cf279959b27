"""Zarr in and out, and `volseg segment` on the blockwise path (Zarr input or --chunks):
the same labels as in memory, checked inputs, nothing half-written."""

import json
import os

import dask
import nibabel
import numpy as np
import pytest
import zarr

from volseg.cli import main
from volseg.io import Frame, VolumeFileError, read_volume, write_zarr
from volseg.io.zarr_store import ZSTD_LEVEL

from ..conftest import smooth_random_field


@pytest.fixture(autouse=True)
def _synchronous():
    with dask.config.set(scheduler="synchronous"):
        yield


@pytest.fixture
def volume():
    field = smooth_random_field((24, 21, 18), np.random.default_rng(4), sigma=2.0)
    return (field * 400 + 128).clip(0, 255).astype(np.uint8)


def test_write_and_read_back_with_frame(tmp_path, volume):
    frame = Frame.from_spacing((0.5, 1.0, 2.0))
    write_zarr(tmp_path / "v.zarr", volume, frame=frame, chunks=(7, 21, 5))
    back = read_volume(tmp_path / "v.zarr")
    assert back.shape == volume.shape and back.spacing == (0.5, 1.0, 2.0)
    assert type(back.data).__module__.startswith("dask")
    assert back.data.chunks[0] == (7, 7, 7, 3)
    assert np.array_equal(back.data.compute(), volume)


def test_ome_zarr_level_0_is_reordered_to_xyz(tmp_path):
    group = zarr.open_group(str(tmp_path / "img.zarr"), mode="w")
    data = np.arange(6 * 5 * 4, dtype=np.float32).reshape(1, 6, 5, 4)
    array = group.create_array("0", shape=data.shape, chunks=(1, 3, 5, 4), dtype="float32")
    array[:] = data
    group.attrs["multiscales"] = [{
        "version": "0.4",
        "axes": [{"name": n} for n in ("c", "z", "y", "x")],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [1.0, 2.0, 0.5, 0.25]}]}]}]
    volume = read_volume(tmp_path / "img.zarr")
    assert volume.shape == (4, 5, 6) and volume.spacing == (0.25, 0.5, 2.0)
    assert np.array_equal(volume.data.compute(), data[0].transpose(2, 1, 0))


def _image(path, axes, scale):
    group = zarr.open_group(str(path), mode="w")
    data = np.arange(6 * 5 * 4, dtype=np.float32).reshape(6, 5, 4)
    group.create_array("0", shape=data.shape, chunks=data.shape, dtype="float32")[:] = data
    group.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": [
        {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": scale}]}]}]
    return path


def test_ome_axes_in_different_units_are_read_in_the_finest(tmp_path):
    """z in millimetres, y and x in micrometres (issue 57, #5): the voxel sizes in
    micrometres, not the numbers as they stand; a time or channel axis named z, a time
    unit on a space axis, or units on some axes only, are refused."""
    space = [{"name": "z", "type": "space", "unit": "millimeter"},
             {"name": "y", "type": "space", "unit": "micrometer"},
             {"name": "x", "type": "space", "unit": "micrometer"}]
    volume = read_volume(_image(tmp_path / "mixed.zarr", space, [0.002, 0.5, 0.25]))
    assert volume.spacing == pytest.approx((0.25, 0.5, 2.0))
    assert volume.frame.unit == "micrometer"
    cases = [([{**space[0], "type": "time", "unit": "second"}, *space[1:]], "of type 'time'"),
             ([{**space[0], "type": "channel"}, *space[1:]], "of type 'channel'"),
             ([{**space[0], "unit": "second"}, *space[1:]], "a time unit"),
             ([{"name": "z", "type": "space"}, *space[1:]], "others none")]
    for i, (axes, message) in enumerate(cases):
        with pytest.raises(VolumeFileError, match=message):
            read_volume(_image(tmp_path / f"bad{i}.zarr", axes, [1.0, 1.0, 1.0]))


def test_bad_stores_are_refused_with_the_reason(tmp_path, volume):
    flat = zarr.create_array(str(tmp_path / "flat.zarr"), shape=(5, 5), chunks=(5, 5), dtype="f4")
    flat[:] = 1
    with pytest.raises(VolumeFileError, match="2-D"):
        read_volume(tmp_path / "flat.zarr")
    group = zarr.open_group(str(tmp_path / "group.zarr"), mode="w")
    group.create_array("a", shape=(3, 3, 3), dtype="f4")
    with pytest.raises(VolumeFileError, match="multiscales"):
        read_volume(tmp_path / "group.zarr")
    write_zarr(tmp_path / "holes.zarr", volume, chunks=(8, 8, 8))
    chunk_files = sorted(p for p in (tmp_path / "holes.zarr" / "c").rglob("*") if p.is_file())
    chunk_files[3].unlink()
    with pytest.raises(VolumeFileError, match="1 of 27 chunks are missing"):
        read_volume(tmp_path / "holes.zarr")
    write_zarr(tmp_path / "bad.zarr", volume, chunks=(8, 8, 8))
    chunk_files = sorted(p for p in (tmp_path / "bad.zarr" / "c").rglob("*") if p.is_file())
    chunk_files[5].write_bytes(b"junk")
    lazy = read_volume(tmp_path / "bad.zarr")            # opens: the chunk is read later
    with pytest.raises(VolumeFileError, match=r"chunk at \[.*\] is unreadable"):
        lazy.data.compute()


def test_cli_zarr_in_zarr_out_equals_in_memory(tmp_path, volume, capsys):
    write_zarr(tmp_path / "vol.zarr", volume, chunks=(10, 9, 7))
    np.save(tmp_path / "vol.npy", volume)
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(tmp_path / "z"), "--regions",
                 "9", "-q"]) == 0
    assert main(["segment", str(tmp_path / "vol.npy"), "-o", str(tmp_path / "m"), "--regions",
                 "9", "--mask", "none", "-q"]) == 0
    blockwise = zarr.open(str(tmp_path / "z" / "vol_labels.zarr"), mode="r")[:]
    in_memory = np.asanyarray(nibabel.load(tmp_path / "m" / "vol_labels.nii.gz").dataobj)
    assert np.array_equal(blockwise, in_memory)
    curvature = zarr.open(str(tmp_path / "z" / "vol_curvature.zarr"), mode="r")[:]
    assert curvature.dtype == np.float64       # what the Morse stage read, exactly
    nifti = nibabel.load(tmp_path / "m" / "vol_curvature.nii.gz")
    assert np.array_equal(curvature.astype(np.float32), np.asanyarray(nifti.dataobj))
    # Every array either path wrote (plain Zarr, both OME-Zarr writers) has volseg's one
    # zstd level, not Zarr's default.
    metadata = [json.loads(f.read_text()) for d in ("z", "m")
                for f in sorted((tmp_path / d).rglob("zarr.json"))]
    codecs = [m["codecs"] for m in metadata if m["node_type"] == "array"]
    assert len(codecs) >= 6
    assert all(c[-1] == {"name": "zstd", "configuration": {"level": ZSTD_LEVEL,
                                                           "checksum": False}} for c in codecs)
    a = json.loads((tmp_path / "z" / "vol_summary.json").read_text())
    b = json.loads((tmp_path / "m" / "vol_summary.json").read_text())
    assert a["regions"] == b["regions"] and a["n_maxima"] == b["n_maxima"]
    assert a["persistence"] == b["persistence"]
    # A small volume also gets the in-memory path's NIfTI files, the same ones.
    for kind in ("labels", "curvature"):
        lazy, eager = (nibabel.load(tmp_path / d / f"vol_{kind}.nii.gz") for d in ("z", "m"))
        assert lazy.get_data_dtype() == eager.get_data_dtype()
        assert np.array_equal(lazy.affine, eager.affine)
        assert np.array_equal(np.asanyarray(lazy.dataobj), np.asanyarray(eager.dataobj))
        assert a["outputs"][f"{kind}_nifti"].endswith(f"vol_{kind}.nii.gz")
    # --chunks takes the same path for any input; outputs are refused, then replaced.
    assert main(["segment", str(tmp_path / "vol.npy"), "-o", str(tmp_path / "z2"), "--regions",
                 "9", "--chunks", "9", "-q"]) == 0
    stored = zarr.open(str(tmp_path / "z2" / "vol_labels.zarr"), mode="r")[:]
    assert np.array_equal(stored, in_memory)
    capsys.readouterr()
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(tmp_path / "z"), "-q"]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(tmp_path / "z"), "--regions", "4",
                 "--force", "-q"]) == 0
    assert zarr.open(str(tmp_path / "z" / "vol_labels.zarr"), mode="r")[:].max() == 4


def test_cli_blockwise_writes_no_nifti_above_its_size_limit(tmp_path, volume, monkeypatch):
    import volseg.outputs._summary as names

    monkeypatch.setattr(names, "BLOCKWISE_NIFTI_VOXELS", volume.size - 1)
    monkeypatch.setattr(names, "PARAVIEW_VOXELS", volume.size - 1)
    write_zarr(tmp_path / "vol.zarr", volume, chunks=(10, 9, 7))
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(tmp_path / "z"), "-q"]) == 0
    assert sorted(os.listdir(tmp_path / "z")) == [
        "vol_curvature.zarr", "vol_labels.zarr", "vol_preview.png", "vol_segmentation.ome.zarr",
        "vol_summary.json"]
    # The ParaView image on request, above its size too.
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(tmp_path / "v"), "-q",
                 "--vti"]) == 0
    assert "vol_volumes.vti" in os.listdir(tmp_path / "v")


@pytest.mark.parametrize("source", ["npy", "zarr"])
def test_cli_blockwise_smoothing_equals_in_memory(tmp_path, volume, source):
    np.save(tmp_path / "vol.npy", volume)
    write_zarr(tmp_path / "vol.zarr", volume, chunks=(9, 11, 7))
    common = ["--regions", "6", "--smooth", "1.5", "--mask", "none", "-q"]
    assert main(["segment", str(tmp_path / "vol.npy"), "-o", str(tmp_path / "m"), *common]) == 0
    lazy = ["vol.npy", "--chunks", "7"] if source == "npy" else ["vol.zarr"]
    assert main(["segment", str(tmp_path / lazy[0]), *lazy[1:], "-o", str(tmp_path / "z"),
                 *common]) == 0
    blockwise = zarr.open(str(tmp_path / "z" / "vol_labels.zarr"), mode="r")[:]
    in_memory = nibabel.load(tmp_path / "m" / "vol_labels.nii.gz").dataobj
    assert np.array_equal(blockwise, np.asanyarray(in_memory))
    a = json.loads((tmp_path / "z" / "vol_summary.json").read_text())
    b = json.loads((tmp_path / "m" / "vol_summary.json").read_text())
    assert a["persistence"] == b["persistence"] and a["n_maxima"] == b["n_maxima"]
    assert a["smooth_sigma_voxels"] == 1.5


@pytest.mark.parametrize("extra, message", [
    (["--chunks", "0"], "--chunks must be a whole number of at least 2"),
    (["--chunks", "99"], "larger than the volume"),
    (["--chunks", "8", "--mask", "bright"], "unknown --mask rule 'bright'"),
    (["--chunks", "8", "--mask-threshold", "1000", "-q"], "selects no voxel"),
    (["--chunks", "8", "--noise", "1"], "needs the volume in memory"),
    (["--chunks", "8", "--smooth", "-1"], "--smooth"),
])
def test_cli_blockwise_bad_arguments_exit_2_and_write_nothing(tmp_path, volume, capsys, extra,
                                                              message):
    np.save(tmp_path / "vol.npy", volume)
    out = tmp_path / "out"
    assert main(["segment", str(tmp_path / "vol.npy"), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists() or not [p for p in os.listdir(out) if not p.startswith(".")]


@pytest.mark.parametrize("mask", [[], ["--mask", "otsu"], ["--mask-threshold", "140"]])
def test_cli_blockwise_masks_equal_in_memory(tmp_path, volume, mask):
    # An empty background over most of the volume (fuel's case): --mask auto, the
    # default, masks it on the blockwise path as in memory.
    empty = volume.copy()
    empty[:, :, :12] = 0
    write_zarr(tmp_path / "empty.zarr", empty, chunks=(8, 7, 8))
    np.save(tmp_path / "empty.npy", empty)
    common = ["--regions", "5", "-q", *mask]
    assert main(["segment", str(tmp_path / "empty.zarr"), "-o", str(tmp_path / "z"), *common]) == 0
    assert main(["segment", str(tmp_path / "empty.npy"), "-o", str(tmp_path / "m"), *common]) == 0
    blockwise = zarr.open(str(tmp_path / "z" / "empty_labels.zarr"), mode="r")[:]
    in_memory = np.asanyarray(nibabel.load(tmp_path / "m" / "empty_labels.nii.gz").dataobj)
    assert np.array_equal(blockwise, in_memory)
    assert (blockwise == 0).sum() >= (empty == 0).sum()         # the background is label 0
    a = json.loads((tmp_path / "z" / "empty_summary.json").read_text())
    b = json.loads((tmp_path / "m" / "empty_summary.json").read_text())
    assert a["mask"] == b["mask"] and a["mask"]["used"] != "none"
    assert a["regions"] == b["regions"] and a["persistence"] == b["persistence"]


def test_cli_blockwise_refuses_a_corrupt_chunk(tmp_path, volume, capsys):
    write_zarr(tmp_path / "bad.zarr", volume, chunks=(8, 8, 8))
    sorted(p for p in (tmp_path / "bad.zarr" / "c").rglob("*") if p.is_file())[2].write_bytes(b"x")
    assert main(["segment", str(tmp_path / "bad.zarr"), "-o", str(tmp_path / "o2"), "--mask",
                 "none", "-q"]) == 2
    err = capsys.readouterr().err
    assert "unreadable" in err and err.count("\n") == 1
    assert not (tmp_path / "o2").exists()         # created by the run, left empty: removed


def test_cli_blockwise_checks_the_free_disk_first(tmp_path, volume, capsys, monkeypatch):
    import shutil

    write_zarr(tmp_path / "vol.zarr", volume, chunks=(10, 9, 7))
    out = tmp_path / "out"
    out.mkdir()
    real = shutil.disk_usage
    need = volume.size * 20       # curvature 8, path ends 8, cells 4 bytes per voxel

    def free(n):
        monkeypatch.setattr(shutil, "disk_usage", lambda path: real(path)._replace(free=n))

    free(need - 1)
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(out), "-q", "--smooth", "0"]) == 2
    err = capsys.readouterr().err
    assert "GB free, but the blockwise run's work folder needs" in err and err.count("\n") == 1
    assert os.listdir(out) == []                       # nothing written, not even the work folder
    free(need - 1 + volume.size * 8)
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(out), "--smooth", "1"]) == 2
    assert "smoothed values 8" in capsys.readouterr().err
    # An earlier run's work folder counts as free (it is reused or emptied).
    (out / ".vol.volseg-work").mkdir()
    (out / ".vol.volseg-work" / "left.npz").write_bytes(b"x" * 1000)
    free(need - 1000)
    assert main(["segment", str(tmp_path / "vol.zarr"), "-o", str(out), "--smooth", "0"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "GB free; the run may need up to" in err   # outputs may not fit
    assert sorted(p for p in os.listdir(out) if not p.startswith(".")) == [
        "vol_curvature.nii.gz", "vol_curvature.zarr", "vol_labels.nii.gz",
        "vol_labels.zarr", "vol_preview.png", "vol_segmentation.ome.zarr", "vol_summary.json",
        "vol_volumes.vti"]


# ---------------------------------------------------------------- hostile stores (issue 27)


def _v2_store(path, shape, chunks):
    path.mkdir()
    (path / ".zarray").write_text(json.dumps({
        "zarr_format": 2, "shape": shape, "chunks": chunks, "dtype": "|u1",
        "compressor": None, "fill_value": 0, "filters": None, "order": "C"}))
    return path


@pytest.mark.parametrize("shape, chunks, message", [
    ([24, 2147483648, 0], [24, 8, 8], "at least 2 samples along each axis"),
    ([16, 16, 16], [0, 8, 8], "every chunk size must be at least 1"),
    ([10**6] * 3, [1, 1, 1], "chunks of [1, 1, 1] declared"),
])
def test_store_metadata_is_checked_before_any_chunk_is_listed(tmp_path, capsys, shape, chunks,
                                                               message):
    import time

    store = _v2_store(tmp_path / "bad.zarr", shape, chunks)
    started = time.perf_counter()
    assert main(["info", str(store)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and str(store) in err
    assert time.perf_counter() - started < 5


def test_a_shard_missing_inner_chunks_is_refused(tmp_path):
    import zarr

    store = zarr.create_array(str(tmp_path / "s.zarr"), shape=(10, 9, 8), chunks=(4, 4, 4),
                              shards=(8, 8, 8), dtype="uint8", fill_value=0)
    store[:] = 1                       # every inner chunk written (edge shards included) ...
    assert read_volume(tmp_path / "s.zarr").data.compute().min() == 1
    store[:4, :4, :4] = 0              # ... then one left empty: Zarr drops it from its shard
    with pytest.raises(VolumeFileError, match="1 inner chunks of its shards are missing"):
        read_volume(tmp_path / "s.zarr")


def test_a_chunk_linked_outside_the_store_is_refused_unless_allowed(tmp_path, capsys):
    import zarr

    store = zarr.create_array(str(tmp_path / "l.zarr"), shape=(8, 8, 8), chunks=(4, 4, 4),
                              dtype="uint8", config={"write_empty_chunks": True})
    store[:] = 2
    chunk = tmp_path / "l.zarr" / "c" / "0" / "0" / "0"
    outside = tmp_path / "elsewhere.bin"
    outside.write_bytes(chunk.read_bytes())
    chunk.unlink()
    chunk.symlink_to(outside)
    assert main(["segment", str(tmp_path / "l.zarr"), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "outside the store" in err and "--allow-external-data" in err
    assert read_volume(tmp_path / "l.zarr", allow_external_data=True).data.compute().min() == 2


def test_info_on_a_zarr_store(tmp_path, capsys):
    write_zarr(tmp_path / "v.zarr", np.arange(60, dtype=np.uint8).reshape(5, 4, 3),
               chunks=(2, 2, 2))
    assert main(["info", str(tmp_path / "v.zarr")]) == 0
    out = capsys.readouterr().out
    assert "range: 0 .. 59 (mean 29.5)" in out and "shape (x, y, z): (5, 4, 3)" in out


def test_ome_images_with_channel_and_time_axes(tmp_path, capsys):
    group = zarr.open_group(str(tmp_path / "o.zarr"), mode="w")
    data = np.arange(1 * 3 * 6 * 5 * 4).reshape(1, 3, 6, 5, 4).astype(np.uint16)   # t c z y x
    group.create_array("0", shape=data.shape, chunks=(1, 1, 4, 3, 2), dtype=data.dtype)[:] = data
    group.attrs["multiscales"] = [{"version": "0.4", "axes": [{"name": n} for n in "tczyx"],
                                   "datasets": [{"path": "0", "coordinateTransformations": [
                                       {"type": "scale", "scale": [1, 1, 3.0, 2.0, 1.0]}]}]}]
    with pytest.raises(VolumeFileError, match="has 3 channels; choose one with --channel"):
        read_volume(tmp_path / "o.zarr")
    volume = read_volume(tmp_path / "o.zarr", channel=2)      # the singleton t is dropped
    np.testing.assert_array_equal(volume.data.compute(), data[0, 2].transpose(2, 1, 0))
    assert volume.spacing == (1.0, 2.0, 3.0)
    with pytest.raises(VolumeFileError, match="not one of its 3 channels"):
        read_volume(tmp_path / "o.zarr", channel=3)
    assert main(["segment", str(tmp_path / "o.zarr"), "--channel", "1", "-o",
                 str(tmp_path / "out"), "-q", "--regions", "2"]) == 0
    # Unsmoothed, the curvature's halos reread the channel's blocks (a fresh copy of
    # the sliced, transposed array: dask's clone failed to fuse it).
    assert main(["segment", str(tmp_path / "o.zarr"), "--channel", "1", "-o",
                 str(tmp_path / "raw"), "-q", "--regions", "2", "--smooth", "0"]) == 0
    assert main(["info", str(tmp_path / "o.zarr")]) == 2
    assert "--channel (0 to 2)" in capsys.readouterr().err


@pytest.mark.parametrize("version", ["0.4", "0.5"])
def test_ome_zarr_04_and_05_keep_translation_units_and_levels(tmp_path, version, capsys):
    """Written by ome-zarr-py (NGFF 0.4: Zarr v2, 0.5: v3, its default): c, z, y, x
    with one channel, micrometres, a translation and a 2-level pyramid. 0.5 was
    refused and 0.4 lost its translation and unit."""
    import warnings

    import zarr
    from ome_zarr.format import FormatV04, FormatV05

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from ome_zarr.writer import write_multiscale

    from volseg.io import read_volume

    rng = np.random.default_rng(0)
    zyx = rng.integers(0, 200, (6, 7, 8)).astype(np.uint16)
    levels = [zyx[None], zyx[None, ::2, ::2, ::2]]
    fmt = FormatV04() if version == "0.4" else FormatV05()
    root = zarr.open_group(str(tmp_path / "img.ome.zarr"), mode="w",
                           zarr_format=2 if version == "0.4" else 3)
    axes = [{"name": "c", "type": "channel"}] + [
        {"name": n, "type": "space", "unit": "micrometer"} for n in "zyx"]
    transforms = [[{"type": "scale", "scale": [1.0, 2.0 * f, 0.5 * f, 0.25 * f]},
                   {"type": "translation", "translation": [0.0, 10.0, -4.0, 3.0]}]
                  for f in (1, 2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        write_multiscale(levels, root, fmt=fmt, axes=axes,
                         coordinate_transformations=transforms)
    volume = read_volume(tmp_path / "img.ome.zarr")
    assert volume.name == "img" and volume.frame.unit == "micrometer"
    np.testing.assert_array_equal(np.asarray(volume.data), zyx.transpose(2, 1, 0))
    np.testing.assert_allclose(volume.frame.affine,
                               [[0.25, 0, 0, 3.0], [0, 0.5, 0, -4.0], [0, 0, 2.0, 10.0],
                                [0, 0, 0, 1]])
    coarse = read_volume(tmp_path / "img.ome.zarr", ome_level=1)
    np.testing.assert_array_equal(np.asarray(coarse.data), zyx[::2, ::2, ::2].transpose(2, 1, 0))
    assert coarse.spacing == (0.5, 1.0, 4.0)
    assert main(["segment", str(tmp_path / "img.ome.zarr"), "--ome-level", "2", "-o",
                 str(tmp_path / "o")]) == 2
    assert "--ome-level 2 is not one of its 2 levels (0 to 1)" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "img.ome.zarr")]) == 0
    assert "(micrometer)" in capsys.readouterr().out


def test_volseg_ome_zarr_output_reads_back_as_its_curvature(tmp_path, volume):
    """The NGFF output is an input like any OME-Zarr image: its level 0 is the
    curvature, on the input's grid and frame."""
    from volseg.io import read_volume

    np.save(tmp_path / "v.npy", volume)
    assert main(["segment", str(tmp_path / "v.npy"), "-o", str(tmp_path / "o"), "-q",
                 "--regions", "4"]) == 0
    back = read_volume(tmp_path / "o" / "v_segmentation.ome.zarr")
    curvature = nibabel.load(tmp_path / "o" / "v_curvature.nii.gz")
    np.testing.assert_array_equal(np.asarray(back.data), np.asarray(curvature.dataobj))
    np.testing.assert_allclose(back.frame.affine, curvature.affine)


@pytest.mark.parametrize("zarr_format", [2, 3])
def test_a_blosc_chunk_cut_short_is_refused_not_read_as_garbage(tmp_path, zarr_format):
    """Noise compresses badly, so blosc stores the chunk raw; cut to half its length it
    used to decode past its end: different garbage on every read. Now the chunk's
    length is checked against its blosc header before anything is decoded."""
    import zarr
    from zarr.codecs import BloscCodec

    from volseg.io import VolumeFileError, read_volume

    store = tmp_path / f"noise{zarr_format}.zarr"
    compressors = (BloscCodec(cname="lz4", clevel=5) if zarr_format == 3
                   else __import__("numcodecs").Blosc(cname="lz4", clevel=5))
    array = zarr.create_array(str(store), shape=(32, 32, 32), chunks=(32, 32, 16),
                              dtype="f8", zarr_format=zarr_format, compressors=compressors)
    array[:] = np.random.default_rng(0).random((32, 32, 32))
    assert np.array_equal(np.asarray(read_volume(store).data), array[:])     # whole: fine
    chunk = store / array.metadata.encode_chunk_key((0, 0, 1))
    chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])
    with pytest.raises(VolumeFileError, match="blosc header says .* cut short"):
        read_volume(store)
