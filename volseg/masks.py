"""Foreground masks: which voxels the Morse stage segments (DESIGN.md section 9).

Scientific volumes are mostly empty (94.8 % of fuel's voxels and 53.6 % of neghip's
are exactly 0). On such a plateau the curvature is exactly 0 and the descending
complex is decided by index tie-breaking alone, so it carves the empty space into
arbitrary regions that use up the region budget and are redrawn by any noise. A
mask takes those voxels out of the Morse graph; the curvature is still computed on
the whole volume (a mask never changes the geometry of the graph in R^4).

Rules (`foreground_mask`):

- ``None`` / ``"none"``: no mask, every voxel is segmented;
- ``"auto"``: ``"nonzero"`` when the minimum-value plateau covers more than
  `AUTO_PLATEAU_SHARE` of the volume (fuel 94.8 %, neghip 53.6 %), else no mask
  (silicium 41.6 %, nucleon 18.3 %, tooth 0 %, the demo 49.7 %);
- ``"nonzero"``: value above the volume's minimum;
- ``"value>T"``, ``"value>=T"``, ``"value<T"``, ``"value<=T"``: a threshold;
- ``"otsu"``: value above Otsu's threshold (scikit-image);
- a boolean array of the volume's shape.

A Dask volume (the blockwise path) gets the same mask, lazily (`foreground_mask`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["foreground_mask", "check_rule", "MaskChoice", "AUTO_PLATEAU_SHARE", "MASK_RULES"]

#: ``"auto"`` masks the minimum plateau when it covers more than this share of the voxels.
AUTO_PLATEAU_SHARE = 0.5
MASK_RULES = ("auto", "none", "nonzero", "otsu", "value>T", "value>=T", "value<T", "value<=T")
_THRESHOLD = re.compile(r"^\s*value\s*(>=|<=|>|<)\s*([-+0-9.eE]+|[-+]?inf)\s*$")


@dataclass(frozen=True)
class MaskChoice:
    """A resolved mask: the boolean array (None for no mask) and how it was chosen.

    ``rule`` is what was asked, ``used`` what it became (``"auto"`` -> ``"nonzero"``
    or ``"none"``), ``voxels`` the number of masked voxels (all of them for none).
    """

    mask: NDArray[np.bool_] | None
    rule: str
    used: str
    voxels: int

    def describe(self) -> dict:
        return {"rule": self.rule, "used": self.used, "voxels": self.voxels}

    def phrase(self) -> str:
        """" in a <used> mask of <voxels> voxels", or "" without a mask (for messages)."""
        return "" if self.mask is None else f" in a {self.used} mask of {self.voxels} voxels"


def foreground_mask(volume, rule="auto") -> MaskChoice:
    """Resolve a mask rule (or array) for `volume`; see the module docstring.

    Parameters
    ----------
    volume : (X, Y, Z) array_like or Dask array
        A Dask volume gets a lazy Dask mask of the same chunks, equal to the one of
        the computed volume (one or two passes over the blocks: the minimum for
        ``"auto"``/``"nonzero"``, the histogram for ``"otsu"``, and the count).
    rule : str, bool ndarray (or Dask array) or None

    Returns
    -------
    MaskChoice

    Raises
    ------
    ValueError
        An unknown rule, an array of the wrong shape or type, or a mask that selects
        no voxel.

    Examples
    --------
    >>> import numpy as np
    >>> volume = np.zeros((4, 4, 4)); volume[1:3, 1:3, 1:3] = 5
    >>> foreground_mask(volume, "auto").describe()
    {'rule': 'auto', 'used': 'nonzero', 'voxels': 8}
    """
    from ._validate import is_lazy

    lazy = is_lazy(volume)
    data = volume if lazy else np.asarray(volume)
    if rule is None or (isinstance(rule, str) and rule.strip().lower() == "none"):
        return MaskChoice(None, "none", "none", int(data.size))
    if not isinstance(rule, str):
        mask = rule if is_lazy(rule) else np.asarray(rule)
        if mask.dtype != bool or mask.shape != data.shape:
            raise ValueError(f"`mask` must be a boolean array of the volume's shape {data.shape}, "
                             f"got {mask.dtype} {mask.shape}")
        if lazy:
            mask = _like(mask, data)
        return _checked(MaskChoice(mask, "array", "array", 0))
    name, threshold = check_rule(rule)
    if name in ("auto", "nonzero"):
        # The mask is the complement of the minimum plateau: one pass finds both.
        lowest, at_lowest = _minimum_plateau(data, lazy)
        mask = data > lowest
        voxels = int(data.size - at_lowest) if lowest == lowest else 0    # NaN: none
        if name == "auto" and 1.0 - voxels / data.size <= AUTO_PLATEAU_SHARE:
            return MaskChoice(None, "auto", "none", int(data.size))
        return _checked(MaskChoice(mask, name, "nonzero", voxels))
    if name == "otsu":
        threshold = _otsu(data)
        return _checked(MaskChoice(data > threshold, "otsu", f"value>{threshold:g}", 0))
    op, value = threshold
    compare = {">": np.greater, ">=": np.greater_equal, "<": np.less, "<=": np.less_equal}[op]
    return _checked(MaskChoice(compare(data, value), rule, f"value{op}{value:g}", 0))


def check_rule(rule: str) -> tuple:
    """(name, None) of a named rule or ("value", (op, T)) of a threshold; a ValueError
    naming the rules for anything else. Needs no data: the command line checks its
    --mask before it reads a volume."""
    name = rule.strip().lower()
    if name in ("auto", "none", "nonzero", "otsu"):
        return name, None
    match = _THRESHOLD.match(name)
    if match is None:
        raise ValueError(f"unknown `mask` rule {rule!r}; use one of {', '.join(MASK_RULES)} "
                         "(T a number), or a boolean array")
    return "value", (match[1], float(match[2]))


def _checked(choice: MaskChoice) -> MaskChoice:
    voxels = choice.voxels or _count(choice.mask)
    if voxels == 0:
        raise ValueError(f"the mask {choice.rule!r} ({choice.used}) selects no voxel")
    return MaskChoice(choice.mask, choice.rule, choice.used, voxels)


def _compute(x):
    """A numpy result of `x`, computed if it is lazy (on Dask's current scheduler)."""
    return x.compute() if hasattr(x, "compute") else x


def _minimum_plateau(data, lazy: bool):
    """The volume's minimum and how many voxels hold it; for a Dask volume in one pass
    (each block's minimum and its count there, joined here)."""
    if not lazy:
        lowest = data.min()
        return lowest, int(np.count_nonzero(data == lowest))
    import dask

    one = tuple((1,) * n for n in data.numblocks)
    lows = data.map_blocks(lambda b: np.min(b, keepdims=True), chunks=one, dtype=data.dtype)
    counts = data.map_blocks(lambda b: np.full((1, 1, 1), np.count_nonzero(b == b.min())),
                             chunks=one, dtype=np.int64)
    lows, counts = dask.compute(lows, counts)     # the blocks are read once for both
    lowest = lows.min()
    return lowest, int(counts[lows == lowest].sum())


def _count(mask) -> int:
    return int(_compute(mask.sum()))


def _like(mask, data):
    """A mask array as a Dask array of the volume's chunks."""
    import dask.array as da

    return da.asarray(mask).rechunk(data.chunks)


def _otsu(data) -> float:
    """scikit-image's `threshold_otsu` of the volume, from a histogram summed over the
    blocks for a Dask volume: the same histogram as scikit-image's of the whole array
    (integers: one bin per value from the minimum to the maximum; floats: 256 bins
    over [min, max]), so the same threshold."""
    from skimage.filters import threshold_otsu

    from ._validate import is_lazy

    if not is_lazy(data):
        return float(threshold_otsu(data.ravel()))
    import dask
    import dask.array as da

    lo, hi = (v.item() for v in dask.compute(data.min(), data.max()))
    if lo == hi:
        return float(lo)           # threshold_otsu of a constant image: its value
    if data.dtype.kind in "biu":
        width = int(hi) - int(lo) + 1
        counts = data.map_blocks(
            lambda b: np.bincount((b.astype(np.int64) - int(lo)).ravel(),
                                  minlength=width)[None, None, None], dtype=np.int64,
            chunks=((1,) * data.numblocks[0], (1,) * data.numblocks[1],
                    (1,) * data.numblocks[2], (width,)), new_axis=3)
        counts = _compute(counts.sum(axis=(0, 1, 2)))
        centers = np.arange(int(lo), int(hi) + 1)
    else:
        counts, edges = da.histogram(data, bins=256, range=(lo, hi))
        counts = _compute(counts)
        centers = (edges[:-1] + edges[1:]) / 2
    return float(threshold_otsu(hist=(counts, centers)))
