"""The napari plugin through napari itself: the manifest, the reader's layers, the
widget's run, the live cut and the output set, against the library and the CLI."""

from pathlib import Path

import numpy as np
import pytest

from volseg import segment_volume
from volseg.datasets import demo_volume
from volseg.io import Frame, write_volume

from .conftest import missing

if not missing():
    from volseg.napari_plugin import open_in

if missing():
    pytest.skip(missing(), allow_module_level=True)

WAIT_MS = 240_000


def _widget(viewer):
    from volseg.napari_plugin._widget import SegmentWidget

    widget = SegmentWidget(viewer)
    viewer.window.add_dock_widget(widget)
    return widget


def _run(qtbot, widget, **settings):
    for name, value in settings.items():
        getattr(widget, name).setValue(value) if hasattr(getattr(widget, name), "setValue") \
            else getattr(widget, name).setCurrentText(value)
    widget.start()
    qtbot.waitUntil(lambda: widget.worker is None, timeout=WAIT_MS)
    assert widget.live.result is not None, widget.status.text()
    return widget.live.result


def test_manifest_names_the_reader_widget_and_sample():
    import npe2

    manager = npe2.PluginManager.instance()
    manager.discover()
    manifest = manager.get_manifest("volseg")
    commands = {c.id: c.python_name for c in manifest.contributions.commands}
    for command in commands.values():      # every command resolves to an object
        module, name = command.split(":")
        assert hasattr(__import__(module, fromlist=[name]), name), command
    assert "*_summary.json" in manifest.contributions.readers[0].filename_patterns
    menu = {item.command for item in manifest.contributions.menus["napari/file/io_utilities"]}
    assert menu == {"volseg.open_file", "volseg.open_folder"}


def test_the_reader_claims_only_what_no_other_reader_opens(make_napari_viewer, tmp_path):
    """A .nii.gz, .tif, .npy, .mha or Zarr store opened (or dropped) with volseg
    installed goes to napari's own readers with no question; volseg's summaries and
    the formats only it reads are its own, and anything else opens by name."""
    import npe2

    manager = npe2.PluginManager.instance()
    manager.discover()
    store = tmp_path / "image.ome.zarr"
    store.mkdir()

    def claims(path):
        return any(r.plugin_name == "volseg" for r in manager.iter_compatible_readers([path]))

    for name in ("scan.nii.gz", "scan.nii", "stack.tif", "stack.tiff", "a.npy", "ct.mha",
                 "ct.mhd", str(store), str(tmp_path)):
        assert not claims(str(tmp_path / name)), name
    for name in ("fuel_summary.json", "fuel.raw", "fuel.dat", "ct.nrrd", "ct.nhdr"):
        assert claims(str(tmp_path / name)), name
    # A .tif opened as a user opens it: napari's own reader, no question asked.
    import tifffile

    tifffile.imwrite(tmp_path / "stack.tif", np.zeros((4, 5, 6), np.uint8))
    layer, = make_napari_viewer().open(str(tmp_path / "stack.tif"), plugin=None)
    assert layer.data.shape == (4, 5, 6)


@pytest.fixture
def rotated_um_nifti(tmp_path):
    """The demo volume as a NIfTI in micrometres, rotated and translated."""
    data = demo_volume(24).astype(np.float32)
    angle = np.deg2rad(30)
    affine = np.eye(4)
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0],
                         [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    affine[:3, :3] = rotation @ np.diag([0.5, 0.5, 2])
    affine[:3, 3] = [10, -4, 3]
    path = tmp_path / "rot.nii.gz"
    write_volume(path, data, frame=Frame(affine, unit="micrometer"))
    return path


def test_reader_places_the_input_as_its_frame(make_napari_viewer, rotated_um_nifti, tmp_path):
    viewer = make_napari_viewer()
    layer, = open_in(viewer, rotated_um_nifti)
    volume = layer.metadata["volseg_volume"]
    assert layer.data.shape == volume.shape[::-1]           # z, y, x
    assert np.array_equal(np.asarray(layer.data), np.asarray(volume.data).transpose(2, 1, 0))
    # A voxel's world position in napari is the frame's, axes reversed.
    voxel = np.array([3, 5, 7])
    world = volume.frame.affine @ [*voxel, 1]
    assert np.allclose(layer.data_to_world(voxel[::-1]), world[:3][::-1])
    assert [str(u) for u in layer.units] == ["micrometer"] * 3
    # An axis-aligned input gets scale and translation, no affine.
    plain = tmp_path / "plain.nii.gz"
    write_volume(plain, np.zeros((6, 7, 8), np.float32), frame=Frame(
        np.array([[0.5, 0, 0, 1], [0, 2, 0, 2], [0, 0, 3, 3], [0, 0, 0, 1.0]])))
    layer, = open_in(viewer, plain)
    assert tuple(layer.scale) == (3, 2, 0.5) and tuple(layer.translate) == (3, 2, 1)
    assert np.allclose(layer.affine.affine_matrix, np.eye(4))


def test_reader_refuses_a_bad_file_in_one_line(tmp_path):
    from volseg.napari_plugin._reader import read

    bad = tmp_path / "bad.nii.gz"
    bad.write_bytes(b"\x1f\x8b not really gzip")
    with pytest.raises(ValueError, match="bad.nii.gz") as err:
        read(str(bad))
    assert "\n" not in str(err.value)


def test_reader_opens_an_output_set_and_the_ngff_output(make_napari_viewer, tmp_path):
    from volseg.cli import main

    volume = tmp_path / "blobs.nii.gz"
    write_volume(volume, demo_volume(32).astype(np.float32), frame=Frame(
        np.array([[2.0, 0, 0, 5], [0, 2, 0, 6], [0, 0, 2, 7], [0, 0, 0, 1]]), unit="millimeter"))
    assert main(["segment", str(volume), "--out-dir", str(tmp_path / "out"), "--regions", "6",
                 "-q"]) == 0
    viewer = make_napari_viewer()
    # A summary is volseg's alone: napari opens it without a question (plugin None
    # is a drop or File > Open: napari chooses among the compatible readers).
    curvature, labels = viewer.open(str(tmp_path / "out" / "blobs_summary.json"), plugin=None)
    assert labels._type_string == "labels" and curvature._type_string == "image"
    import nibabel

    expected = np.asanyarray(nibabel.load(tmp_path / "out" / "blobs_labels.nii.gz").dataobj)
    assert np.array_equal(np.asarray(labels.data), expected.transpose(2, 1, 0))
    assert tuple(labels.scale) == (2, 2, 2) and tuple(labels.translate) == (7, 6, 5)
    alone, = open_in(viewer, tmp_path / "out" / "blobs_labels.nii.gz")
    assert alone._type_string == "labels" and tuple(alone.translate) == (7, 6, 5)
    assert np.array_equal(np.asarray(alone.data), expected.transpose(2, 1, 0))
    curvature_ngff, labels_ngff = open_in(viewer, tmp_path / "out" / "blobs_segmentation.ome.zarr")
    assert np.array_equal(np.asarray(labels_ngff.data[0] if labels_ngff.multiscale
                                     else labels_ngff.data), expected.transpose(2, 1, 0))
    assert tuple(labels_ngff.scale) == (2, 2, 2) and tuple(labels_ngff.translate) == (7, 6, 5)


def test_widget_labels_equal_segment_volume_and_the_slider_recuts(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    data = demo_volume(32)
    viewer.add_image(data, name="blobs", scale=(1.0, 1.5, 2.0))
    widget = _widget(viewer)
    result = _run(qtbot, widget, regions=8)
    expected = segment_volume(data, spacing=(1.0, 1.5, 2.0), n_regions=8)
    assert np.array_equal(widget.labels_layer.data, expected.labels)
    assert np.array_equal(widget.curvature_layer.data, expected.curvature)
    assert tuple(widget.labels_layer.scale) == (1.0, 1.5, 2.0)
    # The smallest type that holds every cut (a quarter of int32's texture)...
    assert widget.labels_layer.data.dtype == np.uint8 and widget.live.max_regions() < 256
    # ... and the output set still gets the CLI's int32.
    assert widget.live.snapshot().labels.dtype == np.int32
    assert result.n_regions == 8 and widget.count_box.value() == 8
    for k in (3, 12, 5, 1):
        widget.count_box.setValue(k)             # as a user types it
        assert np.array_equal(widget.labels_layer.data,
                              expected.hierarchy.segment(**_count_cut(expected, k)))
        assert widget.count_label.text() == f"{k} regions"
    # The slider is a log scale of the count: every position cuts to the count it shows.
    top = widget.live.max_regions()
    for position in (0, 250, 500, 999, 1000):
        widget.count_slider.setValue(position)   # as a user drags it
        widget._count_throttled.flush()          # the drag's last position ...
        widget.wait_for_cut()                    # ... cut in its thread, and shown
        k = widget.count_box.value()
        assert k == min(max(round(top ** (position / 1000)), 1), top)
        assert np.array_equal(widget.labels_layer.data,
                              expected.hierarchy.segment(**_count_cut(expected, k)))
    # The threshold slider cuts by the measure; the count follows.
    widget.threshold_slider.setValue(widget.threshold_slider.maximum())
    widget._threshold_throttled.flush()
    widget.wait_for_cut()
    assert widget.live.result.n_regions == expected.hierarchy.n_components
    widget.threshold_slider.setValue(0)
    widget._threshold_throttled.flush()
    widget.wait_for_cut()
    assert widget.live.result.n_regions == widget.live.max_regions()
    # Another measure recuts at once, with the same count, and its own curve.
    widget.count_box.setValue(6)
    widget.measure.setCurrentText("persistence")
    assert widget.live.result.measure == "persistence" and widget.live.result.n_regions == 6
    assert np.array_equal(widget.labels_layer.data, expected.hierarchy.segment(
        n_regions=6, measure="persistence", min_component=expected.cut["min_component"]))
    assert widget.threshold_label.text().startswith("persistence ")
    widget.measure.setCurrentText(expected.measure)
    # A region's details are the region table's.
    widget.count_box.setValue(4)
    info = widget.show_region(2)
    table = widget.live.result.region_table()[1]
    assert info["size"] == table["size"] and info["maximum"] == table["maximum"]
    assert "region 2:" in widget.region_info.text()
    # Shown in the layer's own index, where napari's status bar puts the cursor.
    assert widget.labels_layer.data[info["layer_index"]] == 2
    assert widget.live.result.labels[tuple(info["maximum"])] == 2


def test_widget_segments_the_field_chosen_and_names_it(make_napari_viewer, qtbot):
    """The field is a choice of the widget; the measure's first entry is the field's
    default; the field's layer is named for it and hidden (it would hide the image)."""
    viewer = make_napari_viewer()
    data = demo_volume(32)
    viewer.add_image(data, name="blobs")
    widget = _widget(viewer)
    result = _run(qtbot, widget, regions=7, field="gradient")
    expected = segment_volume(data, field="gradient", n_regions=7)
    assert result.field == "gradient" and result.measure == expected.measure
    assert np.array_equal(widget.labels_layer.data, expected.labels)
    assert widget.curvature_layer.name == "blobs gradient"
    assert not widget.curvature_layer.visible
    widget.measure.setCurrentText("persistence")
    widget.measure.setCurrentText(widget.measure.itemText(0))      # back to the default
    assert widget.live.result.measure == "volume"


def test_a_slider_drag_cuts_at_most_once_per_throttle_period(make_napari_viewer, qtbot):
    """A drag over 40 positions, one every 10 ms (a quick drag at 100 Hz), cuts at most
    10 times, each in a thread (the main thread only shows it), and the labels end as
    the last position's cut; the marker on the curve is painted with the window (no
    synchronous repaint)."""
    import threading

    from volseg.napari_plugin._widget import SLIDER_THROTTLE_MS

    viewer = make_napari_viewer()
    viewer.add_image(demo_volume(32), name="blobs")
    widget = _widget(viewer)
    expected = _run(qtbot, widget, regions=8)
    cuts, threads = [], set()
    prepare = widget.live.prepare

    def counted(*args, **kwargs):
        cuts.append(kwargs)
        threads.add(threading.current_thread() is threading.main_thread())
        return prepare(*args, **kwargs)

    widget.live.prepare = counted
    # A cut that fails with a bug (no result) does not stall the queue.
    widget.live.prepare = lambda *args, **kwargs: {}["a bug"]
    with qtbot.capture_exceptions() as raised:        # napari shows it; pytest-qt keeps it
        widget.count_slider.setValue(500)
        qtbot.waitUntil(lambda: widget._cutting is None, timeout=5000)
    assert [kind.__name__ for kind, *_ in raised] == ["KeyError"]
    widget.live.prepare = counted
    widget.count_slider.setValue(0)
    qtbot.wait(2 * SLIDER_THROTTLE_MS)
    widget.wait_for_cut()
    cuts.clear()
    repaints = []
    widget.canvas.repaint = lambda *args: repaints.append(args)
    for position in np.linspace(0, 1000, 40).astype(int):
        widget.count_slider.setValue(int(position))
        qtbot.wait(10)
    qtbot.wait(3 * SLIDER_THROTTLE_MS)
    widget.wait_for_cut()
    assert 2 <= len(cuts) <= 10, cuts
    assert threads == {False}
    top = widget.live.max_regions()
    assert cuts[-1] == {"n_regions": top} and widget.count_box.value() == top
    assert np.array_equal(widget.labels_layer.data,
                          expected.hierarchy.segment(**_count_cut(expected, top)))
    assert not repaints


def _count_cut(result, k):
    return {"n_regions": k, "measure": result.measure,
            "min_component": result.cut["min_component"]}


def test_output_button_writes_the_clis_set(make_napari_viewer, qtbot, rotated_um_nifti, tmp_path):
    import json

    import nibabel

    from volseg.cli import main

    viewer = make_napari_viewer()
    open_in(viewer, rotated_um_nifti)
    widget = _widget(viewer)
    _run(qtbot, widget, regions=10)
    widget.count_box.setValue(7)
    widget.out_dir.setText(str(tmp_path / "gui"))
    (tmp_path / "gui").mkdir()
    widget._write_clicked()
    assert not widget.run_button.isEnabled()       # no second worker while it writes
    qtbot.waitUntil(lambda: widget.worker is None, timeout=WAIT_MS)
    assert widget.write_button.isEnabled() and widget.run_button.isEnabled()
    assert widget.status.text().startswith("wrote rot_labels.nii.gz")
    widget._write_clicked()                         # again, without "overwrite"
    qtbot.waitUntil(lambda: widget.worker is None, timeout=WAIT_MS)
    assert "exist" in widget.status.text() and "\n" not in widget.status.text()
    assert main(["segment", str(rotated_um_nifti), "--out-dir", str(tmp_path / "cli"),
                 "--regions", "7", "-q"]) == 0
    gui, cli = (sorted(p.name for p in (tmp_path / d).iterdir()) for d in ("gui", "cli"))
    assert gui == cli
    for name in ("rot_labels.nii.gz", "rot_curvature.nii.gz"):
        a, b = (nibabel.load(tmp_path / d / name) for d in ("gui", "cli"))
        assert np.array_equal(np.asanyarray(a.dataobj), np.asanyarray(b.dataobj))
        assert np.array_equal(a.affine, b.affine) and a.header == b.header
    summaries = [json.loads((tmp_path / d / "rot_summary.json").read_text())
                 for d in ("gui", "cli")]
    for summary in summaries:
        summary.pop("timings_s"), summary.pop("outputs")
    assert summaries[0] == summaries[1]
    # A region's maximum is given in the layer's z, y, x index and world position.
    info = widget.show_region(1)
    assert info["layer_index"] == tuple(info["maximum"][::-1])
    assert widget.labels_layer.data[info["layer_index"]] == 1
    np.testing.assert_allclose(widget.labels_layer.data_to_world(info["layer_index"]),
                               info["world"])
    # The labels layer shows the cut that was written.
    written = np.asanyarray(nibabel.load(tmp_path / "gui" / "rot_labels.nii.gz").dataobj)
    assert np.array_equal(np.asarray(widget.labels_layer.data), written.transpose(2, 1, 0))


def test_widget_cancel_stops_the_run_and_a_bad_layer_says_why(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    viewer.add_image(np.zeros((5, 6)), name="flat2d")
    widget = _widget(viewer)
    widget.image.setCurrentText("flat2d")
    widget.start()
    assert "3-D volumes" in widget.status.text() and widget.worker is None
    viewer.add_image(demo_volume(24), name="blobs")
    widget.image.setCurrentText("blobs")
    widget.start()
    widget.cancel()                       # before its first stage starts, or during one
    qtbot.waitUntil(lambda: widget.worker is None, timeout=WAIT_MS)
    assert widget.status.text() == "cancelled"
    assert widget.labels_layer is None
    # A parameter volseg refuses is one status line, not a traceback dialog.
    widget.mask.setText("value>banana")
    widget.start()
    qtbot.waitUntil(lambda: widget.worker is None, timeout=WAIT_MS)
    assert "banana" in widget.status.text() and widget.labels_layer is None


def test_widget_segments_a_dask_layer_blockwise(make_napari_viewer, qtbot):
    import dask.array as da

    viewer = make_napari_viewer()
    data = demo_volume(24)
    viewer.add_image(da.from_array(data, chunks=(10, 13, 24)), name="lazy")
    widget = _widget(viewer)
    _run(qtbot, widget, regions=6)
    expected = segment_volume(data, n_regions=6)
    assert np.array_equal(np.asarray(widget.labels_layer.data), expected.labels)
    widget.count_box.setValue(3)
    assert np.array_equal(np.asarray(widget.labels_layer.data),
                          expected.hierarchy.segment(**_count_cut(expected, 3)))
    work = widget.live._work
    assert work is not None and Path(work).is_dir()
    widget.close()
    assert not Path(work).exists()


def test_sample_data_and_a_click_on_a_region(make_napari_viewer, qtbot):
    from types import SimpleNamespace

    viewer = make_napari_viewer()
    layer, = viewer.open_sample("volseg", "demo")
    assert layer.data.shape == (48, 48, 48) and "volseg_volume" in layer.metadata
    widget = _widget(viewer)
    _run(qtbot, widget, regions=5)
    labels = widget.labels_layer
    where = tuple(int(i) for i in np.argwhere(np.asarray(labels.data) == 3)[0])
    event = SimpleNamespace(position=labels.data_to_world(where), view_direction=None,
                            dims_displayed=[1, 2])
    widget._clicked(labels, event)       # what napari calls on a mouse press on the layer
    assert widget.region_info.text().startswith("region 3:")
    assert _clicked_twice_is_harmless(widget, labels)


def _clicked_twice_is_harmless(widget, labels):
    """A press outside every region (label 0, or off the volume) changes nothing."""
    from types import SimpleNamespace

    before = widget.region_info.text()
    widget._clicked(labels, SimpleNamespace(position=(-50.0, -50.0, -50.0), view_direction=None,
                                            dims_displayed=[1, 2]))
    return widget.region_info.text() == before


def test_reader_reads_a_store_with_skipped_chunks_and_says_so(tmp_path):
    from volseg.napari_plugin._reader import read

    from ..outputs.test_labels_into_input import _sparse_ome_image

    image, data = _sparse_ome_image(tmp_path / "sparse.ome.zarr")
    with pytest.warns(UserWarning, match="--fill-missing-chunks"):
        (layer_data, options, kind), = read(str(image))
    assert kind == "image"
    np.testing.assert_array_equal(np.asarray(layer_data), data)


def test_reader_refuses_a_fifo_and_names_a_missing_file(tmp_path):
    """A FIFO named like a summary is not opened (it would block the viewer); a summary
    whose files are gone is a one-line error naming the file; a gradient run's set is
    read by its field's name (issue 57, #10)."""
    import os

    from volseg.cli import main
    from volseg.napari_plugin._reader import napari_get_reader, read

    fifo = tmp_path / "x_summary.json"
    os.mkfifo(fifo)
    assert napari_get_reader(str(fifo)) is None
    np.save(tmp_path / "b.npy", demo_volume(24))
    assert main(["segment", str(tmp_path / "b.npy"), "-o", str(tmp_path / "out"), "-q",
                 "--regions", "5", "--field", "gradient", "--no-vti"]) == 0
    summary = tmp_path / "out" / "b_summary.json"
    field, labels = read(str(summary))
    assert field[1]["name"] == "b gradient" and labels[2] == "labels"
    (tmp_path / "out" / "b_labels.nii.gz").unlink()
    with pytest.raises(ValueError, match="b_labels.nii.gz is missing"):
        read(str(summary))
