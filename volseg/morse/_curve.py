"""`CurveSample`: the cuts' curve (regions against the threshold) thinned for drawing, so
that a cut computed where the hierarchy is sends a few thousand numbers, not one per
event (issue 30)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CurveSample", "curve_sample"]

#: Ranks drawn one by one from the largest extinction; past them, ranks `STEP` apart.
EXACT = 4096
#: A staircase on a log count axis moves by log10(STEP) = 0.0004 decades between
#: samples: far under a pixel of any plot.
STEP = 1.001


@dataclass(frozen=True)
class CurveSample:
    """The positive extinctions by decreasing value, at `ranks` (0: the largest, of
    `n_positive`): every rank below `EXACT`, then ranks a factor `STEP` apart, and the
    last; `n_components`: the regions that never merge."""

    values: np.ndarray
    ranks: np.ndarray
    n_positive: int
    n_components: int

    def __len__(self):
        return len(self.values)


def curve_sample(extinction, n_components: int, thin: bool = True) -> CurveSample:
    """The `CurveSample` of the events' `extinction`; `thin` False keeps every rank."""
    p = np.sort(np.asarray(extinction, dtype=np.float64))[::-1]
    p = p[p > 0]
    ranks = sample_ranks(len(p), thin)
    return CurveSample(p[ranks], ranks, len(p), int(n_components))


def sample_ranks(n_positive: int, thin: bool = True) -> np.ndarray:
    """The ranks a `CurveSample` of `n_positive` positive extinctions keeps."""
    n = n_positive
    if not thin or n <= EXACT:
        return np.arange(n)
    steps = int(np.ceil(np.log(n / EXACT) / np.log(STEP))) + 1
    far = np.geomspace(EXACT, n - 1, steps).astype(np.int64)
    return np.unique(np.concatenate([np.arange(EXACT), far, [n - 1]]))
