"""Blockwise vs in-memory `volseg segment`, end to end, side by side (issue 14).

    python benchmarks/bench_blockwise.py --sizes 256 512 [--chunks 128] [--workers 1 2]
                                         [--schedulers threads local]
                                         [--skip-in-memory-above 512] [--folder /tmp/bw]
                                         [--smooth SIGMA] [--repeat R] [--base REV]
                                         [--memory-limit BYTES] [--hierarchy-memory BYTES]
                                         [--threads-per-worker N] [--blocks EDGE]
                                         [--measure persistence] [--field gradient]

For each size N it writes a synthetic smooth uint8 field of N^3 voxels straight to a
Zarr store, block by block (the field is a sum of sinusoids of the global
coordinates, so no full array is ever built), then runs, each in its own process:

- ``volseg segment field.npy --mask none`` (in memory; the .npy is written block by
  block through a memory map) when N <= --skip-in-memory-above;
- ``volseg segment field.zarr`` (blockwise), once per --schedulers x --workers value
  (``--scheduler threads``: Dask's threaded scheduler; ``local``: a local
  dask.distributed cluster of that many worker processes).

It prints wall time, the peak memory of the whole process tree (RSS summed over the
process and its children, sampled every 0.1 s with psutil), of the client process
alone (with ``local``, the workers are its children) and of its largest child (with
``local``, the busiest worker), the maxima and region
counts, and whether the blockwise labels equal the in-memory ones. ``--smooth``
passes ``--smooth SIGMA`` to every run (the 8-bit staircase of a slowly varying
field makes a maximum of the curvature every 15 voxels or so at 1024^3); ``--field``
and ``--measure`` pass theirs.

``--repeat R`` runs every case R times, interleaved (all cases once, then again), and
reports each run and the fastest of each case: on a shared machine the same run can
take 25 % longer ten minutes later, so a ratio of single runs made minutes apart
measures the machine as much as the code.

Before anything is timed, each tree segments a small volume the same way
(`warm_up`), so that the timed runs load numba's kernels instead of compiling them.

``--base REV`` also runs every case with another revision's volseg (a temporary git
worktree first on the children's PYTHONPATH, run from the bench folder so the
checkout's own volseg/ is not imported), interleaved with today's, and prints
today/base per case: the same-run comparison of a refactoring or a speed change.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def smooth_block(block_info, n):
    """The synthetic field on one block, from global coordinates."""
    (x0, x1), (y0, y1), (z0, z1) = block_info[None]["array-location"]
    x, y, z = np.meshgrid(np.arange(x0, x1), np.arange(y0, y1), np.arange(z0, z1), indexing="ij",
                          sparse=True)
    k = 2 * np.pi / n
    f = (np.sin(3.1 * k * x + 0.3) * np.cos(2.3 * k * y) + np.sin(4.7 * k * z + 1.1 * k * x)
         + 0.6 * np.sin(7.3 * k * (x + y) + 2.0) * np.cos(5.9 * k * z)
         + 0.4 * np.cos(11.0 * k * (y - z)))
    return np.round(127.5 + 127.5 * f / 3.0).clip(0, 255).astype(np.uint8)


def write_inputs(folder: Path, n: int, chunks: int, npy: bool):
    import dask.array as da

    from volseg.io import write_zarr

    axis = (chunks,) * (n // chunks) + ((n % chunks,) if n % chunks else ())
    lazy = da.map_blocks(lambda block_info=None: smooth_block(block_info, n), dtype=np.uint8,
                         chunks=(axis,) * 3)
    # Written under a temporary name and renamed: an interrupted benchmark leaves no
    # partial input that the next one would take as ready.
    zarr_path = folder / f"field{n}.zarr"
    if not zarr_path.exists():
        shutil.rmtree(folder / f"field{n}.tmp.zarr", ignore_errors=True)
        write_zarr(folder / f"field{n}.tmp.zarr", lazy)
        os.replace(folder / f"field{n}.tmp.zarr", zarr_path)
    npy_path = folder / f"field{n}.npy"
    if npy and not npy_path.exists():
        temporary = folder / f"field{n}.tmp.npy"
        out = np.lib.format.open_memmap(temporary, mode="w+", dtype=np.uint8, shape=(n, n, n))
        da.store(lazy, out, lock=False)
        out.flush()
        del out
        os.replace(temporary, npy_path)
    return zarr_path, npy_path


def run(argv, env=None, cwd=None) -> dict:
    """Wall time, the peak RSS of the process tree of `argv`, of its own process alone
    (the client, with ``--scheduler local``: the workers are its children) and of the
    largest of its children (with ``local``, the busiest worker)."""
    import psutil

    # The child's output goes to files: a pipe nobody reads while polling would stall
    # the child once it filled.
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.perf_counter()
        process = psutil.Popen(argv, env={**os.environ, **(env or {})}, stdout=out, stderr=err,
                               text=True, cwd=cwd)
        peak = client = worker = 0
        while process.poll() is None:
            try:
                own = process.memory_info().rss
                sizes = [p.memory_info().rss for p in process.children(recursive=True)
                         if p.is_running()]
                client = max(client, own)
                peak = max(peak, own + sum(sizes))
                worker = max(worker, *sizes, 0)
            except psutil.Error:
                pass
            time.sleep(0.1)
        seconds = time.perf_counter() - start
        out.seek(0), err.seek(0)
        if process.returncode:
            raise RuntimeError(f"{' '.join(argv)} failed: {err.read().strip()[-500:]}")
        return {"seconds": seconds, "peak_gb": peak / 2**30, "client_gb": client / 2**30,
                "worker_gb": worker / 2**30, "stdout": out.read()}


def labels_of(folder: Path, stem: str):
    import nibabel
    import zarr

    zarr_path = folder / f"{stem}_labels.zarr"
    if zarr_path.exists():
        return zarr.open(str(zarr_path), mode="r")
    return nibabel.load(folder / f"{stem}_labels.nii.gz").dataobj


def print_stages(blockwise: dict) -> None:
    """A cluster run's stages: seconds, bytes its workers sent (to each other and to
    the client) and bytes the client received; then the Morse phases."""
    stages = blockwise.get("cluster_stages") or []
    if stages:
        print("  | stage | s | workers sent MB | client received MB | client peak so far GB |")
        print("  | --- | --- | --- | --- | --- |")
        for s in stages:
            sent = s["workers_sent_bytes"]
            sent = "?" if sent is None else f"{sent / 1e6:.1f}"
            print(f"  | {s['stage']} | {s['seconds']:.1f} | {sent} "
                  f"| {s['client_received_bytes'] / 1e6:.1f} "
                  f"| {s.get('client_peak_bytes', 0) / 2**30:.2f} |")
    for phase, seconds in (blockwise.get("morse_phases_s") or {}).items():
        print(f"  Morse phase {phase}: {seconds:.1f} s")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    parser.add_argument("--chunks", type=int, default=128)
    parser.add_argument("--workers", type=int, nargs="+", default=[2])
    parser.add_argument("--schedulers", nargs="+", default=["threads"])
    parser.add_argument("--skip-in-memory-above", type=int, default=512)
    parser.add_argument("--folder", default="/tmp/volseg-bench-blockwise")
    parser.add_argument("--smooth", type=float, default=0.0,
                        help="volseg segment --smooth SIGMA for every run (default 0: none)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs of every case, interleaved; the fastest is reported")
    parser.add_argument("--base", help="also run every case with this git revision's volseg")
    parser.add_argument("--measure", help="volseg segment --measure for every run (default: "
                        "volseg's; persistence: the cut in buckets, no hierarchy joined)")
    parser.add_argument("--field", help="volseg segment --field for every run (default: "
                        "volseg's, the curvature)")
    parser.add_argument("--memory-limit",
                        help="volseg segment --memory-limit for the blockwise runs (with "
                             "local: shared by its workers)")
    parser.add_argument("--blocks", type=int,
                        help="volseg segment --chunks: the blockwise runs' block edge "
                             "(default: the store's chunks, --chunks)")
    parser.add_argument("--threads-per-worker", type=int, default=1,
                        help="volseg segment --threads-per-worker for the local blockwise "
                             "runs (default 1)")
    parser.add_argument("--hierarchy-memory",
                        help="volseg segment --hierarchy-memory for the local blockwise runs "
                             "(one more worker, the one that holds the whole hierarchy)")
    args = parser.parse_args(argv)
    if args.base:
        from _common import worktree

        with worktree(args.base) as base:
            return _main(args, {"now": None, "base": str(base)})
    return _main(args, {"now": None})


#: Edge of the volume (in blocks of a third of it) that `warm_up` segments.
WARM_UP_SIZE = 96


def warm_up(folder: Path, trees: dict, volseg: list, in_memory: bool) -> None:
    """Each tree's kernels compiled before anything is timed: a tree's first run
    compiles numba's kernels into that tree's cache (the base's worktree starts
    empty), 16-18 s of a 512^3 blockwise run of 82-100 s here, so a single run of the
    base against a warm today measured the compilation as much as the code. A small
    volume of the same type is segmented blockwise (and in memory, when a case runs
    there) by each tree with the same options, untimed."""
    start = time.perf_counter()
    zarr_path, npy_path = write_inputs(folder, WARM_UP_SIZE, WARM_UP_SIZE // 3, in_memory)
    for tree, path in trees.items():
        env = {"PYTHONPATH": path} if path else None
        out = folder / f"warm_up_{tree}"
        run([*volseg, str(zarr_path), "--scheduler", "threads", "-o", str(out)], env=env,
            cwd=str(folder))
        if in_memory:
            run([*volseg, str(npy_path), "--mask", "none", "-o", str(out)], env=env,
                cwd=str(folder))
        shutil.rmtree(out, ignore_errors=True)
    print(f"kernels compiled or loaded in each tree in {time.perf_counter() - start:.1f} s",
          flush=True)


def _main(args, trees) -> int:
    folder = Path(args.folder)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    volseg = [sys.executable, "-m", "volseg", "segment", "--regions", "30", "-q", "--force",
              "--json", "--smooth", str(args.smooth),
              *(["--measure", args.measure] if args.measure else []),
              *(["--field", args.field] if args.field else [])]
    warm_up(folder, trees, volseg, any(n <= args.skip_in_memory_above for n in args.sizes))
    for n in args.sizes:
        in_memory = n <= args.skip_in_memory_above
        start = time.perf_counter()
        zarr_path, npy_path = write_inputs(folder, n, args.chunks, in_memory)
        print(f"{n}^3: inputs ready in {time.perf_counter() - start:.1f} s", flush=True)
        tag = (f"_s{args.smooth:g}" if args.smooth else "") + (f"_{args.field}" if args.field
                                                                 else "")
        plain = [("in memory", "-", folder / f"mem{n}{tag}",
                  [str(npy_path), "--mask", "none"])] if in_memory else []
        threads = args.threads_per_worker
        each = {s: ("" if s != "local" or threads == 1 else f"x{threads}")
                for s in args.schedulers}
        blocks = args.blocks or args.chunks
        size = "" if blocks == args.chunks else f"_b{blocks}"
        plain += [(f"blockwise {blocks}^3 {scheduler}{each[scheduler]}", workers,
                   folder / f"blk{n}_{scheduler}_{workers}{each[scheduler]}{size}{tag}",
                   [str(zarr_path), "--scheduler", scheduler, "--workers", str(workers),
                    *(["--chunks", str(blocks)] if size else []),
                    *(["--memory-limit", args.memory_limit] if args.memory_limit else []),
                    *(["--threads-per-worker", str(threads)] if each[scheduler] else []),
                    *(["--hierarchy-memory", args.hierarchy_memory]
                      if args.hierarchy_memory and scheduler == "local" else [])])
                  for scheduler in args.schedulers for workers in args.workers]
        cases = [(path if tree == "now" else f"{path} [base]", workers,
                  out.with_name(out.name + ("" if tree == "now" else "_base")), arguments, tree)
                 for path, workers, out, arguments in plain for tree in trees]
        best, reference = {}, None
        for repeat in range(args.repeat):
            for path, workers, out, arguments, tree in cases:
                env = {"PYTHONPATH": trees[tree]} if trees[tree] else None
                result = run([*volseg, *arguments, "-o", str(out)], env=env, cwd=str(folder))
                summary = json.loads(result["stdout"])
                if path == "in memory" and tree == "now":
                    reference = np.asarray(labels_of(out, f"field{n}")[...])
                    same = None
                else:
                    same = None if reference is None else bool(np.array_equal(
                        np.asarray(labels_of(out, f"field{n}")[...]), reference))
                row = {"size": n, "path": path, "workers": workers, **result,
                       "regions": summary["n_regions"], "maxima": summary["n_maxima"],
                       "same_labels": same, "runs": [],
                       "phases": summary.get("blockwise", {}).get("morse_phases_s")}
                key = (path, workers)
                if key in best:     # the fastest run's row; every run's time, peak and labels
                    old = best[key]
                    row["runs"] = old["runs"]
                    row["peak_gb"] = max(old["peak_gb"], row["peak_gb"])
                    row["client_gb"] = max(old["client_gb"], row["client_gb"])
                    row["worker_gb"] = max(old["worker_gb"], row["worker_gb"])
                    row["same_labels"] = None if same is None else same and old["same_labels"]
                    if old["seconds"] <= row["seconds"]:
                        row = {**old, **{k: row[k] for k in ("peak_gb", "client_gb",
                                                             "worker_gb", "same_labels")}}
                row["runs"] = [*row["runs"], round(result["seconds"], 1)]
                best[key] = row
                print(f"{n}^3 {path}, workers {workers}, run {repeat + 1}: "
                      f"{result['seconds']:.1f} s, peak {result['peak_gb']:.2f} GB "
                      f"(client {result['client_gb']:.2f} GB, largest child "
                      f"{result['worker_gb']:.2f} GB), "
                      f"same labels as in memory: {same}", flush=True)
                print_stages(summary.get("blockwise", {}))
        rows += best.values()
        by_workers = {w: r["seconds"] for (p, w), r in best.items()
                      if p.startswith("blockwise") and not p.endswith("[base]")}
        if len(by_workers) > 1:
            least = min(by_workers)
            for w in sorted(by_workers):
                if w != least:
                    print(f"{n}^3: {w} workers are {by_workers[least] / by_workers[w]:.2f}x "
                          f"{least} (fastest runs)", flush=True)
    fastest = {(r["size"], r["path"], r["workers"]): r["seconds"] for r in rows}
    for (size, path, workers), seconds in fastest.items():
        base = fastest.get((size, f"{path} [base]", workers))
        if base:
            print(f"{size}^3 {path}, workers {workers}: now/base = {seconds / base:.2f} "
                  f"({seconds:.1f} s / {base:.1f} s, fastest runs)", flush=True)
    smoothed = (f", smooth {args.smooth:g}" if args.smooth else "") + (
        f", {args.field}" if args.field else "")
    print("\n| size | path | workers | wall s (fastest; every run) | peak GB (all processes) "
          "| client GB | largest child GB | maxima | regions | same labels |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        same = "" if r["same_labels"] is None else r["same_labels"]
        print(f"| {r['size']}^3{smoothed} | {r['path']} | {r['workers']} | {r['seconds']:.1f} "
              f"({', '.join(map(str, r['runs']))}) | {r['peak_gb']:.2f} "
              f"| {r['client_gb']:.2f} | {r['worker_gb']:.2f} | {r['maxima']} "
              f"| {r['regions']} | {same} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
