import json
import os
import stat
import subprocess
import sys

import nibabel
import numpy as np
import pytest

from volseg.cli import main


@pytest.mark.parametrize("name, shape", [("fuel", (64, 64, 64)), ("neghip", (64, 64, 64)),
                                         ("silicium", (98, 34, 34))])
def test_segment_real_datasets_by_name(tmp_path, name, shape, capsys, volvis_dir):
    assert main(["segment", name, "-o", str(tmp_path), "--regions", "25", "-q", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    labels = np.asanyarray(nibabel.load(tmp_path / f"{name}_labels.nii.gz").dataobj)
    curvature = np.asanyarray(nibabel.load(tmp_path / f"{name}_curvature.nii.gz").dataobj)
    assert labels.shape == shape and curvature.shape == shape
    assert np.isfinite(curvature).all()
    # --mask auto: fuel's and neghip's zero plateau is over half; silicium's 41.6 % is
    # a low mode (its histogram peaks at 0): the voxels at or below the triangle
    # threshold are left out.
    assert set(np.unique(labels)) == set(range(26))
    assert summary == json.loads((tmp_path / f"{name}_summary.json").read_text())
    assert summary["n_regions"] == 25
    volume = np.fromfile(next(volvis_dir.glob(f"{name}_*.raw")), np.uint8).reshape(shape[::-1]).T
    if name == "silicium":
        assert summary["mask"]["used"] == "low mode: value>4"
        outside = volume <= 4
        # ... and the specks of the mask below 0.1 % of it are labelled 0 too.
        assert (labels[outside] == 0).all() and (labels[~outside] > 0).mean() > 0.99
    else:
        assert summary["mask"]["used"] == "nonzero"
        assert ((labels == 0) == (volume == 0)).all()
    sizes = np.bincount(labels.ravel(), minlength=26)[1:]
    assert [r["size"] for r in summary["regions"]] == sizes.tolist()
    for region in summary["regions"]:
        assert labels[tuple(region["maximum"])] == region["label"]
    assert summary["input_sha256"] and summary["operator"] == "weighted"


def test_preview_is_a_real_picture(tmp_path, volvis_dir):
    import matplotlib.image

    assert main(["segment", "silicium", "-o", str(tmp_path), "-q"]) == 0
    image = matplotlib.image.imread(tmp_path / "silicium_preview.png")
    assert image.shape[0] > 600 and image.shape[1] > 600
    assert image[..., :3].std() > 0.1  # not blank
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 500  # many colours


def test_segment_a_raw_path_with_options(tmp_path, volvis_dir):
    source = volvis_dir / "silicium_98x34x34_uint8.raw"
    argv = ["segment", str(source), "-o", str(tmp_path), "--operator", "laplace-beltrami",
            "--min-persistence", "0.05", "--noise", "1", "--seed", "3", "-q"]
    assert main(argv) == 0
    summary = json.loads((tmp_path / "silicium_summary.json").read_text())
    assert summary["operator"] == "laplace_beltrami" and summary["noise_percent"] == 1
    assert summary["min_persistence"] == 0.05


def _no_outputs(folder):
    return not folder.exists() or not list(folder.iterdir())


def test_errors_exit_2_with_one_line_and_no_partial_files(tmp_path, capsys):
    out = tmp_path / "out"
    cases = [
        (["segment", str(tmp_path / "missing_4x4x4_uint8.raw")], "no such file"),
        (["segment", "nosuchdataset"], "not a dataset name"),
    ]
    short = tmp_path / "short_4x4x4_uint8.raw"
    short.write_bytes(bytes(10))
    cases.append((["segment", str(short)], "expected 64 bytes"))
    for argv, message in cases:
        assert main(argv + ["-o", str(out), "-q"]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
        assert _no_outputs(out)


def test_checksum_mismatch_is_refused(tmp_path, monkeypatch, capsys):
    mirror = tmp_path / "mirror"
    mirror.mkdir()
    (mirror / "fuel_64x64x64_uint8.raw").write_bytes(bytes(64**3))
    monkeypatch.setenv("VOLSEG_DATA_DIR", str(mirror))
    assert main(["segment", "fuel", "-o", str(tmp_path / "out"), "-q"]) == 2
    assert "checksum mismatch" in capsys.readouterr().err


def test_offline_without_mirror_says_where_to_put_the_file(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("VOLSEG_DATA_DIR", str(tmp_path / "empty"))
    from volseg.datasets import DatasetError, fetch

    with pytest.raises(DatasetError, match="put it at"):
        fetch("nucleon", download=False)


def test_existing_outputs_need_force(tmp_path, volvis_dir, capsys):
    assert main(["segment", "nucleon", "-o", str(tmp_path), "-q"]) == 0
    before = (tmp_path / "nucleon_summary.json").read_text()
    assert main(["segment", "nucleon", "-o", str(tmp_path), "-q", "--regions", "5"]) == 2
    assert "use --force" in capsys.readouterr().err
    assert (tmp_path / "nucleon_summary.json").read_text() == before
    assert main(["segment", "nucleon", "-o", str(tmp_path), "-q", "--regions", "5", "--force"]) == 0
    assert json.loads((tmp_path / "nucleon_summary.json").read_text())["n_regions"] == 5
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_unwritable_output_folder(tmp_path, volvis_dir, capsys, monkeypatch):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(stat.S_IRUSR | stat.S_IXUSR)
    if os.geteuid() == 0:  # root writes anywhere: make the permission check see the mode
        import volseg.files

        monkeypatch.setattr(volseg.files.os, "access", lambda path, mode: False)
    assert main(["segment", "nucleon", "-o", str(locked), "-q"]) == 2
    assert "not writable" in capsys.readouterr().err


def test_output_folder_that_is_a_file(tmp_path, volvis_dir, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["segment", "nucleon", "-o", str(blocker / "sub"), "-q"]) == 2
    assert "cannot create the output folder" in capsys.readouterr().err


def test_usage_errors_exit_2(capsys):
    assert main(["segment"]) == 2
    assert main(["segment", "fuel", "--regions", "3", "--min-persistence", "1"]) == 2
    assert main(["frobnicate"]) == 2


def test_demo_runs_offline_in_a_clean_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("VOLSEG_DATA_DIR", str(tmp_path / "nothing"))
    assert main(["demo", "-q"]) == 0
    printed = capsys.readouterr().out
    for kind in ["labels.nii.gz", "curvature.nii.gz", "summary.json", "preview.png"]:
        assert (tmp_path / "volseg-demo" / f"demo_{kind}").exists()
        assert kind in printed


def test_info_and_compare(tmp_path, volvis_dir, capsys):
    assert main(["info", "silicium"]) == 0
    assert "(98, 34, 34)" in capsys.readouterr().out
    a = np.zeros((4, 4, 4), np.int32)
    b = a.copy()
    b[2:] = 1
    for name, data in [("a.npy", a), ("b.npy", b)]:
        np.save(tmp_path / name, data)
    assert main(["compare", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["hamming_similarity"] == 0.75 and result["region_ratio"] == 0.5
    # Over the foreground of b (labels > 0): one region in each, identical.
    assert main(["compare", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--mask", "b",
                 "--json"]) == 0
    masked = json.loads(capsys.readouterr().out)
    assert masked["hamming_similarity"] == 1.0 and masked["voxels"] == 32


def test_a_degenerate_cut_is_one_warning_line_with_its_fix(volvis_dir, tmp_path, capsys):
    # tooth by persistence, unsmoothed (the old defaults): 92.4 % in one region, 2
    # regions of 1 % or more (8-bit steps).
    tooth = str(volvis_dir / "tooth_103x94x161_uint8.raw")
    assert main(["segment", tooth, "-o", str(tmp_path / "a"), "--measure", "persistence",
                 "--smooth", "0", "--mask", "none"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "92.4 %" in warnings[0]
    assert "--measure hypervolume" in warnings[0] and "--smooth 1" in warnings[0]
    spread = json.loads((tmp_path / "a" / "tooth_summary.json").read_text())["spread"]
    assert spread["degenerate"] and spread["regions_at_least_1_percent"] == 2
    # The fix it names works, and so do the defaults: no region holds half.
    for options in (["--measure", "hypervolume", "--smooth", "1"], []):
        assert main(["segment", tooth, "-o", str(tmp_path / "b"), "--force", *options]) == 0
        assert "warning" not in capsys.readouterr().err
        spread = json.loads((tmp_path / "b" / "tooth_summary.json").read_text())["spread"]
        assert not spread["degenerate"] and spread["largest_share"] < 0.5
        assert spread["regions_at_least_1_percent"] >= 10


def test_measure_threshold_and_min_component_options(tmp_path, capsys, volvis_dir):
    out = tmp_path / "o"
    assert main(["segment", "silicium", "-o", str(out), "-q", "--json", "--measure", "size",
                 "--threshold", "2000", "--min-component", "0", "--mask", "none"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["measure"], summary["threshold"], summary["min_component"]) == (
        "size", 2000.0, 0.0)
    assert summary["cut"] == "size threshold"
    assert summary["smooth_rule"].startswith("auto: uint8 values, noise")
    # One component (no mask): every region that is left holds at least the threshold.
    assert min(r["size"] for r in summary["regions"]) >= 2000 and summary["n_regions"] > 1
    for argv, message in ((["--measure", "size", "--min-persistence", "1"], "--threshold"),
                          (["--threshold", "-1"], "--threshold must be"),
                          (["--min-component", "1.5"], "--min-component must be")):
        assert main(["segment", "silicium", "-o", str(tmp_path / "x"), *argv]) == 2
        assert message in capsys.readouterr().err


def test_compare_takes_whole_float_labels_and_names_a_file_of_fractions(tmp_path, capsys):
    """FSL and others write label maps as float32: whole numbers are labels; a file of
    fractions is refused by name (it said 'label volumes must hold integer labels')."""
    a = np.zeros((4, 4, 4), np.int32)
    b = a.copy()
    b[2:] = 1
    np.save(tmp_path / "a.npy", a)
    np.save(tmp_path / "b.npy", b.astype(np.float32))
    assert main(["compare", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["hamming_similarity"] == 0.75
    c = b.astype(np.float32)
    c[3, 2, 1] = 0.5
    np.save(tmp_path / "c.npy", c)
    assert main(["compare", str(tmp_path / "a.npy"), str(tmp_path / "c.npy")]) == 2
    line = capsys.readouterr().err.strip()
    assert line == (f"volseg: error: {tmp_path / 'c.npy'}: label volumes must hold integer "
                    "labels, got float32 0.5 at voxel [3, 2, 1]")


def test_first_run_note_and_in_memory_stage_progress(tmp_path, capsys, monkeypatch):
    """The first run's note is said exactly when numba compiles (a cache miss), once,
    and never when every kernel loads from the cache (it was said on every run: the
    probe looked for a kernel the default cut never compiles); in-memory runs say
    each stage and the seconds the one before took; -q says nothing."""
    import importlib

    from volseg import _jit_cache

    (tmp_path / "fresh_kernels.py").write_text(
        "import numba\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n"
        "@numba.njit(cache=True)\ndef thrice(x):\n    return 3 * x\n")
    sys.path.insert(0, str(tmp_path))
    said = []
    try:
        module = importlib.import_module("fresh_kernels")
        with _jit_cache.noting_compilation(said.append):        # an empty cache
            assert module.twice(3) == 6 and module.thrice(2) == 6
        assert said == [_jit_cache.FIRST_RUN_NOTE]               # once for both
        sys.modules.pop("fresh_kernels")
        module = importlib.import_module("fresh_kernels")        # a new process's view
        with _jit_cache.noting_compilation(said.append):        # the cache full
            assert module.twice(4) == 8 and module.thrice(1) == 3
        assert said == [_jit_cache.FIRST_RUN_NOTE]
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("fresh_kernels", None)
    source = tmp_path / "v_12x10x8_uint8.raw"
    source.write_bytes(np.arange(960, dtype=np.uint8).tobytes())
    assert main(["segment", str(source), "-o", str(tmp_path / "a"), "--regions", "2"]) == 0
    err = capsys.readouterr().err.splitlines()
    for stage in ("curvature done in", "morse done in", "cut done in"):
        assert any(stage in line for line in err), (stage, err)
    # The command in new processes on an empty numba cache (the note, first) and then
    # on the cache that run filled (no note): about 50 CPU-s of compilation, once.
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    errs = []
    for out in ("b1", "b2"):
        run = subprocess.run([sys.executable, "-m", "volseg", "segment", str(source), "-o",
                              str(tmp_path / out), "--regions", "2"], capture_output=True,
                             text=True, env=env)
        assert run.returncode == 0, run.stderr
        errs.append(run.stderr)
    # Said as the first kernel starts compiling, inside the curvature stage.
    lines = errs[0].splitlines()
    assert lines.count(f"volseg: {_jit_cache.FIRST_RUN_NOTE}") == 1, errs[0]
    assert lines.index(f"volseg: {_jit_cache.FIRST_RUN_NOTE}") < min(
        i for i, line in enumerate(lines) if "curvature done in" in line)
    assert "compiling" not in errs[1], errs[1]
    assert main(["segment", str(source), "-o", str(tmp_path / "c"), "-q", "--regions", "2"]) == 0
    assert capsys.readouterr().err == ""
    # -q silences progress, not warnings: 30 regions of a volume of fewer maxima.
    assert main(["segment", str(source), "-o", str(tmp_path / "d"), "-q"]) == 0
    assert capsys.readouterr().err.startswith("volseg: warning: v: asked for 30 regions")


@pytest.mark.parametrize("argv, message", [
    (["--mask", "brightest"], "unknown --mask rule 'brightest'"),
    (["--chunks", "1"], "--chunks must be a whole number of at least 2 voxels, got 1"),
    (["--smooth", "-1"], "--smooth must be a non-negative number of voxels"),
    (["--regions", "0"], "--regions must be at least 1, got 0"),
])
def test_a_bad_option_is_refused_before_the_input_is_opened(tmp_path, capsys, monkeypatch, argv,
                                                             message):
    """`SegmentRequest.checked` is the one check of every option; the command line runs it
    before it opens anything: no input is read and nothing is written."""
    import volseg.files

    opened = []
    monkeypatch.setattr(volseg.files, "load_for_budget", lambda *a, **k: opened.append(a))
    out = tmp_path / "o"
    assert main(["segment", str(tmp_path / "missing.nii.gz"), "-o", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert opened == [] and not out.exists()


def test_a_degenerate_cut_is_a_warning_from_the_api_and_a_line_even_with_q(tmp_path, capsys,
                                                                          volvis_dir):
    """One region of nearly everything (the unsmoothed tooth cut by persistence: its
    tallest curvature peaks are voxel-sized spikes): `segment_volume` gives a
    VolsegWarning, the command line one stderr line 'volseg: warning:' even with -q."""
    from volseg import read_volume, segment_volume
    from volseg.errors import VolsegWarning

    tooth = volvis_dir / "tooth_103x94x161_uint8.raw"
    with pytest.warns(VolsegWarning, match="largest of 30 regions holds"):
        segment_volume(read_volume(tooth), measure="persistence", smooth_sigma=0)
    assert main(["segment", str(tooth), "-o", str(tmp_path / "o"), "-q",
                 "--measure", "persistence", "--smooth", "0"]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("volseg: warning:")]
    assert len(lines) == 1 and "largest of 30" in lines[0], err


def test_help_names_every_input_format_and_operator(capsys):
    """`volseg segment --help` lists what read_volume reads (from the readers' table,
    not a copy) and what each --operator is (issue 58)."""
    from volseg.cli import main
    from volseg.curvature import REGISTRY
    from volseg.io.readers import _READERS

    assert main(["segment", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for suffixes, _ in _READERS:
        for suffix in suffixes:
            assert suffix in text
    assert "OME-Zarr" in text and "TIFF" in text and ".raw" in text
    for operator in REGISTRY.values():
        assert operator.label in text


def test_compare_refuses_labels_on_different_grids_unless_asked(tmp_path, capsys):
    """Issue 57 (#13): labels of the same shape but other voxel sizes, origin or axes
    were compared voxel by voxel without a word. They are refused naming both grids;
    --any-grid compares them, with a warning; a file without geometry (.npy) is no
    disagreement."""
    import nibabel

    a = np.zeros((6, 5, 4), np.int16)
    a[3:] = 1
    nibabel.save(nibabel.Nifti1Image(a, np.diag([1.0, 1.0, 2.0, 1.0])), tmp_path / "a.nii.gz")
    shifted = np.diag([1.0, 1.0, 2.0, 1.0])
    shifted[:3, 3] = [5, 0, 0]
    nibabel.save(nibabel.Nifti1Image(a, shifted), tmp_path / "b.nii.gz")
    nibabel.save(nibabel.Nifti1Image(a, np.diag([1.0, 1.0, 2.0, 1.0])), tmp_path / "c.nii.gz")
    np.save(tmp_path / "d.npy", a)
    pair = [str(tmp_path / "a.nii.gz"), str(tmp_path / "b.nii.gz")]
    assert main(["compare", *pair]) == 2
    err = capsys.readouterr().err
    assert "places its voxels elsewhere" in err and "origin (5, 0, 0)" in err
    assert "--any-grid" in err and err.count("\n") == 1
    assert main(["compare", *pair, "--any-grid", "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["hamming_similarity"] == 1.0
    assert "volseg: warning:" in captured.err and "--any-grid" in captured.err
    for other in ("c.nii.gz", "d.npy"):
        assert main(["compare", str(tmp_path / "a.nii.gz"), str(tmp_path / other)]) == 0
        assert "warning" not in capsys.readouterr().err
    assert main(["compare", str(tmp_path / "a.nii.gz"), str(tmp_path / "c.nii.gz"),
                 "--mask", str(tmp_path / "b.nii.gz")]) == 2
    assert "--mask" in capsys.readouterr().err


def test_the_gradients_fallback_to_area_is_said_once(volvis_dir, tmp_path, capsys):
    """The tooth's gradient cut by volume is degenerate: the run cuts by area and says
    why, once, on stderr (from the cut record's flag, not from parsing its text); an
    asked measure says nothing of the kind."""
    tooth = str(volvis_dir / "tooth_103x94x161_uint8.raw")
    assert main(["segment", tooth, "-o", str(tmp_path / "a"), "--field", "gradient"]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "cut by area" in line]
    assert len(said) == 1 and "by volume the cut was degenerate" in said[0]
    assert main(["segment", tooth, "-o", str(tmp_path / "b"), "--field", "gradient",
                 "--measure", "volume"]) == 0
    assert "cut by area" not in capsys.readouterr().err
