"""The noise-stability batch pipeline: determinism, Dask runs, resume, interruption."""

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipelines import noise_stability as ns
from pipelines.store import ResultStore
from tests.conftest import smooth_random_field

REPO = Path(__file__).resolve().parents[2]   # the repository: pipelines/ runs from it


def _volume(seed, n=24):
    field = smooth_random_field((n, n, n), sigma=2.0, rng=np.random.default_rng(seed))
    return np.round(255 * (field - field.min()) / np.ptp(field)).astype(np.uint8)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    folder = tmp_path_factory.mktemp("volumes")
    paths = []
    for seed, name in [(1, "alpha"), (2, "beta")]:
        np.save(folder / f"{name}.npy", _volume(seed))
        paths.append(str(folder / f"{name}.npy"))
    return paths


def _task(level, seed, operator="weighted", dataset="alpha", field="curvature",
          cut="threshold"):
    return {"dataset": dataset, "checksum": "x", "operator": operator, "field": field,
            "regions": 8, "cut": cut, "mask": "none", "level": level, "seed": seed}


def _done_rows(db):
    with ResultStore(db, ns.KEY_COLUMNS) as store:
        return store.rows("done")


def test_noise_is_seeded_and_shared_across_levels():
    clean = _volume(1)
    a = ns.noisy_volume(clean, 2.0, 3, "alpha", 255.0)
    b = ns.noisy_volume(clean, 2.0, 3, "alpha", 255.0)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, ns.noisy_volume(clean, 2.0, 4, "alpha", 255.0))
    assert not np.array_equal(a, ns.noisy_volume(clean, 2.0, 3, "beta", 255.0))
    # One standard normal field per (dataset, seed), scaled to each level.
    c = ns.noisy_volume(clean, 4.0, 3, "alpha", 255.0)
    np.testing.assert_allclose(c - clean, 2 * (a - clean), atol=1e-9)
    np.testing.assert_allclose((a - clean).std(), 0.02 * 255, rtol=0.05)
    np.testing.assert_array_equal(ns.noisy_volume(clean, 0.0, 3, "alpha", 255.0), clean)


def test_zero_noise_gives_similarity_one_and_ratio_one():
    clean = _volume(2)
    for operator in ["laplace_beltrami", "weighted", "unweighted"]:
        reference = ns.clean_reference(clean, operator, 8)
        assert reference["n_regions"] == 8
        row = ns.run_task(_task(0.0, 0, operator), clean, reference)
        assert row["similarity"] == 1.0 and row["region_ratio"] == 1.0
        assert row["similarity_foreground"] == 1.0
        assert row["n_regions"] == 8
        assert row["d_clean_to_noisy"] == 0 and row["d_noisy_to_clean"] == 0
        noisy = ns.run_task(_task(5.0, 0, operator), clean, reference)
        assert noisy["similarity"] < 1.0


def test_defaults_protocol_reestimates_everything_on_each_volume():
    """``--cut defaults``: each field as a user runs it (its own measure, mask and
    smoothing, re-estimated on the noisy volume); a field that reads no operator runs
    once; other fields than the curvature need this protocol."""
    clean = _volume(3, n=28)
    for field in ("curvature", "gradient", "value"):
        reference = ns.clean_reference(clean, "weighted", 8, field=field, cut="defaults")
        row = ns.run_task(_task(0.0, 0, field=field, cut="defaults"), clean, reference)
        assert row["similarity"] == 1.0 and row["n_regions"] == reference["n_regions"]
        noisy = ns.run_task(_task(10.0, 0, field=field, cut="defaults"), clean, reference)
        assert noisy["similarity"] < 1.0 and noisy["measure"] == reference["measure"]
    data = [("alpha", clean, "x")]
    tasks = ns.plan(data, ["weighted", "unweighted"], [0.0], 1, 8, "defaults", "none",
                    ("curvature", "gradient"))
    assert [(t["field"], t["operator"]) for t in tasks] == [
        ("curvature", "weighted"), ("curvature", "unweighted"), ("gradient", "weighted")]
    from volseg.errors import UsageError

    with pytest.raises(UsageError, match="need --cut defaults"):
        ns.run(data, "unused", fields=("gradient",))


@pytest.mark.slow
def test_small_run_on_a_local_cluster_then_a_rerun_does_no_work(tiny, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--out", str(out), "--datasets", *tiny, "--operators", "weighted",
            "laplace-beltrami", "--levels", "0", "3", "--seeds", "2", "--regions", "8",
            "--workers", "2", "--report"]
    assert ns.main(argv) == 0
    rows = _done_rows(out / ns.DB_NAME)
    assert len(rows) == 2 * 2 * 2 * 2
    assert {(r["dataset"], r["operator"]) for r in rows} == {
        (d, o) for d in ["alpha", "beta"] for o in ["weighted", "laplace_beltrami"]}
    for row in rows:
        assert row["clean_regions"] == 8
        if row["level"] == 0:
            assert row["similarity"] == 1.0 and row["region_ratio"] == 1.0
        else:
            assert 0 < row["similarity"] < 1
    # Determinism: a row computed here, in this process, equals the cluster's.
    volume = np.load(tiny[0])
    row = next(r for r in rows if r["dataset"] == "alpha" and r["level"] == 3.0
               and r["seed"] == 1 and r["operator"] == "weighted")
    local = ns.run_task({k: row[k] for k in ns.KEY_COLUMNS}, volume,
                        ns.clean_reference(volume, "weighted", 8))
    for metric in ["similarity", "region_ratio", "n_regions", "d_clean_to_noisy", "threshold"]:
        assert local[metric] == row[metric]
    # The report: every row in CSV, a summary and a real figure.
    for name in ["tasks.csv", "summary.csv", "fig5.png", "fig5_foreground.png"]:
        assert (out / name).stat().st_size > 0
    assert len((out / "tasks.csv").read_text().splitlines()) == 1 + 16
    import matplotlib.image

    image = matplotlib.image.imread(out / "fig5.png")
    assert image.shape[0] > 300 and image[..., :3].std() > 0.05
    # The same command again: nothing is run and no row changes.
    before = (out / ns.DB_NAME).read_bytes()
    capsys.readouterr()
    assert ns.main([a for a in argv if a != "--report"]) == 0
    assert "nothing to do" in capsys.readouterr().err
    assert _done_rows(out / ns.DB_NAME) == rows
    assert (out / ns.DB_NAME).read_bytes() == before


@pytest.mark.slow
def test_a_failing_task_is_recorded_and_the_others_finish(tmp_path, capfd):
    good = ("good", _volume(3), "g" * 64)
    flat = ("flat", np.zeros((16, 16), dtype=np.uint8), "f" * 64)  # 2-D: segmenting fails
    said = []
    counts = ns.run([good, flat], tmp_path, operators=["weighted"], levels=[0.0, 1.0],
                    seeds=1, regions=5, workers=1, say=said.append)
    assert counts["ran"] == 2 and counts["failed"] == 2
    # The error is said once, in one line; no worker prints a traceback.
    assert said[-1] == "2 tasks failed with ValueError: `volume` must be 3-D, got shape (16, 16)"
    assert "Compute Failed" not in capfd.readouterr().err
    with ResultStore(tmp_path / ns.DB_NAME, ns.KEY_COLUMNS) as store:
        failed = store.rows("failed")
        assert {r["dataset"] for r in failed} == {"flat"}
        assert all(r["error"] for r in failed)
        assert len(store.rows("done")) == 2


def _count_done(db):
    try:
        with sqlite3.connect(db, timeout=5) as connection:
            return connection.execute("SELECT COUNT(*) FROM tasks WHERE "
                                      "status='done'").fetchone()[0]
    except sqlite3.OperationalError:  # not created yet
        return 0


@pytest.mark.slow
def test_killed_run_resumes_and_every_task_is_there_once(tiny, tmp_path):
    out = tmp_path / "killed"
    argv = [sys.executable, "-m", "pipelines.noise_stability", "--out", str(out),
            "--datasets", *tiny, "--operators", "weighted", "unweighted",
            "--levels", "0", "1", "2", "4", "--seeds", "6", "--regions", "8",
            "--workers", "2", "-q"]
    total = 2 * 2 * 4 * 6
    process = subprocess.Popen(argv, cwd=REPO, start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    db = out / ns.DB_NAME
    deadline = time.monotonic() + 120
    while _count_done(db) < 3 and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(process.pid, signal.SIGKILL)  # the client and its workers, mid-run
    process.wait()
    survivors = _done_rows(db)
    assert 3 <= len(survivors) < total, "the kill did not land mid-run"
    assert ns.main(argv[3:]) == 0
    rows = _done_rows(db)
    keys = [tuple(r[k] for k in ns.KEY_COLUMNS) for r in rows]
    assert len(rows) == total and len(set(keys)) == total
    # Work finished before the kill was kept, not redone.
    after = {tuple(r[k] for k in ns.KEY_COLUMNS): r["seconds"] for r in rows}
    for row in survivors:
        assert after[tuple(row[k] for k in ns.KEY_COLUMNS)] == row["seconds"]


def test_bad_arguments_exit_2(tmp_path, capsys):
    assert ns.main(["--out", str(tmp_path), "--datasets", "no-such-volume"]) == 2
    assert "no-such-volume" in capsys.readouterr().err
    assert ns.main(["--out", str(tmp_path), "--levels", "-1"]) == 2
    assert ns.main(["--out", str(tmp_path / "empty"), "--report-only"]) == 2
    assert "no results" in capsys.readouterr().err
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    volume = tmp_path / "v.npy"
    np.save(volume, _volume(6, n=12))
    assert ns.main(["--out", str(blocked / "run"), "--datasets", str(volume)]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_an_existing_scheduler_is_used_and_left_running(tmp_path):
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        data = ("gamma", _volume(5, n=16), "c" * 64)
        counts = ns.run([data], tmp_path, operators=["unweighted"], levels=[0.0, 2.0], seeds=1,
                        regions=4, scheduler=cluster.scheduler_address)
        assert counts["ran"] == 2 and counts["failed"] == 0
        with Client(cluster.scheduler_address) as client:  # still up for its owner
            assert len(client.scheduler_info()["workers"]) == 1


@pytest.mark.slow
def test_region_count_cut_keeps_the_count_and_is_keyed_apart(tmp_path, capsys):
    data = ("delta", _volume(7, n=20), "d" * 64)
    for cut in ["threshold", "regions"]:
        counts = ns.run([data], tmp_path, operators=["weighted"], levels=[0.0, 3.0], seeds=2,
                        regions=6, cut=cut, workers=1)
        assert counts["ran"] == 4  # the other cut's rows do not count as done
    rows = _done_rows(tmp_path / ns.DB_NAME)
    assert len(rows) == 8
    recut = [r for r in rows if r["cut"] == "regions"]
    assert all(r["n_regions"] == 6 and r["region_ratio"] == 1.0 for r in recut)
    held = [r for r in rows if r["cut"] == "threshold" and r["level"] == 3.0]
    assert any(r["n_regions"] != 6 for r in held)  # the held threshold lets the count move
    paths = {p.name for p in ns.report(tmp_path)}
    assert {"fig5.png", "fig5_foreground.png", "fig5_regions.png"} <= paths
    with pytest.raises(SystemExit) as exit_:  # argparse: usage error, exit code 2
        ns.main(["--out", str(tmp_path), "--cut", "sideways"])
    assert exit_.value.code == 2
    assert "--cut" in capsys.readouterr().err


def test_a_results_file_with_other_keys_is_refused(tmp_path, capsys):
    with ResultStore(tmp_path / ns.DB_NAME, ("dataset", "level")) as store:
        store.record({"dataset": "x", "level": 1.0, "similarity": 0.5})
    assert ns.main(["--out", str(tmp_path), "--report-only"]) == 2
    assert "another version" in capsys.readouterr().err


@pytest.mark.slow
def test_unreachable_or_malformed_scheduler_is_one_line_exit_2(tiny, tmp_path, capsys):
    for address, message in [("not-an-address", "missing port number"),
                             ("tcp://127.0.0.1:9", "cannot reach")]:
        assert ns.main(["--out", str(tmp_path), "--datasets", tiny[0], "--seeds", "1",
                        "--levels", "0", "--operators", "weighted", "--scheduler", address,
                        "-q"]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and address in err and message in err


def test_two_runs_on_one_folder_do_not_compute_the_same_tasks(tiny, tmp_path, capsys):
    from volseg.io import FolderLock

    with FolderLock(tmp_path, "results"):
        assert ns.main(["--out", str(tmp_path), "--datasets", tiny[0], "--seeds", "1",
                        "--levels", "0", "--operators", "weighted", "-q"]) == 2
    assert "another noise-stability run is using it" in capsys.readouterr().err


def test_masked_run_segments_and_scores_the_clean_foreground_only():
    volume = _volume(4)
    volume[:12] = 0  # an exact-zero half: auto masks it
    reference = ns.clean_reference(volume, "weighted", 6, mask="auto")
    assert reference["mask"] is not None and not reference["mask"][:12].any()
    row = ns.run_task({**_task(1.0, 0), "mask": "auto"}, volume, reference)
    noisy = ns.noisy_volume(volume, 1.0, 0, "alpha", reference["value_range"])
    from volseg import compare, segment_volume

    direct = segment_volume(noisy, value_scale=reference["value_scale"], mask=reference["mask"],
                            min_persistence=reference["threshold"])
    assert (direct.labels[:12] == 0).all()
    expected = compare(reference["labels"], direct.labels, mask=reference["mask"])
    assert row["similarity"] == expected["hamming_similarity"]
    assert expected["voxels"] == int(reference["mask"].sum())
