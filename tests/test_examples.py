"""Every script in examples/ runs offline (the shared mirror, built-in volumes) and
does what it says: the files it names are written, its own checks hold."""

import runpy
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("plot_*.py"))
#: What each example must leave in its folder.
WRITES = {"plot_dataset_cut.py": ["fuel_curve.png"], "plot_mesh.py": ["blobs_regions.vtu"],
          "plot_blockwise_zarr.py": ["blockwise_out/blobs_labels.zarr",
                                     "blockwise_out/blobs_segmentation.ome.zarr"],
          "plot_compare.py": [], "plot_noise_stability.py": []}


def test_every_example_is_listed():
    assert {path.name for path in EXAMPLES} == set(WRITES)


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda path: path.stem)
def test_example_runs(script, tmp_path, monkeypatch, volvis_dir, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")     # the examples save figures, show none
    runpy.run_path(str(script), run_name="__main__")
    for name in WRITES[script.name]:
        assert (tmp_path / name).exists(), name
    assert capsys.readouterr().out.strip()          # it reports what it did
