"""
The noise-stability experiment, in small
========================================

The paper's Fig. 5 on one dataset: add Gaussian value noise of a growing share of
the value range, segment with the clean volume's value scale and threshold, and
score each noisy segmentation against the clean one. (``python -m
pipelines.noise_stability`` runs the whole experiment on Dask, resumable.)
"""

import warnings

import numpy as np

from volseg import hamming_similarity, segment_volume
from volseg.errors import VolsegWarning
from volseg.files import load_volume
from volseg.noise import add_value_noise

volume = load_volume("fuel")
# The paper's cut (persistence, no mask) of an 8-bit field can be degenerate: volseg
# says so with a VolsegWarning; here the stability is the point, so it is silenced.
warnings.simplefilter("ignore", VolsegWarning)
clean = segment_volume(volume, n_regions=30, measure="persistence", mask=None)
print(f"clean: {clean.n_regions} regions at persistence {clean.min_persistence:.4g}")
for percent in (0.5, 1, 2, 4):
    noisy = add_value_noise(np.asarray(volume), percent, seed=1)
    result = segment_volume(noisy, spacing=volume.spacing, min_persistence=clean.min_persistence,
                            value_scale=clean.value_scale, smooth_sigma=clean.smooth_sigma,
                            mask=None)
    print(f"{percent:4.1f} % noise: {result.n_regions:3d} regions, Hamming similarity "
          f"{hamming_similarity(clean.labels, result.labels):.3f}")
