"""SIGKILL at random moments, then rerun: every output folder must hold exactly one
complete set, and the rerun's labels must equal an uninterrupted run's (issue 27).

Runs of three kinds, in turn: in memory (a raw file), blockwise (``--chunks``) and a
Zarr store, each half the time with ``--force`` over an older set of another cut
(``--regions 7``). Each run is killed after a random share (0.05 - 1.3) of a clean
run's time; the folder is then checked (one complete set: the old, the new, or none
for a first run), a rerun with ``--force`` must succeed, and its labels must equal
the uninterrupted run's.

    python benchmarks/kill_runs.py [--runs 200] [--seed 0]

Prints one line per kind and the totals.
"""

import argparse
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

KINDS = ("memory", "blockwise", "zarr")


def _volume(folder: Path):
    from volseg.io import write_zarr

    rng = np.random.default_rng(1)
    axis = np.linspace(-1, 1, 48)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    field = sum(np.exp(-((x - a) ** 2 + (y - b) ** 2 + z**2) / 0.08)
                for a, b in rng.uniform(-0.6, 0.6, (6, 2)))
    data = np.clip(np.round(200 * field / field.max() + rng.normal(0, 3, field.shape)),
                   0, 255).astype(np.uint8)
    raw = folder / "v_48x48x48_uint8.raw"
    raw.write_bytes(np.ascontiguousarray(data.transpose(2, 1, 0)).tobytes())
    write_zarr(folder / "v.zarr", data, chunks=(16, 16, 16))
    return raw, folder / "v.zarr"


def _argv(kind, raw, store, out, *extra):
    source = store if kind == "zarr" else raw
    argv = [sys.executable, "-m", "volseg", "segment", str(source), "-o", str(out), "-q",
            *extra]
    return argv + (["--chunks", "16"] if kind == "blockwise" else [])


def _labels(out: Path):
    import nibabel
    import zarr

    for path in sorted(out.glob("v_labels.*")):
        if path.name.endswith(".zarr"):
            return np.asarray(zarr.open(str(path), mode="r"))
        return np.asanyarray(nibabel.load(path).dataobj)
    return None


def _state(out: Path):
    """'none', 'old', 'new' (by the summary's region count), or what is wrong."""
    visible = sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) \
        if out.exists() else []
    if not visible:
        return "none"
    summary = out / "v_summary.json"
    if not summary.exists():
        return f"mixed: {visible}"
    info = json.loads(summary.read_text())
    names = sorted(Path(p).name for p in info["outputs"].values())
    if names != visible:
        return f"mixed: {visible} vs {names}"
    return {7: "old", 30: "new"}.get(info["n_regions"], f"odd: {info['n_regions']}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        raw, store = _volume(tmp)
        reference, duration = {}, {}
        for kind in KINDS:                          # uninterrupted runs (and warm caches)
            out = tmp / f"ref-{kind}"
            subprocess.run(_argv(kind, raw, store, out), check=True)
            started = time.perf_counter()          # a second, warm run is the one timed
            subprocess.run(_argv(kind, raw, store, out, "--force"), check=True)
            duration[kind] = time.perf_counter() - started
            reference[kind] = _labels(out)
        tally = {kind: {} for kind in KINDS}
        failures = []
        for run in range(args.runs):
            kind = KINDS[run % len(KINDS)]
            force = bool(run // len(KINDS) % 2)
            out = tmp / f"run{run}"
            if force:                                  # an older set of another cut
                subprocess.run(_argv(kind, raw, store, out, "--regions", "7"), check=True)
            process = subprocess.Popen(_argv(kind, raw, store, out, *(["--force"] if force
                                                                      else [])),
                                       stderr=subprocess.DEVNULL)
            time.sleep(float(rng.uniform(0.05, 1.3)) * duration[kind])
            process.send_signal(signal.SIGKILL)
            process.wait()
            rerun_probe = subprocess.run(_argv(kind, raw, store, out, "--regions", "30"),
                                         capture_output=True, text=True)
            # The probe (no --force) finishes any interrupted commit, then refuses to
            # overwrite a complete set (exit 2) or writes the first one (exit 0).
            state = _state(out)
            ok = (state in ("old", "new") if force else state in ("none", "new"))
            ok = ok and rerun_probe.returncode in (0, 2)
            again = subprocess.run(_argv(kind, raw, store, out, "--force"),
                                   capture_output=True, text=True)
            hidden = [p.name for p in out.iterdir() if p.name.startswith(".")]
            equal = again.returncode == 0 and np.array_equal(_labels(out), reference[kind])
            key = f"{state}{' after a probe that wrote' if rerun_probe.returncode == 0 else ''}"
            tally[kind][key] = tally[kind].get(key, 0) + 1
            if not (ok and equal and not hidden):
                failures.append((run, kind, force, state, rerun_probe.returncode,
                                 rerun_probe.stderr.strip()[-200:], again.returncode,
                                 again.stderr.strip()[-400:], hidden))
            shutil.rmtree(out, ignore_errors=True)
        for kind in KINDS:
            print(f"{kind}: {sum(tally[kind].values())} kills, clean run {duration[kind]:.1f} s;"
                  f" states found: {tally[kind]}")
        print(f"{args.runs} kills, {len(failures)} failures")
        for failure in failures:
            print("  FAIL", failure)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
