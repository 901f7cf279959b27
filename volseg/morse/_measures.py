"""Measures of the hierarchy's regions beside persistence (docs/design.md section 12): each
cell's size and hypervolume, additive over the cells of a region.

- ``size``: the cell's vertices (voxels), times the vertex weight (a voxel's volume
  from the spacing, a mesh vertex's share of its star);
- ``hypervolume``: the sum over the cell's vertices of f(v) - s for those above s,
  where s is the cell's highest saddle (the first one it meets sweeping down, where
  Carr et al. prune a leaf), times the vertex weight.

On a grid the terms are integers (a count; the hypervolume in fixed point, `STEPS`
steps per range of the field), so the sums are exact in any order: a blockwise sum
of per-block sums equals the in-memory one bit for bit, whatever the chunking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._registry import Registry
from .._sizes import SizedByArrays
from . import _prune

__all__ = ["Measure", "MEASURE_REGISTRY", "MEASURES", "PERSISTENCE", "SIZE", "STEPS", "Fixed",
           "get_measure",
           "check_measure", "cell_measures"]


@dataclass(frozen=True)
class Measure:
    """A cut measure (docs/design.md section 12): what decides which regions survive a cut.

    `pruned`: False for a measure read off the elder-rule events as they are (the
    height, persistence); True for one that is a sum of per-vertex terms over a
    region: cut by the Carr et al. pruning, or with `watershed` by the saliency of
    the events as a watershed hierarchy (`_basins`). `by_height`: a vertex's term is
    its height above the saddle (hypervolume, volume), else 1 (size, area), both
    times the vertex weight. `option`: the command line's option for its threshold; `unit`:
    what its threshold counts.
    """

    name: str
    label: str
    pruned: bool
    by_height: bool
    option: str
    unit: str
    summary: str
    aliases: tuple[str, ...] = ()
    watershed: bool = False


MEASURE_REGISTRY = Registry("measure", [
    Measure("persistence", "persistence", False, False, "--min-persistence",
            "field units", "height of a peak above the saddle where it merges "
            "(Edelsbrunner et al. 2002); higra's dynamics", ("height", "dynamics")),
    Measure("size", "size", True, False, "--threshold", "voxels x voxel volume",
            "the region's volume (Carr et al. 2004)"),
    Measure("hypervolume", "hypervolume", True, True, "--threshold",
            "field units x voxel volume", "the region's volume under the field "
            "above its saddle (Carr et al. 2004)"),
    Measure("area", "basin area", True, False, "--threshold", "voxels x voxel volume",
            "watershed hierarchy by area: the smaller region's size at the saddle "
            "(higra's watershed_hierarchy_by_area)", ("basin-area",), watershed=True),
    Measure("volume", "basin volume", True, True, "--threshold",
            "field units x voxel volume", "watershed hierarchy by volume: the smaller "
            "region's volume above the saddle (higra's watershed_hierarchy_by_volume)",
            ("basin-volume",), watershed=True),
])
#: The cut measures' names; ``persistence`` is the height of docs/design.md section 5.
MEASURES = tuple(MEASURE_REGISTRY)
#: The measure that `min_persistence` thresholds, read off the events as they are.
PERSISTENCE = MEASURE_REGISTRY["persistence"]
#: The size measure: what `min_component` weighs a mask's components by.
SIZE = MEASURE_REGISTRY["size"]


def get_measure(measure: str | Measure) -> Measure:
    """The registry entry of a measure name or alias."""
    return MEASURE_REGISTRY[measure]


#: Fixed-point steps of a hypervolume term per range (max - min) of the field:
#: 2^-32 of the range, while a cell of 2^31 voxels still sums within int64.
STEPS = 2.0 ** 32


@dataclass(frozen=True)
class Fixed:
    """A measure of every cell in fixed point: `sums` (M,) int64 steps of `scale`. The
    pruning adds the integers (exact in any order, so a pruning decided in groups
    equals the sequential one, `_prune_groups`); `values` are what it reports."""

    sums: np.ndarray
    scale: float

    @property
    def values(self) -> np.ndarray:
        """(M,) float64: the measure itself."""
        return self.sums.astype(np.float64) * self.scale


def check_measure(measure) -> str:
    """The checked measure's name (one of `MEASURES`)."""
    return get_measure(measure).name


def cell_measures(hierarchy, measure: str):
    """`measure` of each maximum's cell (``size`` or ``hypervolume``): `Fixed` on a grid
    or with a scalar vertex weight, (M,) float64 sums with a mesh's weights; for a
    watershed measure (``area``, ``volume``) its cells' `_basins.Basins`."""
    n_max = len(hierarchy.maxima)
    weight = hierarchy.vertex_weight
    if get_measure(measure).watershed:                  # per (cell, rank): `_basins`
        from ._basins import records

        return records(hierarchy.cells, hierarchy._field, hierarchy.saddle_value, weight,
                       unit_of, scale_of)
    hypervolume = get_measure(measure).by_height
    saddles, unit = np.zeros(0), 1.0          # a size: every term is 1, no saddle read
    if hypervolume:
        low, high = _prune.masked_range(hierarchy.cells.ravel(), hierarchy._field.ravel())
        unit = unit_of(low, high)
        saddles = _cell_saddles(hierarchy, n_max, low)
    if weight is not None and np.ndim(weight) > 0:      # a mesh: in memory, float sums
        cells = hierarchy.cells.ravel()
        inside = cells >= 0
        terms = np.asarray(weight, dtype=np.float64)[inside]
        if hypervolume:
            f = hierarchy._field.ravel()[inside]
            terms = terms * np.maximum(f - saddles[cells[inside]], 0.0)
        return np.bincount(cells[inside], weights=terms, minlength=n_max)
    sums = np.zeros(n_max, dtype=np.int64)
    _prune.cell_sums(hierarchy.cells.ravel(), hierarchy._field.ravel(), saddles, unit,
                     hypervolume, sums)
    return _scaled(sums, weight, unit)


@dataclass(frozen=True)
class _Events(SizedByArrays):
    """The three event arrays `_cell_saddles` reads."""

    source: np.ndarray
    target: np.ndarray
    saddle_value: np.ndarray


def unit_of(low, high) -> float:
    """A hypervolume term's fixed-point step: `STEPS` per range of the field."""
    return (float(high) - float(low)) / STEPS if high > low else 1.0


def scale_of(weight, unit: float) -> float:
    """A fixed-point measure's step: the vertex weight (None: 1) times the term's unit."""
    return (1.0 if weight is None else float(weight)) * unit


def _scaled(sums, weight, unit) -> Fixed:
    return Fixed(sums, scale_of(weight, unit))


def range_of(*parts) -> tuple:
    """(min, max) of the field over the vertices that took part, from the blocks'."""
    return float(min(p[0] for p in parts)), float(max(p[1] for p in parts))


def _cell_saddles(hierarchy, n_max, low) -> np.ndarray:
    """(M,) the highest saddle value among each cell's events (its first merge sweeping
    down); `low` for a cell with none (alone in its component)."""
    return highest_saddles(n_max, [(hierarchy.source, hierarchy.saddle_value),
                                   (hierarchy.target, hierarchy.saddle_value)], low)


def highest_saddles(n: int, pairs, low: float) -> np.ndarray:
    """(n,) the highest of the saddle values given to each of n cells (`pairs` of
    (cells, values)); `low` for a cell given none."""
    out = np.full(n, -np.inf)
    for cells, values in pairs:
        np.maximum.at(out, cells, values)
    out[out == -np.inf] = low
    return out
