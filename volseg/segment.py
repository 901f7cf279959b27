"""Volume -> curvature -> Morse hierarchy -> labels: the pipeline behind `volseg segment`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import _validate
from .curvature import default_value_scale, get_operator
from .curvature._grid import check_boundary, checked_grid_curvature
from .masks import MaskChoice
from .morse import MorseHierarchy, check_cut, descending_complex

__all__ = ["Segmentation", "segment_volume", "DEFAULT_REGIONS", "AUTO_REGION_RANGE"]

#: Default cut: 30 regions, the middle of the paper's 20-40 range.
DEFAULT_REGIONS = 30
#: Where ``n_regions="auto"`` looks for the largest persistence gap: the paper's range.
AUTO_REGION_RANGE = (20, 40)


@dataclass
class Segmentation:
    """The result of `segment_volume`.

    Attributes
    ----------
    labels : (X, Y, Z) ndarray of int32
        Regions 1..k, ordered by decreasing curvature at their centre; 0 for
        voxels outside the mask (none without one). The same in the NIfTI outputs.
    curvature : (X, Y, Z) ndarray of float64
        On the whole volume (after `smooth`), mask or not.
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

    def _cut(self) -> dict:
        return {"min_persistence": self.cut.get("min_persistence"),
                "n_regions": self.cut.get("n_regions")}

    def region_maxima(self) -> NDArray[np.int64]:
        """(k,) flat voxel index of each region's highest curvature maximum (region
        label i + 1 at position i)."""
        region = self.hierarchy.region_of_maximum(**self._cut())
        # Maximum ids run by decreasing value: the first id seen per region is its top.
        seen = np.unique(region, return_index=True)[1]
        return self.hierarchy.maxima[seen].astype(np.int64)

    def region_table(self) -> list[dict]:
        """One entry per region: ``label`` (1..k), ``size`` (voxels), ``maximum``
        ([x, y, z] of its highest curvature maximum) and ``curvature_at_maximum``."""
        sizes = np.bincount(self.labels.ravel(), minlength=self.n_regions + 1)
        table = []
        for region, top in enumerate(self.region_maxima(), 1):
            where = tuple(int(c) for c in np.unravel_index(top, self.labels.shape))
            table.append({"label": region, "size": int(sizes[region]), "maximum": list(where),
                          "curvature_at_maximum": float(self.curvature[where])})
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
    auto = isinstance(n_regions, str) and n_regions == "auto"
    min_persistence, n_regions = check_cut(min_persistence, None if auto else n_regions)
    if min_persistence is None and n_regions is None and not auto:
        n_regions = DEFAULT_REGIONS
    spacing = _validate.spacing(spacing, getattr(volume, "spacing", (1.0, 1.0, 1.0)))
    data = _validate.volume_array(volume)
    smooth = _validate.smooth(smooth)
    check_boundary(boundary)
    choice = foreground_mask(data, mask)
    timings = {}
    start = time.perf_counter()
    if smooth:
        from scipy.ndimage import gaussian_filter

        data = gaussian_filter(data.astype(np.float64), smooth, mode="nearest")
    value_scale = _validate.value_scale(default_value_scale(data, spacing)
                                        if value_scale is None else value_scale)
    curvature = checked_grid_curvature(data, entry, spacing, value_scale, boundary)
    timings["curvature"] = time.perf_counter() - start
    start = time.perf_counter()
    hierarchy = descending_complex(curvature, mask=choice.mask)
    timings["morse"] = time.perf_counter() - start
    start = time.perf_counter()
    if auto:
        n_regions = hierarchy.largest_gap(AUTO_REGION_RANGE)
    labels = hierarchy.segment(min_persistence=min_persistence, n_regions=n_regions)
    if choice.mask is None:
        labels += 1  # regions 1..k; 0 is kept for voxels outside a mask
    timings["cut"] = time.perf_counter() - start
    k = int(labels.max())
    threshold = float(min_persistence) if min_persistence is not None else hierarchy.threshold_for(k)
    cut = {"min_persistence": min_persistence, "n_regions": n_regions, "auto": auto}
    return Segmentation(labels, curvature, hierarchy, k, entry.name, threshold, value_scale,
                        spacing, timings, cut, choice, smooth)
