import numpy as np
import pytest

from volseg import Volume, segment_volume
from volseg.cli import _synthetic_volume


def test_segment_volume_defaults_to_30_regions_and_accepts_volume_or_array():
    data = _synthetic_volume(32)
    result = segment_volume(data)
    assert result.n_regions == 30 and result.labels.shape == data.shape
    again = segment_volume(Volume(data, spacing=(1.0, 1.0, 1.0)))
    np.testing.assert_array_equal(again.labels, result.labels)
    recut = result.hierarchy.segment(n_regions=10)
    assert recut.max() + 1 == 10
    assert result.labels[np.unravel_index(result.region_maxima()[0], data.shape)] == 0


def test_blob_centres_are_curvature_maxima():
    # Three separated Gaussian blobs: with 4 regions (3 blobs + background) each blob
    # centre lies in its own region.
    axis = np.linspace(-1, 1, 33)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    centres = [(-0.5, -0.5, 0), (0.5, -0.4, 0.3), (0, 0.5, -0.4)]
    f = sum(np.exp(-((x - a) ** 2 + (y - b) ** 2 + (z - c) ** 2) / 0.04) for a, b, c in centres)
    labels = segment_volume(f, n_regions=4).labels
    index = [tuple(np.round((np.array(c) + 1) * 16).astype(int)) for c in centres]
    assert len({labels[i] for i in index}) == 3


def test_segment_errors():
    with pytest.raises(ValueError, match="not both"):
        segment_volume(np.zeros((4, 4, 4)), n_regions=2, min_persistence=1.0)
    with pytest.raises(ValueError, match="unknown `operator`"):
        segment_volume(np.zeros((4, 4, 4)), operator="nope")


@pytest.mark.parametrize("kwargs, message", [
    ({"spacing": (1.0, 2.0)}, "`spacing` must be three positive numbers"),
    ({"spacing": (1.0, -1.0, 1.0)}, "`spacing` must be three positive numbers"),
    ({"n_regions": 2.5}, "`n_regions` must be an integer"),
    ({"min_persistence": -0.1}, "`min_persistence` must be a non-negative number"),
])
def test_bad_arguments_name_themselves(kwargs, message):
    with pytest.raises(ValueError, match=message):
        segment_volume(np.random.default_rng(0).random((6, 6, 6)), **kwargs)
    with pytest.raises(ValueError, match="`volume` must be 3-D"):
        segment_volume(np.zeros((6, 6)))
