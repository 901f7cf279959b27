"""A cut of the blockwise hierarchy (`HierarchyOnWorkers`), where it is kept: in its
buckets (no task joins every maximum) for a count of at most `MAX_COUNT_IN_BUCKETS`,
else beside the joined hierarchy, by the same `report_of` as in memory."""

from __future__ import annotations

import numpy as np

from .._measures import get_measure
from ..cuts import LISTED_PERSISTENCES, CutReport, record_of, report_of

__all__ = ["MAX_COUNT_IN_BUCKETS", "in_buckets", "cut_of", "cut_in_buckets"]

#: The largest region count a blockwise cut chooses from the buckets' heads (each
#: bucket sends its count + 1 largest persistences to the task that merges them);
#: above it the cut runs where the hierarchy is joined.
MAX_COUNT_IN_BUCKETS = 100_000


def in_buckets(hierarchy, cut) -> bool:
    """Whether the cut of a blockwise `hierarchy` runs where its buckets are, joining
    no maximum (`volseg.morse.HierarchyOnWorkers.cut_in_buckets`): a cut of at most
    `MAX_COUNT_IN_BUCKETS` regions, by persistence or by a size measure with no
    per-vertex weight. A watershed measure (``area``, ``volume``) reads the events
    in sweep order: where the hierarchy is joined."""
    measure = get_measure(cut.measure)
    return (hierarchy.buckets is not None and cut.ranks_read <= MAX_COUNT_IN_BUCKETS + 1
            and not measure.watershed
            and (not measure.pruned or np.ndim(hierarchy.vertex_weight) == 0))


def cut_of(hierarchy, cut) -> tuple:
    """(lazy labels 1..k, `CutReport`) of `cut` on a `HierarchyOnWorkers`: in its
    buckets when `in_buckets`, else where its joined hierarchy is (`report_of`, as in
    memory)."""
    masked = hierarchy.mask is not None
    if in_buckets(hierarchy, cut):
        return cut_in_buckets(hierarchy, cut, masked)
    return hierarchy.run(report_of, cut, measures=cut.measures(masked))


def cut_in_buckets(hierarchy, cut, masked: bool) -> tuple:
    """`cut_of` where the buckets are: no task holds every maximum."""
    min_component = cut.min_component if masked else 0.0
    dropped = hierarchy.dropped_components(min_component) if min_component > 0 else None
    merges = (hierarchy.pruned_in_buckets(cut.measure) if get_measure(cut.measure).pruned
              else None)
    head = hierarchy.head(max(LISTED_PERSISTENCES, cut.ranks_read), dropped, merges)
    listed = (head if dropped is None and merges is None
              else hierarchy.head(LISTED_PERSISTENCES))
    asked = cut.of(head, masked)
    labels, (top_maxima, top_values, top_persistence), curve = hierarchy.cut_in_buckets(
        head, asked["threshold"], asked["n_regions"], dropped, merges)
    k = len(top_maxima)
    report = CutReport(
        record_of(cut, asked, k, head), k, top_maxima, top_values, top_persistence,
        listed.n_maxima, listed.n_components, listed.n_events,
        listed.values[:LISTED_PERSISTENCES].copy(), curve)
    return labels, report
