"""``--labels-into-input``: the labels added to an OME-Zarr input as its NGFF labels
image ``labels/<name>``, in the input's own NGFF version (0.4 and 0.5) and axis order,
where ome-zarr-py and napari-ome-zarr find an image's labels; refused clearly for
anything else; the input image itself untouched."""

import json
import warnings

import nibabel
import numpy as np
import pytest

from volseg.cli import main
from volseg.datasets import demo_volume

SCALE, TRANSLATION = [2.0, 1.0, 0.5], [5.0, 6.0, 7.0]


def _ome_image(path, version: str):
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from ome_zarr.format import FormatV04, FormatV05
        from ome_zarr.writer import write_multiscale

        fmt = FormatV04() if version == "0.4" else FormatV05()
        root = zarr.open_group(str(path), mode="w", zarr_format=fmt.zarr_format)
        write_multiscale([demo_volume(40).transpose(2, 1, 0)], root, fmt=fmt,
                         axes=[{"name": a, "type": "space", "unit": "micrometer"} for a in "zyx"],
                         coordinate_transformations=[[{"type": "scale", "scale": SCALE},
                                                      {"type": "translation",
                                                       "translation": TRANSLATION}]])
    return path


def _labels_node(image):
    """ome-zarr-py's node of ``labels/volseg``, found by walking the image as its reader
    does (image, then its labels)."""
    from ome_zarr.io import parse_url
    from ome_zarr.reader import Reader

    found = [node for node in Reader(parse_url(str(image)))()
             if "labels/volseg" in str(node).split(" ")[0]]
    assert len(found) == 1, [str(node) for node in Reader(parse_url(str(image)))()]
    return found[0]


def _image_bytes(path) -> dict:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file() and p.relative_to(path).parts[0] != "labels"}


@pytest.mark.parametrize("version", ["0.4", "0.5"])
def test_labels_land_in_the_input_image_where_readers_find_them(tmp_path, version):
    image = _ome_image(tmp_path / "cells.ome.zarr", version)
    before = _image_bytes(image)
    assert main(["segment", str(image), "-o", str(tmp_path / "out"), "--labels-into-input",
                 "--regions", "6", "-q"]) == 0
    assert _image_bytes(image) == before                   # the image is as it was
    nifti = np.asarray(nibabel.load(tmp_path / "out" / "cells_labels.nii.gz").dataobj)

    labels = _labels_node(image)
    assert [type(s).__name__ for s in labels.specs] == ["Label", "Multiscales"]
    assert [a["name"] for a in labels.metadata["axes"]] == ["z", "y", "x"]
    scale, translation = labels.metadata["coordinateTransformations"][0]
    assert scale["scale"] == SCALE and translation["translation"] == TRANSLATION
    np.testing.assert_array_equal(np.asarray(labels.data[0]), nifti.transpose(2, 1, 0))

    # napari-ome-zarr opens the image with our labels as a labels layer beside it.
    napari_ome_zarr = pytest.importorskip("napari_ome_zarr")
    layers = [(kind, data) for data, _, kind in
              napari_ome_zarr.napari_get_reader(str(image))(str(image))]
    kinds = [kind for kind, _ in layers]
    assert kinds.count("labels") == 1 and kinds.count("image") == 1
    data = dict(layers)["labels"]
    np.testing.assert_array_equal(np.asarray(data[0] if isinstance(data, list) else data),
                                  nifti.transpose(2, 1, 0))

    # The input's checksum ignores its labels: a second run reads the same input.
    assert main(["segment", str(image), "-o", str(tmp_path / "again"), "--labels-into-input",
                 "--regions", "4", "--force", "-q"]) == 0
    first, second = (json.loads((tmp_path / d / "cells_summary.json").read_text())
                     for d in ("out", "again"))
    assert first["input_sha256"] == second["input_sha256"]
    again = np.asarray(nibabel.load(tmp_path / "again" / "cells_labels.nii.gz").dataobj)
    labels = _labels_node(image)
    np.testing.assert_array_equal(np.asarray(labels.data[0]), again.transpose(2, 1, 0))
    assert not any(p.name.startswith(".volseg") for p in (image / "labels").iterdir())


def test_labels_into_input_refusals_come_before_any_output(tmp_path, capsys):
    image = _ome_image(tmp_path / "cells.ome.zarr", "0.5")
    nifti = tmp_path / "plain.npy"
    np.save(nifti, demo_volume(16))
    cases = [([str(nifti)], "is not an OME-Zarr image"),
             ([str(image), "--labels-into-input", "../up"], "is not a labels image name")]
    for extra, message in cases:
        inputs, options = extra[:1], extra[1:] or ["--labels-into-input"]
        assert main(["segment", *inputs, "-o", str(tmp_path / "out"), *options, "-q"]) == 2
        assert message in capsys.readouterr().err
    assert main(["segment", str(image), "-o", str(tmp_path / "out"), "--labels-into-input",
                 "-q"]) == 0
    assert main(["segment", str(image), "-o", str(tmp_path / "out2"), "--labels-into-input",
                 "-q"]) == 2
    err = capsys.readouterr().err
    assert "labels/volseg exists; give --force" in err and str(image) in err
    assert not (tmp_path / "out2").exists() or not any((tmp_path / "out2").iterdir())


def test_a_blockwise_run_adds_its_stored_labels(tmp_path):
    """The blockwise path's labels (a Zarr store, never whole in memory) go into the
    input image block by block and equal the run's own labels store."""
    from volseg.files import load_volume

    image = _ome_image(tmp_path / "cells.ome.zarr", "0.5")
    assert main(["segment", str(image), "-o", str(tmp_path / "out"), "--chunks", "16",
                 "--labels-into-input", "regions-v1", "--regions", "6", "-q"]) == 0
    added = np.asarray(load_volume(str(image / "labels" / "regions-v1")).data)
    stored = np.asarray(load_volume(str(tmp_path / "out" / "cells_labels.zarr")).data)
    np.testing.assert_array_equal(added, stored)
    assert added.max() == 6


def test_what_a_killed_writer_left_is_undone(tmp_path):
    """A kill while staging leaves a hidden staging group (removed); a kill between
    moving the old labels image aside and moving the new one in leaves only the old one
    aside (moved back): readers never find a listed labels image missing or partial."""
    import shutil

    from volseg.files import load_volume
    from volseg.io.ngff import recover_labels, write_labels_into

    image = _ome_image(tmp_path / "cells.ome.zarr", "0.4")
    first = (np.asarray(load_volume(str(image)).data) > 100).astype(np.uint8)
    write_labels_into(image, first)
    root = image / "labels"
    # Killed between the two renames of a replacement: the old image is aside.
    (root / "volseg").rename(root / ".volseg.volseg-old")
    shutil.copytree(root / ".volseg.volseg-old", root / ".volseg.volseg-staging")
    recover_labels(image, "volseg")
    assert sorted(p.name for p in root.iterdir() if not p.name.startswith(".z")) == ["volseg"]
    np.testing.assert_array_equal(np.asarray(load_volume(str(root / "volseg")).data), first)
    # Killed after the new one arrived: the old copy aside is removed.
    shutil.copytree(root / "volseg", root / ".volseg.volseg-old")
    second = 1 - first
    write_labels_into(image, second, force=True)
    assert not any(p.name.startswith(".volseg") for p in root.iterdir())
    np.testing.assert_array_equal(np.asarray(load_volume(str(root / "volseg")).data), second)
    # A planted link where volseg's own groups go is refused, not followed.
    (root / ".volseg.volseg-old").symlink_to(tmp_path)
    with pytest.raises(ValueError, match="is a link"):
        recover_labels(image, "volseg")


@pytest.mark.parametrize("version", ["0.4", "0.5"])
def test_background_chunks_are_written_so_volseg_reads_its_own_outputs(tmp_path, version):
    """Zarr skips chunks of the fill value by default, and volseg's reader refuses a
    store with missing chunks: every chunk of the NGFF output and of the labels added
    to an input is written, so both read back through volseg (and its napari reader)."""
    import zarr

    from volseg.files import load_volume
    from volseg.io import Frame, write_ngff
    from volseg.io.ngff import write_labels_into

    labels = np.zeros((130, 140, 150), np.uint8)        # 3 x 3 x 3 chunks, 26 all zero
    labels[60:70, 60:70, 60:70] = 1
    out = write_ngff(tmp_path / "x.ome.zarr", labels, np.zeros(labels.shape),
                     Frame.from_spacing((1.0, 2.0, 3.0)))
    for sub in ("", "labels/regions"):
        for level in (0, 1):
            data = np.asarray(load_volume(str(out / sub), ome_level=level).data)
            assert data.shape == tuple(s // 2**level for s in labels.shape)
    np.testing.assert_array_equal(np.asarray(load_volume(str(out / "labels/regions")).data),
                                  labels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from ome_zarr.format import FormatV04, FormatV05
        from ome_zarr.writer import write_multiscale

        fmt = FormatV04() if version == "0.4" else FormatV05()
        root = zarr.open_group(str(tmp_path / "in.ome.zarr"), mode="w",
                               zarr_format=fmt.zarr_format)
        write_multiscale([np.zeros(labels.shape[::-1], np.uint8)], root, fmt=fmt,
                         axes=[{"name": a, "type": "space"} for a in "zyx"])
    added = write_labels_into(tmp_path / "in.ome.zarr", labels)
    np.testing.assert_array_equal(np.asarray(load_volume(str(added)).data), labels)


def _sparse_ome_image(path):
    """An OME-Zarr image as ome-zarr-py writes it by default: chunks of the fill value
    (an empty background) are not written at all."""
    import zarr

    data = np.zeros((40, 40, 130), np.uint8)             # z, y, x: 1 x 1 x 3 chunks of 64
    data[:, :, :40] = demo_volume(40).transpose(2, 1, 0)[:, :, :40]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import dask.array as da
        from ome_zarr.format import FormatV05
        from ome_zarr.writer import write_multiscale

        root = zarr.open_group(str(path), mode="w", zarr_format=3)
        write_multiscale([da.from_array(data, chunks=64)], root, fmt=FormatV05(),
                         axes=[{"name": a, "type": "space"} for a in "zyx"])
    written = zarr.open_array(str(path / "s0"), mode="r")
    assert written.nchunks_initialized < written.nchunks      # as the writer leaves it
    return path, data


def test_a_store_whose_writer_skipped_empty_chunks_reads_on_request(tmp_path, capsys):
    """Refused by default (an interrupted copy looks the same), with the way out named;
    `--fill-missing-chunks` reads the skipped chunks as the fill value, exactly."""
    from volseg import segment_volume
    from volseg.files import load_volume

    image, data = _sparse_ome_image(tmp_path / "sparse.ome.zarr")
    assert main(["segment", str(image), "-o", str(tmp_path / "no"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "chunks are missing" in err and "--fill-missing-chunks" in err
    assert main(["info", str(image), "--fill-missing-chunks"]) == 0
    assert main(["segment", str(image), "-o", str(tmp_path / "out"), "--regions", "4",
                 "--fill-missing-chunks", "-q"]) == 0
    read = np.asarray(load_volume(str(image), fill_missing_chunks=True).data)
    np.testing.assert_array_equal(read, data.transpose(2, 1, 0))
    expected = segment_volume(data.transpose(2, 1, 0), n_regions=4)
    written = np.asarray(nibabel.load(tmp_path / "out" / "sparse_labels.nii.gz").dataobj)
    np.testing.assert_array_equal(written, expected.labels)


@pytest.mark.parametrize("version", ["0.4", "0.5"])
def test_labels_added_to_an_input_validate_in_its_ngff_version(tmp_path, version):
    """The input with volseg's labels added is still an image ome-zarr-models reads,
    in its own version, labels listed and versioned."""
    import zarr
    from ome_zarr_models import open_ome_zarr

    image = _ome_image(tmp_path / f"in{version}.ome.zarr", version)
    assert main(["segment", str(image), "-o", str(tmp_path / "o"), "-q", "--regions", "3",
                 "--labels-into-input"]) == 0
    model = open_ome_zarr(zarr.open_group(str(image), mode="r"))
    assert type(model).__module__.startswith(f"ome_zarr_models.v0{version[-1]}")
    labels = open_ome_zarr(zarr.open_group(str(image / "labels" / "volseg"), mode="r"))
    assert type(labels).__name__ == "ImageLabel"


def test_labels_into_input_hazards_are_refused_before_computing(tmp_path, capsys):
    """Issue 57, #3, #9, #11: a Zarr metadata name, a labels group that is a file,
    garbage labels metadata, a read-only image and a user's file at labels/<name> are
    refused before anything is computed or written, naming the path, and the image is
    left as it was."""
    import os
    import shutil

    base = _ome_image(tmp_path / "base.ome.zarr", "0.5")

    def fresh(name):
        copy = tmp_path / name
        shutil.copytree(base, copy)
        return copy

    def refused(image, message, *options):
        before = _image_bytes(image)
        out = tmp_path / f"out-{image.name}"
        assert main(["segment", str(image), "-o", str(out), "-q", *options]) == 2
        assert message in capsys.readouterr().err
        assert _image_bytes(image) == before and not out.exists()

    refused(fresh("a.ome.zarr"), "Zarr keeps for its own metadata",
            "--labels-into-input", "zarr.json")
    image = fresh("b.ome.zarr")
    (image / "labels").write_text("not a group")
    refused(image, "is a file, not the image's labels group", "--labels-into-input")
    image = fresh("c.ome.zarr")
    (image / "labels").mkdir()
    (image / "labels" / "zarr.json").write_text("{garbage")
    refused(image, "is not readable JSON", "--labels-into-input")
    image = fresh("d.ome.zarr")
    (image / "labels").mkdir()
    (image / "labels" / "volseg").write_text("a user's notes")
    refused(image, "is a file, not a labels image", "--labels-into-input", "--force")
    if os.geteuid() != 0:                          # root writes through any mode
        image = fresh("e.ome.zarr")
        os.chmod(image, 0o555)
        try:
            refused(image, "is not writable", "--labels-into-input")
        finally:
            os.chmod(image, 0o755)


def _add_labels(args):
    from volseg.io.ngff import write_labels_into

    image, name = args
    write_labels_into(image, np.full((40, 40, 40), len(name), np.uint8), name=name)
    return name


def test_writers_of_different_names_lose_no_listing_entry(tmp_path):
    """Issue 57, #4: the listing is one shared file; eight processes adding eight names
    at once leave all eight listed."""
    import multiprocessing

    image = _ome_image(tmp_path / "many.ome.zarr", "0.5")
    names = [f"run{i}" for i in range(8)]
    with multiprocessing.get_context("spawn").Pool(4) as pool:
        assert sorted(pool.map(_add_labels, [(str(image), n) for n in names])) == names
    meta = json.loads((image / "labels" / "zarr.json").read_text())
    assert sorted(meta["attributes"]["ome"]["labels"]) == names
