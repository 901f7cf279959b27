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
    """One layer's segmentation (`run`) and its current cut (`cut`, `result`)."""

    def __init__(self, source: LayerVolume, options: Options = Options()):
        self.source, self.options = source, options
        self.result: Segmentation | None = None
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
        if _validate.is_lazy(volume.data):
            self.result = self._blockwise(volume, say)
        else:
            self.result = segment_volume(volume, **self.options.keywords(), progress=say)
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
        labels as the layer shows them. In memory, every cut is written into the first
        cut's array (no 4 bytes per voxel allocated per slider step): the layer's data
        stays the same object, and `snapshot` gives a copy that later cuts leave alone."""
        return self._recut(n_regions, threshold=threshold, measure=self.result.measure)

    def set_measure(self, measure: str | None):
        """Cut by another measure (docs/design.md section 12; None: the field's),
        keeping the region count: the hierarchy has every measure, nothing is
        recomputed."""
        if measure is None:
            measure = get_field(self.options.field).measure
        return self._recut(self.result.n_regions, measure=measure)

    def _recut(self, n_regions, **cut):
        labels = self.result.labels
        reuse = isinstance(labels, np.ndarray) and labels.dtype == np.int32
        self.result = self.result.recut(n_regions, **cut, out=labels if reuse else None)
        return self.labels()

    def snapshot(self) -> Segmentation:
        """The current cut with labels of its own (for a writer in another thread)."""
        labels = self.result.labels
        return dataclasses.replace(self.result, labels=labels.copy()
                                   if isinstance(labels, np.ndarray) else labels)

    def labels(self):
        """The current cut's labels as layer data."""
        return self.source.shown(self.result.labels)

    def curvature(self):
        return self.source.shown(self.result.curvature)

    def curve(self) -> tuple:
        """(thresholds, counts): the region count (``counts[i]``) of the cut just below
        each extinction of the measure (``thresholds``, decreasing, positive)."""
        result = self.result
        key = (id(result.hierarchy), result.measure, result.cut.get("min_component", 0.0))
        if self._curve is None or self._curve[0] != key:
            extinction, components = result.hierarchy.curve(*key[1:])
            extinction = np.sort(extinction[np.isfinite(extinction) & (extinction > 0)])[::-1]
            self._curve = key, (extinction, components + np.arange(1, len(extinction) + 1))
        return self._curve[1]

    def max_regions(self) -> int:
        """The most regions a cut can have (every maximum kept)."""
        thresholds, counts = self.curve()
        return int(counts[-1]) if len(counts) else max(int(self.result.n_regions), 1)

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
