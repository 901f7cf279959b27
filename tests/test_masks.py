"""volseg.masks: each rule on small exact volumes, the auto rule's plateau share, Otsu
against scikit-image, the refusals."""

import numpy as np
import pytest
from skimage.filters import threshold_otsu

from volseg.masks import AUTO_PLATEAU_SHARE, check_rule, foreground_mask


def test_mask_rules():
    volume = np.arange(64, dtype=float).reshape(4, 4, 4)
    assert foreground_mask(volume, "value>=60").voxels == 4
    assert foreground_mask(volume, "value < 3").voxels == 3
    assert foreground_mask(volume, "none").mask is None
    assert foreground_mask(volume, "auto").used == "none"  # no plateau
    assert foreground_mask(volume, "otsu").used.startswith("value>")
    with pytest.raises(ValueError, match="unknown `mask` rule 'bright'"):
        foreground_mask(volume, "bright")
    with pytest.raises(ValueError, match="selects no voxel"):
        foreground_mask(volume, "value>100")
    with pytest.raises(ValueError, match="boolean array of the volume's shape"):
        foreground_mask(volume, np.ones((4, 4), bool))


@pytest.mark.parametrize("plateau, used", [(32, "low mode: value>0.375"), (33, "nonzero")])
def test_auto_masks_the_minimum_plateau_only_above_half_the_volume(plateau, used):
    assert AUTO_PLATEAU_SHARE == 0.5
    volume = np.arange(1, 65, dtype=float).reshape(4, 4, 4)
    volume.ravel()[:plateau] = 0.0            # 32 of 64 voxels: exactly half
    choice = foreground_mask(volume, "auto")
    # Half is no plateau by the first rule; the histogram's peak at 0 is a low mode.
    assert choice.used == used
    assert choice.voxels == 64 - plateau
    assert np.array_equal(choice.mask, volume > 0)


def test_nonzero_is_above_the_minimum_even_when_it_is_not_zero():
    volume = np.full((3, 3, 3), -2.0)
    volume[1, 1, 1] = 5.0
    choice = foreground_mask(volume, "nonzero")
    assert choice.voxels == 1 and choice.mask[1, 1, 1] and choice.describe()["used"] == "nonzero"


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_otsu_is_scikit_images_threshold(dtype):
    rng = np.random.default_rng(0)
    volume = np.concatenate([rng.normal(40, 5, 500), rng.normal(180, 10, 500)])
    volume = volume.clip(0, 255).astype(dtype).reshape(10, 10, 10)
    choice = foreground_mask(volume, "otsu")
    threshold = threshold_otsu(volume.ravel())
    assert np.array_equal(choice.mask, volume > threshold)
    assert choice.used == f"value>{float(threshold):g}"


def test_rules_parse_without_data_and_a_boolean_array_is_taken_as_it_is():
    assert check_rule(" Value<=2.5 ") == ("value", ("<=", 2.5))
    assert check_rule("OTSU") == ("otsu", None)
    with pytest.raises(ValueError, match="unknown `mask` rule"):
        check_rule("value=3")
    mask = np.zeros((2, 3, 4), bool)
    mask[1, 2, 3] = True
    choice = foreground_mask(np.zeros((2, 3, 4)), mask)
    assert choice.mask is mask or np.array_equal(choice.mask, mask)
    assert choice.describe() == {"rule": "array", "used": "array", "voxels": 1}
    assert choice.phrase().endswith("mask of 1 voxels")
