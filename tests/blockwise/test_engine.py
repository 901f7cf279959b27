"""The blockwise run's engine, resume and reads: memory-mapped block reads equal whole
reads, bad engine arguments and an unreachable scheduler are one line and exit 2 with
nothing written, a killed run resumes from its finished blocks with the same result,
and no worker holds more than a few blocks (the scheduler's own accounting)."""

import os
import pickle

import dask
import numpy as np
import pytest
import zarr

from volseg.blockwise import engine as engine_module
from volseg.cli import main
from volseg.io import read_volume

from ..conftest import smooth_random_field


@pytest.fixture
def volume():
    field = smooth_random_field((24, 21, 18), np.random.default_rng(4), sigma=2.0)
    return (field * 400 + 128).clip(0, 255).astype(np.uint8)


def _visible(folder):
    return sorted(p for p in os.listdir(folder) if not p.startswith(".")) if folder.exists() else []


def test_mapped_block_reads_equal_whole_reads(tmp_path, volume):
    wide = volume.astype(np.uint16) * 250
    raw = tmp_path / "v_24x21x18_uint16.raw"
    raw.write_bytes(wide.transpose(2, 1, 0).tobytes())           # x fastest
    np.save(tmp_path / "f.npy", np.asfortranarray(volume.astype(np.float32)))
    for path, expected in ((raw, wide), (tmp_path / "f.npy", volume.astype(np.float32))):
        whole = read_volume(path).data
        lazy = read_volume(path, chunks=(5, 7, 9)).data
        assert lazy.chunks[0] == (5, 5, 5, 5, 4)
        assert np.array_equal(whole, expected) and np.array_equal(lazy.compute(), expected)
        # What a distributed worker receives: the file's name and layout, not its data.
        assert len(pickle.dumps(lazy)) < expected.nbytes / 2


@pytest.mark.slow
def test_bad_engine_arguments_and_an_unreachable_scheduler(tmp_path, volume, capsys, monkeypatch):
    np.save(tmp_path / "vol.npy", volume)
    monkeypatch.setattr(engine_module, "CONNECT_TIMEOUT", 1.0)
    for extra, message in ((["--workers", "0"], "--workers must be at least 1"),
                           (["--memory-limit", "lots"], "--memory-limit 'lots'"),
                           (["--hierarchy-memory", "2GB"], "--hierarchy-memory adds a worker"),
                           (["--threads-per-worker", "2"], "--threads-per-worker sets the local"),
                           (["--scheduler", "local", "--threads-per-worker", "0"],
                            "--threads-per-worker must be at least 1"),
                           (["--scheduler", "local", "--hierarchy-memory", "10MB"],
                            "--hierarchy-memory 10 MiB is less than"),
                           (["--scheduler", "tcp://127.0.0.1:9"],
                            "cannot reach the Dask scheduler")):
        out = tmp_path / "out"
        assert main(["segment", str(tmp_path / "vol.npy"), "--chunks", "8", "-o", str(out), "-q",
                     *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
        assert _visible(out) == [] and not (out / ".vol.volseg-work").exists()
    # The failed Client does not stay Dask's default scheduler.
    assert dask.config.get("scheduler", None) in (None, "synchronous", "sync")


def _whole_and_interrupted(tmp_path, volume, monkeypatch, stage_function, options=()):
    """Segment `volume` blockwise (27 blocks; `options` added) once whole, then again
    into ``out`` with Ctrl-C in `_morse_blocks.<stage_function>` after 5 blocks;
    returns (argv, the whole run's labels, out), with the function restored."""
    from volseg.morse.blocks import _build as _morse_blocks

    np.save(tmp_path / "vol.npy", volume)
    argv = ["segment", str(tmp_path / "vol.npy"), "--chunks", "8", "--mask", "none",
            "--scheduler", "threads", "--workers", "1", *options, "-q"]
    assert main([*argv, "-o", str(tmp_path / "whole")]) == 0
    expected = zarr.open(str(tmp_path / "whole" / "vol_labels.zarr"), mode="r")[:]
    assert not (tmp_path / "whole" / ".vol.volseg-work").exists()     # removed once committed
    original, seen = getattr(_morse_blocks, stage_function), []

    def interrupted(*args):
        if len(seen) == 5:
            raise KeyboardInterrupt
        seen.append(1)
        return original(*args)

    monkeypatch.setattr(_morse_blocks, stage_function, interrupted)
    out = tmp_path / "out"
    assert main([*argv, "-o", str(out)]) != 0
    assert _visible(out) == []
    monkeypatch.setattr(_morse_blocks, stage_function, original)
    return argv, expected, out


@pytest.mark.slow
def test_a_run_killed_in_the_cells_pass_resumes_from_the_kept_path_ends(tmp_path, volume,
                                                                        monkeypatch):
    from volseg.morse.blocks import _build as _morse_blocks

    argv, expected, out = _whole_and_interrupted(tmp_path, volume, monkeypatch, "_cells_of_ends")
    work = out / ".vol.volseg-work"
    assert len(list((work / "ends").glob("*.npy"))) == 27
    assert len(list((work / "cells").glob("*.npys"))) == 5
    ascend, climbs = _morse_blocks._ascend, []
    monkeypatch.setattr(_morse_blocks, "_ascend", lambda *a: climbs.append(1) or ascend(*a))
    assert main([*argv, "-o", str(out)]) == 0
    assert climbs == []                        # no block climbs again: its ends were kept
    assert np.array_equal(zarr.open(str(out / "vol_labels.zarr"), mode="r")[:], expected)


@pytest.mark.slow
def test_the_smoothed_range_is_taken_as_the_blocks_are_kept(tmp_path, volume, monkeypatch):
    """A smoothed blockwise run's default value scale reads the range its storage took
    as it kept the smoothed blocks, not a pass over them again: the same range as the
    smoothed values in memory, so the in-memory value scale. A run resumed with every
    smoothed block on disk sees none of them pass, takes the pass, and gives the whole
    run's labels and scale."""
    import json

    import dask

    from volseg import segment as _segment

    ranges, real = [], _segment.default_value_scale

    def recorded(values, spacing, *, value_range=None):
        # the range given, and that of the values given (a pass, for the test)
        ranges.append((value_range, tuple(float(v) for v in dask.compute(
            values.min(), values.max()))))
        return real(values, spacing, value_range=value_range)

    monkeypatch.setattr(_segment, "default_value_scale", recorded)
    argv, expected, out = _whole_and_interrupted(tmp_path, volume, monkeypatch,
                                                 "_pairs_of_block", ["--smooth", "1"])
    assert main(["segment", str(tmp_path / "vol.npy"), "--mask", "none", "--smooth", "1",
                 "-q", "-o", str(tmp_path / "memory")]) == 0
    (whole, whole_range), (killed, _), (memory, memory_range) = ranges
    assert whole == killed == whole_range == memory_range and memory is None
    summaries = [json.loads((folder / "vol_summary.json").read_text())
                 for folder in (tmp_path / "whole", tmp_path / "memory")]
    assert summaries[0]["value_scale"] == summaries[1]["value_scale"]
    assert main([*argv, "-o", str(out)]) == 0                   # resumed: every block kept
    assert ranges[-1] == (None, whole_range)                    # so the pass is taken
    assert np.array_equal(zarr.open(str(out / "vol_labels.zarr"), mode="r")[:], expected)
    assert json.loads((out / "vol_summary.json").read_text())["value_scale"] == \
        summaries[0]["value_scale"]


@pytest.mark.slow
def test_a_killed_run_resumes_from_its_finished_blocks(tmp_path, volume, capsys, monkeypatch):
    from volseg.curvature import _grid_blocks

    # Ctrl-C in the edge pass, after 5 of its 27 blocks
    argv, expected, out = _whole_and_interrupted(tmp_path, volume, monkeypatch, "_pairs_of_block")
    work = out / ".vol.volseg-work"
    done = {stage: len(list((work / stage).glob("*.npys")))
            for stage in ("curvature", "cells", "forests")}
    assert done["cells"] == 27 and done["forests"] == 5 and done["curvature"] > 0
    assert not (work / "ends").exists()        # the ascent's ends: gone once cells are stored

    kernel, runs = _grid_blocks.BlockCurvature.__call__, []
    monkeypatch.setattr(_grid_blocks.BlockCurvature, "__call__",
                        lambda self, *a, **k: runs.append(1) or kernel(self, *a, **k))
    capsys.readouterr()
    assert main([*argv[:-1], "-o", str(out)]) == 0
    assert "resuming from finished blocks" in capsys.readouterr().err
    assert runs == []                          # no curvature block computed again
    assert np.array_equal(zarr.open(str(out / "vol_labels.zarr"), mode="r")[:], expected)
    assert not work.exists()


@pytest.mark.slow
def test_no_worker_holds_more_than_a_few_blocks_and_the_shells(tmp_path):
    """The scheduler's accounting of the bytes each worker holds, at every transition
    of a whole blockwise run (curvature, Morse, labels) on 27 blocks.

    A block's halo is assembled in the task that reads it from its neighbours'
    shells (outer layers) and the block itself, read again from its store
    (`volseg._halo`, fresh). So a worker holds a few blocks and at most every
    block's shell (6/c of the volume per pass for c^3 blocks: 4.7 % at 128^3; half
    of it here, where blocks are 12^3). Bound: six float64 halo blocks plus every
    shell of the curvature (float64), of the cells (int32) and of the ascent's path
    ends (a gid and an end, 16 B: the maps the exits are resolved in, on the workers
    since issue 30). Measured: 355-398 KB when the exits went to the client; 404-554
    KB since, against a bound of 785 KB; the halos joined axis by axis before this
    held 487-507 KB, dask's overlap more.
    """
    from distributed import Client, LocalCluster
    from distributed.diagnostics.plugin import SchedulerPlugin

    from volseg.files import segment_to_files
    from volseg.io import OutputSet, Volume
    from volseg.outputs import output_names

    class Peak(SchedulerPlugin):
        peak = 0

        def transition(self, key, start, finish, *args, **kwargs):
            for worker in self.scheduler.workers.values():
                self.peak = max(self.peak, worker.nbytes)

    field = smooth_random_field((36, 36, 36), np.random.default_rng(1), sigma=4.0)
    np.save(tmp_path / "big.npy", (field * 300 + 128).clip(0, 255).astype(np.uint8))
    lazy = read_volume(tmp_path / "big.npy", chunks=12)
    (tmp_path / "o").mkdir()
    peak = Peak()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster, Client(cluster):
        peak.scheduler = cluster.scheduler
        cluster.scheduler.add_plugin(peak)
        # (No NIfTI outputs: those of a small volume are read whole from the stores.)
        with OutputSet(tmp_path / "o", "big", output_names("big", False, True)) as outputs:
            info = segment_to_files(Volume(lazy.data, frame=lazy.frame, name="big"), outputs)
    halo_block = 14**3 * 8
    shells = 27 * 6 * 12**2 * (8 + 4 + 16)
    assert info["n_regions"] >= 1 and peak.peak > 0
    assert peak.peak < 6 * halo_block + shells, (peak.peak, 6 * halo_block + shells)


def test_an_input_above_the_memory_limit_takes_the_blockwise_path(tmp_path, volume, capsys):
    np.save(tmp_path / "vol.npy", volume)
    argv = ["segment", str(tmp_path / "vol.npy"), "--mask", "none", "--scheduler", "threads"]
    assert main([*argv, "--memory-limit", "1000", "-o", str(tmp_path / "small")]) == 0
    assert "exceeds the memory limit" in capsys.readouterr().err
    assert (tmp_path / "small" / "vol_labels.zarr").is_dir()
    assert main([*argv, "-o", str(tmp_path / "big"), "-q"]) == 0          # default: half the RAM
    assert (tmp_path / "big" / "vol_labels.nii.gz").is_file()
    assert np.array_equal(zarr.open(str(tmp_path / "small" / "vol_labels.zarr"), mode="r")[:],
                          np.asarray(read_volume(tmp_path / "big" / "vol_labels.nii.gz").data))


@pytest.mark.slow
def test_a_cluster_that_cannot_go_on_stops_with_one_line(monkeypatch):
    """A worker paused at its memory limit with work pending waited forever (its log
    lines flooding stderr); one that dies over its limit ended in exit 1 KilledWorker.
    Both are now an `EngineError` naming the stage and the per-worker limit."""
    import time

    monkeypatch.setattr(engine_module, "STALL_SECONDS", 3.0)

    def hold(megabytes):            # unmanaged memory the worker cannot spill
        import builtins
        import time

        builtins.volseg_test_hold = np.ones(int(megabytes * 2**20) // 8)
        time.sleep(1.0)             # the worker's memory monitor pauses it meanwhile
        return 1

    def later(x):
        return x + 1

    def resident_megabytes():
        import psutil

        return psutil.Process().memory_info().rss / 2**20

    # What the worker holds already (60 MiB with older packages, more with newer ones)
    # plus the array: 87.5 % of the limit, above the pause (80 %), below the kill (95 %).
    with engine_module.Engine("local", workers=1, memory_limit="1GiB") as engine:
        base, = engine.compute(dask.delayed(resident_megabytes)(), stage="base")
        assert base < 700, f"the worker holds {base:.0f} MiB before any work"
        held = dask.delayed(hold)(0.875 * 1024 - base)
        started = time.monotonic()
        with pytest.raises(engine_module.EngineError,
                           match=r"^stalled: every Dask worker has been paused .* for 3 s "
                                 r"with work pending \(1024 MiB per worker\)"):
            engine.compute(dask.delayed(later)(held), dask.delayed(later)(5), stage="stalled")
        assert time.monotonic() - started < 40
    with engine_module.Engine("local", workers=1, memory_limit="300MiB") as engine:
        with pytest.raises(engine_module.EngineError, match=r"^killed: Dask workers died"):
            engine.compute(dask.delayed(hold)(400), stage="killed")
    # A task that holds the hierarchy runs on its worker only, and its line says so:
    # the 1 GiB worker would have held it.
    with engine_module.Engine("local", workers=1, memory_limit="1GiB",
                              hierarchy_memory="300MiB") as engine:
        with pytest.raises(engine_module.EngineError,
                           match=r"^joined: Dask workers died .*300 MiB for the hierarchy\); "
                                 r"this task holds the whole Morse hierarchy .*--hierarchy-memory"):
            engine.persist(dask.delayed(hold)(400), stage="joined", hierarchy=True)


@pytest.mark.slow
def test_the_hierarchy_is_joined_and_cut_on_the_worker_given_for_it():
    """With a worker of `HIERARCHY_RESOURCE` (`--hierarchy-memory`), the tasks that
    read arrays of every maximum (the join of the events, the cells' saddles, their
    measures' totals, the cut, each block's share of the saddles and regions) run there
    and the hierarchy stays there; the labels are those of the cut in memory."""
    import dask.array as da
    from dask.utils import key_split

    from volseg._block_hooks import BlockHooks
    from volseg.morse import cut_of, descending_complex
    from volseg.segment import CutRequest

    field = smooth_random_field((24, 24, 24), np.random.default_rng(5), sigma=1.5)
    # A count past what the buckets' heads hold: the hierarchy is joined for it.
    cut = CutRequest.checked(n_regions=10**5 + 1, measure="hypervolume")
    with engine_module.Engine("local", workers=1, memory_limit="1GiB",
                              hierarchy_memory="700MiB") as engine:
        info = engine.client.scheduler_info()["workers"]
        big = {a for a, w in info.items()
               if w["resources"].get(engine_module.HIERARCHY_RESOURCE)}
        assert len(info) == 2 and len(big) == 1 and "0.7 GiB for the hierarchy" in \
            engine.describe()
        hooks = BlockHooks(compute=engine.compute, persist=engine.persist)
        lazy = descending_complex(da.from_array(field, chunks=8), on_workers=True,
                                  block_hooks=hooks)
        labels, report = cut_of(lazy, cut)      # warns on the worker: more than the maxima
        # Not there by chance: the scheduler was told to run them nowhere else, and
        # nothing else there (the blocks' sums, each reading a block, go anywhere).
        # (Asked before the labels: a later graph naming a finished task drops its
        # restriction.)
        restricted = engine.client.run_on_scheduler(lambda dask_scheduler: [
            (key_split(k), t.resource_restrictions)
            for k, t in dask_scheduler.tasks.items() if t.resource_restrictions])
        # (getitem: the cut's table taken from its result, for the gathers)
        assert {name for name, _ in restricted} == {"cell_saddles", "joined", "run",
                                                    "summed", "gather", "getitem"}, restricted
        assert all(r == {engine_module.HIERARCHY_RESOURCE: 1} for _, r in restricted)
        # The saddles' and the regions' share of each block, nothing else per block
        assert [name for name, _ in restricted].count("gather") == 2 * 3 ** 3
        labels = np.asarray(labels.compute())
        # The hierarchy stays there; the cut's result, once its table is gathered for
        # each block, is let go.
        held = {key_split(k): v for k, v in engine.client.who_has().items() if v}
        assert set(held["joined"]) == big and "run" not in held, held
    with pytest.warns(UserWarning, match="only"):           # more regions than maxima
        expected, expected_report = cut_of(descending_complex(field), cut)
    assert np.array_equal(labels, expected) and report.n_regions == expected_report.n_regions


@pytest.mark.slow
@pytest.mark.parametrize("measure", ["persistence", "hypervolume"])
def test_a_cut_on_a_cluster_joins_no_hierarchy(measure, monkeypatch):
    """The scheduler's accounting of every task result of a blockwise cut (by
    persistence, or by hypervolume pruned in a tree of 125 leaves), small components
    dropped, on two worker processes (issue 30): no task joins the events (`joined`), none
    holds a quarter of the maxima's and events' bytes (40 B each, as the buckets keep
    them), and the cut runs on none of them in particular (no restriction). The labels
    and the report are those of the cut in memory."""
    import dask.array as da
    from dask.utils import key_split
    from distributed.diagnostics.plugin import SchedulerPlugin

    from volseg._block_hooks import BlockHooks
    from volseg.morse import cut_of, descending_complex
    from volseg.morse.blocks import _bucket_prune
    from volseg.segment import CutRequest

    class Largest(SchedulerPlugin):
        def __init__(self):
            self.largest, self.names = {}, set()

        def transition(self, key, start, finish, *args, **kwargs):
            task = self.scheduler.tasks.get(key)
            self.names.add(key_split(key))
            if task is not None and task.nbytes > 0:
                name = key_split(key)
                self.largest[name] = max(self.largest.get(name, 0), task.nbytes)

    # A noisy field: its maxima's bytes well above a group's faces' (O(N^2)).
    field = smooth_random_field((40, 40, 40), np.random.default_rng(9), sigma=0.5)
    mask = field > np.quantile(field, 0.3)          # many components, the small ones dropped
    cut = CutRequest.checked(n_regions="auto", measure=measure, min_component=0.01)
    monkeypatch.setattr(_bucket_prune, "MIN_LEAF_EDGE", 8)
    with engine_module.Engine("local", workers=2, memory_limit="2GiB") as engine:
        largest = Largest()
        largest.scheduler = engine.client.cluster.scheduler     # in this process
        largest.scheduler.add_plugin(largest)
        hooks = BlockHooks(compute=engine.compute, persist=engine.persist)
        lazy = descending_complex(da.from_array(field, chunks=10), on_workers=True,
                                  mask=da.from_array(mask, chunks=10), block_hooks=hooks)
        labels, report = cut_of(lazy, cut)
        labels = np.asarray(labels.compute())
        restricted = engine.client.run_on_scheduler(lambda dask_scheduler: [
            key_split(k) for k, t in dask_scheduler.tasks.items() if t.resource_restrictions])
    sizes, names = largest.largest, largest.names
    assert lazy.n_maxima > 3000 and not restricted
    assert "joined" not in names and "bucket-morse-buckets" in names, names
    assert (measure == "hypervolume") == ("pruned_leaf-morse-prune" in names)
    whole = 40 * lazy.n_maxima
    sizes.pop("finalize-hlgfinalizecompute")      # this test's own gather of the labels
    assert max(sizes.values()) < whole / 4, sorted(sizes.items(), key=lambda i: -i[1])[:5]
    expected, expected_report = cut_of(descending_complex(field, mask=mask), cut)
    assert np.array_equal(labels, expected) and report.n_regions == expected_report.n_regions
    assert np.array_equal(report.top_maxima, expected_report.top_maxima)
    assert report.curve.n_components < report.n_components     # some were dropped


def test_the_engine_knows_its_threads_where_it_makes_them():
    # What sets the Morse stage's bucket count (`BlockHooks.threads`).
    Engine = engine_module.Engine
    assert Engine("threads", workers=3).threads == 3
    assert Engine("local", workers=2, threads_per_worker=2).threads == 4
    assert Engine("tcp://127.0.0.1:8786").threads is None      # a running cluster may grow


@pytest.mark.slow
def test_a_local_worker_of_two_threads_gives_the_labels_of_the_threads(tmp_path, volume):
    """``--threads-per-worker 2``: one worker process whose two threads run the blocks
    (each kernel on one numba thread); the same output as Dask's threads."""
    np.save(tmp_path / "vol.npy", volume)
    argv = ["segment", str(tmp_path / "vol.npy"), "--chunks", "8", "--mask", "none", "-q"]
    assert main([*argv, "-o", str(tmp_path / "threads"), "--scheduler", "threads"]) == 0
    assert main([*argv, "-o", str(tmp_path / "local"), "--scheduler", "local", "--workers", "1",
                 "--threads-per-worker", "2", "--memory-limit", "1GiB"]) == 0
    labels = [read_volume(tmp_path / run / "vol_labels.nii.gz").data
              for run in ("threads", "local")]
    assert labels[0].max() > 1 and np.array_equal(labels[0], labels[1])
    with engine_module.Engine("local", workers=1, threads_per_worker=2,
                              memory_limit="1GiB") as engine:
        (info,) = engine.client.scheduler_info()["workers"].values()
        assert info["nthreads"] == 2 and "1 workers of 2 threads" in engine.describe()


@pytest.mark.slow
def test_a_script_importing_volseg_gets_one_numba_thread_per_local_worker(tmp_path):
    """A script that imports volseg at its top imports numba in the spawned workers
    before their environment is set; numba must still take NUMBA_NUM_THREADS=1 (else
    it oversubscribes the cores, and a later compilation fails)."""
    import subprocess
    import sys
    import textwrap

    script = tmp_path / "user_script.py"
    script.write_text(textwrap.dedent("""
        import volseg.cli  # noqa: F401  (numba imported in every spawned worker)
        from volseg.blockwise.engine import Engine

        def threads():
            from numba.core import config
            return config.NUMBA_NUM_THREADS

        if __name__ == "__main__":
            with Engine("local", workers=1, memory_limit="1GiB") as engine:
                print(list(engine.client.run(threads).values()))
    """))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[1]", done.stdout
