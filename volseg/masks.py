"""Foreground masks: which voxels the Morse stage segments (docs/design.md section 9).

Scientific volumes are mostly empty (94.8 % of fuel's voxels and 53.6 % of neghip's
are exactly 0). On such a plateau the curvature is exactly 0 and the descending
complex is decided by index tie-breaking alone, so it carves the empty space into
arbitrary regions that use up the region budget and are redrawn by any noise. A
mask takes those voxels out of the Morse graph; the curvature is still computed on
the whole volume (a mask never changes the geometry of the graph in R^4).

Rules (`foreground_mask`):

- ``None`` / ``"none"``: no mask, every voxel is segmented;
- ``"auto"``, the first of these that applies:

  1. a *plateau*: when the voxels at the volume's minimum cover more than
     `AUTO_PLATEAU_SHARE` of it (fuel 94.8 %, neghip 53.6 %, a skull-stripped MRI's
     exact zeros), they are masked out (``"nonzero"``); a signed volume (minimum
     below 0, maximum above) whose voxels at exactly 0 cover more than that share
     (a statistical map's background) has them masked out (``"value!=0"``);
  2. a *low mode*: the background is noise about a low value (air in CT and MRI,
     Rician noise), masked out as ``"value>T"`` when all of these hold: the
     histogram (256 bins, one per value for integers, as scikit-image's; smoothed to
     find its modes) peaks in the lowest `AUTO_LOW_MODE_RANGE` of the value range;
     no other mode below that peak holds `AUTO_OTHER_MODE_SHARE` of the voxels; the
     triangle threshold T of the histogram (Zack et al. 1977, as scikit-image's
     `threshold_triangle`; without a saturated top bin) lies above the peak and leaves at least
     `AUTO_BACKGROUND_SHARE` of the voxels at or below it; and the voxels above T
     reach the border less than `AUTO_BORDER_RATIO` times as often as they fill the
     volume (an object inside its background, not a field whose bright values are
     everywhere), on the faces of two of the three axes: an axial CT slab's end
     slices are cross-sections of the body;
  3. else no mask (a simulation without background, a random field);
- ``"nonzero"``: value above the volume's minimum;
- ``"value>T"``, ``"value>=T"``, ``"value<T"``, ``"value<=T"``: a threshold;
- ``"otsu"``: value above Otsu's threshold (scikit-image);
- a boolean array of the volume's shape.

A Dask volume (the blockwise path) gets the same mask, lazily (`foreground_mask`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._census import MAX_INTEGER_BINS, Census, value_counts, widened

__all__ = ["foreground_mask", "check_rule", "MaskChoice", "AUTO_PLATEAU_SHARE",
           "AUTO_LOW_MODE_RANGE", "AUTO_OTHER_MODE_SHARE", "AUTO_BACKGROUND_SHARE",
           "AUTO_BORDER_RATIO", "MASK_RULES"]

#: ``"auto"`` masks the minimum plateau when it covers more than this share of the voxels.
AUTO_PLATEAU_SHARE = 0.5
#: ``"auto"``'s low mode: the histogram's peak lies in this lowest share of the range,
AUTO_LOW_MODE_RANGE = 1 / 3
#: with no other mode below it holding this share of the voxels (a CT's air below
#: its soft-tissue peak),
AUTO_OTHER_MODE_SHARE = 0.02
#: at least this share of the voxels at or below its triangle threshold,
AUTO_BACKGROUND_SHARE = 0.25
#: and the voxels above it reach the volume's border less than this fraction as
#: often as they fill the volume (an object surrounded by its background).
AUTO_BORDER_RATIO = 0.2
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
        """The choice as the summary records it."""
        return {"rule": self.rule, "used": self.used, "voxels": self.voxels}

    def left_out(self, data) -> tuple[int, int]:
        """(non-zero voxels of `data` outside the mask, non-zero voxels of `data`): what
        a mask takes from the segmentation beyond an empty background (one pass)."""
        if self.mask is None:
            return 0, 0
        nonzero = data != 0
        counts = ((nonzero & ~self.mask).sum(), nonzero.sum())
        if hasattr(counts[0], "dask"):
            import dask

            counts = dask.compute(*counts)
        return int(counts[0]), int(counts[1])

    def phrase(self) -> str:
        """" in a <used> mask of <voxels> voxels", or "" without a mask (for messages)."""
        return "" if self.mask is None else f" in a {self.used} mask of {self.voxels} voxels"


def foreground_mask(volume, rule="auto", *, value_range=None, lattice=None,
                    census: Census | None = None) -> MaskChoice:
    """Resolve a mask rule (or array) for `volume`; see the module docstring.

    Parameters
    ----------
    volume : (X, Y, Z) array_like or Dask array
        A Dask volume gets a lazy Dask mask of the same chunks, equal to the one of
        the computed volume (one or two passes over the blocks: the minimum for
        ``"auto"``/``"nonzero"``, the histogram for ``"otsu"``, and the count).
    rule : str, bool ndarray (or Dask array) or None
    value_range : (min, max), optional
        Of `volume`, when the caller has it (`run_stages` does): spares a lazy
        volume's rules another pass for it.
    lattice : volseg._lattice.Lattice, optional
        The levels a quantised `volume` lies on: ``"auto"`` and ``"otsu"`` then read
        its histogram of levels, so that every exactly scaled or offset copy of a
        volume gets the same mask (the threshold is still said in its values).
    census : volseg._census.Census, optional
        Of `volume`, when the caller read it (`run_stages` does): its range, plateaus
        and (integers) histogram are taken from it, not read again. Not used with
        `lattice`, whose rules read the lattice's integers.

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
    if lattice is not None and name in ("auto", "otsu"):
        return _on_levels(data, rule, lattice)
    if census is not None:
        value_range = census.value_range
    if name == "auto":
        return _auto(data, lazy, value_range, census)
    if name == "nonzero":
        lowest, at_lowest = _plateau(data, lazy, census=census)
        voxels = int(data.size - at_lowest) if lowest == lowest else 0    # NaN: none
        return _checked(MaskChoice(data > lowest, name, "nonzero", voxels))
    if name == "otsu":
        from skimage.filters import threshold_otsu

        counts, centers = _histogram(data, lazy, value_range, census)
        if centers.dtype.kind in "iu":      # Otsu's class means in float64 on the offsets
            base = centers[0].item()        # from the minimum (exact: centers near 2^63
            offsets = np.arange(len(centers), dtype=np.int64)        # are 2048 apart)
            threshold = base + threshold_otsu(hist=(counts, offsets)).item()
        else:
            threshold = threshold_otsu(hist=(counts, centers))
        threshold = _level(threshold, data.dtype)
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


def _on_levels(data, rule, lattice) -> MaskChoice:
    """`foreground_mask` of the lattice integers of `data`, its threshold said in the
    values of `data`."""
    import re

    from ._lattice import on_lattice

    choice = foreground_mask(on_lattice(data, lattice), rule,
                             value_range=(0.0, float(lattice.levels - 1)))

    def in_values(match):
        return f"{match[1]}{lattice.low + lattice.step * float(match[2]):g}"

    used = re.sub(r"(value[<>]=?)([-+0-9.e]+)", in_values, choice.used)
    return MaskChoice(choice.mask, choice.rule, used, choice.voxels)


def _auto(data, lazy: bool, value_range=None, census=None) -> MaskChoice:
    """The ``"auto"`` rule of the module docstring: a plateau, a low mode, or none."""
    lowest, highest = value_range if value_range is not None else _range(data, lazy)
    level, at_level = _plateau(data, lazy, census=census)
    if at_level > AUTO_PLATEAU_SHARE * data.size:
        return _checked(MaskChoice(data > level, "auto", "nonzero", int(data.size - at_level)))
    if lowest < 0 < highest:
        _, at_zero = _plateau(data, lazy, 0, census=census)
        if at_zero > AUTO_PLATEAU_SHARE * data.size:
            return _checked(MaskChoice(data != 0, "auto", "value!=0", int(data.size - at_zero)))
    threshold = _low_mode(data, lazy, lowest, highest, census)
    if threshold is not None:
        return _checked(MaskChoice(data > threshold, "auto", f"low mode: value>{threshold:g}", 0))
    return MaskChoice(None, "auto", "none", int(data.size))


def _low_mode(data, lazy: bool, lowest: float, highest: float, census=None):
    """The triangle threshold of a background that is a low mode of the histogram (the
    module docstring's rule 2), or None."""
    from scipy.ndimage import gaussian_filter1d

    counts, centers = _histogram(data, lazy, (lowest, highest), census)
    smooth = gaussian_filter1d(counts.astype(np.float64), max(1.0, len(counts) / 128))
    peak = int(np.argmax(smooth))
    if centers[peak] - lowest > AUTO_LOW_MODE_RANGE * (highest - lowest):
        return None
    valley = int(np.argmin(smooth[:peak + 1]))         # below the peak: another mode?
    if (counts[:valley].sum() >= AUTO_OTHER_MODE_SHARE * data.size
            and smooth[:valley].max(initial=0) > 1.5 * smooth[valley]):
        return None
    top = len(counts)
    if top > 2 and counts[-1] > 3 * counts[-2]:
        top -= 1            # a saturated top bin (values clipped at the type's maximum)
    threshold = _level(_triangle(counts[:top], centers[:top]), data.dtype)
    above = counts[centers > threshold].sum() / data.size
    if threshold <= centers[peak] or 1 - above < AUTO_BACKGROUND_SHARE:
        return None
    if _border_share_above(data, threshold, lazy) >= AUTO_BORDER_RATIO * above:
        return None               # the bright voxels reach the border as often: no object
    return threshold


def _border_share_above(data, threshold, lazy: bool) -> float:
    """The share of the volume's border voxels above `threshold`, on the faces of the
    middle one of the three axes (each axis's two faces taken together): an object
    needs background on the faces of two axes, not three, so that an axial CT slab,
    whose first and last slices cut through the body, still has its air found."""
    faces = [data[index] for axis in range(3) for index in
             ((slice(None),) * axis + (0,), (slice(None),) * axis + (-1,))]
    counts = [(face > threshold).sum() for face in faces]
    if lazy:
        import dask

        counts = dask.compute(*counts)
    shares = [(int(counts[2 * a]) + int(counts[2 * a + 1]))
              / (faces[2 * a].size + faces[2 * a + 1].size) for a in range(3)]
    return float(np.median(shares))


def _range(data, lazy: bool) -> tuple:
    """(min, max) as Python numbers (exact, integers stay integers)."""
    if lazy:
        import dask

        return tuple(v.item() for v in dask.compute(data.min(), data.max()))
    return data.min().item(), data.max().item()


def _plateau(data, lazy: bool, level=None, *, census=None):
    """The plateau's value (default the minimum) and how many voxels hold it; for a
    Dask volume in one pass (each block's minimum and its count there, joined here);
    none with a `census` that counted them (the minimum's, and 0's)."""
    if census is not None and level is None:
        return census.low, census.at_low
    if census is not None and level == 0 and census.at_zero is not None:
        return level, census.at_zero
    if not lazy:
        level = data.min() if level is None else level
        return level, int(np.count_nonzero(data == level))
    import dask

    one = tuple((1,) * n for n in data.numblocks)
    if level is not None:
        counts = data.map_blocks(lambda b: np.full((1, 1, 1), np.count_nonzero(b == level)),
                                 chunks=one, dtype=np.int64)
        return level, int(_compute(counts.sum()))
    lows = data.map_blocks(lambda b: np.min(b, keepdims=True), chunks=one, dtype=data.dtype)
    counts = data.map_blocks(lambda b: np.full((1, 1, 1), np.count_nonzero(b == b.min())),
                             chunks=one, dtype=np.int64)
    lows, counts = dask.compute(lows, counts)     # the blocks are read once for both
    lowest = lows.min()
    return lowest, int(counts[lows == lowest].sum())


def _histogram(data, lazy: bool, value_range=None, census=None) -> tuple:
    """(counts, bin centres) of the volume as scikit-image's `exposure.histogram`
    makes it (integers: one bin per value from the minimum to the maximum; floats:
    256 bins over [min, max]), summed over the blocks for a Dask volume (its
    `value_range` read first unless given). Integers spanning more than
    `MAX_INTEGER_BINS` values get the 256 bins too (scikit-image asks for one bin
    per value up to the maximum: 2^62 of them for an int64 near 2^62). A `census`
    with value counts gives them (the same counts, no pass)."""
    lo, hi = value_range if value_range is not None else _range(data, lazy)
    if data.dtype.kind in "biu" and int(hi) - int(lo) < MAX_INTEGER_BINS:
        width = int(hi) - int(lo) + 1
        if census is not None and census.counts is not None and census.low == lo:
            return census.counts, _value_centers(data.dtype, lo, width)
        if not lazy:
            return value_counts(data, lo, width), _value_centers(data.dtype, lo, width)
        counts = data.map_blocks(
            lambda b: value_counts(b, lo, width)[None, None, None], dtype=np.int64,
            chunks=((1,) * data.numblocks[0], (1,) * data.numblocks[1],
                    (1,) * data.numblocks[2], (width,)), new_axis=3)
        return _compute(counts.sum(axis=(0, 1, 2))), _value_centers(data.dtype, lo, width)
    lo, hi = float(lo), float(hi)
    if lo == hi:
        return np.array([data.size]), np.array([lo])
    if lazy:
        import dask.array as da

        counts, edges = da.histogram(data, bins=256, range=(lo, hi))
        counts = _compute(counts)
    else:
        counts, edges = np.histogram(data.ravel(), bins=256, range=(lo, hi))
    return counts, (edges[:-1] + edges[1:]) / 2


def _value_centers(dtype, lo, width):
    kind = widened(np.zeros(0, dtype)).dtype
    return np.arange(width, dtype=kind) + kind.type(lo)


def _level(threshold, dtype):
    """A threshold as a level of the volume's type: an integer volume's exact (a
    float near 2^62 compares equal to its neighbours), the floor of a float threshold
    (``value > floor(t)`` is ``value > t`` for integers), clipped to the type."""
    if np.dtype(dtype).kind not in "biu":
        return float(threshold)
    info = np.iinfo(np.dtype(dtype)) if np.dtype(dtype).kind != "b" else np.iinfo(np.uint8)
    value = threshold.item() if isinstance(threshold, np.generic) else threshold
    return int(min(max(math.floor(value), info.min), info.max))


def _triangle(counts, centers):
    """The triangle threshold of a histogram (Zack, Rogers, Latt 1977), the algorithm
    of scikit-image's `threshold_triangle` (which takes no histogram): the level
    farthest below the line from the peak to the end of the longer tail."""
    counts = np.asarray(counts, dtype=np.float64)
    n = len(counts)
    peak = int(np.argmax(counts))
    low, high = np.flatnonzero(counts)[[0, -1]]
    if low == high:
        return centers[low]
    flip = peak - low < high - peak
    if flip:
        counts, low, peak = counts[::-1], n - high - 1, n - peak - 1
    width = peak - low
    x = np.arange(width)
    norm = np.hypot(counts[peak], width)
    level = int(np.argmax(counts[peak] / norm * x - width / norm * counts[x + low])) + low
    return centers[n - level - 1] if flip else centers[level]


def _count(mask) -> int:
    return int(_compute(mask.sum()))


def _like(mask, data):
    """A mask array as a Dask array of the volume's chunks."""
    import dask.array as da

    return da.asarray(mask).rechunk(data.chunks)
