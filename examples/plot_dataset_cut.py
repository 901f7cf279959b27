"""
Segment a named dataset and pick a cut
======================================

Segment the Volvis ``fuel`` volume (a fuel injection simulation, 64^3) once, then
look at the hierarchy's curve and cut it again at other region counts: every cut
after the first is a relabelling, nothing is recomputed.
"""

import matplotlib.pyplot as plt
import numpy as np

from volseg import segment_volume
from volseg.files import load_volume

volume = load_volume("fuel")        # from ../shared/data/volvis, or the download cache
result = segment_volume(volume)     # the CLI's defaults: 30 regions by hypervolume
print(f"{volume.name}: {result.n_regions} regions from {len(result.hierarchy.maxima)} maxima, "
      f"smoothing sigma {result.smooth_sigma:g} ({result.smooth_rule})")

# %%
# The curve: how many regions each threshold of the measure leaves. A long flat
# step is a cut that is stable under the threshold.
extinction, components = result.hierarchy.curve(result.measure, result.cut["min_component"])
thresholds = np.sort(extinction[extinction > 0])[::-1]
fig, ax = plt.subplots(figsize=(5, 3.5))
ax.step(thresholds, components + np.arange(1, len(thresholds) + 1), where="post")
ax.set(xscale="log", yscale="log", xlabel=f"{result.measure} threshold", ylabel="regions")
ax.axvline(result.threshold, color="tab:red")
fig.savefig("fuel_curve.png", dpi=100)

# %%
# Cut again: 8 and 60 regions, with the share of the largest region of each.
for k in (8, 30, 60):
    cut = result.recut(k)
    sizes = np.bincount(cut.labels.ravel())[1:]
    print(f"{k:3d} regions: largest {sizes.max() / sizes.sum():.1%}, "
          f"smallest {sizes.min()} voxels, threshold {cut.threshold:.4g}")
