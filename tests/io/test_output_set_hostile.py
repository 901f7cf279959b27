"""The output folder is not trusted (issue 27): kills in the commit window over folder
outputs, stems that share a prefix, planted links and journals."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from volseg.cli import main
from volseg.errors import OutputError
from volseg.io import OutputSet, recover

NAMES = {"labels": "fuel_labels.zarr", "summary": "fuel_summary.json"}


def _old_set(folder):
    (folder / "fuel_labels.zarr").mkdir(parents=True)
    (folder / "fuel_labels.zarr" / "chunk").write_text("old")
    (folder / "fuel_summary.json").write_text("old")


def _staging(folder, stem="fuel", suffix="abcd1234", journal=None):
    staging = folder / f".volseg-staging-{stem}-{suffix}"
    (staging / "new" / f"{stem}_labels.zarr").mkdir(parents=True)
    (staging / "new" / f"{stem}_labels.zarr" / "chunk").write_text("new")
    (staging / "new" / f"{stem}_summary.json").write_text("new")
    (staging / "old").mkdir()
    if journal is not None:
        (staging / "COMMIT").write_text(journal if isinstance(journal, str)
                                        else json.dumps(journal))
    return staging


def _fuel_file(folder):
    """A small raw volume named fuel (stem ``fuel``), made here: no dataset needed."""
    axis = np.linspace(-1, 1, 12)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    data = np.round(200 * np.exp(-3 * (x**2 + y**2 + z**2))).astype(np.uint8)
    path = folder / "fuel_12x12x12_uint8.raw"
    path.write_bytes(np.ascontiguousarray(data.transpose(2, 1, 0)).tobytes())
    return str(path)


def _contents(folder):
    return ((folder / "fuel_labels.zarr" / "chunk").read_text(),
            (folder / "fuel_summary.json").read_text())


@pytest.mark.parametrize("moved_aside", [0, 1, 2])
def test_a_commit_killed_over_an_old_set_of_folders_is_finished_by_the_next_run(
        tmp_path, moved_aside):
    _old_set(tmp_path)
    staging = _staging(tmp_path, journal={"names": list(NAMES.values()),
                                          "discard": [".fuel.volseg-work"]})
    (tmp_path / ".fuel.volseg-work").mkdir()          # the blockwise run's finished blocks
    for name in list(NAMES.values())[:moved_aside]:  # killed after some old moved aside
        os.replace(tmp_path / name, staging / "old" / name)
    with OutputSet(tmp_path, "fuel", NAMES, force=True) as out:
        assert out.recovered and "completed an interrupted commit" in out.recovered[0]
    assert _contents(tmp_path) == ("new", "new")      # one complete set: the new one
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(NAMES.values())


def test_a_commit_over_folders_replaces_them_and_removes_what_it_discards(tmp_path):
    _old_set(tmp_path)
    (tmp_path / ".fuel.volseg-work").mkdir()

    def write(paths):
        paths["labels"].mkdir()
        (paths["labels"] / "chunk").write_text("new")
        paths["summary"].write_text("new")

    with OutputSet(tmp_path, "fuel", NAMES, force=True) as out:
        out.discard = [tmp_path / ".fuel.volseg-work"]
        out.commit(write)
    assert _contents(tmp_path) == ("new", "new")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(NAMES.values())


def test_recovery_of_a_stem_leaves_a_longer_stems_staging_alone(tmp_path):
    live = _staging(tmp_path, stem="scan-2")                        # a run on scan-2
    old = _staging(tmp_path, stem="scan", suffix="zz99yy88")       # scan's, stale
    done = recover(tmp_path, "scan")
    assert len(done) == 1 and not old.exists() and live.exists()
    assert recover(tmp_path, "scan-2") and not live.exists()


def test_a_planted_lock_link_is_refused_and_its_target_untouched(tmp_path, capsys):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "out"
    out.mkdir()
    (out / ".fuel.volseg-lock").symlink_to("../victim.txt")
    assert main(["segment", _fuel_file(tmp_path), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "symbolic link" in err and ".fuel.volseg-lock" in err
    assert victim.read_text() == "precious"
    assert sorted(p.name for p in out.iterdir()) == [".fuel.volseg-lock"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fuel_12x12x12_uint8.raw", "out",
                                                          "victim.txt"]


@pytest.mark.parametrize("journal, problem", [
    (["../escaped.txt"], "names files that are not this set's"),
    ({"names": ["fuel_summary.json"], "discard": ["../../home"]},
     "names files that are not this set's"),
    ("[1, 2]", "names files that are not this set's"),
    ("{", "is not JSON"),
    ('{"names": 3}', "does not list the set's names"),
])
def test_a_planted_or_corrupt_journal_is_refused_with_one_line_and_nothing_moves(
        tmp_path, capsys, journal, problem):
    out = tmp_path / "out"
    out.mkdir()
    source = _fuel_file(tmp_path)
    staging = _staging(out, journal=journal)
    (staging / "escaped.txt").write_text("planted")
    before = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert main(["segment", source, "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and problem in err and str(staging / "COMMIT") in err
    assert "then remove" in err                     # what to do
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == before
    assert not (tmp_path / "escaped.txt").exists()
    # Done as told, the folder is usable again.
    import shutil

    shutil.rmtree(staging)
    assert main(["segment", source, "-o", str(out), "-q"]) == 0


def test_a_staging_link_is_refused(tmp_path):
    elsewhere = _staging(tmp_path / "elsewhere", journal=list(NAMES.values()))
    out = tmp_path / "out"
    out.mkdir()
    (out / ".volseg-staging-fuel-abcd1234").symlink_to(elsewhere)
    with pytest.raises(OutputError, match="is not a folder volseg made"):
        recover(out, "fuel")
    assert (elsewhere / "new" / "fuel_summary.json").exists()


@pytest.mark.slow
def test_a_blockwise_run_killed_after_its_journal_over_an_old_set_heals(tmp_path, volvis_dir):
    out = tmp_path / "out"
    source = str(volvis_dir / "silicium_98x34x34_uint8.raw")
    assert main(["segment", source, "-o", str(out), "-q", "--regions", "7",
                 "--chunks", "16"]) == 0
    old = json.loads((out / "silicium_summary.json").read_text())
    assert old["n_regions"] == 7
    # The next run is killed after its journal and the first rename of the swap.
    script = textwrap.dedent(f"""
        import os, sys
        from volseg.io import output_set
        real = output_set.OutputSet._swap
        def swap(self, staging):
            first = next(iter(self.targets.values()))
            os.replace(first, staging / "old" / first.name)
            os._exit(9)
        output_set.OutputSet._swap = swap
        from volseg.cli import main
        sys.exit(main(["segment", {source!r}, "-o", {str(out)!r}, "-q", "--force",
                       "--chunks", "16"]))
    """)
    killed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert killed.returncode == 9, killed.stderr
    assert any((p / "COMMIT").exists() for p in out.iterdir() if p.name.startswith("."))
    # Any later run finishes that commit first (the killed run's set, 30 regions,
    # its work folder removed); without --force it then refuses to overwrite it ...
    assert main(["segment", source, "-o", str(out), "-q", "--chunks", "16"]) == 2
    summary = json.loads((out / "silicium_summary.json").read_text())
    assert summary["n_regions"] == 30 and summary["input_sha256"] == old["input_sha256"]
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
    # ... and with --force it writes its own.
    assert main(["segment", source, "-o", str(out), "-q", "--force", "--chunks", "16",
                 "--regions", "9"]) == 0
    assert json.loads((out / "silicium_summary.json").read_text())["n_regions"] == 9
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
    labels = np.asarray(__import__("zarr").open(str(out / "silicium_labels.zarr"), mode="r"))
    assert labels.max() == 9


def test_a_staging_refilled_by_a_late_worker_is_removed_on_release(tmp_path):
    import threading
    import time

    late = []

    def write(paths):
        def worker():          # a block still being written when the run is interrupted
            time.sleep(0.3)
            paths["summary"].parent.mkdir(parents=True, exist_ok=True)
            paths["summary"].write_text("late")
        late.append(threading.Thread(target=worker))
        late[0].start()
        raise KeyboardInterrupt

    out = OutputSet(tmp_path, "fuel", NAMES)
    out.acquire()
    with pytest.raises(KeyboardInterrupt):
        out.commit(write)
    late[0].join()                                   # the engine stops its threads ...
    assert any(p.name.startswith(".volseg-staging-") for p in tmp_path.iterdir())
    out.release()                                    # ... then the set lets go
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_between_making_the_staging_and_owning_it_leaves_nothing(tmp_path,
                                                                             monkeypatch):
    # SIGTERM lands just after `mkdtemp` made the folder, before `commit` holds it
    # (CI saw this window once, the signal sent as the lock file appeared).
    import tempfile

    from volseg.io import output_set

    made = tempfile.mkdtemp

    def interrupted(*args, **kwargs):
        made(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(output_set.tempfile, "mkdtemp", interrupted)
    with pytest.raises(KeyboardInterrupt), OutputSet(tmp_path, "fuel", NAMES) as out:
        out.commit(lambda paths: None)
    assert list(tmp_path.iterdir()) == []


def test_release_leaves_a_journalled_staging_for_recovery(tmp_path):
    out = OutputSet(tmp_path, "fuel", NAMES)
    out.acquire()
    staging = _staging(tmp_path, journal=sorted(NAMES.values()))
    out.release()
    assert staging.is_dir()                       # a commit to finish, not to discard
    with OutputSet(tmp_path, "fuel", NAMES, force=True) as again:
        assert again.recovered
    assert (tmp_path / "fuel_summary.json").read_text() == "new"


def test_release_after_the_folder_was_removed_raises_nothing(tmp_path):
    import shutil

    folder = tmp_path / "out"
    folder.mkdir()
    out = OutputSet(folder, "fuel", NAMES)
    out.acquire()
    shutil.rmtree(folder)                       # a user cleaning up during the run
    out.release()
    assert not out._lock.held


def _snapshots_during_commit(folder, monkeypatch):
    """The folder's files of stem fuel after every rename the commit makes."""
    from volseg.io import output_set

    seen = []
    real = os.replace

    def replace(src, dst):
        real(src, dst)
        seen.append(sorted(p.name for p in folder.iterdir() if p.name.startswith("fuel_")))

    monkeypatch.setattr(output_set.os, "replace", replace)
    return seen


def test_the_summary_goes_first_and_comes_last_with_nothing_stale_beside_it(
        tmp_path, monkeypatch):
    """Issue 57 (#12): a reader saw a partial folder between a commit's renames. The
    summary (the set's index) is now moved aside first and placed last, after every
    other new file and after the older run's other outputs are gone: whenever a
    summary is there, the files beside it are exactly one run's set."""
    old = {"fuel_labels.nii.gz": "old", "fuel_summary.json": "old", "fuel_volumes.vti": "old",
           "fuel_persistence.png": "old"}
    for name, text in old.items():
        (tmp_path / name).write_text(text)
    seen = _snapshots_during_commit(tmp_path, monkeypatch)
    names = {"labels": "fuel_labels.nii.gz", "curvature": "fuel_curvature.nii.gz",
             "summary": "fuel_summary.json"}
    with OutputSet(tmp_path, "fuel", names, force=True,
                   owns=["fuel_volumes.vti", "fuel_persistence.png"]) as out:
        out.commit(lambda paths: [p.write_text("new") for p in paths.values()])
    with_summary = [files for files in seen if "fuel_summary.json" in files]
    assert with_summary and all(files in (sorted(old), sorted(names.values()))
                                for files in with_summary)
    first_new = seen.index(sorted(names.values()))
    assert "fuel_summary.json" not in seen[first_new - 1]      # placed last
    assert seen[-1] == sorted(names.values())
    assert all((tmp_path / n).read_text() == "new" for n in names.values())


def test_read_set_reads_one_runs_set_or_says_it_is_being_written(tmp_path):
    """`read_set`: a read overlapping a commit is read again and gives the new run's
    files only; a set left in a commit (an interrupted one) is refused naming it."""
    from volseg.io.output_set import read_set

    names = {"labels": "fuel_labels.nii.gz", "summary": "fuel_summary.json"}
    with OutputSet(tmp_path, "fuel", names) as out:
        out.commit(lambda paths: [p.write_text("1") for p in paths.values()])
    reads = []

    def read():
        labels = (tmp_path / "fuel_labels.nii.gz").read_text()
        if not reads:             # a second run commits while this one reads
            with OutputSet(tmp_path, "fuel", names, force=True) as again:
                again.commit(lambda paths: [p.write_text("2") for p in paths.values()])
        reads.append(labels)
        return labels, (tmp_path / "fuel_summary.json").read_text()

    assert read_set(tmp_path / "fuel_summary.json", "fuel", read, pause=0) == ("2", "2")
    assert reads == ["1", "2"]
    _staging(tmp_path, journal={"names": list(names.values()), "discard": []})
    with pytest.raises(OutputError, match="being written"):
        read_set(tmp_path / "fuel_summary.json", "fuel", read, tries=3, pause=0)
