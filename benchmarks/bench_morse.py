"""Morse stage vs scikit-image (h_maxima + watershed) and higra (watershed by dynamics).

Same smooth random field, same Kuhn 14-neighbourhood, one run, side by side:

    python benchmarks/bench_morse.py                # 128^3
    python benchmarks/bench_morse.py 128 256        # and 256^3 (about 4 minutes for the others)
    python benchmarks/bench_morse.py --curvature    # bench_kernels.py's curvature field

`--curvature`: the weighted curvature of an 8-bit smoothed random volume (sigma 3),
the field of `bench_kernels.py` and issue 56 (50,792 maxima at 128^3), instead of the
smooth random field.
"""

import sys

from _common import in_fresh_process

SETUP = """
import json, resource, time
import numpy as np
from scipy.ndimage import gaussian_filter
n = {n}
field = gaussian_filter(np.random.default_rng(0).standard_normal((n, n, n)), {sigma})
if {curvature}:
    from volseg.curvature import grid_curvature
    field = grid_curvature(np.round(255 * (field - field.min()) / np.ptp(field)).astype(np.uint8),
                           "weighted")
from volseg.morse import grid_offsets
offsets = grid_offsets(3, "kuhn")
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
"""

VOLSEG = SETUP + """
from volseg.morse import descending_complex
descending_complex(field[:8, :8, :8]).segment(n_regions=2)   # compiled kernels load from cache
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # memory beyond input and loaded code
start = time.perf_counter(); h = descending_complex(field); build = time.perf_counter() - start
start = time.perf_counter(); labels = h.segment(n_regions=30); cut = time.perf_counter() - start
threshold = h.threshold_for(30)
start = time.perf_counter(); h.segment(min_persistence=threshold)
cut2 = time.perf_counter() - start
extra = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) * 1024 / field.size
print(json.dumps(dict(build=build, cut=cut, cut_threshold=cut2, total=build + cut,
      maxima=len(h.maxima), bytes_per_voxel=extra, threshold=threshold)))
"""

SKIMAGE = SETUP + """
from skimage.morphology import h_maxima
from skimage.segmentation import watershed
from skimage.measure import label
footprint = np.zeros((3, 3, 3), bool); footprint[1, 1, 1] = True
for o in offsets: footprint[tuple(o + 1)] = True
t = {threshold}
start = time.perf_counter()
markers = label(h_maxima(field, t, footprint=footprint), connectivity=3)
labels = watershed(-field, markers, connectivity=footprint)
print(json.dumps(dict(total=time.perf_counter() - start, regions=int(labels.max()))))
"""

HIGRA = SETUP + """
import higra as hg
shape = field.shape
graph = hg.get_nd_regular_graph(shape, hg.mask_2_neighbours(
    np.pad(np.zeros((1, 1, 1), bool), 1) | np.isin(np.indices((3, 3, 3)).reshape(3, -1).T - 1,
    offsets).all(1).reshape(3, 3, 3)))
start = time.perf_counter()
weights = hg.weight_graph(graph, -field.ravel(), hg.WeightFunction.max)
tree, altitudes = hg.watershed_hierarchy_by_dynamics(graph, weights)
labels = hg.labelisation_horizontal_cut_from_num_regions(tree, altitudes, 30)
print(json.dumps(dict(total=time.perf_counter() - start, regions=int(labels.max()))))
"""


def main(sizes, curvature=False):
    sigma = 3 if curvature else 2
    for n in sizes:
        ours = in_fresh_process(VOLSEG.format(n=n, sigma=sigma, curvature=curvature))
        print(f"{n}^3 volseg: build {ours['build']:.2f} s, cut to 30 regions {ours['cut']:.3f} s "
              f"({100 * ours['cut'] / ours['build']:.1f}% of the build), {ours['maxima']} maxima, "
              f"peak memory beyond the input {ours['bytes_per_voxel']:.1f} bytes/voxel", flush=True)
        sk = in_fresh_process(SKIMAGE.format(n=n, sigma=sigma, curvature=curvature,
                                            threshold=ours["threshold"]))
        print(f"{n}^3 scikit-image h_maxima + watershed: {sk['total']:.2f} s "
              f"-> volseg is {sk['total'] / ours['total']:.1f}x faster", flush=True)
        try:
            hi = in_fresh_process(HIGRA.format(n=n, sigma=sigma, curvature=curvature))
            print(f"{n}^3 higra watershed_hierarchy_by_dynamics: {hi['total']:.2f} s "
                  f"-> volseg is {hi['total'] / ours['total']:.1f}x faster", flush=True)
        except Exception as err:  # noqa: BLE001
            print(f"{n}^3 higra failed: {err}")


if __name__ == "__main__":
    sizes = [int(a) for a in sys.argv[1:] if a != "--curvature"]
    main(sizes or [128], curvature="--curvature" in sys.argv)
