"""Volume -> curvature -> Morse hierarchy -> labels: the pipeline behind `volseg segment`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .curvature import default_value_scale, grid_curvature, normalize_operator
from . import _validate
from .morse import MorseHierarchy, check_cut, descending_complex

__all__ = ["Segmentation", "segment_volume", "DEFAULT_REGIONS"]

#: Default cut: 30 regions, the middle of the paper's 20-40 range.
DEFAULT_REGIONS = 30


@dataclass
class Segmentation:
    """The result of `segment_volume`.

    Attributes
    ----------
    labels : (X, Y, Z) ndarray of int32
        Regions 0..k-1, ordered by decreasing curvature at their centre.
    curvature : (X, Y, Z) ndarray of float64
    hierarchy : MorseHierarchy
        Cut it again (``hierarchy.segment(n_regions=...)``) without recomputing.
    n_regions : int
    operator, min_persistence, value_scale, spacing
        The parameters used; `min_persistence` is the threshold of the cut (for a
        region-count cut, one that gives the same count where ties allow).
    timings : dict of str -> float
        Seconds per stage.
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

    def region_maxima(self) -> NDArray[np.int64]:
        """(k,) flat voxel index of each region's highest curvature maximum."""
        region = self.hierarchy.region_of_maximum(**self.cut)
        first = np.zeros(self.n_regions, dtype=np.int64)
        # Maximum ids run by decreasing value: the first id seen per region is its top.
        seen = np.unique(region, return_index=True)[1]
        first[:] = self.hierarchy.maxima[seen]
        return first

    def region_table(self) -> list[dict]:
        """One entry per region: ``label``, ``size`` (voxels), ``maximum`` ([x, y, z] of
        its highest curvature maximum) and ``curvature_at_maximum``."""
        sizes = np.bincount(self.labels.ravel(), minlength=self.n_regions)
        table = []
        for region, top in enumerate(self.region_maxima()):
            where = tuple(int(c) for c in np.unravel_index(top, self.labels.shape))
            table.append({"label": region, "size": int(sizes[region]), "maximum": list(where),
                          "curvature_at_maximum": float(self.curvature[where])})
        return table


def segment_volume(
    volume,
    *,
    operator: str = "weighted",
    min_persistence: float | None = None,
    n_regions: int | None = None,
    value_scale: float | None = None,
    spacing=None,
    boundary: str = "linear",
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
    n_regions : int, optional
        Or cut it into exactly this many regions. Neither given: 30.
    value_scale : float, optional
        Default `volseg.curvature.default_value_scale` (graph as tall as wide).
    spacing : (3,) sequence of float, optional
        Default the Volume's spacing, or 1.
    boundary : {'linear', 'mirror'}
        Padding rule of `grid_curvature`.

    Returns
    -------
    Segmentation
    """
    operator = normalize_operator(operator)
    min_persistence, n_regions = check_cut(min_persistence, n_regions)
    if min_persistence is None and n_regions is None:
        n_regions = DEFAULT_REGIONS
    spacing = _validate.spacing(spacing, getattr(volume, "spacing", (1.0, 1.0, 1.0)))
    data = _validate.volume_array(volume)
    if value_scale is None:
        value_scale = default_value_scale(data, spacing)
    timings = {}
    start = time.perf_counter()
    curvature = grid_curvature(data, operator, spacing=spacing, value_scale=value_scale,
                               boundary=boundary)
    timings["curvature"] = time.perf_counter() - start
    start = time.perf_counter()
    hierarchy = descending_complex(curvature)
    timings["morse"] = time.perf_counter() - start
    start = time.perf_counter()
    labels = hierarchy.segment(min_persistence=min_persistence, n_regions=n_regions)
    timings["cut"] = time.perf_counter() - start
    k = int(labels.max()) + 1
    threshold = float(min_persistence) if min_persistence is not None else hierarchy.threshold_for(k)
    cut = {"min_persistence": min_persistence, "n_regions": n_regions}
    return Segmentation(labels, curvature, hierarchy, k, operator, threshold, float(value_scale),
                        spacing, timings, cut)
