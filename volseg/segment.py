"""Volume -> curvature -> Morse hierarchy -> labels: the pipeline behind `volseg segment`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import _validate
from ._smoothing import gaussian
from .curvature import default_value_scale, get_operator
from .curvature._grid import check_boundary, checked_grid_curvature
from .masks import MaskChoice
from .morse import MorseHierarchy, check_cut, descending_complex

__all__ = ["Segmentation", "segment_volume", "segment_mesh", "DEFAULT_REGIONS", "AUTO_REGION_RANGE"]

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
        On the whole volume (after `smooth`), mask or not; per mesh vertex.
    hierarchy : MorseHierarchy
        Cut it again (``hierarchy.segment(n_regions=...)``) without recomputing.
    n_regions : int
        Regions (foreground regions, with a mask).
    operator, min_persistence, value_scale, spacing, smooth
        The parameters used; `min_persistence` is the threshold of the cut (for a
        region-count cut, one that gives the same count where ties allow).
    mask : MaskChoice
        The mask used (``mask.mask`` is None for none) and how it was chosen.
    timings : dict of str -> float
        Seconds per stage.
    cut : dict
        The cut as asked (``min_persistence``, ``n_regions``, and ``auto`` when the
        count was chosen at the largest persistence gap).
    """

    labels: NDArray[np.int32]
    curvature: NDArray[np.float64]
    hierarchy: MorseHierarchy
    n_regions: int
    operator: str
    min_persistence: float
    value_scale: float
    spacing: tuple
    timings: dict = field(default_factory=dict)
    cut: dict = field(default_factory=dict)
    mask: MaskChoice | None = None
    smooth: float = 0.0
    vertices: NDArray[np.float64] | None = None
    simplices: NDArray[np.intp] | None = None

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

    def region_table(self) -> list[dict]:
        """One entry per region: ``label`` (1..k), ``size`` (voxels or vertices),
        ``maximum`` (its highest curvature maximum: [x, y, z] voxel, or the vertex
        index with its ``position`` on a mesh) and ``curvature_at_maximum``."""
        if _validate.is_lazy(self.labels):   # one pass over the blocks
            import dask.array as da

            sizes = da.bincount(self.labels.ravel(), minlength=self.n_regions + 1).compute()
        else:
            sizes = np.bincount(self.labels.ravel(), minlength=self.n_regions + 1)
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


def segment_volume(
    volume,
    *,
    operator: str = "weighted",
    min_persistence: float | None = None,
    n_regions: int | str | None = None,
    value_scale: float | None = None,
    spacing=None,
    boundary: str = "linear",
    mask=None,
    smooth: float = 0.0,
) -> Segmentation:
    """Segment a volume by the descending Morse complex of its mean curvature.

    Segment centres sit at maxima of the curvature field (peaks of a density),
    boundaries in its valleys (DESIGN.md section 2).

    Parameters
    ----------
    volume : (X, Y, Z) array_like or Volume
    operator : {'weighted', 'unweighted', 'laplace_beltrami', 'intrinsic'}
    min_persistence : float, optional
        Cut the hierarchy at this persistence threshold.
    n_regions : int or 'auto', optional
        Or cut it into exactly this many regions (foreground regions with a mask);
        ``'auto'``: the count in the paper's 20-40 range at the largest gap between
        consecutive persistences (log scale). Neither given: 30.
    value_scale : float, optional
        Default `volseg.curvature.default_value_scale` (graph as tall as wide) of
        the volume after `smooth`.
    spacing : (3,) sequence of float, optional
        Default the Volume's spacing, or 1.
    boundary : {'linear', 'mirror'}
        Padding rule of `grid_curvature`.
    mask : bool ndarray, str or None
        The voxels the Morse stage segments (`volseg.masks.foreground_mask`: None,
        ``'auto'``, ``'nonzero'``, ``'otsu'``, ``'value>T'``, or an array). The
        curvature is always computed on the whole volume. Default None: every voxel.
    smooth : float
        Standard deviation in voxels of a Gaussian applied to the values before the
        curvature (0: none, the values as they are). Tames the checkerboard that
        8-bit quantization gives the curvature; features smaller than about
        2 `smooth` voxels vanish.

    Returns
    -------
    Segmentation
    """
    from .masks import foreground_mask

    entry = get_operator(operator)
    min_persistence, n_regions, auto = _cut_request(min_persistence, n_regions)
    if _validate.is_lazy(getattr(volume, "data", volume)):
        return _segment_dask(volume, entry, min_persistence, n_regions, auto, value_scale,
                             spacing, boundary, mask, smooth)
    spacing = _validate.spacing(spacing, getattr(volume, "spacing", (1.0, 1.0, 1.0)))
    data = _validate.volume_array(volume)
    smooth = _validate.smooth(smooth)
    check_boundary(boundary)
    choice = foreground_mask(data, mask)
    timings = {}
    start = time.perf_counter()
    data = gaussian(data, smooth)
    value_scale = _validate.value_scale(default_value_scale(data, spacing)
                                        if value_scale is None else value_scale)
    curvature = checked_grid_curvature(data, entry, spacing, value_scale, boundary)
    timings["curvature"] = time.perf_counter() - start
    start = time.perf_counter()
    hierarchy = descending_complex(curvature, mask=choice.mask)
    timings["morse"] = time.perf_counter() - start
    labels, k, threshold, cut = _cut(hierarchy, min_persistence, n_regions, auto, timings)
    return Segmentation(labels, curvature, hierarchy, k, entry.name, threshold, value_scale,
                        spacing, timings, cut, choice, smooth)


def _segment_dask(volume, entry, min_persistence, n_regions, auto, value_scale, spacing,
                  boundary, mask, smooth) -> Segmentation:
    """`segment_volume` of a Dask array: smoothing, curvature and Morse stage block by
    block (DESIGN.md section 10), labels, curvature and mask returned as lazy Dask
    arrays."""
    from .curvature import grid_curvature
    from .masks import foreground_mask

    smooth = _validate.smooth(smooth)
    data = getattr(volume, "data", volume)
    spacing = _validate.spacing(spacing, getattr(volume, "spacing", (1.0, 1.0, 1.0)))
    check_boundary(boundary)
    _validate.lazy_volume_array(data)
    choice = foreground_mask(data, mask)     # a lazy mask (its rule's passes run now)
    timings = {}
    start = time.perf_counter()
    data = gaussian(data, smooth)
    value_scale = _validate.value_scale(default_value_scale(data, spacing)
                                        if value_scale is None else value_scale)
    curvature = grid_curvature(data, entry.name, spacing=spacing, value_scale=value_scale,
                               boundary=boundary)
    timings["value scale"] = time.perf_counter() - start
    start = time.perf_counter()
    # computes the curvature block by block
    hierarchy = descending_complex(curvature, mask=choice.mask)
    timings["curvature and morse"] = time.perf_counter() - start
    labels, k, threshold, cut = _cut(hierarchy, min_persistence, n_regions, auto, timings)
    return Segmentation(labels, curvature, hierarchy, k, entry.name, threshold, value_scale,
                        spacing, timings, cut, choice, smooth)


def _cut_request(min_persistence, n_regions) -> tuple:
    """(min_persistence, n_regions, auto) from what the caller asked; 30 regions when
    nothing was."""
    auto = isinstance(n_regions, str) and n_regions == "auto"
    min_persistence, n_regions = check_cut(min_persistence, None if auto else n_regions)
    if min_persistence is None and n_regions is None and not auto:
        n_regions = DEFAULT_REGIONS
    return min_persistence, n_regions, auto


def _cut(hierarchy: MorseHierarchy, min_persistence, n_regions, auto, timings) -> tuple:
    """Labels 1..k (0 outside the mask), k, the cut's threshold and its description."""
    start = time.perf_counter()
    if auto:
        n_regions = hierarchy.largest_gap(AUTO_REGION_RANGE)
    region = hierarchy.region_of_maximum(min_persistence, n_regions)
    labels = hierarchy.relabel(region)
    if hierarchy.mask is None:
        labels += 1  # regions 1..k; 0 is kept for voxels outside a mask
    timings["cut"] = time.perf_counter() - start
    k = int(region.max()) + 1
    threshold = float(min_persistence) if min_persistence is not None else hierarchy.threshold_for(k)
    return labels, k, threshold, {"min_persistence": min_persistence, "n_regions": n_regions,
                                  "auto": auto}


def segment_mesh(
    vertices,
    simplices,
    *,
    operator: str = "weighted",
    n_regions: int | str | None = None,
    min_persistence: float | None = None,
    boundary: str = "partial",
    smooth: int = 0,
) -> Segmentation:
    """Segment an oriented n-manifold in R^(n+1) by the descending Morse complex of its
    mean curvature on the mesh's vertex graph (its edges).

    The same stage as `segment_volume`, for meshes that are not graphs of a volume:
    isosurfaces of time-varying fields (`volseg.tessellation.isosurface`), spheres,
    any closed or bounded hypersurface.

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
    smooth : int
        Rounds of 1-ring averaging of the curvature before the Morse stage (the
        paper smooths estimates on irregular meshes; 0: none).

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
    smooth = int(smooth)
    if smooth < 0:
        raise ValueError(f"`smooth` must be a number of rounds >= 0, got {smooth}")
    min_persistence, n_regions, auto = _cut_request(min_persistence, n_regions)
    vertices, simplices = _mesh.check_mesh(vertices, simplices)
    timings = {}
    start = time.perf_counter()
    curvature = vertex_curvature(vertices, simplices, entry.name, boundary=boundary)
    if smooth:
        curvature = _mesh.ring_average(curvature, simplices, smooth)
    timings["curvature"] = time.perf_counter() - start
    start = time.perf_counter()
    known = np.isfinite(curvature)   # boundary vertices with 'nan', vertices in no simplex
    mask = None if known.all() else known
    hierarchy = descending_complex(np.where(known, curvature, 0.0),
                                   adjacency=_mesh.edges(simplices), mask=mask)
    timings["morse"] = time.perf_counter() - start
    labels, k, threshold, cut = _cut(hierarchy, min_persistence, n_regions, auto, timings)
    used = "all vertices" if mask is None else "vertices with a complete star"
    choice = MaskChoice(mask, boundary, used, int(known.sum()))
    return Segmentation(labels, curvature, hierarchy, k, entry.name, threshold, None, None,
                        timings, cut, choice, float(smooth), vertices, simplices)
