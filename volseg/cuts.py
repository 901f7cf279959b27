"""One cut of a hierarchy for the pipeline: its labels and its `CutReport`, what the
summary, the files and a `Segmentation` need of the hierarchy (O(regions), a thinned
curve). `cut_of` runs the cut in memory, or where a blockwise hierarchy is kept
(`volseg.morse._on_workers`): the same function, `report_of`, in both."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .morse import CurveSample, HierarchyOnWorkers, curve_sample

__all__ = ["CutReport", "LISTED_PERSISTENCES", "MAX_COUNT_IN_BUCKETS", "cut_of", "in_buckets",
           "report_of"]

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
    """(labels 1..k, `CutReport`) of `cut` (a `volseg.segment.CutRequest`): lazy labels
    for a blockwise hierarchy, relabelled block by block; into `out` when given (in
    memory)."""
    masked = hierarchy.mask is not None
    if isinstance(hierarchy, HierarchyOnWorkers):
        if out is not None:
            raise ValueError("`out` takes labels in memory; these are blockwise (lazy)")
        if in_buckets(hierarchy, cut):
            return _cut_in_buckets(hierarchy, cut, masked)
        return hierarchy.run(report_of, cut, measures=cut.measures(masked))
    region, report = report_of(hierarchy, masked, cut)
    return hierarchy.relabel(region, out=out), report


#: The largest region count a blockwise cut chooses from the buckets' heads (each
#: bucket sends its count + 1 largest persistences to the task that merges them);
#: above it the cut runs where the hierarchy is joined.
MAX_COUNT_IN_BUCKETS = 100_000


def in_buckets(hierarchy, cut) -> bool:
    """Whether the cut of a blockwise `hierarchy` runs where its buckets are, joining
    no maximum (`volseg.morse.HierarchyOnWorkers.cut_in_buckets`): a cut of at most
    `MAX_COUNT_IN_BUCKETS` regions, by persistence or by a size measure with no
    per-vertex weight."""
    return (hierarchy.buckets is not None and cut.ranks_read <= MAX_COUNT_IN_BUCKETS + 1
            and (cut.measure == "persistence" or np.ndim(hierarchy.vertex_weight) == 0))


def _cut_in_buckets(hierarchy, cut, masked: bool) -> tuple:
    min_component = cut.min_component if masked else 0.0
    dropped = hierarchy.dropped_components(min_component) if min_component > 0 else None
    merges = None if cut.measure == "persistence" else hierarchy.pruned_in_buckets(cut.measure)
    head = hierarchy.head(max(LISTED_PERSISTENCES, cut.ranks_read), dropped, merges)
    listed = (head if dropped is None and merges is None
              else hierarchy.head(LISTED_PERSISTENCES))
    asked = cut.of(head, masked)
    labels, (top_maxima, top_values, top_persistence), curve = hierarchy.cut_in_buckets(
        head, asked["threshold"], asked["n_regions"], dropped, merges)
    k = len(top_maxima)
    report = CutReport(
        _record(cut, asked, k, head), k, top_maxima, top_values, top_persistence,
        listed.n_maxima, listed.n_components, listed.n_events,
        listed.values[:LISTED_PERSISTENCES].copy(), curve)
    return labels, report


def _record(cut, asked: dict, k: int, hierarchy) -> dict:
    """The cut asked and made, as a report records it (`hierarchy` gives the threshold
    of a count)."""
    threshold = (float(cut.threshold) if cut.threshold is not None
                 else hierarchy.threshold_for(k, cut.measure, asked["min_component"]))
    return {"measure": cut.measure, "threshold": cut.threshold,
            "min_persistence": cut.min_persistence, "n_regions": asked["n_regions"],
            "auto": cut.auto, "cut_threshold": threshold,
            "min_component": asked["min_component"]}


def report_of(hierarchy, masked: bool, cut) -> tuple:
    """(region of each maximum, `CutReport`) of `cut` on a `MorseHierarchy` (`masked`:
    whether its vertices were masked)."""
    asked = cut.of(hierarchy, masked)
    region = hierarchy.region_of_maximum(**asked)
    k = int(region.max()) + 1
    record = _record(cut, asked, k, hierarchy)
    # Maximum ids run by decreasing value: the first id seen per region is its top
    # (-1, a dropped component, sorts first).
    ids, tops = np.unique(region, return_index=True)
    tops = tops[ids >= 0]
    persistence = hierarchy.event_persistence
    if len(persistence) > LISTED_PERSISTENCES:
        persistence = persistence[np.argpartition(persistence, -LISTED_PERSISTENCES)
                                  [-LISTED_PERSISTENCES:]]
    persistence = np.sort(persistence)[::-1]
    extinction, components = hierarchy.curve(cut.measure, asked["min_component"])
    report = CutReport(
        record, k, hierarchy.maxima[tops].astype(np.int64), hierarchy.values[tops].copy(),
        hierarchy.persistence[tops], len(hierarchy.maxima), int(hierarchy.n_components),
        len(hierarchy.young), persistence,
        curve_sample(extinction, components))
    return region, report
