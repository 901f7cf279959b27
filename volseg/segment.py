"""Volume -> curvature -> Morse hierarchy -> labels: the one stage sequence behind
`segment_volume`, `segment_mesh`, `volseg segment` and the blockwise path.

`run_stages` runs the stages of a volume once, whatever the array: numpy in memory,
a Dask array lazily, or a Dask array through the blockwise path's storage
(`volseg.blockwise`), which keeps each stage's result on disk for the next. What a
path does differently is its `Storage`: hooks that do nothing in memory
(`InMemory`) and store each stage when blockwise. A new stage is written here, once.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import _validate
from ._block_hooks import BlockHooks
from ._block_hooks import compute as _compute
from ._census import census as _census
from ._distinct import counts
from ._lattice import lattice_of, on_lattice
from ._smoothing import gaussian, noise_sigma
from .curvature import (
    Operator,
    check_padding,
    default_value_scale,
    get_operator,
)
from .errors import VolsegWarning
from .fields import FIELD_REGISTRY, GIVEN, Field, field_entry, for_morse
from .masks import MaskChoice, check_rule, foreground_mask
from .morse import (
    PERSISTENCE,
    SIZE,
    CutReport,
    MorseHierarchy,
    check_measure_cut,
    cut_of,
    descending_complex,
    get_measure,
)

__all__ = ["Segmentation", "SegmentRequest", "CutRequest", "Storage", "InMemory", "run_stages",
           "segment_volume", "segment_mesh", "input_range", "DEFAULT_REGIONS", "DEFAULT_MEASURE",
           "DEFAULT_MIN_COMPONENT", "DEFAULT_MESH_MEASURE", "AUTO_REGION_RANGE",
           "AUTO_INTEGER_SIGMA", "AUTO_NOISE_UNIT", "AUTO_MAX_SIGMA", "auto_smoothing"]

#: Default cut: 30 regions, the middle of the paper's 20-40 range.
DEFAULT_REGIONS = 30
#: Mask components holding less than this share of the mask are labelled 0 (they
#: take no region of the count): the specks a threshold leaves in noise.
DEFAULT_MIN_COMPONENT = 0.001
#: Default Gaussian pre-smoothing (voxels) of integer data of at most 16 bits: at
#: least this, ...
AUTO_INTEGER_SIGMA = 1.0
#: ... sqrt(noise / this) for noisier data (noise in the values' units) ...
AUTO_NOISE_UNIT = 2.5
#: ... and at most this.
AUTO_MAX_SIGMA = 2.0
#: Default measure of the cut (docs/design.md section 12).
DEFAULT_MEASURE = "hypervolume"
#: Default measure of a mesh's cut (`segment_mesh`): the watershed hierarchy by volume.
#: By hypervolume, a raw marching 3-sphere with two low bumps (25^4 samples) kept one
#: region of 98.8 % and a speck at 2 regions; by volume the bumps are the two regions
#: at 17^4 to 33^4 samples, and fsaverage5's pial surface has 30 of 30 regions >= 1 %.
DEFAULT_MESH_MEASURE = "volume"
#: Where ``n_regions="auto"`` looks for the largest persistence gap: the paper's range.
AUTO_REGION_RANGE = (20, 40)


@dataclass
class Segmentation:
    """The result of `segment_volume` (a volume) or `segment_mesh` (a mesh).

    Attributes
    ----------
    labels : (X, Y, Z) or (V,) ndarray of int32
        Regions 1..k, ordered by decreasing curvature at their centre; 0 for
        voxels outside the mask (none without one) or mesh vertices left out. The
        same in the NIfTI outputs.
    curvature : (X, Y, Z) or (V,) ndarray of float64
        On the whole volume (after `smooth_sigma`), mask or not; per mesh vertex.
    hierarchy : MorseHierarchy
        Cut it again (``hierarchy.segment(n_regions=...)``) without recomputing. A
        blockwise run's stays where it was built (`volseg.morse.HierarchyOnWorkers`) until
        something of it is read.
    n_regions : int
        Regions (foreground regions, with a mask).
    operator, min_persistence, value_scale, spacing
        The parameters used; `min_persistence` is the persistence threshold of a
        persistence cut (for a region-count cut, one that gives the same count where
        ties allow), None for a cut by another measure.
    measure, threshold
        The cut's measure (`volseg.morse.MEASURES`) and its threshold in that
        measure (for a count, as `min_persistence`); sizes in world units (voxel
        volume from the spacing; a mesh's vertex volumes).
    mask : MaskChoice
        The mask used (``mask.mask`` is None for none) and how it was chosen.
    timings : dict of str -> float
        Seconds per stage: ``curvature``, ``morse``, ``cut``, ``labels`` on every
        path (a lazy Dask run computes its curvature inside ``morse``).
    cut : dict
        The cut as asked (``measure``, ``threshold``, ``n_regions``, and ``auto``
        when the count was chosen at the largest gap of the measure).
    report : CutReport
        What the cut found (`volseg.morse.CutReport`): each region's highest
        maximum, the hierarchy's counts, the measure's curve thinned.
    smooth_sigma : float
        A volume's Gaussian pre-smoothing, sigma in voxels (0: none).
    smooth_rule : str
        How `smooth_sigma` was chosen: ``"given"``, or the `auto_smoothing` rule.
    smooth_rounds : int
        A mesh's rounds of 1-ring averaging of the curvature (0: none).
    padding : str or None
        A volume's padding rule at the grid's boundary (`grid_curvature`).
    field : str
        The field the complex was built on (`volseg.fields.FIELD_REGISTRY`, or
        ``"given"``); `curvature` holds that field (the gradient magnitude for
        ``"gradient"``, ...).
    """

    labels: NDArray[np.int32]
    curvature: NDArray[np.float64]
    hierarchy: MorseHierarchy
    n_regions: int
    operator: str
    min_persistence: float | None
    value_scale: float | None
    spacing: tuple | None
    timings: dict = field(default_factory=dict)
    cut: dict = field(default_factory=dict)
    mask: MaskChoice | None = None
    smooth_sigma: float = 0.0
    smooth_rounds: int = 0
    padding: str | None = None
    field: str = "curvature"
    vertices: NDArray[np.float64] | None = None
    simplices: NDArray[np.intp] | None = None
    measure: str = PERSISTENCE.name
    threshold: float | None = None
    smooth_rule: str = "given"
    report: CutReport | None = None

    def region_maxima(self) -> NDArray[np.int64]:
        """(k,) flat voxel index of each region's highest curvature maximum (region
        label i + 1 at position i)."""
        return self.report.top_maxima.copy()

    def region_sizes(self) -> NDArray[np.int64]:
        """(k + 1,) voxels (or vertices) per label, label 0 first (one pass over the
        blocks of lazy labels)."""
        return _label_sizes(self.labels, self.n_regions)

    def region_table(self) -> list[dict]:
        """One entry per region: ``label`` (1..k), ``size`` (voxels or vertices),
        ``maximum`` (its highest curvature maximum: [x, y, z] voxel, or the vertex
        index with its ``position`` on a mesh) and ``curvature_at_maximum``."""
        sizes = self.region_sizes()
        table = []
        for region, (top, value) in enumerate(zip(self.report.top_maxima,
                                                  self.report.top_values, strict=True), 1):
            where = tuple(int(c) for c in np.unravel_index(int(top), self.labels.shape))
            entry = {"label": region, "size": int(sizes[region]), "maximum": list(where),
                     "curvature_at_maximum": float(value)}
            if self.vertices is not None:
                entry["maximum"] = int(top)
                entry["position"] = self.vertices[top].tolist()
            table.append(entry)
        return table

    def region(self, label: int) -> dict:
        """Region `label` (1..k) of the cut: its ``size`` (voxels or vertices) and
        ``volume`` (in world units), its highest maximum (``maximum``: [x, y, z] voxel, or
        the vertex index), ``curvature_at_maximum``, and that maximum's ``persistence``
        (inf for the highest maximum of a connected component)."""
        if not 1 <= int(label) <= self.n_regions:
            raise ValueError(f"`label` must be a region 1..{self.n_regions}, got {label}")
        top = int(label) - 1
        size = (self.labels == int(label)).sum()
        size = int(size.compute() if _validate.is_lazy(size) else size)
        flat = int(self.report.top_maxima[top])
        maximum = (flat if self.vertices is not None
                   else [int(c) for c in np.unravel_index(flat, self.labels.shape)])
        unit = float(np.prod(self.spacing)) if self.spacing is not None else 1.0
        return {"label": int(label), "size": size, "volume": size * unit, "maximum": maximum,
                "curvature_at_maximum": float(self.report.top_values[top]),
                "persistence": float(self.report.top_persistence[top])}

    def recut(self, n_regions: int | str | None = None, *, min_persistence: float | None = None,
              measure: str | None = None, threshold: float | None = None,
              out=None) -> Segmentation:
        """The same segmentation cut again: new labels from `hierarchy` (one gather per
        voxel, nothing recomputed), the curvature and everything else shared.

        The arguments are `segment_volume`'s; `measure` defaults to this cut's (to
        persistence with `min_persistence`) and the cut keeps its `min_component`.
        `out`: an integer array of the labels' shape to write the labels into (in-memory
        results; a viewer reuses its buffer rather than allocating one per cut).
        """
        if measure is None:
            measure = PERSISTENCE.name if min_persistence is not None else self.measure
        cut = CutRequest.checked(min_persistence, n_regions, measure=measure,
                                 threshold=threshold,
                                 min_component=self.cut.get("min_component", 0.0))
        timings = dict(self.timings)
        with _timed(timings, "recut"):
            labels, report = cut_of(self.hierarchy, cut, out=out)
        return dataclasses.replace(self, labels=labels, timings=timings, **_cut_fields(report))


@dataclass(frozen=True)
class CutRequest:
    """The cut asked of a hierarchy: a threshold of a measure, a region count, or
    ``auto`` (the count in `AUTO_REGION_RANGE` at the largest gap between the
    measure's extinctions); `checked` gives `DEFAULT_REGIONS` when nothing is asked.

    `measure` is one of `volseg.morse.MEASURES` (docs/design.md section 12); the
    persistence measure's threshold is `min_persistence`.
    """

    threshold: float | None
    n_regions: int | None
    auto: bool
    measure: str = PERSISTENCE.name
    min_component: float = 0.0
    fallback: str | None = None

    @classmethod
    def checked(cls, min_persistence=None, n_regions=None, *, measure=None,
                threshold=None, min_component=0.0, fallback=None) -> CutRequest:
        """The checked cut; `measure` None: persistence when `min_persistence` is
        given, else `DEFAULT_MEASURE`. `fallback`: the measure a count cut takes
        instead when its own cut is degenerate (a field's default: `Field.fallback`);
        a threshold cut keeps its measure (the threshold is in its units)."""
        if measure is None:
            measure = PERSISTENCE.name if min_persistence is not None else DEFAULT_MEASURE
        auto = isinstance(n_regions, str) and n_regions == "auto"
        threshold, n_regions, measure = check_measure_cut(
            min_persistence, None if auto else n_regions, measure, threshold)
        if threshold is None and n_regions is None and not auto:
            n_regions = DEFAULT_REGIONS
        if fallback is not None:
            fallback = get_measure(fallback).name if threshold is None else None
        return cls(threshold, n_regions, auto, measure, _validate.share(min_component,
                                                                        "min_component"),
                   fallback)

    @property
    def min_persistence(self) -> float | None:
        """The threshold of a persistence cut (None for another measure)."""
        return None if get_measure(self.measure).pruned else self.threshold

    @property
    def auto_range(self) -> tuple:
        """The counts ``auto`` chooses from (`AUTO_REGION_RANGE`)."""
        return AUTO_REGION_RANGE

    def of(self, hierarchy: MorseHierarchy, masked: bool | None = None) -> dict:
        """The keyword arguments of ``hierarchy.segment`` / ``region_of_maximum`` for
        this cut, the ``auto`` count chosen on `hierarchy` (`masked`: its vertices
        were masked, default whether it has a mask)."""
        masked = hierarchy.mask is not None if masked is None else masked
        min_component = self.min_component if masked else 0.0
        n_regions = (hierarchy.largest_gap(AUTO_REGION_RANGE, self.measure, min_component,
                                           fallback=DEFAULT_REGIONS)
                     if self.auto else self.n_regions)
        return {"n_regions": n_regions, "measure": self.measure, "threshold": self.threshold,
                "min_component": min_component}

    @property
    def ranks_read(self) -> int:
        """How many of the largest extinctions choosing this cut reads (0: a threshold)."""
        if self.auto:
            return AUTO_REGION_RANGE[1] + 1
        return 0 if self.n_regions is None else self.n_regions + 1

    def measures(self, masked: bool) -> tuple:
        """The cells' measures the cut reads: its own, and the sizes that
        `min_component` weighs the components by."""
        needed = {self.measure} if get_measure(self.measure).pruned else set()
        if masked and self.min_component > 0:
            needed.add(SIZE.name)
        return tuple(sorted(needed))


@dataclass(frozen=True)
class SegmentRequest:
    """What a segmentation of a volume is asked to do, checked once (`checked`), before
    any input is read: the one place every segmentation option is checked (the command
    line maps its errors to its option names and checks nothing itself).

    `mask` is a checked `foreground_mask` rule or an array (its shape is checked
    against the volume's when the mask is made); `value_scale` None for the default of
    the values after smoothing; `chunks` the blockwise path's chunk edge in voxels, or
    None for the path the input's size chooses.
    """

    operator: Operator
    cut: CutRequest
    value_scale: float | None
    spacing: tuple
    padding: str
    mask: object
    smooth_sigma: float | None
    smooth_rule: str = "given"
    dtype: np.dtype | None = None
    chunks: int | None = None
    field: Field = FIELD_REGISTRY["curvature"]

    @classmethod
    def checked(cls, *, operator="weighted", min_persistence=None, n_regions=None,
                value_scale=None, spacing=None, default_spacing=(1.0, 1.0, 1.0),
                padding="linear", mask=None, smooth_sigma=0.0, measure=None,
                threshold=None, min_component=None, dtype=None,
                chunks=None, field="curvature") -> SegmentRequest:
        """The request with every option checked; a ValueError names the option."""
        entry = field_entry(field)
        fallback = None
        if measure is None and min_persistence is None:
            measure, fallback = entry.measure, entry.fallback
        cut = CutRequest.checked(
            min_persistence, n_regions, threshold=threshold, measure=measure,
            min_component=DEFAULT_MIN_COMPONENT if min_component is None else min_component,
            fallback=fallback)
        sigma = None if smooth_sigma is None else _validate.smooth(smooth_sigma)
        if isinstance(mask, str):
            check_rule(mask)
        return cls(get_operator(operator), cut,
                   None if value_scale is None else _validate.value_scale(value_scale),
                   _validate.spacing(spacing, default_spacing), check_padding(padding), mask,
                   sigma, "given" if sigma is not None else "auto",
                   None if dtype is None else np.dtype(dtype),
                   None if chunks is None else _validate.chunk_edge(chunks), entry)

    def with_smoothing(self, data, mask, lattice=None) -> SegmentRequest:
        """The request with its smoothing resolved: `auto_smoothing` of `data` inside
        `mask` when none was given (`lattice`: the levels the input lies on)."""
        if self.smooth_sigma is not None:
            return self
        sigma, rule = auto_smoothing(data, mask, self.dtype, lattice=lattice)
        return dataclasses.replace(self, smooth_sigma=sigma, smooth_rule=rule)


def auto_smoothing(data, mask=None, dtype=None, *, lattice=None) -> tuple:
    """(sigma, rule) of the default pre-smoothing of `data` (values of `dtype`, by
    default the array's: the file's type, before any added noise).

    Quantised data, on a lattice of at most 2^16 levels whatever its type (8-bit CT and
    MRI, 12-bit scanners, an 8-bit scan saved as float32 / 255: `volseg._lattice`):
    its steps are voxel-sized curvature noise, so sigma is at least
    `AUTO_INTEGER_SIGMA`; with more noise, ``sqrt(noise / AUTO_NOISE_UNIT)`` up to
    `AUTO_MAX_SIGMA`, where noise is `volseg._smoothing.noise_sigma` inside `mask` in
    steps of the lattice (1 on a clean 8-bit scan, 12 under Rician noise of 12). So
    every exactly scaled or offset copy of a volume gets the same sigma. `lattice`: the
    one `data` was mapped from (its integers given as `data`); None with an integer
    `dtype` of at most 16 bits means steps of 1. Continuous values (simulations, float
    maps): 0.
    """
    dtype = np.dtype(data.dtype if dtype is None else dtype)
    if lattice is None and (dtype.kind not in "biu" or dtype.itemsize > 2):
        return 0.0, f"auto: {dtype} values, none"
    noise = noise_sigma(data, mask)
    sigma = round(float(np.clip(np.sqrt(noise / AUTO_NOISE_UNIT), AUTO_INTEGER_SIGMA,
                                AUTO_MAX_SIGMA)), 2)
    steps = "" if lattice is None else f" steps ({lattice.describe()})"
    return sigma, f"auto: {dtype} values, noise {noise:.3g}{steps}"


class Storage:
    """Where each stage's result goes: the hooks of `run_stages`.

    This base class is the in-memory storage (`InMemory`): every hook returns what it
    is given, so numpy stays numpy and a Dask array stays lazy. The blockwise path
    (`volseg.blockwise`) stores each stage on disk and returns it read back.
    """

    #: `BlockHooks` for the blockwise stages (None: plain Dask, or numpy).
    block_hooks: BlockHooks | None = None
    #: (min, max) of the values `smoothed` returned, when it saw every block of them as
    #: it kept them (the blockwise storage); None: not known, and the default value
    #: scale takes a pass over them.
    smoothed_range: tuple[float, float] | None = None

    def begin(self, choice: MaskChoice, request: SegmentRequest) -> None:
        """Called once the mask and the smoothing are resolved, before any stage runs."""

    def smoothed(self, values):
        """The values after smoothing, as this storage keeps them."""
        return values

    def curvature(self, curvature):
        """The curvature field, as this storage keeps it."""
        return curvature

    def labels(self, labels, n_regions: int):
        """The labels of a cut into `n_regions`, as this storage keeps them."""
        return labels

    def finish(self) -> None:
        """Called once the outputs are committed (the blockwise work folder goes)."""

    def stage(self, name: str) -> None:
        """Called as each stage (curvature, morse, cut, labels) starts: progress."""


class InMemory(Storage):
    """Keep every stage as computed (`Storage`'s hooks as they are); `say`, when
    given, is told each stage as it starts and the seconds the one before took."""

    def __init__(self, say=None):
        self._say, self._started, self._stage = say, None, None

    def stage(self, name: str) -> None:
        """Say that stage `name` starts (and how long the one before took)."""
        if self._say is None:
            return
        now = time.perf_counter()
        if self._stage is not None:
            self._say(f"{self._stage} done in {now - self._started:.1f} s; {name}")
        else:
            self._say(name)
        self._started, self._stage = now, name


def run_stages(data, request: SegmentRequest, storage: Storage | None = None, *,
               source: str = "the volume",
               keep_hierarchy: bool = True) -> tuple[Segmentation, tuple]:
    """The stages of a volume: mask, smoothing, value scale, curvature, Morse, cut.

    Parameters
    ----------
    data : (X, Y, Z) ndarray or Dask array
        Checked (`volseg._validate.volume_array` or `lazy_volume_array`).
    request : SegmentRequest
    storage : Storage, optional
        Default `InMemory`.
    source : str
        What messages call the data (the file's path).
    keep_hierarchy : bool
        False: the result's `hierarchy` is None, for a caller that needs the cut
        alone (the files); a field the Morse stage read negated (the gradient) then
        comes back in place, in the Morse stage's buffer, not beside it (8 bytes a
        voxel off the peak).

    Returns
    -------
    (Segmentation, (min, max) of the input's values)
    """
    storage = storage or InMemory()
    if data.dtype == bool:
        raise ValueError(f"{source} holds booleans (a mask or a label map?), not an image "
                         "to segment; cast it (astype(numpy.uint8)) if that is what you mean")
    raw = data                                       # values as read: the mask's rules
    read = _census(data)                             # one pass, before anything is kept
    value_range = read.value_range
    if not all(np.isfinite(v) for v in value_range):
        raise ValueError(f"{source} holds NaN or infinite values (its range is "
                         f"{value_range[0]} .. {value_range[1]}); replace them first")
    widest = max(data.shape)
    if request.smooth_sigma is not None and request.smooth_sigma > widest:
        raise ValueError(f"the smoothing sigma {request.smooth_sigma:g} (--smooth, "
                         f"`smooth_sigma`) is wider than {source} "
                         f"({widest} voxels along its longest axis): it would blur it to "
                         f"one value; use at most {widest}")
    data, shifted_range, lattice = _as_computed(data, value_range, read)
    # A mask rule reads the histogram of levels, unless the values are those levels
    # already (integers of step 1: the same histogram, as before the lattice).
    levels = None if lattice is None or (raw.dtype.kind in "iu" and lattice.step == 1) \
        else lattice
    choice = foreground_mask(raw, request.mask, value_range=value_range, lattice=levels,
                             census=read if levels is None else None)
    request = request.with_smoothing(data, choice.mask, lattice)
    storage.begin(choice, request)
    hooks = storage.block_hooks       # set by `begin` (the blockwise work folder's)
    timings = {}
    entry = request.field
    with _timed(timings, "curvature", storage):
        lazy = _validate.is_lazy(data)
        values = storage.smoothed(gaussian(data, request.smooth_sigma, margin=0 if lazy else 1))
        scale = request.value_scale
        if scale is None and entry.needs_scale:
            scale = _default_scale(values, request, shifted_range, source,
                                   storage.smoothed_range)
        # A smoothed copy in memory is the stages' own: the field may overwrite it.
        field = entry.make(values, shifted_range, request, scale, hooks, choice.mask,
                           owned=values is not data and not lazy)
        if entry.name == GIVEN:                 # the user's array: checked here, once
            field = _checked_given(field, data)
        field = storage.curvature(field)
    # The Morse stage needs the field alone: the smoothed and lattice copies (8 bytes
    # per voxel each) are let go before its own arrays are made.
    del values, data
    morse_field = for_morse(entry, field)
    # A negation in memory (the gradient's) is all the Morse stage and the cut read:
    # the field goes too (8 bytes a voxel), and comes back after as its exact negation.
    negated = morse_field is not field and not _validate.is_lazy(field)
    if negated:
        del field
    hierarchy, labels, report = _morse_and_cut(
        morse_field, request.cut, timings, mask=choice.mask, storage=storage,
        vertex_weight=float(np.prod(request.spacing)), own_field=entry.name != GIVEN)
    if not keep_hierarchy:
        hierarchy = None                    # it read `morse_field`, negated next
    if negated:
        field = np.negative(morse_field, out=None if keep_hierarchy else morse_field)
    del morse_field
    result = Segmentation(labels, field, hierarchy, operator=request.operator.name,
                          value_scale=scale, spacing=request.spacing, timings=timings,
                          mask=choice, smooth_sigma=request.smooth_sigma,
                          smooth_rule=request.smooth_rule, padding=request.padding,
                          field=entry.name, **_cut_fields(report))
    return result, value_range


def _checked_given(field, data):
    """A field the user gave: of the volume's shape, float64, finite (the checks of
    `_validate.volume_array`, naming `field`)."""
    if field.shape != data.shape:
        raise ValueError(f"`field` must have the volume's shape {data.shape}, got {field.shape}")
    if _validate.is_lazy(field):
        return _validate.lazy_volume_array(field, "field").astype(np.float64)
    return np.asarray(_validate.volume_array(field, "field"), dtype=np.float64)


def _morse_and_cut(field, cut: CutRequest, timings, *, mask=None, adjacency=None,
                   vertex_weight=None, storage: Storage, own_field=False) -> tuple:
    """The Morse stage and the cut: (hierarchy, labels 1..k, `CutReport`), sizes
    counted in `vertex_weight` per vertex (`MorseHierarchy.with_vertex_weight`). A
    blockwise hierarchy stays where it was built and is cut there
    (`volseg.morse.HierarchyOnWorkers`). `own_field`: the field is the stages' own
    (not the user's array): the build may use its buffer (``overwrite_field``)."""
    with _timed(timings, "morse", storage):
        hierarchy = descending_complex(field, adjacency=adjacency, mask=mask,
                                       block_hooks=storage.block_hooks, on_workers=True,
                                       overwrite_field=own_field)
        if vertex_weight is not None:
            hierarchy = hierarchy.with_vertex_weight(vertex_weight)
    with _timed(timings, "cut", storage):
        labels, report = cut_of(hierarchy, cut)
        if cut.fallback is not None:
            labels, report = _unless_degenerate(hierarchy, cut, labels, report)
        if isinstance(hierarchy, MorseHierarchy):       # the cut is done: 4 B a voxel
            hierarchy.release_vertex_records()
    with _timed(timings, "labels", storage):
        labels = storage.labels(labels, report.n_regions)
    return hierarchy, labels, report


def _unless_degenerate(hierarchy, cut: CutRequest, labels, report: CutReport) -> tuple:
    """The cut by `cut.fallback` instead when the cut by the field's default measure is
    degenerate (`volseg.metrics.region_spread`: one region of most of the volume and
    specks, as the volume hierarchy leaves a single homogeneous object); the report
    records the rule either way (``measure_rule``) and whether it was taken
    (``fell_back``)."""
    from .metrics import region_spread

    sizes = _label_sizes(labels, report.n_regions)
    spread = region_spread(sizes[1:]) if sizes[1:].sum() else {"degenerate": False}
    rule = f"{cut.measure} (the field's default)"
    fell_back = bool(spread["degenerate"])
    if fell_back:
        rule = (f"{cut.fallback}: by {cut.measure} the cut was degenerate (largest region "
                f"{spread['largest_share']:.0%}, {spread['regions_at_least_1_percent']} of "
                f"{report.n_regions} regions >= 1 %)")
        labels, report = cut_of(hierarchy, dataclasses.replace(cut, measure=cut.fallback,
                                                               fallback=None))
    return labels, dataclasses.replace(report, record={**report.record, "measure_rule": rule,
                                                       "fell_back": fell_back})


def _label_sizes(labels, n_regions: int) -> np.ndarray:
    """Voxels per label 0..k of labels in memory or lazy (one pass)."""
    if not _validate.is_lazy(labels):
        return counts(labels, n_regions + 1)
    import dask.array as da

    return da.bincount(labels.ravel(), minlength=n_regions + 1).compute()


def _cut_fields(report: CutReport) -> dict:
    """The `Segmentation` fields of a cut (`cut_of`)."""
    record = report.record
    threshold = record["cut_threshold"]
    return {"n_regions": report.n_regions, "cut": record, "report": report,
            "min_persistence": None if get_measure(record["measure"]).pruned else threshold,
            "measure": record["measure"], "threshold": threshold}


@contextmanager
def _timed(timings: dict, stage: str, storage: Storage | None = None):
    if storage is not None:
        storage.stage(stage)
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def _default_scale(values, request, value_range, source, smoothed_range=None) -> float:
    """`default_value_scale` of the (smoothed) values, or a message naming the values'
    range when none is finite (denormal or astronomically large values). The range
    is the input's, or with smoothing `smoothed_range` (`Storage.smoothed_range`);
    without it, a pass over the smoothed values."""
    try:
        return _validate.value_scale(default_value_scale(
            values, request.spacing,
            value_range=smoothed_range if request.smooth_sigma else value_range))
    except ValueError:
        raise ValueError(f"{source}: its values span {value_range[0]:g} .. {value_range[1]:g}, "
                         "too narrow or too wide a range for a default value scale; give "
                         "one (value_scale, --value-scale)") from None


def _as_computed(data, value_range, read) -> tuple:
    """(data, its range, lattice) as the stages compute on it: a quantised volume as
    its lattice integers (`volseg._lattice`: every exactly scaled or offset copy the
    same numbers, docs/design.md section 13), 64-bit integers beyond 2^53 as offsets
    (`_exact_in_float64`), anything else as it is (lattice None). `read`: the
    `volseg._census.Census` of `data` (its lattice sample and distinct values)."""
    shifted, value_range = _exact_in_float64(data, value_range)
    lattice = (lattice_of(data, value_range, sample=read.sample, present=read.present())
               if shifted is data else lattice_of(shifted, value_range))
    data = shifted
    if lattice is None:
        return data, value_range, None
    if data.dtype.kind in "iu" and lattice.step == 1 and lattice.low == 0:
        return data, value_range, lattice          # already its own integers
    return on_lattice(data, lattice), (0, lattice.levels - 1), lattice


def _exact_in_float64(data, value_range) -> tuple:
    """(data, its range) with 64-bit integers beyond 2^53 as offsets from the minimum:
    float64 is 1024 apart near 2^62, so 2^62 + (0 .. 999) would be a few levels, and
    the curvature (which only sees differences of values) the same as unshifted.
    The offsets are exact: the difference wraps in the type, and read as uint64 it is
    the true one (under 2^64)."""
    lo, hi = value_range
    if data.dtype.kind not in "iu" or max(abs(lo), abs(hi)) <= 2**53:
        return data, value_range
    base = data.dtype.type(lo)

    def offsets(block):
        return np.subtract(block, base, dtype=data.dtype).view(np.uint64)

    shifted = (data.map_blocks(offsets, dtype=np.uint64) if _validate.is_lazy(data)
               else offsets(np.asarray(data)))
    return shifted, (0, int(hi) - int(lo))


def input_range(data) -> tuple:
    """(min, max) of the input, in one pass (the value scale and the preview's grey
    scale both read it), before any stage's block hooks exist."""
    if _validate.is_lazy(data):
        return tuple(v.item() for v in _compute(None, data.min(), data.max(),
                                                stage="value range"))
    return (np.min(data).item(), np.max(data).item())


def segment_volume(
    volume,
    *,
    operator: str = "weighted",
    min_persistence: float | None = None,
    n_regions: int | str | None = None,
    value_scale: float | None = None,
    spacing=None,
    padding: str = "linear",
    mask="auto",
    smooth_sigma: float | None = None,
    measure: str | None = None,
    threshold: float | None = None,
    min_component: float | None = None,
    field="curvature",
    progress=None,
) -> Segmentation:
    """Segment a volume by the descending Morse complex of its mean curvature (or of
    another field: its gradient magnitude, its values).

    Segment centres sit at maxima of the curvature field (peaks of a density),
    boundaries in its valleys (docs/design.md section 2).

    Parameters
    ----------
    volume : (X, Y, Z) array_like, Dask array, Volume, nibabel or SimpleITK image
        A Dask array is segmented block by block (docs/design.md section 10); the
        labels, curvature and mask come back as lazy Dask arrays. A `Volume` or an
        image (``nibabel.load(path)``, ``SimpleITK.ReadImage(path)``) brings its voxel
        spacing; a bare array has none (every voxel a unit cube) unless `spacing` is
        given: pass the image, not ``image.get_fdata()``, to segment anisotropic
        voxels as they are.
    operator : {'weighted', 'unweighted', 'laplace_beltrami', 'intrinsic'}
    min_persistence : float, optional
        Cut the hierarchy at this persistence threshold.
    n_regions : int or 'auto', optional
        Or cut it into exactly this many regions (foreground regions with a mask);
        ``'auto'``: the count in the paper's 20-40 range at the largest gap between
        consecutive persistences (log scale). Neither given: 30.
    value_scale : float, optional
        Default `volseg.curvature.default_value_scale` (graph as tall as wide) of
        the volume after `smooth_sigma`.
    spacing : (3,) sequence of float, optional
        Default the Volume's spacing, or 1.
    padding : {'linear', 'mirror'}
        How the grid is continued past its boundary (`grid_curvature`).
    mask : bool ndarray, str or None
        The voxels the Morse stage segments (`volseg.masks.foreground_mask`: None,
        ``'auto'``, ``'nonzero'``, ``'otsu'``, ``'value>T'``, or an array). The
        curvature is always computed on the whole volume. Default ``'auto'`` (the
        command line's): a plateau or a low-mode background is left out, else
        every voxel; None segments every voxel.
    smooth_sigma : float, optional
        Standard deviation in voxels of a Gaussian applied to the values before the
        curvature (0: none, the values as they are). Tames the checkerboard that
        8-bit quantization gives the curvature; features smaller than about
        2 `smooth_sigma` voxels vanish. Default `auto_smoothing`: for integers of
        at most 16 bits 1 to 2 voxels by the measured noise, else 0.
    measure : {'persistence', 'size', 'hypervolume'}, optional
        What decides which regions survive the cut (docs/design.md section 12;
        default `DEFAULT_MEASURE`): ``persistence`` keeps the tallest peaks of the
        curvature, ``size`` the largest regions (Carr et al. 2004: the smallest
        region merges across its highest saddle until `n_regions` are left),
        ``hypervolume`` weighs size by height.
    threshold : float, optional
        Instead of a count, merge every region whose `measure` is below it (for
        ``size``, in world units: voxels times the voxel volume).
    min_component : float, optional
        With a mask: its connected components (in the Morse graph's connectivity)
        holding less than this share of the masked voxels are labelled 0 and take
        no region of `n_regions` (default `DEFAULT_MIN_COMPONENT`; 0 keeps all).
    field : {'curvature', 'gradient', 'value'} or (X, Y, Z) array_like
        The field the complex is built on (docs/design.md section 13,
        `volseg.fields.FIELD_REGISTRY`): the paper's mean curvature (territories around
        its peaks); ``'gradient'``, the basins of the gradient magnitude (regions
        bounded by edges: a watershed hierarchy); ``'value'``, bright blobs of the
        values; or an array of the volume's shape (numpy or Dask), built on as it is.
        Its default measure applies when `measure` is not given.
    progress : callable, optional
        Called with a line as each stage starts (and the seconds the one before
        took). An exception it raises stops the run there: how a viewer cancels.

    Returns
    -------
    Segmentation
        Its `labels` (regions 1..k, 0 outside the mask), `curvature`, `hierarchy`
        (cut it again with `Segmentation.recut`) and the choices made.

    See Also
    --------
    volseg.morse.descending_complex : the Morse stage alone, on any field or graph.
    volseg.curvature.grid_curvature : the curvature stage alone.
    volseg.metrics.compare : Huang-Dom similarity and variation of information [4]_.
    skimage.segmentation.watershed : marker flooding, a close relative.

    Notes
    -----
    The volume's graph in R^4 is tessellated by the Kuhn split and its mean curvature
    estimated by the weighted extrinsic distortion [1]_; the descending Morse complex of
    that field is simplified by the elder rule [2]_ and cut by a measure (the height,
    or a region's size or hypervolume pruned as in [3]_), all on one hierarchy.

    References
    ----------
    .. [1] P. Simari, L. De Floriani, F. Iuricich, M. M. Mesmoudi, "Generalized
           extrinsic distortion and applications", Computers & Graphics 37(6),
           SMI 2013.
    .. [2] H. Edelsbrunner, D. Letscher, A. Zomorodian, "Topological persistence and
           simplification", Discrete & Computational Geometry 28, 2002.
    .. [3] H. Carr, J. Snoeyink, M. van de Panne, "Simplifying flexible isosurfaces
           using local geometric measures", IEEE Visualization 2004.
    .. [4] Q. Huang, B. Dom, "Quantitative methods of evaluating image segmentation",
           ICIP 1995.

    Examples
    --------
    >>> import numpy as np
    >>> from volseg import segment_volume
    >>> x, y, z = np.meshgrid(*[np.linspace(-1, 1, 24)] * 3, indexing="ij")
    >>> blob = lambda cx: np.exp(-8 * ((x - cx)**2 + y**2 + z**2))
    >>> two_blobs = blob(0.5) + blob(-0.5)
    >>> result = segment_volume(two_blobs, n_regions=2, mask=None)
    >>> result.n_regions, result.labels.shape
    (2, (24, 24, 24))
    >>> int(result.labels[4, 12, 12]) != int(result.labels[19, 12, 12])   # one blob each
    True
    """
    if _is_image(volume):
        from .io import volume_of_image

        volume = volume_of_image(volume)
    data = getattr(volume, "data", volume)
    lazy = _validate.is_lazy(data)
    data = _validate.lazy_volume_array(data) if lazy else _validate.volume_array(volume)
    request = SegmentRequest.checked(
        operator=operator, min_persistence=min_persistence, n_regions=n_regions,
        value_scale=value_scale, spacing=spacing,
        default_spacing=getattr(volume, "spacing", (1.0, 1.0, 1.0)), padding=padding, mask=mask,
        smooth_sigma=smooth_sigma, measure=measure, threshold=threshold,
        min_component=min_component, dtype=data.dtype, field=field)
    result = run_stages(data, request, InMemory(say=progress))[0]
    if not lazy:
        _warn_if_degenerate(result, data.dtype)
    return result


def _warn_if_degenerate(result: Segmentation, dtype) -> None:
    """A `VolsegWarning` when the cut is degenerate (one region of nearly everything and
    specks: docs/design.md section 12), naming the likely cause and its fix."""
    from .metrics import region_spread
    from .outputs import degenerate_cut_warning

    sizes = result.region_sizes()[1:]
    if sizes.sum() == 0:
        return
    line = degenerate_cut_warning("the volume", result, region_spread(sizes), dtype)
    if line:
        warnings.warn(line, VolsegWarning, stacklevel=3)


def _is_image(volume) -> bool:
    """Whether `volume` is a nibabel or SimpleITK image (it carries its geometry)."""
    return (hasattr(volume, "affine") and hasattr(volume, "dataobj")) or (
        hasattr(volume, "GetSpacing") and hasattr(volume, "GetDirection"))


def segment_mesh(
    vertices,
    simplices,
    *,
    operator: str = "weighted",
    n_regions: int | str | None = None,
    min_persistence: float | None = None,
    boundary: str = "partial",
    smooth_rounds: int = 10,
    measure: str | None = None,
    threshold: float | None = None,
    min_component: float | None = None,
) -> Segmentation:
    """Segment an oriented n-manifold in R^(n+1) by the descending Morse complex of its
    mean curvature on the mesh's vertex graph (its edges).

    The same Morse stage and cut as `segment_volume`, for meshes that are not graphs
    of a volume: isosurfaces of time-varying fields (`volseg.tessellation.isosurface`),
    spheres, any closed or bounded hypersurface.

    Parameters
    ----------
    vertices : (V, n+1) array_like of float
    simplices : (S, n+1) array_like of int
        Consistently oriented (docs/design.md section 2); H > 0 where the surface bends
        away from its normals (on a blob with outward normals, everywhere).
    operator : {'weighted', 'unweighted', 'laplace_beltrami', 'intrinsic'}
    n_regions : int or 'auto', optional
        As in `segment_volume` (default 30 without `min_persistence`).
    min_persistence : float, optional
    boundary : {'partial', 'nan'}
        Boundary vertices (on a face of one simplex, e.g. where an isosurface meets
        the grid's edge): ``'partial'`` gives them the operator over their
        incomplete star (its bending is only that of the faces inside, so it is
        biased; they are segmented like the others); ``'nan'`` leaves them out of
        the Morse graph with label 0 and NaN curvature.
    smooth_rounds : int
        Rounds of 1-ring averaging of the curvature before the Morse stage (the
        paper smooths estimates on irregular meshes; 0: none). Default 10, as the
        command line: a raw marching mesh's curvature is noisy at the vertex scale.
    measure, threshold, min_component
        As in `segment_volume` (default measure `DEFAULT_MESH_MEASURE`, the watershed
        hierarchy by volume); sizes are the vertices' volumes (a 1/(n+1) share of
        each simplex around them); `min_component` applies to the vertices
        segmented when some are left out (``boundary='nan'``).

    Returns
    -------
    Segmentation
        ``labels`` and ``curvature`` per vertex; ``vertices`` and ``simplices`` the
        mesh; ``spacing`` None; ``mask`` names the vertices segmented.

    Raises
    ------
    ValueError
        A mesh `vertex_curvature` refuses (not a manifold, inconsistent orientation,
        degenerate simplices), a bad cut, or an unknown operator or boundary rule.
    """
    from . import mesh as _mesh
    from .curvature import vertex_curvature

    entry = get_operator(operator)
    if boundary not in ("partial", "nan"):
        raise ValueError(f"unknown `boundary` {boundary!r}; choose 'partial' or 'nan'")
    rounds = _validate.rounds(smooth_rounds, "smooth_rounds")
    if measure is None and min_persistence is None:
        measure = DEFAULT_MESH_MEASURE
    cut = CutRequest.checked(
        min_persistence, n_regions, threshold=threshold, measure=measure,
        min_component=DEFAULT_MIN_COMPONENT if min_component is None else min_component)
    vertices, simplices = _mesh.check_mesh(vertices, simplices)
    timings = {}
    with _timed(timings, "curvature"):
        curvature = vertex_curvature(vertices, simplices, entry.name, boundary=boundary)
        if rounds:
            curvature = _mesh.ring_average(curvature, simplices, rounds)
    known = np.isfinite(curvature)   # boundary vertices with 'nan', vertices in no simplex
    mask = None if known.all() else known
    hierarchy, labels, report = _morse_and_cut(
        np.where(known, curvature, 0.0), cut, timings, mask=mask,
        adjacency=_mesh.edges(simplices), storage=InMemory(),
        vertex_weight=_mesh.vertex_volumes(vertices, simplices))
    used = "all vertices" if mask is None else "vertices with a complete star"
    choice = MaskChoice(mask, boundary, used, int(known.sum()))
    return Segmentation(labels, curvature, hierarchy, operator=entry.name, value_scale=None,
                        spacing=None, timings=timings, mask=choice,
                        smooth_rounds=rounds, vertices=vertices, simplices=simplices,
                        **_cut_fields(report))
