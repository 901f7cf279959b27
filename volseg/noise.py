"""Seeded noise models of the paper's experiments."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["add_value_noise"]


def add_value_noise(volume: ArrayLike, percent: float, *, seed=None, reference_range=None) -> NDArray[np.float64]:
    """The volume plus Gaussian noise of sigma = `percent` % of its value range.

    Parameters
    ----------
    volume : ndarray
    percent : float
        Standard deviation as a percentage of ``reference_range`` (default the
        volume's own max - min).
    seed : int or numpy Generator, optional
        The same seed gives the same noise on any machine.

    Returns
    -------
    ndarray of float64
        A new array; the input is not modified.
    """
    data = np.asarray(volume, dtype=np.float64)
    if not np.isfinite(percent) or percent < 0:
        raise ValueError(f"noise `percent` must be a non-negative number, got {percent}")
    if reference_range is None:
        reference_range = float(data.max() - data.min())
    rng = np.random.default_rng(seed)
    return data + rng.standard_normal(data.shape) * (percent / 100.0 * reference_range)
