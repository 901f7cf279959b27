"""A PNG montage that shows at a glance what a segmentation found.

Drawn with numpy and Pillow alone: slices are coloured by lookup tables, scaled by
nearest neighbour, and labelled with Pillow's FreeType default font. Importing and
drawing with matplotlib cost about 0.6 s of the 1.3-1.5 s that `volseg segment
fuel` took end to end; this costs about 0.05 s. (Pillow is already installed with
matplotlib; it is listed as a dependency of its own for this module.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..morse import CurveSample, curve_sample, get_measure

__all__ = ["write_preview", "write_persistence_plot", "persistence_panel", "TAB20", "gray",
           "diverging", "overlay"]

# tab20 (matplotlib's qualitative map), so region colours match the usual tools.
TAB20 = np.array([
    (31, 119, 180), (174, 199, 232), (255, 127, 14), (255, 187, 120), (44, 160, 44),
    (152, 223, 138), (214, 39, 40), (255, 152, 150), (148, 103, 189), (197, 176, 213),
    (140, 86, 75), (196, 156, 148), (227, 119, 194), (247, 182, 210), (127, 127, 127),
    (199, 199, 199), (188, 189, 34), (219, 219, 141), (23, 190, 207), (158, 218, 229),
], dtype=np.float64)

# ColorBrewer RdBu, reversed: blue for valleys (negative curvature), red for peaks.
_RDBU_R = np.array([
    (5, 48, 97), (33, 102, 172), (67, 147, 195), (146, 197, 222), (209, 229, 240),
    (247, 247, 247), (253, 219, 199), (244, 165, 130), (214, 96, 77), (178, 24, 43),
    (103, 0, 31),
], dtype=np.float64)

_OVERLAY_ALPHA = 0.55
_BOX = 250  # panel size in pixels
_GAP = 46
_LEFT = 34
_TOP = 58
_BACKGROUND = (255, 255, 255)
_INK = (20, 20, 20)


def gray(values, lo, hi):
    """(..., 3) uint8 gray levels of `values` scaled from [lo, hi]."""
    scaled = np.clip((np.asarray(values, float) - lo) / ((hi - lo) or 1.0), 0.0, 1.0)
    return np.repeat(np.round(255 * scaled)[..., None], 3, axis=-1).astype(np.uint8)


def diverging(values, limit):
    """(..., 3) uint8 RdBu_r colours of `values` in [-limit, limit]."""
    t = np.clip((np.asarray(values, float) / (limit or 1.0) + 1) / 2, 0.0, 1.0)
    position = t * (len(_RDBU_R) - 1)
    low = np.minimum(position.astype(int), len(_RDBU_R) - 2)
    frac = (position - low)[..., None]
    return np.round((1 - frac) * _RDBU_R[low] + frac * _RDBU_R[low + 1]).astype(np.uint8)


def overlay(values, labels, lo, hi):
    """Region colours (label i gets tab20 colour i - 1) blended over the gray volume;
    label 0 (outside the mask) is left gray."""
    labels = np.asarray(labels)
    base = gray(values, lo, hi).astype(np.float64)
    colours = TAB20[(labels - 1) % len(TAB20)]
    blended = (1 - _OVERLAY_ALPHA) * base + _OVERLAY_ALPHA * colours
    return np.round(np.where((labels > 0)[..., None], blended, base)).astype(np.uint8)


#: Events per block of the persistence curve's corners (`persistence_panel`).
_CURVE_BLOCK = 1 << 20


def _log_ticks(lo, hi):
    return [10.0**e for e in range(int(np.floor(np.log10(lo))), int(np.ceil(np.log10(hi))) + 1)]


def persistence_panel(persistence, n_components, threshold, n_regions, *, width=_BOX * 3 + 2 * _GAP,
                      height=190, measure="persistence"):
    """An RGB image of the persistence curve (or the curve of another `measure`):
    regions of the cut against the threshold (log x, log y), the chosen cut marked.
    Read it to choose `--min-persistence` (`--threshold`): a long flat step is a
    threshold range over which the segmentation is stable.

    Parameters
    ----------
    persistence : (E,) array of float, or CurveSample
        The extinction of every merge event in `measure`
        (`MorseHierarchy.extinction`; the persistence by default), or the curve
        thinned for drawing (`volseg.morse.curve_sample`: what a blockwise cut
        sends).
    n_components : int
        Regions that never merge (one per connected component of the graph).
    threshold : float
        The chosen threshold; `n_regions` its region count.
    """
    from PIL import Image, ImageDraw

    if not isinstance(persistence, CurveSample):
        persistence = curve_sample(persistence, n_components, thin=False)
    p, ranks = persistence.values, persistence.ranks
    canvas = Image.new("RGB", (width, height), _BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    small, medium = _font(11), _font(13)
    left, right, top, bottom = 62, 18, 24, 40
    option = get_measure(measure).option
    draw.text((width // 2, 4), f"{measure} curve: regions of the cut at each threshold "
              f"(choose {option} in a long flat step)", fill=_INK, font=medium, anchor="ma")
    if len(p) == 0:
        draw.text((width // 2, height // 2), "no merge events: a single maximum per component",
                  fill=_INK, font=small, anchor="mm")
        return np.asarray(canvas)
    # Four decades below the largest persistence: smaller events (near-ties) all sit
    # at the left edge, where the curve starts at the count of every maximum.
    x_lo, x_hi = max(p[-1], p[0] * 1e-4) / 1.5, p[0] * 1.5
    y_hi = n_components + persistence.n_positive

    def x_of(t):
        return left + (np.log10(t) - np.log10(x_lo)) / (np.log10(x_hi) - np.log10(x_lo)) * (
            width - left - right)

    def y_of(r):
        return height - bottom - np.log10(r) / max(np.log10(y_hi), 1e-9) * (height - top - bottom)

    box = (left, top, width - right, height - bottom)
    _curve_axes(draw, box, (x_lo, x_hi, y_hi), x_of, y_of, small, width, measure)
    xs, ys = _curve_corners(p[::-1], n_components + 1 + ranks[::-1], x_of, y_of,
                            (x_lo, x_hi, y_hi), n_components)
    draw.line(list(zip(xs.tolist(), ys.tolist(), strict=True)), fill=(31, 119, 180), width=2)
    if threshold > 0 and x_lo < threshold < x_hi:
        x = x_of(threshold)
        draw.line([x, top, x, height - bottom], fill=(214, 39, 40), width=1)
        right_side = x < width * 0.7
        draw.text((x + 4 if right_side else x - 4, top + 2),
                  f"cut: {n_regions} regions at {threshold:.3g}", fill=(214, 39, 40), font=small,
                  anchor="la" if right_side else "ra")
    return np.asarray(canvas)


def _curve_axes(draw, box, limits, x_of, y_of, font, width, measure="persistence"):
    """The frame, the log ticks and the axis names of the persistence curve."""
    left, top, right, bottom = box
    x_lo, x_hi, y_hi = limits
    draw.rectangle(list(box), outline=_INK)
    for t in _log_ticks(x_lo, x_hi):
        if x_lo <= t <= x_hi:
            x = x_of(t)
            draw.line([x, bottom, x, bottom + 4], fill=_INK)
            draw.text((x, bottom + 6), f"{t:g}", fill=_INK, font=font, anchor="ma")
    for r in [1, 10, 100, 1000, 10000, 100000, 1000000]:
        if r <= y_hi:
            y = y_of(r)
            draw.line([left - 4, y, left, y], fill=_INK)
            draw.text((left - 6, y), str(r), fill=_INK, font=font, anchor="rm")
    draw.text((width // 2, bottom + 26), f"{measure} threshold (log)", fill=_INK, font=font,
              anchor="ma")
    draw.text((6, top - 12), "regions (log)", fill=_INK, font=font)


def _curve_corners(ascending, above, x_of, y_of, limits, n_components) -> tuple:
    """(xs, ys) pixel corners of the persistence staircase.

    Regions at threshold t: n_components + #{p >= t}, a staircase falling at each p
    from `above` (the count just below it) by one, drawn through its corners (of the
    sampled events only, for a `CurveSample`); a corner in the same tenth of a pixel as the one
    before it is dropped: millions of events (8 M maxima at 512^3) draw the same few
    thousand pixels. A block of events at a time, so that the corners of all the
    events are never in memory at once (they were the preview's peak at 512^3).
    """
    x_lo, x_hi, y_hi = limits
    start = (x_of(x_lo), y_of(y_hi))
    xs, ys = [np.array([start[0]])], [np.array([start[1]])]
    previous = np.round(np.array(start) * 10)
    for first in range(0, len(ascending), _CURVE_BLOCK):
        block = ascending[first:first + _CURVE_BLOCK]
        counts = above[first:first + _CURVE_BLOCK]
        bx = np.repeat(x_of(np.maximum(block, x_lo)), 2)
        by = y_of(np.stack([counts, counts - 1], axis=1).ravel())
        step = np.round(np.stack([bx, by], axis=1) * 10)
        keep = np.empty(len(step), dtype=bool)
        keep[0] = (step[0] != previous).any()
        keep[1:] = (step[1:] != step[:-1]).any(axis=1)
        previous = step[-1]
        xs.append(bx[keep])
        ys.append(by[keep])
    xs.append(np.array([x_of(x_hi)]))            # the last corner is always drawn
    ys.append(np.array([y_of(max(n_components, 1))]))
    return np.concatenate(xs), np.concatenate(ys)


def write_persistence_plot(path, persistence, n_components, threshold, n_regions, *,
                           measure="persistence") -> Path:
    """The persistence curve alone, as PNG (see `persistence_panel`)."""
    from PIL import Image

    Image.fromarray(persistence_panel(persistence, n_components, threshold, n_regions,
                                      measure=measure)).save(path, format="PNG")
    return Path(path)


def _fit(rgb):
    """A slice (rows = second axis upward, columns = first axis) scaled by nearest
    neighbour to fit a _BOX square, keeping its aspect ratio."""
    image = rgb[::-1]  # origin at the bottom left
    rows, cols = image.shape[:2]
    factor = _BOX / max(rows, cols)
    r = np.minimum((np.arange(max(1, round(rows * factor))) / factor).astype(int), rows - 1)
    c = np.minimum((np.arange(max(1, round(cols * factor))) / factor).astype(int), cols - 1)
    return image[r][:, c]


def _font(size):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: fixed bitmap font
        return ImageFont.load_default()


def _colour_bar(canvas, draw, x, y, width, colours, ticks, label, font):
    strip = np.repeat(colours[None], 12, axis=0)
    from PIL import Image

    canvas.paste(Image.fromarray(strip), (x, y))
    draw.rectangle([x - 1, y - 1, x + width, y + 12], outline=_INK)
    for fraction, text in ticks:
        tx = x + int(round(fraction * (width - 1)))
        draw.line([tx, y + 12, tx, y + 16], fill=_INK)
        draw.text((tx, y + 17), text, fill=_INK, font=font, anchor="ma")
    draw.text((x + width // 2, y + 34), label, fill=_INK, font=font, anchor="ma")


def write_preview(path, volume, curvature, labels, *, title="", persistence=None,
                  value_range=None, n_labels=None, measure="persistence",
                  field="curvature") -> Path:
    """Mid slices along x, y, z: the volume, its curvature, the labels over the volume,
    and (given ``persistence=(extinction, n_components, threshold)``) the curve of
    the cut's `measure` below them.

    Written to `path` as PNG (the caller handles atomic renaming). Labels are 1..k
    (0, outside a mask, is left uncoloured); region colours cycle through the 20
    tab20 colours; the legend names the first ten. The curvature colour scale is
    +-(99th percentile of ``|H|`` over the slices shown).
    `value_range` (the volume's min and max) and `n_labels` (the largest label), when
    the caller knows them, spare a lazy volume's passes over the volume and the labels.
    `field`: the field `curvature` holds (`volseg.fields`), named in the middle panels
    and their colour bar.
    """
    from PIL import Image, ImageDraw

    indices, sliced = _mid_slices(volume, curvature, labels)
    lo, hi, k = _range_and_count(volume, labels, value_range, n_labels)
    mids = sliced[1]
    shown = np.concatenate([m.ravel() for m in mids])
    limit = float(np.percentile(np.abs(shown), 99)) or 1.0
    signed = bool(shown.size and shown.min() < 0)      # else (gradient) 0 .. limit only
    rows = []
    for row, axis in enumerate("xyz"):
        vol, cur, lab = sliced[0][row].T, sliced[1][row].T, sliced[2][row].T
        panels = [("volume", gray(vol, lo, hi)), (field, diverging(cur, limit)),
                  ("regions", overlay(vol, lab, lo, hi))]
        rows.append((axis, indices[row][row], [(name, _fit(rgb)) for name, rgb in panels]))
    heights = [max(image.shape[0] for _, image in panels) for _, _, panels in rows]
    width = _LEFT + 3 * _BOX + 2 * _GAP + 30
    height = _TOP + sum(heights) + 3 * _GAP + 62
    curve = None
    if persistence is not None:
        curve = persistence_panel(*persistence, k, measure=measure)
        height += curve.shape[0] + 12
    canvas = Image.new("RGB", (width, height), _BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    small, large = _font(11), _font(17)
    for size in (17, 15, 13, 11):          # a long title (a degenerate cut's) still fits
        large = _font(size)
        if draw.textlength(title, font=large) <= width - 16:
            break
    draw.text((width // 2, 14), title, fill=_INK, font=large, anchor="ma")
    bar_y = _draw_rows(canvas, draw, rows, heights, k) - 8
    ramp = np.linspace(0, 1, _BOX)
    _colour_bar(canvas, draw, _LEFT, bar_y, _BOX, gray(ramp, 0, 1),
                [(0, f"{lo:.4g}"), (1, f"{hi:.4g}")], "value", small)
    _colour_bar(canvas, draw, _LEFT + _BOX + _GAP, bar_y, _BOX,
                diverging(np.linspace(-limit if signed else 0.0, limit, _BOX), limit),
                [(0, f"{-limit:.3g}"), (0.5, "0"), (1, f"{limit:.3g}")] if signed
                else [(0, "0"), (1, f"{limit:.3g}")],
                "mean curvature (+ peak, - valley)" if field == "curvature" else field, small)
    if curve is not None:
        canvas.paste(Image.fromarray(curve), (_LEFT, bar_y + 62))
    canvas.save(path, format="PNG")
    return Path(path)


def _mid_slices(volume, curvature, labels) -> tuple:
    """The three mid-slice indices and, for each of volume, curvature and labels, its
    three mid slices: only they are read (a lazy volume is never loaded whole)."""
    shape = tuple(volume.shape)
    indices = []
    for row in range(3):
        index = [slice(None)] * 3
        index[row] = shape[row] // 2
        indices.append(tuple(index))
    return indices, [[np.asarray(a[index]) for index in indices]
                     for a in (volume, curvature, labels)]


def _range_and_count(volume, labels, value_range, n_labels) -> tuple:
    """(lo, hi, k): the volume's range and the largest label, as given, else computed
    (in one pass over a lazy volume and labels)."""
    from .._validate import is_lazy

    lazy = is_lazy(volume)
    if not lazy:
        volume, labels = np.asarray(volume), np.asarray(labels)
    wanted = ([] if value_range is not None else [volume.min(), volume.max()]) + (
        [] if n_labels is not None else [labels.max() if labels.size else 0])
    if lazy:
        import dask

        wanted = dask.compute(*wanted)
    found = [float(v) for v in wanted]
    lo, hi = (float(v) for v in (value_range if value_range is not None else found[:2]))
    return lo, hi, int(n_labels if n_labels is not None else found[-1])


def _draw_rows(canvas, draw, rows, heights, k) -> int:
    """Paste the panels row by row, with their names, axes and the legend; returns the
    y below the last row."""
    from PIL import Image

    small, medium = _font(11), _font(13)
    y0 = _TOP
    for row, (axis, position, panels) in enumerate(rows):
        other = [c for c in "xyz" if c != axis]
        for col, (name, image) in enumerate(panels):
            x0 = _LEFT + col * (_BOX + _GAP)
            canvas.paste(Image.fromarray(np.ascontiguousarray(image)), (x0, y0))
            h, w = image.shape[:2]
            draw.rectangle([x0 - 1, y0 - 1, x0 + w, y0 + h], outline=_INK)
            draw.text((x0 + w // 2, y0 - 4), f"{name}, {axis} = {position}", fill=_INK,
                      font=medium, anchor="md")
            draw.text((x0 + w // 2, y0 + h + 3), other[0], fill=_INK, font=small, anchor="ma")
            draw.text((x0 - 4, y0 + h // 2), other[1], fill=_INK, font=small, anchor="rm")
        if row == 0 and k:
            _legend(draw, y0, k, small)
        y0 += heights[row] + _GAP
    return y0


def _legend(draw, y0, k, font):
    """The first ten regions' colours, top right of the first row."""
    shown = min(k, 10)
    x0 = _LEFT + 2 * (_BOX + _GAP) + _BOX - 112
    draw.rectangle([x0 - 6, y0 + 4, x0 + 108, y0 + 28 + 14 * shown],
                   fill=(255, 255, 255), outline=_INK)
    draw.text((x0, y0 + 8), f"{k} regions" + (" (first 10)" if k > 10 else ""),
              fill=_INK, font=font)
    for i in range(shown):
        yy = y0 + 24 + 14 * i
        draw.rectangle([x0, yy, x0 + 12, yy + 10], fill=tuple(int(c) for c in TAB20[i]))
        draw.text((x0 + 18, yy - 1), f"region {i + 1}", fill=_INK, font=font)
