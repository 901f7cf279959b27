"""
Compare two segmentations
=========================

Huang and Dom's Hamming similarity (the paper's score), its two directional
distances, the region ratio and the variation of information, between the weighted
and the unweighted extrinsic distortion on the Volvis ``neghip`` volume.
"""

from volseg import compare, segment_volume
from volseg.files import load_volume

volume = load_volume("neghip")
weighted = segment_volume(volume, operator="weighted", n_regions=30)
unweighted = segment_volume(volume, operator="unweighted", n_regions=30)
scores = compare(weighted.labels, unweighted.labels, mask=weighted.labels > 0)
for name, value in scores.items():
    print(f"{name:>28}: {value:.4g}" if isinstance(value, float) else f"{name:>28}: {value}")
