"""The segmentation of one layer and its cuts, without Qt: what the widget drives and
its tests check.

A run is the pipeline of ``volseg segment``: `segment_volume` for an array in memory,
the blockwise path (`volseg.blockwise.BlockwiseStorage`, each stage stored in a work
folder) for a Dask layer, so that the hierarchy's cells are read from disk by each cut
rather than climbed again. Every cut after it is `Segmentation.recut`: nothing is
recomputed, one gather per voxel.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import _validate
from .._distinct import label_type
from ..fields import get_field
from ..segment import Segmentation, SegmentRequest, run_stages, segment_volume
from ._layers import LayerVolume

__all__ = ["Cancelled", "Options", "LiveSegmentation"]


class Cancelled(Exception):
    """The run was cancelled (at the start of a stage)."""


@dataclass(frozen=True)
class Options:
    """The widget's parameters, as `segment_volume` names them."""

    operator: str = "weighted"
    smooth_sigma: float | None = None       # None: `volseg.segment.auto_smoothing`
    mask: str = "auto"
    measure: str | None = None              # None: the field's (`volseg.fields.Field`)
    n_regions: int | str = 30
    field: str = "curvature"

    def keywords(self) -> dict:
        return {"operator": self.operator, "smooth_sigma": self.smooth_sigma, "mask": self.mask,
                "measure": self.measure, "n_regions": self.n_regions, "field": self.field}


class LiveSegmentation:
    """One layer's segmentation (`run`) and its current cut (`cut`, `result`; a cut in
    another thread: `prepare` there, `adopt` here)."""

    def __init__(self, source: LayerVolume, options: Options = Options()):
        self.source, self.options = source, options
        self.result: Segmentation | None = None
        self._spare = None           # the labels buffer `prepare` writes into
        self._default_measure = None  # the measure the field's rule chose in `run`
        self._work: Path | None = None
        self._curve = None

    @property
    def volume(self):
        return self.source.volume

    def run(self, progress=None, cancelled=lambda: False) -> Segmentation:
        """Segment the layer's volume. `progress` is told each stage; `cancelled` is asked
        at each stage's start and stops the run with `Cancelled` when true."""
        def say(message):
            if cancelled():
                raise Cancelled("cancelled")
            if progress is not None:
                progress(message)

        volume = self.volume
        self._curve = self._spare = None
        self._default_measure = None
        if _validate.is_lazy(volume.data):
            self.result = self._blockwise(volume, say)
        else:
            result = segment_volume(volume, **self.options.keywords(), progress=say)
            # The layer's labels in the smallest type that holds every cut's labels (a
            # quarter of int32's texture at most 255 regions); the cuts write into them.
            buffer = np.empty(result.labels.shape, label_type(self.max_regions(result)))
            buffer[...] = result.labels
            self.result = dataclasses.replace(result, labels=buffer)
        if self.options.measure is None:       # the field's rule chose it
            self._default_measure = self.result.measure
        return self.result

    def _blockwise(self, volume, say) -> Segmentation:
        from ..blockwise import BlockwiseStorage

        data = _validate.lazy_volume_array(volume.data)
        request = SegmentRequest.checked(**self.options.keywords(), spacing=volume.spacing,
                                         dtype=data.dtype)
        self.close()
        self._work = Path(tempfile.mkdtemp(prefix="volseg-napari-"))
        # Removed on `close`, or when this object goes or the interpreter exits (a
        # viewer closed without closing its dock widget first).
        self._finalizer = weakref.finalize(self, shutil.rmtree, str(self._work), True)
        paths = {kind: self._work / f"{kind}.zarr" for kind in ("curvature", "labels")}
        storage = BlockwiseStorage(data, request, paths, folder=self._work, stem=volume.name,
                                   checksum=None, frame=volume.frame, say=say)
        return run_stages(data, request, storage, source=volume.name)[0]

    # The cut -----------------------------------------------------------------------

    def cut(self, n_regions: int | None = None, threshold: float | None = None):
        """Cut again into `n_regions`, or at `threshold` of the measure; returns the
        labels as the layer shows them (`prepare`, then `adopt`)."""
        return self.adopt(self.prepare(n_regions, threshold=threshold))

    def set_measure(self, measure: str | None):
        """Cut by another measure (docs/design.md section 12; None: the field's),
        keeping the region count: the hierarchy has every measure, nothing is
        recomputed. The field's default is the measure the run chose by the field's
        rule (the gradient's volume, or area where the volume cut was degenerate)."""
        if measure is None:
            measure = self._default_measure or get_field(self.options.field).measure
        return self.adopt(self.prepare(self.result.n_regions, measure=measure))

    def prepare(self, n_regions: int | None = None, *, threshold: float | None = None,
                measure: str | None = None) -> Segmentation:
        """The cut (into `n_regions`, or at `threshold` of `measure`, default the
        current cut's), the current one left as it is: what a worker thread computes
        while the layer shows the current labels. In memory its labels are written
        into a second buffer, the same for every cut (no allocation per slider step):
        one `prepare` runs at a time, and `adopt` shows it."""
        result = self.result
        out = None
        if isinstance(result.labels, np.ndarray):
            if self._spare is None:
                self._spare = np.empty_like(result.labels)
            out = self._spare
        return result.recut(n_regions, threshold=threshold, measure=measure or result.measure,
                            out=out)

    def adopt(self, result: Segmentation):
        """Make `result` (from `prepare`) the current cut; returns its labels as layer
        data. In memory they are copied into the array the layer shows (a refresh
        redraws it; handing napari another array costs it twice as much)."""
        shown = self.result.labels
        if isinstance(shown, np.ndarray) and result.labels is self._spare:
            np.copyto(shown, self._spare)
            result = dataclasses.replace(result, labels=shown)
        self.result = result
        return self.labels()

    def snapshot(self) -> Segmentation:
        """The current cut with labels of its own (for a writer in another thread), as
        int32 as ``volseg segment`` writes them."""
        labels = self.result.labels
        return dataclasses.replace(self.result, labels=labels.astype(np.int32)
                                   if isinstance(labels, np.ndarray) else labels)

    def labels(self):
        """The current cut's labels as layer data."""
        return self.source.shown(self.result.labels)

    def curvature(self):
        return self.source.shown(self.result.curvature)

    def curve(self, result: Segmentation | None = None) -> tuple:
        """(thresholds, counts): the region count (``counts[i]``) of the cut just below
        each extinction of the measure (``thresholds``, decreasing, positive), of
        `result` (default the current one)."""
        result = self.result if result is None else result
        key = (id(result.hierarchy), result.measure, result.cut.get("min_component", 0.0))
        if self._curve is None or self._curve[0] != key:
            extinction, components = result.hierarchy.curve(*key[1:])
            extinction = np.sort(extinction[np.isfinite(extinction) & (extinction > 0)])[::-1]
            self._curve = key, (extinction, components + np.arange(1, len(extinction) + 1))
        return self._curve[1]

    def max_regions(self, result: Segmentation | None = None) -> int:
        """The most regions a cut of `result` (default the current one) can have
        (every maximum kept)."""
        result = self.result if result is None else result
        thresholds, counts = self.curve(result)
        return int(counts[-1]) if len(counts) else max(int(result.n_regions), 1)

    def region(self, label: int) -> dict:
        return self.result.region(label)

    def write(self, folder, *, result: Segmentation | None = None, force=False,
              say=None) -> dict:
        """A cut (default the current one) as the output set ``volseg segment``
        writes (same files, same checks); returns its summary."""
        from ..files import result_to_files

        return result_to_files(self.volume, result or self.snapshot(), folder, force=force,
                               say=say or (lambda message: None))

    def close(self) -> None:
        """Remove the blockwise work folder (the cells the cuts read)."""
        if self._work is not None:
            self._finalizer()
            self._work = None
