"""The widget's model without Qt (`LiveSegmentation`): its cuts and the measure the
field's default stands for."""

import warnings

import numpy as np

from volseg import segment_volume
from volseg.io import Volume
from volseg.napari_plugin._live import LiveSegmentation, Options


class _Source:
    """A layer's volume, shown as it is (what `LayerVolume` gives the model)."""

    def __init__(self, data):
        self.volume = Volume(data, name="tooth")

    def shown(self, array):
        return array


def test_the_fields_default_measure_is_the_one_the_run_chose(volvis_dir):
    """The tooth's gradient cut by volume is degenerate, so the run cut by area (the
    field's rule). Choosing another measure and then "the field's default" again
    recuts by area, as the run did, not by volume (issue 55's review)."""
    from volseg.io import read_volume

    data = read_volume(next(volvis_dir.glob("tooth_*.raw"))).data
    live = LiveSegmentation(_Source(data), Options(field="gradient"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = live.run()
        expected = segment_volume(data, field="gradient")
    assert result.measure == expected.measure == "area"
    assert np.array_equal(live.labels(), expected.labels)
    live.set_measure("persistence")
    assert live.result.measure == "persistence"
    labels = live.set_measure(None)
    assert live.result.measure == "area" and np.array_equal(labels, expected.labels)
    assert live.labels().dtype == np.min_scalar_type(live.max_regions())
