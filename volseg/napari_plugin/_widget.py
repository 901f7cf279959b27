"""The dock widget: segment an image layer, then choose the cut by looking.

- parameters (operator, smoothing, mask rule, measure, regions) and a run in a napari
  thread worker, with per-stage progress and a Cancel that stops it at the next stage;
- the live cut: a region-count slider and a threshold slider (log scale) that
  relabel the labels layer from the hierarchy (`LiveSegmentation.cut`: no
  recomputation; a drag cuts at most once per `SLIDER_THROTTLE_MS`, and always at
  the position it stops, each cut in a thread while the layer shows the last one),
  the curve of the measure beside them with the cut marked;
- a click on a region shows its size, its maximum and its persistence;
- "Write output set" writes the current cut as ``volseg segment`` would.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from napari.layers import Image
from napari.qt.threading import create_worker
from qtpy.QtCore import QObject, Qt, Signal
from qtpy.QtWidgets import (
    QApplication,
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QSlider,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)
from superqt.utils import qthrottled

from ..curvature import OPERATORS
from ..fields import FIELDS
from ..morse import MEASURES
from ..segment import DEFAULT_REGIONS
from ._layers import LayerVolume
from ._live import Cancelled, LiveSegmentation, Options

__all__ = ["SegmentWidget"]

#: The measure entry that leaves the choice to the field (`volseg.fields.Field.measure`).
FIELD_DEFAULT = "field's default"
#: Stages a run reports (`volseg.segment.run_stages`): the progress bar's steps.
STAGES = ("curvature", "morse", "cut", "labels")
#: Positions of the sliders: log scales of the region count (1 to every maximum) and
#: of the threshold (the smallest to the largest extinction).
SLIDER_STEPS = 1000
#: A dragged slider cuts at most once per this many milliseconds (the first position
#: at once, the last when the drag pauses): a drag over 40 positions in a second or
#: two makes about 10 cuts, not 40, and the viewer keeps up.
SLIDER_THROTTLE_MS = 100


def _guarded(function, *args, **kwargs) -> tuple:
    """(result, None), or (None, the error) for what a user can act on: a cancel, a
    refused input, parameter or output (volseg's errors are ValueErrors with one-line
    messages), a full disk. napari shows any other exception with its traceback: a
    bug."""
    try:
        return function(*args, **kwargs), None
    except (Cancelled, ValueError, OSError) as err:
        return None, err


class _Bridge(QObject):
    """Carries a worker thread's progress lines to the GUI thread (queued signal)."""

    said = Signal(str)


class SegmentWidget(QWidget):
    """Curvature segmentation of the selected image layer, with a live cut."""

    def __init__(self, napari_viewer):
        super().__init__()
        self.viewer = napari_viewer
        self.live: LiveSegmentation | None = None
        self.labels_layer = None
        self.curvature_layer = None
        self.worker = None
        self._cutting = None         # the worker of the cut being computed, if any
        self._pending = None         # the latest cut asked while one was computed
        self._cancel = False
        self._bridge = _Bridge()
        self._bridge.said.connect(self._progress)
        self._build()
        self.viewer.layers.events.inserted.connect(self._refresh_layers)
        self.viewer.layers.events.removed.connect(self._refresh_layers)
        self._refresh_layers()

    # Layout ----------------------------------------------------------------------

    def _build(self):
        layout = QVBoxLayout(self)
        layout.addLayout(self._parameters())
        layout.addLayout(self._run_controls())
        layout.addWidget(self.status)
        layout.addWidget(self._cut_controls())
        layout.addLayout(self._output_controls())
        layout.addStretch()
        self._cut_enabled(False)

    def _parameters(self) -> QFormLayout:
        form = QFormLayout()
        self.image = QComboBox()
        self.operator = QComboBox()
        self.operator.addItems(list(OPERATORS))
        self.smooth = QDoubleSpinBox()
        self.smooth.setRange(-1.0, 10.0)
        self.smooth.setSingleStep(0.5)
        self.smooth.setSpecialValueText("auto")      # shown at the minimum, -1
        self.smooth.setValue(-1.0)
        self.mask = QLineEdit("auto")
        self.mask.setToolTip("auto, none, nonzero, otsu or value>T")
        self.field = QComboBox()
        self.field.addItems(list(FIELDS))
        self.field.setToolTip("curvature: territories around peaks (blobs); gradient: "
                              "basins bounded by edges (anatomy); value: bright blobs")
        self.measure = QComboBox()
        self.measure.addItems([FIELD_DEFAULT, *MEASURES])
        self.measure.setToolTip("the field's default: hypervolume for curvature and value, "
                                "volume (area where degenerate) for gradient")
        self.measure.currentTextChanged.connect(self._measure_changed)
        self.regions = QSpinBox()
        self.regions.setRange(1, 1_000_000)
        self.regions.setValue(DEFAULT_REGIONS)
        for label, widget in (("image", self.image), ("field", self.field),
                              ("operator", self.operator),
                              ("smoothing sigma", self.smooth), ("mask", self.mask),
                              ("measure", self.measure), ("regions", self.regions)):
            form.addRow(label, widget)
        return form

    def _run_controls(self) -> QVBoxLayout:
        buttons = QHBoxLayout()
        self.run_button = QPushButton("Segment")
        self.run_button.clicked.connect(self.start)
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.cancel_button.clicked.connect(self.cancel)
        buttons.addWidget(self.run_button)
        buttons.addWidget(self.cancel_button)
        self.progress = QProgressBar()
        self.progress.setRange(0, len(STAGES))
        self.status = QLabel("")
        self.status.setWordWrap(True)
        column = QVBoxLayout()
        column.addLayout(buttons)
        column.addWidget(self.progress)
        return column

    def _cut_controls(self) -> QGroupBox:
        cut = QGroupBox("cut")
        cut_layout = QFormLayout(cut)
        # Counts on a log scale (2 and 20 as far apart as 200 and 2,000), the exact
        # count in the box beside it.
        self.count_slider = QSlider(Qt.Orientation.Horizontal)
        self.count_slider.setRange(0, SLIDER_STEPS)
        self._count_throttled = qthrottled(self._count_moved, timeout=SLIDER_THROTTLE_MS,
                                           parent=self)
        self.count_slider.valueChanged.connect(self._count_throttled)
        self.count_box = QSpinBox()
        self.count_box.setRange(1, 1)
        self.count_box.valueChanged.connect(self._count_typed)
        self.count_label = QLabel("")
        self.threshold_slider = QSlider(Qt.Orientation.Horizontal)
        self.threshold_slider.setRange(0, SLIDER_STEPS)
        self._threshold_throttled = qthrottled(self._threshold_moved,
                                               timeout=SLIDER_THROTTLE_MS, parent=self)
        self.threshold_slider.valueChanged.connect(self._threshold_throttled)
        self.threshold_label = QLabel("")
        counts = QHBoxLayout()
        counts.addWidget(self.count_slider)
        counts.addWidget(self.count_box)
        cut_layout.addRow("regions", counts)
        cut_layout.addRow("", self.count_label)
        cut_layout.addRow("threshold", self.threshold_slider)
        cut_layout.addRow("", self.threshold_label)
        # Fixed margins: no layout pass on any draw.
        self.figure = Figure(figsize=(3.2, 2.2))
        self.figure.subplots_adjust(left=0.2, right=0.97, bottom=0.22, top=0.95)
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.canvas.setMinimumHeight(180)
        self.canvas.mpl_connect("draw_event", self._captured)
        self._marker = None
        cut_layout.addRow(self.canvas)
        self.region_info = QLabel("click a region")
        self.region_info.setWordWrap(True)
        cut_layout.addRow(self.region_info)
        return cut

    def _output_controls(self) -> QHBoxLayout:
        out = QHBoxLayout()
        self.out_dir = QLineEdit()
        self.out_dir.setPlaceholderText("output folder")
        browse = QPushButton("...")
        browse.clicked.connect(self._browse)
        self.force = QCheckBox("overwrite")
        self.write_button = QPushButton("Write output set")
        self.write_button.clicked.connect(self._write_clicked)
        for widget in (self.out_dir, browse, self.force, self.write_button):
            out.addWidget(widget)
        return out

    def _refresh_layers(self, event=None):
        current = self.image.currentText()
        names = [layer.name for layer in self.viewer.layers if isinstance(layer, Image)]
        self.image.clear()
        self.image.addItems(names)
        if current in names:
            self.image.setCurrentText(current)

    def _cut_enabled(self, enabled: bool):
        for widget in (self.count_slider, self.count_box, self.threshold_slider,
                       self.write_button):
            widget.setEnabled(enabled)

    # The run ---------------------------------------------------------------------

    def options(self) -> Options:
        sigma = self.smooth.value()
        measure = self.measure.currentText()
        return Options(operator=self.operator.currentText(),
                       smooth_sigma=None if sigma < 0 else sigma, mask=self.mask.text().strip(),
                       measure=None if measure == FIELD_DEFAULT else measure,
                       n_regions=self.regions.value(), field=self.field.currentText())

    def start(self):
        """Segment the chosen image layer in a thread worker."""
        name = self.image.currentText()
        if not name:
            self.status.setText("no image layer to segment")
            return
        try:
            source = LayerVolume(self.viewer.layers[name])
        except ValueError as err:
            self.status.setText(str(err))
            return
        self.wait_for_cut()
        if self.live is not None:
            self.live.close()
        self.live = LiveSegmentation(source, self.options())
        self._cancel = False
        self.progress.setValue(0)
        self.status.setText(f"segmenting {name} ...")
        self.run_button.setEnabled(False)
        self.cancel_button.setEnabled(True)
        self._cut_enabled(False)
        self.worker = create_worker(_guarded, self.live.run, progress=self._bridge.said.emit,
                                    cancelled=lambda: self._cancel)
        self.worker.returned.connect(self._finished)
        self.worker.finished.connect(self._idle)
        self.worker.start()

    def cancel(self):
        """Stop the run at the start of its next stage."""
        self._cancel = True
        self.status.setText("cancelling at the next stage ...")

    def _progress(self, message: str):
        done = [stage for stage in STAGES if message.endswith(stage)]
        if done:
            self.progress.setValue(STAGES.index(done[0]))
        self.status.setText(message)

    def _idle(self):
        self.run_button.setEnabled(True)
        self.cancel_button.setEnabled(False)
        self.worker = None

    def _failed(self, err):
        self.progress.setValue(0)
        self.status.setText("cancelled" if isinstance(err, Cancelled) else str(err))

    def _finished(self, outcome):
        result, err = outcome
        if err is not None:
            self._failed(err)
            return
        live = self.live
        self.progress.setValue(len(STAGES))
        kwargs = live.source.layer_kwargs
        name = live.volume.name
        # The field, hidden: shown, an opaque layer would hide the image it was made of.
        self._replace_layer("curvature_layer", live.curvature(), f"{name} {result.field}",
                            "image", {**kwargs, "colormap": "magma", "visible": False})
        self._replace_layer("labels_layer", live.labels(), f"{name} labels", "labels", kwargs)
        self.labels_layer.mouse_drag_callbacks.append(self._clicked)
        self._cut_enabled(True)
        self.count_box.blockSignals(True)
        self.count_box.setRange(1, live.max_regions())
        self.count_box.blockSignals(False)
        self._draw_curve()
        self._show_cut()
        self.status.setText(f"{result.n_regions} regions from {len(result.hierarchy.maxima)} "
                            f"maxima in {sum(result.timings.values()):.1f} s; move the sliders "
                            "to cut again")

    def _replace_layer(self, attribute, data, name, kind, kwargs):
        old = getattr(self, attribute)
        if old is not None and old in self.viewer.layers:
            self.viewer.layers.remove(old)
        add = self.viewer.add_image if kind == "image" else self.viewer.add_labels
        setattr(self, attribute, add(data, name=name, **kwargs))

    # The live cut ------------------------------------------------------------------

    def set_regions(self, n_regions: int):
        """Cut into `n_regions` now (what typing the count does; the slider's cuts run
        in a thread)."""
        self.wait_for_cut()
        self._show_labels(self.live.cut(n_regions=int(n_regions)))

    def set_threshold(self, threshold: float):
        """Cut at `threshold` of the measure now."""
        self.wait_for_cut()
        self._show_labels(self.live.cut(threshold=float(threshold)))

    def wait_for_cut(self):
        """Return once the cut computed in a thread (and any asked meanwhile) is shown:
        a cut asked after it is the latest."""
        while self._cutting is not None:
            QApplication.processEvents()
            time.sleep(0.001)

    def _queue_cut(self, **cut):
        """Cut in a thread (`LiveSegmentation.prepare`): the layer keeps showing the
        last cut, and the main thread only shows the new one. One cut at a time; asked
        while one runs, only the latest is cut next."""
        self._pending = cut
        if self._cutting is None:
            self._next_cut()

    def _next_cut(self):
        cut, self._pending = self._pending, None
        live = self.live
        if cut is None or live is None or live.result is None:
            return
        worker = create_worker(_guarded, live.prepare, **cut)
        worker.returned.connect(lambda outcome: self._cut_ready(live, outcome))
        # A bug's exception returns nothing (napari shows its traceback): the queue
        # must not wait for that cut forever.
        worker.finished.connect(lambda: self._cut_ended(worker))
        self._cutting = worker
        worker.start()

    def _cut_ended(self, worker):
        if self._cutting is worker:
            self._cutting = None
            self._next_cut()

    def _cut_ready(self, live, outcome):
        result, err = outcome
        self._cutting = None
        if live is self.live and self.labels_layer is not None:
            if err is not None:
                self.status.setText(str(err))
            else:
                self._show_labels(live.adopt(result))
        self._next_cut()

    def _show_labels(self, labels):
        layer = self.labels_layer
        if isinstance(labels, np.ndarray) and isinstance(layer.data, np.ndarray) and \
                np.may_share_memory(labels, layer.data):
            layer.refresh()          # the cut was written into the layer's own array
        else:
            layer.data = labels
        self._show_cut()

    def _measure_changed(self, measure: str):
        """After a run, another measure recuts at once (same count, its own curve)."""
        if self.live is not None and self.live.result is not None \
                and self.labels_layer is not None:
            self.wait_for_cut()
            labels = self.live.set_measure(None if measure == FIELD_DEFAULT else measure)
            self._draw_curve()
            self._show_labels(labels)

    def _count_moved(self, position: int):
        if self.live is not None and self.live.result is not None:
            self._queue_cut(n_regions=self._count_at(position))

    def _count_typed(self, value: int):
        if self.live is not None and self.live.result is not None:
            self.set_regions(value)

    def _count_at(self, position: int) -> int:
        """The region count at a position of the (log-scale) region slider."""
        top = self.live.max_regions()
        return int(min(max(round(top ** (position / SLIDER_STEPS)), 1), top))

    def _count_position(self, count: int) -> int:
        top = self.live.max_regions()
        return 0 if top <= 1 else int(round(SLIDER_STEPS * np.log(count) / np.log(top)))

    def _threshold_moved(self, position: int):
        if self.live is not None and self.live.result is not None:
            self._queue_cut(threshold=self._threshold_at(position))

    def _bounds(self) -> tuple:
        thresholds, _ = self.live.curve()
        if not len(thresholds):
            return 1.0, 1.0
        return float(thresholds[-1]), float(thresholds[0]) * 1.01

    def _threshold_at(self, position: int) -> float:
        low, high = self._bounds()
        return low * (high / low) ** (position / SLIDER_STEPS)

    def _show_cut(self):
        """Sliders, labels and the curve at the current cut (signals held)."""
        result = self.live.result
        low, high = self._bounds()
        threshold = float(result.threshold)
        position = (0 if high <= low or threshold <= low else
                    int(round(SLIDER_STEPS * np.log(threshold / low) / np.log(high / low))))
        for slider, value in ((self.count_slider, self._count_position(result.n_regions)),
                              (self.count_box, result.n_regions),
                              (self.threshold_slider, min(position, SLIDER_STEPS))):
            slider.blockSignals(True)
            slider.setValue(int(value))
            slider.blockSignals(False)
        self.count_label.setText(f"{result.n_regions} regions")
        self.threshold_label.setText(f"{result.measure} {threshold:.4g}")
        self._mark_cut()

    def _draw_curve(self):
        """The measure's curve, drawn once per run; the cut's marker is blitted over it
        (`_mark_cut`), so a slider step redraws two artists, not the figure."""
        thresholds, counts = self.live.curve()
        self.figure.clear()
        axes = self.axes = self.figure.add_subplot()
        if len(thresholds):
            axes.step(thresholds, counts, where="post", color="0.2", linewidth=1)
            axes.set_xscale("log")
            axes.set_yscale("log")
        axes.set_xlabel(f"{self.live.result.measure} threshold", fontsize=8)
        axes.set_ylabel("regions", fontsize=8)
        axes.tick_params(labelsize=7)
        self._marker = (axes.axvline(1.0, color="tab:red", linewidth=1, animated=True),
                        axes.plot([1.0], [1.0], "o", color="tab:red", animated=True)[0])
        self._background = None
        self.canvas.draw()

    def _captured(self, event=None):
        """After every full draw (a resize too): keep the plot without the marker."""
        if getattr(self, "_marker", None) is not None:
            self._background = self.canvas.copy_from_bbox(self.axes.bbox)
            self._mark_cut()

    def _mark_cut(self):
        if self._background is None or self.live is None or self.live.result is None:
            return
        result = self.live.result
        line, dot = self._marker
        where = max(float(result.threshold), self._bounds()[0])
        line.set_xdata([where, where])
        dot.set_data([where], [result.n_regions])
        self.canvas.restore_region(self._background)
        self.axes.draw_artist(line)
        self.axes.draw_artist(dot)
        # Painted with the next paint of the window (matplotlib's `blit` repaints at
        # once, synchronously: 50-60 ms of the main thread per step, in napari's
        # window).
        self.canvas.update()

    def _clicked(self, layer, event):
        value = layer.get_value(event.position, view_direction=event.view_direction,
                                dims_displayed=event.dims_displayed, world=True)
        if value:
            self.show_region(int(value))

    def show_region(self, label: int) -> dict:
        """Show region `label`'s size, maximum and persistence; returns them."""
        info = self.live.region(label)
        index, world = self.live.source.place(info["maximum"])
        unit = self.live.volume.frame.unit
        self.region_info.setText(
            f"region {info['label']}: {info['size']:,} voxels ({info['volume']:.4g} "
            f"{unit + '^3' if unit else 'in world units'}); highest maximum at "
            f"{index} (world {', '.join(f'{w:.4g}' for w in world)}), curvature "
            f"{info['curvature_at_maximum']:.4g}, persistence {info['persistence']:.4g}")
        return {**info, "layer_index": index, "world": world}

    # Output ------------------------------------------------------------------------

    def _browse(self):
        folder = QFileDialog.getExistingDirectory(self, "Output folder")
        if folder:
            self.out_dir.setText(folder)

    def _write_clicked(self):
        folder = self.out_dir.text().strip()
        if not folder:
            self.status.setText("choose an output folder first")
            return
        self.wait_for_cut()
        self.write_button.setEnabled(False)
        self.run_button.setEnabled(False)      # one worker at a time
        # The cut as it is now: the sliders may move while the set is written.
        self.worker = create_worker(_guarded, self.live.write, folder,
                                    result=self.live.snapshot(), force=self.force.isChecked(),
                                    say=self._bridge.said.emit)
        self.worker.returned.connect(self._written)
        self.worker.finished.connect(self._written_idle)
        self.worker.start()

    def _written_idle(self):
        self.write_button.setEnabled(True)
        self.run_button.setEnabled(True)
        self.worker = None

    def _written(self, outcome):
        info, err = outcome
        if err is not None:
            self._failed(err)
        else:
            names = ", ".join(Path(path).name for path in info["outputs"].values())
            self.status.setText(f"wrote {names}")

    def closeEvent(self, event):      # noqa: N802 (Qt's name)
        self.wait_for_cut()
        if self.live is not None:
            self.live.close()
        super().closeEvent(event)
