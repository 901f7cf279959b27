"""volseg.outputs.preview, directly: the picture, the label convention, the persistence plot."""

import numpy as np
from PIL import Image

from volseg.outputs.preview import write_persistence_plot, write_preview


def _case():
    x = np.linspace(-1, 1, 20)
    volume = np.exp(-(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2) * 4)
    labels = np.where(volume > 0.2, 1 + (x[:, None, None] > 0), 0).astype(np.int32)
    labels = np.broadcast_to(labels, volume.shape).copy()
    return volume, np.gradient(volume)[0], labels


def test_preview_is_a_png_with_colour_only_inside_the_labels(tmp_path):
    volume, curvature, labels = _case()
    persistence = (np.array([0.5, 0.1, 0.01]), 1, 0.05)
    path = write_preview(tmp_path / "p.png", volume, curvature, labels, title="case",
                         persistence=persistence)
    with Image.open(path) as png:
        image = np.asarray(png.convert("RGB"))
    assert image.shape[0] > 300 and image.shape[1] > 600
    # The regions panel of the first row (x = mid slice), as written: grey exactly
    # where the label is 0, the region's colour blended in where it is not.
    from volseg.outputs import preview

    mid = volume.shape[0] // 2
    lo, hi = volume.min(), volume.max()
    panel = preview._fit(preview.overlay(volume[mid].T, labels[mid].T, lo, hi))
    fitted_labels = preview._fit(np.repeat(labels[mid].T[..., None], 3, axis=2))[..., 0]
    x0, y0 = preview._LEFT + 2 * (preview._BOX + preview._GAP), preview._TOP
    # (Left of the legend box, drawn over the panel's top right corner.)
    clear = preview._BOX - 112 - 6
    panel, fitted_labels = panel[:, :clear], fitted_labels[:, :clear]
    written = image[y0:y0 + panel.shape[0], x0:x0 + panel.shape[1]].astype(int)
    assert np.array_equal(written, panel)
    assert (fitted_labels == 0).any() and (fitted_labels > 0).any()
    grey = (written.max(axis=2) == written.min(axis=2))
    assert grey[fitted_labels == 0].all()
    assert not grey[fitted_labels > 0].any()


def test_label_zero_is_not_coloured(tmp_path):
    volume, curvature, labels = _case()
    empty = write_preview(tmp_path / "a.png", volume, curvature, np.zeros_like(labels))
    full = write_preview(tmp_path / "b.png", volume, curvature, labels)
    with Image.open(empty) as one, Image.open(full) as two:
        a = np.asarray(one.convert("RGB")).astype(int)
        b = np.asarray(two.convert("RGB")).astype(int)
    assert a.shape == b.shape and (a != b).any()  # the regions change the picture
    saturation = lambda im: (im.max(axis=2) - im.min(axis=2)).mean()  # noqa: E731
    assert saturation(b) > saturation(a)


def test_persistence_plot_alone(tmp_path):
    path = write_persistence_plot(tmp_path / "curve.png", np.geomspace(1, 1e-3, 40), 1, 0.01, 20)
    with Image.open(path) as image:
        assert image.format == "PNG" and image.size[0] > 200


def test_persistence_curve_drawn_in_blocks_is_the_same_image(monkeypatch):
    # The curve's corners are made a block of events at a time (memory): the seams
    # between blocks must not change a pixel (ties, zeros and a wide range included).
    import volseg.outputs.preview as preview

    rng = np.random.default_rng(3)
    p = rng.lognormal(-3, 2, 5000)
    p[:500], p[500:900] = 0.0, p[900]
    whole = preview.persistence_panel(p, 2, 0.1, 30)
    for block in (1, 7, 1000):
        monkeypatch.setattr(preview, "_CURVE_BLOCK", block)
        assert np.array_equal(preview.persistence_panel(p, 2, 0.1, 30), whole)


def test_a_lazy_preview_given_its_range_and_labels_is_the_same_image(tmp_path):
    # The blockwise run passes what it knows (the input's range, k) instead of two
    # passes over the volume and the labels: the picture must not change.
    import dask.array as da

    volume, curvature, labels = _case()
    lazy = [da.from_array(a, chunks=(7, 9, 20)) for a in (volume, curvature, labels)]
    persistence = (np.array([0.5, 0.1, 0.01]), 1, 0.05)
    images = []
    for name, arrays, known in (("eager", (volume, curvature, labels), {}), ("lazy", lazy, {}),
                                ("given", lazy, {"value_range": (volume.min(), volume.max()),
                                                 "n_labels": int(labels.max())})):
        path = write_preview(tmp_path / f"{name}.png", *arrays, title="case",
                             persistence=persistence, **known)
        with Image.open(path) as png:
            images.append(np.asarray(png.convert("RGB")))
    assert all(np.array_equal(image, images[0]) for image in images[1:])
    other = write_preview(tmp_path / "other.png", *lazy, title="case", persistence=persistence,
                          value_range=(volume.min(), 2 * volume.max()), n_labels=2)
    with Image.open(other) as png:
        assert not np.array_equal(np.asarray(png.convert("RGB")), images[0])


def test_a_thinned_curve_draws_the_curve_of_every_event():
    # A blockwise cut sends the curve thinned (`curve_sample`: a few thousand ranks,
    # not one number per event; issue 30). Drawn, it must be the curve of every event:
    # at most a few pixels differ (a corner's antialiasing), none by a line.
    import volseg.outputs.preview as preview
    from volseg.morse import curve_sample

    rng = np.random.default_rng(5)
    p = rng.lognormal(-3, 2, 2_000_000)
    p[:1000] = 0.0
    sample = curve_sample(p, 3)
    assert sample.n_positive == len(p) - 1000
    assert len(sample) < 4096 + np.log(len(p) / 4096) / np.log(1.001) + 2
    assert sample.values[0] == p.max() and sample.ranks[-1] == sample.n_positive - 1
    whole = preview.persistence_panel(p, 3, 0.1, 30)
    thinned = preview.persistence_panel(sample, 3, 0.1, 30)
    differ = np.any(whole != thinned, axis=-1)
    assert differ.sum() <= 40, differ.sum()
    assert np.any(whole != preview.persistence_panel(p[: len(p) // 2], 3, 0.1, 30))
