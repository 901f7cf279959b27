"""Segmentation quality against ground truth, side by side in one run (issue 26).

Phantoms with known parts: smooth bumps of different sizes and heights, some
touching, on a zero background, 8-bit quantized, clean, with Gaussian noise and with
Rician noise over everything. Every method is asked for as many regions as there are
parts and scored over the true parts' voxels (the background is not a part):
adjusted Rand index (1 = the truth), variation of information (0 = the truth), the
effective number of regions (1 / sum of squared shares), and the Huang-Dom
similarity of the noisy segmentation to the clean one (docs/design.md section 6; 1 for
one giant region, so read it beside the others).

Methods, on the same field:
- volseg's cut by hypervolume (the default), by size, and by persistence, each
  with volseg's defaults otherwise (auto mask, noise-aware sigma for 8-bit);
- volseg by persistence without smoothing or mask (the defaults before issue 26);
- scikit-image `h_maxima` markers + `watershed` of the curvature (and of the
  value), h chosen by bisection for the part count, in volseg's mask;
- higra's watershed hierarchies by area and by dynamics of the curvature (and of
  the value) on the 6-adjacency grid, cut into the part count plus one (the
  outside of volseg's mask is one region of its own).

    python benchmarks/bench_quality.py [--size 64] [--seed 0]

Needs the ``bench`` extra (higra). Prints a Markdown table.
"""

import argparse
import time

import numpy as np

import volseg
from volseg.curvature import default_value_scale, grid_curvature
from volseg.masks import foreground_mask
from volseg.segment import auto_smoothing

PARTS = [  # centre (in [-1, 1]^3), width, height: touching pairs and loners
    ((-0.45, -0.4, 0.0), 0.16, 1.0), ((-0.1, -0.4, 0.05), 0.12, 0.8),
    ((0.45, 0.35, -0.2), 0.2, 0.9), ((0.45, -0.3, 0.35), 0.1, 0.7),
    ((-0.4, 0.45, 0.3), 0.14, 0.6), ((0.05, 0.3, -0.45), 0.09, 0.75),
]


def phantom(n):
    """(clean 8-bit volume, truth labels 1..P with 0 for the background)."""
    axis = np.linspace(-1, 1, n)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)
    bumps = np.stack([h * np.exp(-((grid - c) ** 2).sum(-1) / (2 * w**2)) for c, w, h in PARTS])
    total = bumps.sum(0)
    truth = np.where(total > 0.08, bumps.argmax(0) + 1, 0)
    return np.where(truth > 0, np.round(220 * total), 0).astype(np.uint8), truth


def noisy(clean, kind, seed):
    rng = np.random.default_rng(seed)
    x = clean.astype(float)
    if kind == "gaussian":
        x = x + rng.normal(0, 6, x.shape)
    elif kind == "rician":
        x = np.hypot(x + rng.normal(0, 8, x.shape), rng.normal(0, 8, x.shape))
    return np.clip(np.round(x), 0, 255).astype(np.uint8)


def adjusted_rand(a, b):
    """Hubert and Arabie's adjusted Rand index of two labelings."""
    from scipy.special import comb

    _, ai = np.unique(a, return_inverse=True)
    _, bi = np.unique(b, return_inverse=True)
    table = np.zeros((ai.max() + 1, bi.max() + 1))
    np.add.at(table, (ai, bi), 1)
    pairs = comb(table, 2).sum()
    rows, cols = comb(table.sum(1), 2).sum(), comb(table.sum(0), 2).sum()
    expected = rows * cols / comb(len(a), 2)
    return float((pairs - expected) / (0.5 * (rows + cols) - expected))


def _field(volume, mask, use):
    """The field the anchors segment: volseg's curvature of the (auto-)smoothed
    volume, or that smoothed value."""
    from volseg._smoothing import gaussian

    sigma, _ = auto_smoothing(volume, mask)
    values = gaussian(volume, sigma)
    if use == "value":
        return np.asarray(values, dtype=float)
    return grid_curvature(values, "weighted", value_scale=default_value_scale(values))


def skimage_watershed(field, mask, k):
    from scipy import ndimage
    from skimage.morphology import h_maxima
    from skimage.segmentation import watershed

    lo, hi = 0.0, float(field[mask].max() - field[mask].min())
    markers = None
    for _ in range(40):                      # bisection on h for k markers in the mask
        h = 0.5 * (lo + hi)
        markers, count = ndimage.label(h_maxima(np.where(mask, field, field[mask].min()), h)
                                       & mask)
        if count == k:
            break
        lo, hi = (h, hi) if count > k else (lo, h)
    return watershed(-field, markers, mask=mask)


def higra_cut(field, mask, k, attribute):
    import higra as hg

    graph = hg.get_6_adjacency_graph(field.shape)
    top = float(field[mask].max()) + 1.0
    inverted = np.where(mask, -field, -top + 2 * top)          # outside: above everything
    weights = hg.weight_graph(graph, inverted, hg.WeightFunction.max)
    build = {"area": hg.watershed_hierarchy_by_area,
             "dynamics": hg.watershed_hierarchy_by_dynamics}[attribute]
    tree, altitudes = build(graph, weights)
    cut = hg.HorizontalCutExplorer(tree, altitudes).horizontal_cut_from_num_regions(k + 1)
    return cut.labelisation_leaves(tree).reshape(field.shape)


def methods(volume, k):
    """name -> labels of `volume` cut into `k` regions."""
    found = foreground_mask(volume, "auto").mask
    mask = np.ones(volume.shape, bool) if found is None else found
    out = {}
    for measure in ("hypervolume", "size", "persistence"):
        out[f"volseg {measure} (defaults)" if measure == "hypervolume" else
            f"volseg {measure}"] = volseg.segment_volume(volume, n_regions=k,
                                                         measure=measure).labels
    out["volseg persistence, no smoothing or mask (before)"] = volseg.segment_volume(
        volume, n_regions=k, measure="persistence", smooth_sigma=0, mask=None).labels
    for use in ("curvature", "value"):
        field = _field(volume, found, use)
        out[f"skimage h_maxima + watershed, {use}"] = skimage_watershed(field, mask, k)
        for attribute in ("area", "dynamics"):
            out[f"higra by {attribute}, {use}"] = higra_cut(field, mask, k, attribute)
    return out


def spread(labels, where):
    sizes = np.bincount(labels[where].ravel())
    share = sizes[sizes > 0] / where.sum()
    return 1.0 / float((share**2).sum())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    clean, truth = phantom(args.size)
    parts = truth > 0
    k = len(PARTS)
    start = time.perf_counter()
    clean_labels = methods(clean, k)
    rows = {}
    for kind in ("clean", "gaussian", "rician"):
        labels = clean_labels if kind == "clean" else methods(noisy(clean, kind, args.seed), k)
        for name, lab in labels.items():
            score = volseg.compare(clean_labels[name], lab, mask=parts)
            rows.setdefault(name, {})[kind] = (
                adjusted_rand(truth[parts], lab[parts]),
                volseg.compare(truth, lab, mask=parts)["variation_of_information"],
                spread(lab, parts), score["hamming_similarity"])
    print(f"{args.size}^3 phantom, {k} parts ({parts.mean():.1%} of the voxels), seed "
          f"{args.seed}, {time.perf_counter() - start:.0f} s\n")
    print("| method | ARI clean / gauss / rician | VI clean / gauss / rician | "
          "effective regions (rician) | Huang-Dom vs clean (gauss / rician) |")
    print("|---|---|---|---|---|")
    for name, by in rows.items():
        ari = " / ".join(f"{by[kind][0]:.2f}" for kind in ("clean", "gaussian", "rician"))
        vi = " / ".join(f"{by[kind][1]:.2f}" for kind in ("clean", "gaussian", "rician"))
        print(f"| {name} | {ari} | {vi} | {by['rician'][2]:.1f} | "
              f"{by['gaussian'][3]:.3f} / {by['rician'][3]:.3f} |")


if __name__ == "__main__":
    main()
