"""One cut of a hierarchy for the pipeline: its labels and its `CutReport`, what the
summary, the files and a `Segmentation` need of the hierarchy (O(regions), a thinned
curve). `cut_of` runs the cut in memory, or hands it to a hierarchy kept where it was
built (`volseg.morse.blocks.HierarchyOnWorkers.cut_of`), which runs the same
`report_of` there or cuts in its buckets."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._curve import CurveSample, curve_sample
from ._hierarchy import MorseHierarchy

__all__ = ["CutReport", "LISTED_PERSISTENCES", "cut_of", "report_of", "record_of"]

#: Event persistences listed in a summary, the largest first.
LISTED_PERSISTENCES = 200


@dataclass(frozen=True)
class CutReport:
    """A cut of a hierarchy, as the pipeline reports it.

    `record`: the cut asked and made (measure, threshold, counts, ``cut_threshold``);
    `n_regions` its regions; `top_maxima`, `top_values`, `top_persistence`: each
    region's highest maximum (flat index), its value and its persistence, region i + 1
    at position i; `n_maxima`, `n_components`, `n_events` of the hierarchy;
    `largest_persistences`: the events' largest, decreasing; `curve`: the cut
    measure's curve, thinned (`volseg.morse.CurveSample`).
    """

    record: dict
    n_regions: int
    top_maxima: np.ndarray
    top_values: np.ndarray
    top_persistence: np.ndarray
    n_maxima: int
    n_components: int
    n_events: int
    largest_persistences: np.ndarray
    curve: CurveSample


def cut_of(hierarchy, cut, out=None) -> tuple:
    """(labels 1..k, `CutReport`) of `cut` (a `volseg.segment.CutRequest`): into `out`
    when given (in memory); a hierarchy kept where it was built (not a
    `MorseHierarchy`) cuts itself there and gives lazy labels."""
    if not isinstance(hierarchy, MorseHierarchy):
        if out is not None:
            raise ValueError("`out` takes labels in memory; these are blockwise (lazy)")
        return hierarchy.cut_of(cut)
    region, report = report_of(hierarchy, hierarchy.mask is not None, cut)
    return hierarchy.relabel(region, out=out), report


def record_of(cut, asked: dict, k: int, hierarchy) -> dict:
    """The cut asked and made, as a report records it (`hierarchy` gives the threshold
    of a count)."""
    threshold = (float(cut.threshold) if cut.threshold is not None
                 else hierarchy.threshold_for(k, cut.measure, asked["min_component"]))
    record = {"measure": cut.measure, "threshold": cut.threshold,
              "min_persistence": cut.min_persistence, "n_regions": asked["n_regions"],
              "auto": cut.auto, "cut_threshold": threshold,
              "min_component": asked["min_component"]}
    if cut.auto:
        record["auto_evidence"] = hierarchy.gap_evidence(cut.auto_range, cut.measure,
                                                         asked["min_component"])
    return record


def report_of(hierarchy, masked: bool, cut) -> tuple:
    """(region of each maximum, `CutReport`) of `cut` on a `MorseHierarchy` (`masked`:
    whether its vertices were masked)."""
    asked = cut.of(hierarchy, masked)
    region = hierarchy.region_of_maximum(**asked)
    k = int(region.max()) + 1
    record = record_of(cut, asked, k, hierarchy)
    tops = region_tops(region, k)
    # What is the same for every cut of the hierarchy, once per hierarchy (a viewer's
    # slider cuts it again and again).
    cache = hierarchy._pruned
    if "listed_persistence" not in cache:
        persistence = hierarchy.event_persistence
        if len(persistence) > LISTED_PERSISTENCES:
            persistence = persistence[np.argpartition(persistence, -LISTED_PERSISTENCES)
                                      [-LISTED_PERSISTENCES:]]
        cache["listed_persistence"] = np.sort(persistence)[::-1]
        cache["persistence"] = hierarchy.persistence
    key = ("curve_sample", cut.measure, asked["min_component"])
    if key not in cache:
        cache[key] = curve_sample(*hierarchy.curve(cut.measure, asked["min_component"]))
    report = CutReport(
        record, k, hierarchy.maxima[tops].astype(np.int64), hierarchy.values[tops].copy(),
        cache["persistence"][tops], len(hierarchy.maxima), int(hierarchy.n_components),
        len(hierarchy.young), cache["listed_persistence"].copy(), cache[key])
    return region, report


def region_tops(region, k: int) -> np.ndarray:
    """The first maximum (its highest: ids run by decreasing value) of each region
    0..k-1 of `region` (-1: a dropped component). Cuts number regions in the order
    their first maximum comes, so the firsts are where the running maximum of the ids
    steps up: O(M), no sort; any other numbering takes `np.unique`'s sort."""
    running = np.maximum.accumulate(region) if len(region) else region
    steps = np.flatnonzero(np.diff(running, prepend=-1) > 0)
    if len(steps) == k and np.array_equal(region[steps], np.arange(k)):
        return steps
    ids, tops = np.unique(region, return_index=True)
    return tops[ids >= 0]
