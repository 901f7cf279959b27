"""Descending Morse complex of a vertex field, simplified hierarchically by persistence.

Stands alone: of volseg it imports only its own modules and the shared leaves
(`volseg._kuhn`, the grid neighbourhood; `volseg._union_find`; `volseg._registry`;
`volseg.errors`); otherwise numpy, scipy and numba, networkx only for graph input and
`region_adjacency`. It imports nothing of Dask: a Dask field is handed to the
distributed build, `volseg.morse.blocks`, imported only then. The package:

- `_graph`: grid connectivities, graph input as CSR, the checked field;
- `_build`: the in-memory build (`descending_complex`), `_edges` and `_kernels` its
  cross-cell edges and compiled passes;
- `_hierarchy`: `MorseHierarchy`, every cut of it without recomputation; `cuts`: a
  cut with the report the pipeline writes;
- `_measures`: the cut measures, a registry (`MEASURE_REGISTRY`: persistence, size,
  hypervolume; docs/design.md section 12), and each cell's size and hypervolume;
  `_prune` and `_prune_groups` (with `_group_tree`, `_group_kernels`): the Carr et al.
  pruning over the merge events, sequential or in a tree of groups;
- `blocks/`: the same build on a Dask array, block by block, and its hierarchy kept in
  buckets on the workers (`HierarchyOnWorkers`).

docs/design.md section 5 is the contract:

- order: simulation of simplicity, u is higher than v when (f(u), u) > (f(v), v),
  so every result is deterministic and plateaus need no special case;
- maxima: vertices higher than all their neighbours;
- descending cells: each vertex belongs to the maximum its steepest ascent (always
  to the highest neighbour) reaches;
- persistence (0-dimensional, superlevel sets, elder rule): sweeping from high to
  low, when two components meet at vertex v the one with the lower maximum m dies,
  ``persistence(m) = f(m) - f(v)``; a component's highest maximum has infinite
  persistence. The saddle of an edge (u, v) is ``min(f(u), f(v))``;
- simplification at threshold t: every maximum with persistence < t merges, with
  its whole cell, across the saddle edge where it died into the cell on the other
  side (transitively). Merging across the saddle edge, rather than into the
  component's oldest maximum, keeps every region connected; the region count is
  still ``1 + #{non-global maxima with persistence >= t}`` (per connected
  component of the graph).

Examples
--------
>>> import numpy as np
>>> field = np.array([0.0, 3.0, 1.0, 2.0, 0.5])  # two peaks, at 1 and 3
>>> hierarchy = descending_complex(field)
>>> hierarchy.maxima.tolist(), hierarchy.persistence.tolist()
([1, 3], [inf, 1.0])
>>> hierarchy.segment().tolist(), hierarchy.segment(n_regions=1).tolist()
([1, 1, 1, 2, 2], [1, 1, 1, 1, 1])
"""

from __future__ import annotations

from ._build import descending_complex
from ._curve import CurveSample, curve_sample
from ._graph import grid_offsets
from ._hierarchy import AUTO_GAP_SIGNIFICANCE, MorseHierarchy, check_cut, check_measure_cut
from ._measures import MEASURE_REGISTRY, MEASURES, PERSISTENCE, SIZE, Measure, get_measure
from .cuts import CutReport, cut_of

__all__ = ["descending_complex", "MorseHierarchy", "grid_offsets", "check_cut",
           "check_measure_cut", "Measure", "MEASURE_REGISTRY", "MEASURES", "PERSISTENCE",
           "SIZE", "get_measure", "CurveSample", "curve_sample", "CutReport", "cut_of",
           "AUTO_GAP_SIGNIFICANCE"]
