"""`MorseHierarchy`: the maxima, the merge events and every cut of them, without
recomputation; `check_cut`, the checked request of a cut."""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import NDArray

from .._sizes import SizedByArrays
from ..errors import VolsegWarning
from . import _basins, _kernels, _measures, _prune, _prune_groups
from ._basins import BASINS
from ._graph import grid_offsets
from ._measures import SIZE, get_measure

__all__ = ["MorseHierarchy", "check_cut", "check_measure_cut", "AUTO_GAP_SIGNIFICANCE"]


def check_cut(min_persistence=None, n_regions=None, *, name="min_persistence") -> tuple:
    """The checked cut of a hierarchy, ``(min_persistence, n_regions)``, at most one given.

    `n_regions` must be a positive integer (not a float or a bool); `min_persistence`
    a non-negative number (``inf`` merges everything).
    """
    import numbers

    if min_persistence is not None and n_regions is not None:
        raise ValueError(f"give `{name}` or `n_regions`, not both")
    if n_regions is not None:
        if isinstance(n_regions, bool) or not isinstance(n_regions, numbers.Integral):
            raise ValueError(f"`n_regions` must be an integer, got {n_regions!r}")
        if n_regions < 1:
            raise ValueError(f"`n_regions` must be at least 1, got {n_regions}")
        n_regions = int(n_regions)
    if min_persistence is not None:
        try:
            value = float(min_persistence)
        except (TypeError, ValueError):
            raise ValueError(f"`{name}` must be a number, got "
                             f"{min_persistence!r}") from None
        if not value >= 0:  # NaN too
            raise ValueError(f"`{name}` must be a non-negative number, got "
                             f"{min_persistence!r}")
        min_persistence = value
    return min_persistence, n_regions

def check_measure_cut(min_persistence=None, n_regions=None, measure="persistence",
                      threshold=None) -> tuple:
    """The checked cut by a measure, ``(threshold, n_regions, measure)``.

    `min_persistence` is the persistence measure's `threshold` (give one of them);
    a size measure takes `threshold`. At most one of the threshold and `n_regions`.
    """
    measure = get_measure(measure).name
    if min_persistence is not None:
        if threshold is not None:
            raise ValueError("give `threshold` or `min_persistence`, not both")
        if get_measure(measure).pruned:
            raise ValueError(f"`min_persistence` is a threshold of persistence; with "
                             f"measure {measure!r} give `threshold`")
        threshold = min_persistence
    threshold, n_regions = check_cut(threshold, n_regions, name="threshold" if min_persistence
                                     is None else "min_persistence")
    return threshold, n_regions, measure


@dataclass(eq=False)
class MorseHierarchy(SizedByArrays):
    """The descending Morse complex of a field and its merge hierarchy.

    Made by `descending_complex`; every cut (`segment`, `region_of_maximum`) reads it
    without recomputation, by persistence, size or hypervolume (docs/design.md sections
    5 and 12).

    See Also
    --------
    descending_complex : builds it.
    volseg.morse.MEASURE_REGISTRY : the cut measures.

    Notes
    -----
    The merge events are those of 0-dimensional persistence of the superlevel sets
    (the elder rule of Edelsbrunner et al. 2002); a size measure prunes them as Carr et
    al. 2004: the region of least measure merges across its highest saddle first.

    References
    ----------
    H. Edelsbrunner, D. Letscher, A. Zomorodian, "Topological persistence and
    simplification", Discrete & Computational Geometry 28, 2002.

    H. Carr, J. Snoeyink, M. van de Panne, "Simplifying flexible isosurfaces using
    local geometric measures", IEEE Visualization 2004.

    Examples
    --------
    >>> import numpy as np
    >>> from volseg.morse import descending_complex
    >>> hierarchy = descending_complex(np.array([0.0, 3.0, 1.0, 2.0, 0.5]))
    >>> hierarchy.maxima.tolist(), hierarchy.n_components
    ([1, 3], 1)
    >>> hierarchy.segment(n_regions=2, measure="size").tolist()
    [1, 1, 1, 2, 2]

    Attributes
    ----------
    shape : tuple
        The field's shape; labels have it.
    cells : ndarray of int32, `shape`
        The unsimplified descending cells: the id of each vertex's maximum.
    maxima : (M,) ndarray of int
        Flat vertex index of each maximum, by decreasing value (id = position).
    values : (M,) ndarray of float
        Field value at each maximum.
    young, elder, target, source : (E,) ndarray of int32
        Merge events, in sweep order (decreasing saddle value): maximum ``young``
        dies into the component of ``elder`` (elder rule); its cell joins the cell
        ``target`` across the saddle edge when simplified. ``source`` and
        ``target`` are the cells at the two ends of that edge (young's side and
        elder's side): the edges of the cell graph's maximum spanning forest, on
        which the size measures prune.
    saddle : (E,) ndarray of int
        Flat vertex index of each event's saddle (the lower end of the highest edge
        crossing between the two components).
    saddle_value : (E,) ndarray of float
    mask : bool ndarray of `shape`, or None
        The vertices that took part; cuts label the others 0. Regions are 1..k
        with or without a mask (before 0.2, 0..k-1 without one).
    timings : dict
        Seconds per phase of the build (steepest ascent, path compression, ...).
    vertex_weight : float, (V,) ndarray, or None
        What one vertex counts in the ``size`` and ``hypervolume`` measures: None
        for 1 (sizes in vertices), a voxel's volume for world units, a mesh's
        vertex volumes (`with_vertex_weight`).

    A hierarchy fetched from the distributed build (`volseg.morse.blocks`) keeps its
    cells lazy and carries the function that sums its cells' measures on the workers
    (``_measure_cells``, default `_measures.cell_measures`).
    """

    shape: tuple
    cells: NDArray[np.int32]
    maxima: NDArray[np.int64]
    values: NDArray[np.float64]
    young: NDArray[np.int32]
    elder: NDArray[np.int32]
    target: NDArray[np.int32]
    source: NDArray[np.int32]
    saddle: NDArray[np.int64]
    saddle_value: NDArray[np.float64]
    mask: NDArray[np.bool_] | None
    _field: NDArray[np.float64]
    _adjacency: tuple | None = None
    _connectivity: object = None
    timings: dict = dataclass_field(default_factory=dict, repr=False)
    vertex_weight: object = None
    _pruned: dict = dataclass_field(default_factory=dict, repr=False)
    _measure_cells: object = dataclass_field(default=None, repr=False)

    def with_vertex_weight(self, weight) -> MorseHierarchy:
        """The same hierarchy with sizes counted in `weight` per vertex (a positive
        number, or one per vertex); persistence cuts are unchanged."""
        return dataclasses.replace(self, vertex_weight=checked_weight(weight, self.shape),
                                   _pruned={})

    @property
    def persistence(self) -> NDArray[np.float64]:
        """(M,) persistence of each maximum, aligned with `maxima`; inf for survivors."""
        out = np.full(len(self.maxima), np.inf)
        out[self.young] = self.values[self.young] - self.saddle_value
        return out

    @property
    def event_persistence(self) -> NDArray[np.float64]:
        """(E,) persistence of each merge event."""
        return self.values[self.young] - self.saddle_value

    @property
    def n_components(self) -> int:
        """Connected components of the graph (regions that can never merge)."""
        return len(self.maxima) - len(self.young)

    def extinction(self, measure: str = "persistence") -> NDArray[np.float64]:
        """(E,) the measure at which each event merges: its persistence, or the
        ``size`` / ``hypervolume`` of the region pruned across it (docs/design.md section
        12; pruned once per measure, then every cut is a lookup)."""
        if not get_measure(measure).pruned:
            return self.event_persistence
        return self._pruning(measure)[1]

    def curve(self, measure: str = "persistence", min_component: float = 0.0) -> tuple:
        """(extinctions, components) of the cuts' curve: the `extinction` of every
        event and the count of components that never merge, both without the
        components that `min_component` drops (they take no region)."""
        dropped = self.small_components(min_component)
        kept = ~dropped[self.young]
        components = self.n_components - len(np.unique(self.component_of_maximum()[dropped]))
        return self.extinction(measure)[kept], components

    def cell_measure(self, measure: str) -> NDArray[np.float64]:
        """(M,) the ``size`` or ``hypervolume`` of each maximum's own cell."""
        if not get_measure(measure).pruned:
            raise ValueError("persistence belongs to the events (`extinction`), not to cells")
        return self._pruning(measure)[2]

    def _cell_base(self, measure):
        """`cell_measure` before any pruning, computed once (a blockwise cut on the
        workers is given it: `with_cell_measures`): `_measures.Fixed`, or float sums
        with a mesh's vertex weights, or what both watershed measures read (one of
        `_basins.BASINS`, computed once for the two: a cut by volume that falls back
        to area reads the same records)."""
        key = _base_key(measure)
        if key not in self._pruned:
            self._pruned[key] = (self._measure_cells or _measures.cell_measures)(self, measure)
        return self._pruned[key]

    def release_vertex_records(self) -> None:
        """Let go of the per-vertex records that a cut by a watershed measure (area,
        volume) reads in memory (`_basins.records`: 4 bytes a vertex). The cuts made
        are kept; a first cut by the other watershed measure makes them again."""
        if isinstance(self.cells, np.ndarray):     # else given or summed blockwise: kept
            self._pruned.pop(_WATERSHED_BASE, None)

    def _cell_values(self, measure) -> NDArray[np.float64]:
        base = self._cell_base(measure)
        return base.values if isinstance(base, _measures.Fixed) else base

    def with_cell_measures(self, measures: dict) -> MorseHierarchy:
        """The same hierarchy given each cell's measures ({measure: what
        `_measures.cell_measures` gives}), so that its cuts read no cell."""
        out = dataclasses.replace(self, _pruned={})
        out._pruned.update({_base_key(m): v if isinstance(v, (_measures.Fixed, *BASINS))
                            else np.asarray(v, np.float64) for m, v in measures.items()})
        return out

    def _pruning(self, measure):
        """(order, extinction, cell values) of the pruning to the end by `measure`: in
        fixed point decided in groups of 64^3 voxels on a grid (`_prune_groups`; their
        small heaps stay in cache), else sequentially."""
        if measure not in self._pruned:
            base = self._cell_base(measure)
            if isinstance(base, BASINS):
                self._pruned[measure] = self._watershed(measure, base)
                return self._pruned[measure]
            fixed = isinstance(base, _measures.Fixed)
            if fixed and self._adjacency is None and len(self.shape) == 3:
                leaf_of, tree = _prune_groups.grid_leaves(self.maxima, self.shape)
                order, extinction = _prune_groups.grouped_prune(
                    self.source, self.target, base.sums, leaf_of, tree)
            else:
                order = np.empty(len(self.young), dtype=np.int64)
                extinction = np.empty(len(self.young), np.int64 if fixed else np.float64)
                _prune.prune(self.source, self.target, len(self.maxima),
                             base.sums if fixed else base, order, extinction)
            if fixed:
                extinction = extinction.astype(np.float64) * base.scale
            self._pruned[measure] = (order, extinction, self._cell_values(measure))
        return self._pruned[measure]

    def _watershed(self, measure, basins):
        """(order, extinction, cell values) of a watershed measure: the events by
        saliency (`_basins`), every cut a prefix of the order."""
        volume = get_measure(measure).by_height
        salient = _basins.saliency(basins, self.source, self.target, self.saddle_value,
                                   len(self.maxima), volume)
        order = _basins.merge_order(salient)
        scale = basins.scale * (basins.unit if volume else 1.0)
        return order, salient.astype(np.float64) * scale, basins.values

    def threshold_for(self, n_regions: int, measure: str = "persistence",
                      min_component: float = 0.0) -> float:
        """A threshold of `measure` whose cut has `n_regions` regions, if ties allow.

        The midpoint between the last kept and the first merged event's extinction;
        `segment(n_regions=k)` is exact even where ties make no threshold so. With
        `min_component`, among the components that are kept.
        """
        _, n_regions = check_cut(n_regions=n_regions)
        extinction, components = self.curve(measure, min_component)
        p = np.sort(extinction)[::-1]
        return midpoint_threshold(p, len(p), components, n_regions)

    def regions_at(self, thresholds, measure: str = "persistence") -> NDArray[np.int64]:
        """Region count of the cut at each threshold of `measure` (the persistence
        curve, or the size curve)."""
        p = np.sort(self.extinction(measure))
        return self.n_components + len(p) - np.searchsorted(p, np.asarray(thresholds), side="left")

    def largest_gap(self, region_range=(20, 40), measure: str = "persistence",
                    min_component: float = 0.0, fallback: int | None = None) -> int:
        """The region count k in `region_range` (inclusive) whose cut sits in the widest
        gap between consecutive extinctions of `measure`, on a log scale: the most
        clearly separated simplification (among the components `min_component`
        keeps). Falls back to the range's ends when the hierarchy has fewer maxima.
        Without `fallback`, the widest gap; with it, the gap that stands out most
        from a power law fitted to the window (`gap_evidence`) if it is larger than
        such a law makes in 95 % of windows (`AUTO_GAP_SIGNIFICANCE`), else
        `fallback`."""
        try:
            lo, hi = (int(r) for r in region_range)
        except (TypeError, ValueError):
            raise ValueError(f"`region_range` must be two region counts (lo, hi), got "
                             f"{region_range!r}") from None
        if not 1 <= lo <= hi:
            raise ValueError(f"`region_range` must be counts 1 <= lo <= hi, got {region_range!r}")
        extinction, components = self.curve(measure, min_component)
        p = np.sort(extinction)[::-1]
        return widest_gap_count(p, len(p), components, (lo, hi), len(self.maxima), fallback)

    def gap_evidence(self, region_range, measure: str = "persistence",
                     min_component: float = 0.0) -> dict:
        """What `largest_gap` with a fallback read (`gap_evidence`)."""
        extinction, components = self.curve(measure, min_component)
        p = np.sort(extinction)[::-1]
        return gap_evidence(p, len(p), components, tuple(region_range))

    def component_of_maximum(self) -> NDArray[np.int32]:
        """(M,) the connected component of the graph (of the mask) of each maximum,
        numbered by its highest maximum: the regions of the cut that merges all."""
        if "components" not in self._pruned:
            region = np.empty(len(self.maxima), dtype=np.int32)
            _kernels.regions_of_cut(self.young, self.target, np.ones(len(self.young), bool),
                                    region)
            self._pruned["components"] = region
        return self._pruned["components"]

    def small_components(self, min_share: float) -> NDArray[np.bool_]:
        """(M,) True for the maxima of components holding less than `min_share` of the
        vertices that took part (of their weight, with `vertex_weight`)."""
        if not 0 <= min_share < 1:
            raise ValueError(f"`min_component` must be a share in [0, 1), got {min_share!r}")
        if min_share == 0 or self.n_components == 1:
            return np.zeros(len(self.maxima), dtype=bool)
        component = self.component_of_maximum()
        # In vertices (exact integers) on a grid, as where a blockwise hierarchy's
        # buckets are (`_bucket_cut.small_components`); a mesh's weights otherwise.
        base = self._cell_base(SIZE.name)
        sizes = np.bincount(component, weights=base.sums if isinstance(base, _measures.Fixed)
                            else base)
        return (sizes < min_share * sizes.sum())[component]

    def _merged_events(self, min_persistence, n_regions, measure, threshold, dropped):
        threshold, n_regions, measure = check_measure_cut(min_persistence, n_regions,
                                                          measure, threshold)
        gone = dropped[self.young]           # the events inside a dropped component
        keep = None
        if n_regions is not None:
            components = self.n_components - len(np.unique(self.component_of_maximum()[dropped]))
            keep = events_kept(n_regions, len(self.maxima), components, stacklevel=4)
        if not get_measure(measure).pruned:
            p = np.where(gone, -np.inf, self.event_persistence)
            if keep is not None:
                return _all_but_most_persistent(p, self.young, keep)
            return gone | (p < (0.0 if threshold is None else threshold))
        order, extinction, _ = self._pruning(measure)
        if keep is None:
            return gone | (extinction < (0.0 if threshold is None else threshold))
        order = order[~gone[order]]
        merged = gone.copy()
        merged[order[:max(len(order) - keep, 0)]] = True
        return merged

    def region_of_maximum(self, min_persistence=None, n_regions=None, *,
                          measure="persistence", threshold=None,
                          min_component=0.0) -> NDArray[np.int32]:
        """(M,) region index 0..k-1 of each maximum for a cut (see `segment`; the
        label is the index + 1): the maxima joined by the merged events, regions
        numbered by their highest maximum (a compiled union-find: 8 M maxima take a
        few hundred ms and a few bytes each); -1 for the maxima of a dropped
        component (`min_component`)."""
        dropped = self.small_components(min_component)
        merged = self._merged_events(min_persistence, n_regions, measure, threshold, dropped)
        region = np.empty(len(self.maxima), dtype=np.int32)
        # Persistence joins each young maximum to its target (as it always has: every
        # cell of its component at its death is a lower-persistence event, merged
        # too); a size measure joins the two ends of the saddle edge.
        young = self.source if get_measure(measure).pruned else self.young
        _kernels.regions_of_cut(young, self.target, merged, region)
        if dropped.any():
            kept = np.unique(region[~dropped])         # consecutive again, in order
            region = np.searchsorted(kept, region).astype(np.int32)
            region[dropped] = -1
        return region

    def segment(self, min_persistence: float | None = None, n_regions: int | None = None, *,
                measure: str = "persistence", threshold: float | None = None,
                min_component: float = 0.0):
        """Labels of a cut of the hierarchy: no recomputation, one gather per vertex.

        Parameters
        ----------
        min_persistence : float, optional
            Merge every maximum with persistence below it (default 0: the
            unsimplified complex); the same as ``threshold`` with the persistence
            measure.
        n_regions : int, optional
            Instead, exactly this many regions: the ``n_regions - 1`` most
            persistent non-global maxima stay (ties broken by maximum value), or the
            regions left when the pruning by `measure` reaches that count. Fewer
            maxima than asked: all of them, with a warning.
        measure : {'persistence', 'size', 'hypervolume'}
            What decides which regions survive (docs/design.md section 12). ``size`` and
            ``hypervolume`` prune as Carr et al. (2004): the region of least measure
            merges across its highest saddle, its measure added to its neighbour's.
        threshold : float, optional
            Merge every region whose `measure` is below it when its turn comes (the
            events whose `extinction` is below it).
        min_component : float
            With a mask: the connected components of the mask holding less than
            this share of its vertices are labelled 0 and take no region of
            `n_regions` (default 0: none dropped).

        Returns
        -------
        ndarray of int32, `shape`
            Consecutive labels 1..k, ordered by decreasing maximum value; 0 for the
            vertices outside the mask or in a dropped component. Every region is
            connected. (Before volseg 0.2, 0..k-1 without a mask: region 0 showed as
            background in napari, ITK-SNAP and Slicer.)
        """
        return self.relabel(self.region_of_maximum(min_persistence, n_regions, measure=measure,
                                                   threshold=threshold,
                                                   min_component=min_component))

    def relabel(self, region, out=None):
        """Labels 1..k of every vertex from the region index of each maximum (the
        result of `region_of_maximum`), 0 outside the mask: what `segment` returns,
        for a caller that needs the regions too. `out`: an integer array of `shape` to
        write them into (numpy cells only; a viewer's live cut reuses its buffer, in the
        smallest type that holds its largest label)."""
        lazy = type(self.cells).__module__.startswith("dask.")
        table = region_table(region, self.mask is not None)
        if out is not None:
            if lazy or out.shape != self.cells.shape or out.dtype.kind not in "iu" \
                    or not out.flags.c_contiguous:
                raise ValueError(f"`out` must be a C-contiguous integer array of the cells' "
                                 f"shape {self.cells.shape}, for cells in memory")
            if int(table.max(initial=0)) > np.iinfo(out.dtype).max:
                raise ValueError(f"`out` ({out.dtype}) cannot hold label "
                                 f"{int(table.max())}")
            table = table.astype(out.dtype, copy=False)
        if not lazy:
            out = np.empty(self.cells.shape, table.dtype) if out is None else out
            cells = np.ascontiguousarray(self.cells)
            _kernels.take(table, cells.reshape(-1), out.reshape(-1))
            return out
        import dask

        # The table as one shared task: a distributed scheduler sends it to each
        # worker once, not inside every block's task.
        return relabelled(self.cells, dask.delayed(table, pure=True), table.dtype)

    def region_adjacency(self, labels=None, **cut):
        """The regions of a cut as a networkx graph.

        Nodes are region labels with ``size``, ``maximum`` (flat vertex index) and
        ``value``; edges join adjacent regions with ``saddle`` (the highest value
        min(f(u), f(v)) over edges (u, v) crossing between them). `labels`
        defaults to ``segment(**cut)``. With a mask, label 0 (outside it) is not
        a region: it has no node and no edges.
        """
        import networkx as nx

        if labels is None:
            labels = self.segment(**cut)
        labels = np.asarray(labels)
        if labels.shape != tuple(self.shape):
            raise ValueError(f"`labels` must have the field's shape {tuple(self.shape)}, "
                             f"got {labels.shape}")
        if labels.dtype.kind not in "biu" or (labels.size and labels.min() < 0):
            raise ValueError("`labels` must hold non-negative integer labels")
        f = self._field
        pairs, saddles = [], []
        if self._adjacency is None:
            for step in grid_offsets(len(self.shape), self._connectivity):
                if tuple(step) <= (0,) * len(step):
                    continue
                sizes = zip(step, self.shape, strict=True)
                src = tuple(slice(max(-s, 0), n - max(s, 0)) for s, n in sizes)
                sizes = zip(step, self.shape, strict=True)
                dst = tuple(slice(max(s, 0), n - max(-s, 0)) for s, n in sizes)
                a, b = labels[src].ravel(), labels[dst].ravel()
                cross = a != b
                pairs.append(np.sort(np.stack([a[cross], b[cross]], 1), axis=1))
                saddles.append(np.minimum(f[src].ravel()[cross], f[dst].ravel()[cross]))
        else:
            indptr, indices = self._adjacency
            u = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
            a, b = labels[u], labels[indices]
            cross = a < b
            pairs.append(np.stack([a[cross], b[cross]], 1))
            saddles.append(np.minimum(f[u[cross]], f[indices[cross]]))
        pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), int)
        saddles = np.concatenate(saddles) if saddles else np.zeros(0)
        first = 0
        if self.mask is not None:  # label 0 is outside the mask: no edges, no node
            inside = pairs[:, 0] > 0
            pairs, saddles, first = pairs[inside], saddles[inside], 1
        graph = nx.Graph()
        flat_field = f.ravel()
        # The labels present, compacted: sparse or huge labels (2^40) cost nothing.
        regions, inverse, sizes = np.unique(labels.ravel(), return_inverse=True,
                                            return_counts=True)
        # Highest vertex per region under simulation of simplicity: the last write wins.
        order = np.lexsort((np.arange(flat_field.size), flat_field))
        top = np.full(len(regions), -1)
        top[inverse.ravel()[order]] = order
        for i in range(first if len(regions) and regions[0] == 0 else 0, len(regions)):
            graph.add_node(int(regions[i]), size=int(sizes[i]), maximum=int(top[i]),
                           value=float(flat_field[top[i]]))
        if len(pairs):
            n = np.int64(len(regions))
            key = np.searchsorted(regions, pairs[:, 0]) * n + np.searchsorted(regions, pairs[:, 1])
            order = np.lexsort((saddles, key))
            last = np.r_[key[order][1:] != key[order][:-1], True]
            for k, s in zip(key[order][last], saddles[order][last], strict=True):
                graph.add_edge(int(regions[k // n]), int(regions[k % n]), saddle=float(s))
        return graph


def events_kept(n_regions: int, n_maxima: int, components: int, stacklevel: int = 2) -> int:
    """How many events a cut into `n_regions` keeps unmerged, with a warning when the
    count cannot be met (more regions than maxima, fewer than components)."""
    if n_regions > n_maxima:
        warnings.warn(f"asked for {n_regions} regions but the field has only {n_maxima} "
                      "maxima; returning all of them", VolsegWarning, stacklevel=stacklevel)
    elif n_regions < components:
        warnings.warn(f"asked for {n_regions} regions but the graph has {components} "
                      "connected components; returning one region per component",
                      VolsegWarning, stacklevel=stacklevel)
    return max(n_regions - components, 0)


def midpoint_threshold(p, n_events: int, components: int, n_regions: int) -> float:
    """`MorseHierarchy.threshold_for` from the extinctions sorted decreasing: `p`, the
    first of `n_events` of them (at least ``n_regions + 1`` where there are as many)."""
    keep = n_regions - components
    if keep <= 0:
        return float(p[0]) + 1.0 if n_events else 0.0
    if keep >= n_events:
        return 0.0
    return 0.5 * float(p[keep - 1] + p[keep])


#: ``auto`` takes a gap only when a power law fitted to the window's extinctions would
#: make one as large (relative to its own step there) in fewer than this share of
#: windows. Real scans' curves are power laws, whose widest step (log scale) always
#: falls at the window's low edge; the spacings of a power law's order statistics, in
#: units of its step, are about exponential, so the largest of n exceeds
#: -log(1 - (1 - share)^(1/n)) with probability `share` (6.0 for the 21 counts 20-40).
AUTO_GAP_SIGNIFICANCE = 0.05


def gap_factor(n: int) -> float:
    """The ratio a gap must reach among `n` to stand out (`AUTO_GAP_SIGNIFICANCE`)."""
    return float(-np.log(1.0 - (1.0 - AUTO_GAP_SIGNIFICANCE) ** (1.0 / max(n, 1))))


def gap_evidence(p, n_events: int, components: int, region_range) -> dict:
    """The gap that stands out most between consecutive extinctions `p` (sorted
    decreasing, the first of `n_events`) for a count in `region_range`: each log gap
    divided by the step of the power law p_r ~ r^-a fitted (least squares, log-log) to
    the window's extinctions. ``n_regions`` at it, its ``gap``, the power law's
    ``expected`` step there and their ``ratio``; ``widest``, the count at the widest
    gap; ``needed``, the ratio that stands out (`gap_factor`); None without a count in
    the window."""
    lo, hi = region_range
    ranks = np.arange(max(lo, components), hi + 1) - components      # events kept
    ranks = ranks[(ranks >= 1) & (ranks < n_events)]
    if not len(ranks):
        return {"n_regions": None, "gap": None, "expected": None, "ratio": None,
                "widest": None, "needed": None}
    upper, lower = p[ranks - 1], p[ranks]
    with np.errstate(divide="ignore", invalid="ignore"):
        gaps = np.where(lower > 0, np.log(upper) - np.log(lower), np.inf)
        window = np.r_[upper, lower[-1]]
        r = np.arange(ranks[0], ranks[-1] + 2, dtype=np.float64)
        fit = window > 0
        slope = (-np.polyfit(np.log(r[fit]), np.log(window[fit]), 1)[0]
                 if fit.sum() >= 2 else 0.0)
        expected = max(slope, 0.0) * np.log((ranks + 1) / ranks)
        ratio = np.where(expected > 0, gaps / expected, np.where(gaps > 0, np.inf, 0.0))
    best = int(np.argmax(ratio))
    return {"n_regions": int(ranks[best] + components), "gap": float(gaps[best]),
            "expected": float(expected[best]), "ratio": float(ratio[best]),
            "widest": int(ranks[int(np.argmax(gaps))] + components),
            "needed": gap_factor(len(ranks))}


def widest_gap_count(p, n_events: int, components: int, region_range, n_maxima: int,
                     fallback: int | None = None) -> int:
    """`MorseHierarchy.largest_gap` from the extinctions sorted decreasing: `p`, the
    first of `n_events` of them (at least ``region_range[1] + 1`` where there are as
    many), with a checked `region_range`. With `fallback`, that count (within the
    range) unless the gap that stands out most is `stands out (`gap_evidence`,
    `AUTO_GAP_SIGNIFICANCE`)."""
    lo, hi = region_range
    evidence = gap_evidence(p, n_events, components, region_range)
    if evidence["n_regions"] is None:
        return max(min(hi, n_maxima), 1)
    if fallback is None:
        return evidence["widest"]
    if not evidence["ratio"] >= evidence["needed"]:
        return max(min(min(max(fallback, lo), hi), n_maxima), 1)
    return evidence["n_regions"]


def _all_but_most_persistent(p, young, keep):
    """True for every event but the `keep` most persistent; ties: the older (lower id)
    young maximum first. The order of ``np.lexsort((young, -p))[:keep]``, in linear
    time: the keep-th largest persistence by a partition, then only its ties sorted
    (a full sort of 8 M events took 3 s per cut at 512^3)."""
    merged = np.ones(len(p), dtype=bool)
    if keep <= 0:
        return merged
    if keep >= len(p):
        return ~merged
    kth = np.partition(p, len(p) - keep)[len(p) - keep]      # the keep-th largest
    above = p > kth
    ties = np.flatnonzero(p == kth)
    chosen = ties[np.argsort(young[ties], kind="stable")[:keep - int(above.sum())]]
    merged[above] = False
    merged[chosen] = False
    return merged


def checked_weight(weight, shape):
    """`with_vertex_weight`'s checked `weight` for a field of `shape`."""
    if np.ndim(weight) == 0:
        weight = float(weight)
        if not (weight > 0 and np.isfinite(weight)):
            raise ValueError(f"`weight` must be a positive number, got {weight!r}")
        return weight
    weight = np.asarray(weight, dtype=np.float64)
    if weight.shape != (int(np.prod(shape)),) or not np.all(weight >= 0):
        raise ValueError("`weight` must hold one non-negative number per vertex "
                         f"({int(np.prod(shape))}), got shape {weight.shape}")
    return weight


def relabelled(cells, table, dtype):
    """Lazy labels of lazy `cells` by a relabelling `table` (a Delayed of
    `region_table`, wherever it was computed), block by block."""
    return cells.map_blocks(lambda block, table: table[block], table, dtype=dtype,
                            meta=np.empty((0,) * cells.ndim, dtype))


def region_table(region, masked: bool):
    """The relabelling table of a cut: regions 1..k, and a last entry 0 for the cells
    of -1 (outside the mask) and for the regions -1 (dropped components)."""
    if not masked and region.size and region.min() < 0:
        raise ValueError("only a hierarchy with a mask can drop components "
                         "(`min_component`): label 0 is outside the mask")
    return np.concatenate([region + 1, np.zeros(1, dtype=region.dtype)])


#: The cache key of the records both watershed measures (area, volume) read.
_WATERSHED_BASE = ("cells", "watershed")


def _base_key(measure) -> tuple:
    """The cache key of a measure's cell base: `_WATERSHED_BASE` for both watershed
    measures."""
    found = get_measure(measure)
    return _WATERSHED_BASE if found.watershed else ("cells", found.name)
