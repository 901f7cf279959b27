"""Volume -> curvature -> Morse hierarchy -> labels: the one stage sequence behind
`segment_volume`, `segment_mesh`, `volseg segment` and the blockwise path.

`run_stages` runs the stages of a volume once, whatever the array: numpy in memory,
a Dask array lazily, or a Dask array through the blockwise path's storage
(`volseg.blockwise`), which keeps each stage's result on disk for the next. What a
path does differently is its `Storage`: hooks that do nothing in memory
(`InMemory`) and store each stage when blockwise. A new stage is written here, once.
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import _validate
from ._block_hooks import BlockHooks
from ._block_hooks import compute as _compute
from ._smoothing import gaussian
from .curvature import (
    Operator,
    check_padding,
    checked_grid_curvature,
    default_value_scale,
    get_operator,
)
from .masks import MaskChoice, foreground_mask
from .morse import MorseHierarchy, check_cut, descending_complex

__all__ = ["Segmentation", "SegmentRequest", "CutRequest", "Storage", "InMemory", "run_stages",
           "segment_volume", "segment_mesh", "DEFAULT_REGIONS", "AUTO_REGION_RANGE"]

#: Default cut: 30 regions, the middle of the paper's 20-40 range.
DEFAULT_REGIONS = 30
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
        Cut it again (``hierarchy.segment(n_regions=...)``) without recomputing.
    n_regions : int
        Regions (foreground regions, with a mask).
    operator, min_persistence, value_scale, spacing
        The parameters used; `min_persistence` is the threshold of the cut (for a
        region-count cut, one that gives the same count where ties allow).
    mask : MaskChoice
        The mask used (``mask.mask`` is None for none) and how it was chosen.
    timings : dict of str -> float
        Seconds per stage: ``curvature``, ``morse``, ``cut``, ``labels`` on every
        path (a lazy Dask run computes its curvature inside ``morse``).
    cut : dict
        The cut as asked (``min_persistence``, ``n_regions``, and ``auto`` when the
        count was chosen at the largest persistence gap).
    smooth_sigma : float
        A volume's Gaussian pre-smoothing, sigma in voxels (0: none).
    smooth_rounds : int
        A mesh's rounds of 1-ring averaging of the curvature (0: none).
    padding : str or None
        A volume's padding rule at the grid's boundary (`grid_curvature`).
    """

    labels: NDArray[np.int32]
    curvature: NDArray[np.float64]
    hierarchy: MorseHierarchy
    n_regions: int
    operator: str
    min_persistence: float
    value_scale: float | None
    spacing: tuple | None
    timings: dict = field(default_factory=dict)
    cut: dict = field(default_factory=dict)
    mask: MaskChoice | None = None
    smooth_sigma: float = 0.0
    smooth_rounds: int = 0
    padding: str | None = None
    vertices: NDArray[np.float64] | None = None
    simplices: NDArray[np.intp] | None = None

    @property
    def smooth(self):
        """Deprecated: `smooth_sigma` (a volume) or `smooth_rounds` (a mesh)."""
        warnings.warn("Segmentation.smooth is deprecated: use smooth_sigma (volumes) or "
                      "smooth_rounds (meshes)", DeprecationWarning, stacklevel=2)
        return self.smooth_rounds if self.vertices is not None else self.smooth_sigma

    def _cut(self) -> dict:
        return {"min_persistence": self.cut.get("min_persistence"),
                "n_regions": self.cut.get("n_regions")}

    def _region_tops(self) -> NDArray[np.int64]:
        """(k,) maximum id of each region's highest maximum."""
        region = self.hierarchy.region_of_maximum(**self._cut())
        # Maximum ids run by decreasing value: the first id seen per region is its top.
        return np.unique(region, return_index=True)[1]

    def region_maxima(self) -> NDArray[np.int64]:
        """(k,) flat voxel index of each region's highest curvature maximum (region
        label i + 1 at position i)."""
        return self.hierarchy.maxima[self._region_tops()].astype(np.int64)

    def region_sizes(self) -> NDArray[np.int64]:
        """(k + 1,) voxels (or vertices) per label, label 0 first (one pass over the
        blocks of lazy labels)."""
        if _validate.is_lazy(self.labels):
            import dask.array as da

            return da.bincount(self.labels.ravel(), minlength=self.n_regions + 1).compute()
        return np.bincount(self.labels.ravel(), minlength=self.n_regions + 1)

    def region_table(self) -> list[dict]:
        """One entry per region: ``label`` (1..k), ``size`` (voxels or vertices),
        ``maximum`` (its highest curvature maximum: [x, y, z] voxel, or the vertex
        index with its ``position`` on a mesh) and ``curvature_at_maximum``."""
        sizes = self.region_sizes()
        tops = self._region_tops()
        table = []
        for region, (top, value) in enumerate(zip(self.hierarchy.maxima[tops],
                                                  self.hierarchy.values[tops], strict=True), 1):
            where = tuple(int(c) for c in np.unravel_index(int(top), self.labels.shape))
            entry = {"label": region, "size": int(sizes[region]), "maximum": list(where),
                     "curvature_at_maximum": float(value)}
            if self.vertices is not None:
                entry["maximum"] = int(top)
                entry["position"] = self.vertices[top].tolist()
            table.append(entry)
        return table


@dataclass(frozen=True)
class CutRequest:
    """The cut asked of a hierarchy: a persistence threshold, a region count, or
    ``auto`` (the count in `AUTO_REGION_RANGE` at the largest persistence gap);
    `checked` gives `DEFAULT_REGIONS` when nothing is asked."""

    min_persistence: float | None
    n_regions: int | None
    auto: bool

    @classmethod
    def checked(cls, min_persistence=None, n_regions=None) -> CutRequest:
        auto = isinstance(n_regions, str) and n_regions == "auto"
        min_persistence, n_regions = check_cut(min_persistence, None if auto else n_regions)
        if min_persistence is None and n_regions is None and not auto:
            n_regions = DEFAULT_REGIONS
        return cls(min_persistence, n_regions, auto)


@dataclass(frozen=True)
class SegmentRequest:
    """What a segmentation of a volume is asked to do, checked once (`checked`).

    `mask` is a `foreground_mask` rule or array; `value_scale` None for the default
    of the values after smoothing.
    """

    operator: Operator
    cut: CutRequest
    value_scale: float | None
    spacing: tuple
    padding: str
    mask: object
    smooth_sigma: float

    @classmethod
    def checked(cls, *, operator="weighted", min_persistence=None, n_regions=None,
                value_scale=None, spacing=None, default_spacing=(1.0, 1.0, 1.0),
                padding="linear", mask=None, smooth_sigma=0.0) -> SegmentRequest:
        return cls(get_operator(operator), CutRequest.checked(min_persistence, n_regions),
                   None if value_scale is None else _validate.value_scale(value_scale),
                   _validate.spacing(spacing, default_spacing), check_padding(padding), mask,
                   _validate.smooth(smooth_sigma))


class Storage:
    """Where each stage's result goes: the hooks of `run_stages`.

    This base class is the in-memory storage (`InMemory`): every hook returns what it
    is given, so numpy stays numpy and a Dask array stays lazy. The blockwise path
    (`volseg.blockwise`) stores each stage on disk and returns it read back.
    """

    #: `BlockHooks` for the blockwise stages (None: plain Dask, or numpy).
    block_hooks: BlockHooks | None = None

    def begin(self, choice: MaskChoice) -> None:
        """Called once the mask is resolved, before any stage runs."""

    def smoothed(self, values):
        return values

    def curvature(self, curvature):
        return curvature

    def labels(self, labels, n_regions: int):
        return labels

    def finish(self) -> None:
        """Called once the outputs are committed (the blockwise work folder goes)."""


class InMemory(Storage):
    """Keep every stage as computed (`Storage`'s hooks as they are)."""


def run_stages(data, request: SegmentRequest, storage: Storage | None = None
               ) -> tuple[Segmentation, tuple]:
    """The stages of a volume: mask, smoothing, value scale, curvature, Morse, cut.

    Parameters
    ----------
    data : (X, Y, Z) ndarray or Dask array
        Checked (`volseg._validate.volume_array` or `lazy_volume_array`).
    request : SegmentRequest
    storage : Storage, optional
        Default `InMemory`.

    Returns
    -------
    (Segmentation, (min, max) of the input's values)
    """
    storage = storage or InMemory()
    choice = foreground_mask(data, request.mask)     # of the values as read
    storage.begin(choice)
    hooks = storage.block_hooks       # set by `begin` (the blockwise work folder's)
    timings = {}
    with _timed(timings, "curvature"):
        value_range = _value_range(data, hooks)
        values = storage.smoothed(gaussian(data, request.smooth_sigma))
        scale = request.value_scale
        if scale is None:
            scale = _validate.value_scale(default_value_scale(
                values, request.spacing,
                value_range=None if request.smooth_sigma else value_range))
        curvature = storage.curvature(checked_grid_curvature(
            values, request.operator, request.spacing, scale, request.padding,
            block_hooks=hooks))
    hierarchy, labels, k, threshold, cut = _morse_and_cut(
        curvature, request.cut, timings, mask=choice.mask, storage=storage)
    result = Segmentation(labels, curvature, hierarchy, k, request.operator.name, threshold,
                          scale, request.spacing, timings, cut, choice, request.smooth_sigma,
                          padding=request.padding)
    return result, value_range


def _morse_and_cut(field, cut: CutRequest, timings, *, mask=None, adjacency=None,
                   storage: Storage) -> tuple:
    """The Morse stage and the cut: (hierarchy, labels 1..k, k, threshold, cut)."""
    with _timed(timings, "morse"):
        hierarchy = descending_complex(field, adjacency=adjacency, mask=mask,
                                       block_hooks=storage.block_hooks)
    with _timed(timings, "cut"):
        n_regions = hierarchy.largest_gap(AUTO_REGION_RANGE) if cut.auto else cut.n_regions
        region = hierarchy.region_of_maximum(cut.min_persistence, n_regions)
        labels = hierarchy.relabel(region)
        if hierarchy.mask is None:
            labels += 1  # regions 1..k; 0 is kept for voxels outside a mask
        k = int(region.max()) + 1
    with _timed(timings, "labels"):
        labels = storage.labels(labels, k)
    threshold = (float(cut.min_persistence) if cut.min_persistence is not None
                 else hierarchy.threshold_for(k))
    asked = {"min_persistence": cut.min_persistence, "n_regions": n_regions, "auto": cut.auto}
    return hierarchy, labels, k, threshold, asked


@contextmanager
def _timed(timings: dict, stage: str):
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def _value_range(data, hooks) -> tuple:
    """(min, max) of the input, in one pass (the value scale and the preview's grey
    scale both read it)."""
    if _validate.is_lazy(data):
        return tuple(v.item() for v in _compute(hooks, data.min(), data.max(),
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
    mask=None,
    smooth_sigma: float = 0.0,
    smooth: float | None = None,
    boundary: str | None = None,
) -> Segmentation:
    """Segment a volume by the descending Morse complex of its mean curvature.

    Segment centres sit at maxima of the curvature field (peaks of a density),
    boundaries in its valleys (DESIGN.md section 2).

    Parameters
    ----------
    volume : (X, Y, Z) array_like, Dask array, or Volume
        A Dask array is segmented block by block (DESIGN.md section 10); the
        labels, curvature and mask come back as lazy Dask arrays.
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
        curvature is always computed on the whole volume. Default None: every voxel.
    smooth_sigma : float
        Standard deviation in voxels of a Gaussian applied to the values before the
        curvature (0: none, the values as they are). Tames the checkerboard that
        8-bit quantization gives the curvature; features smaller than about
        2 `smooth_sigma` voxels vanish.
    smooth, boundary
        Deprecated names of `smooth_sigma` and `padding`.

    Returns
    -------
    Segmentation
    """
    smooth_sigma = _validate.renamed(smooth_sigma, smooth, "smooth_sigma", "smooth", 0.0)
    padding = _validate.renamed(padding, boundary, "padding", "boundary", "linear")
    data = getattr(volume, "data", volume)
    lazy = _validate.is_lazy(data)
    data = _validate.lazy_volume_array(data) if lazy else _validate.volume_array(volume)
    request = SegmentRequest.checked(
        operator=operator, min_persistence=min_persistence, n_regions=n_regions,
        value_scale=value_scale, spacing=spacing,
        default_spacing=getattr(volume, "spacing", (1.0, 1.0, 1.0)), padding=padding, mask=mask,
        smooth_sigma=smooth_sigma)
    return run_stages(data, request)[0]


def segment_mesh(
    vertices,
    simplices,
    *,
    operator: str = "weighted",
    n_regions: int | str | None = None,
    min_persistence: float | None = None,
    boundary: str = "partial",
    smooth_rounds: int = 0,
    smooth: int | None = None,
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
        Consistently oriented (DESIGN.md section 2); H > 0 where the surface bends
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
        paper smooths estimates on irregular meshes; 0: none).
    smooth
        Deprecated name of `smooth_rounds`.

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

    smooth_rounds = _validate.renamed(smooth_rounds, smooth, "smooth_rounds", "smooth", 0)
    entry = get_operator(operator)
    if boundary not in ("partial", "nan"):
        raise ValueError(f"unknown `boundary` {boundary!r}; choose 'partial' or 'nan'")
    rounds = _validate.rounds(smooth_rounds, "smooth_rounds")
    cut = CutRequest.checked(min_persistence, n_regions)
    vertices, simplices = _mesh.check_mesh(vertices, simplices)
    timings = {}
    with _timed(timings, "curvature"):
        curvature = vertex_curvature(vertices, simplices, entry.name, boundary=boundary)
        if rounds:
            curvature = _mesh.ring_average(curvature, simplices, rounds)
    known = np.isfinite(curvature)   # boundary vertices with 'nan', vertices in no simplex
    mask = None if known.all() else known
    hierarchy, labels, k, threshold, cut = _morse_and_cut(
        np.where(known, curvature, 0.0), cut, timings, mask=mask,
        adjacency=_mesh.edges(simplices), storage=InMemory())
    used = "all vertices" if mask is None else "vertices with a complete star"
    choice = MaskChoice(mask, boundary, used, int(known.sum()))
    return Segmentation(labels, curvature, hierarchy, k, entry.name, threshold, None, None,
                        timings, cut, choice, smooth_rounds=rounds, vertices=vertices,
                        simplices=simplices)
