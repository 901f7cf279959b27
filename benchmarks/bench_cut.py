"""The default cut (hypervolume pruning) against another revision, side by side.

    python benchmarks/bench_cut.py --base 7eb96cb                 # 256^3 and 512^3
    python benchmarks/bench_cut.py --base 7eb96cb --sizes 512 --blockwise   # 256^3 chunks

The field is the pipeline's: the weighted curvature (as float32) of `bench_kernels.py`'s
gaussian-filtered noise quantized to 8 bits, computed once and saved; each revision
then loads it in a fresh interpreter, builds the hierarchy (not timed; with
--blockwise, of the field as a Dask array of 256^3 chunks, threads, its cells persisted
as the pipeline stores them), and times the two parts of the first hypervolume cut:
the cells' measures (`cell_measures`) and the pruning to the end (`_pruning`), best of
--repeat, one revision after the other. Memory is each part's own: the peak resident
size above the one before it, sampled every 5 ms with psutil (the build's peak,
higher, is not the cut's). Both revisions must give the same extinctions (to 1e-9,
on all but 0.1 % of the events: a revision before the fixed-point pruning summed
floats): the script checks it and fails otherwise. The last figure of each line, the
cut's microseconds per maximum (measures and pruning), is the size-scaling curve:
`--sigma` moves the maxima per voxel (2: 0.013, 3: 0.023 on this field).
"""

import argparse
import tempfile
from pathlib import Path

from _common import worktree
from bench_kernels import ROOT, SETUP, run

INPUT = SETUP + """
np.save({path!r}, grid_curvature(field({n}), "weighted").astype(np.float32))
print(json.dumps(dict()))
"""

CUT = SETUP + """
import threading
import psutil
from volseg.morse import _measures
field = np.load({path!r})
if {blockwise}:
    import dask, dask.array as da
    dask.config.set(scheduler="threads")
    field = da.from_array(field, chunks=256)
descending_complex(warm).segment(n_regions=3, measure="hypervolume")
h = descending_complex(field)
if {blockwise}:   # the cells computed once, as the pipeline stores them
    import dataclasses
    h = dataclasses.replace(h, cells=h.cells.persist())
process = psutil.Process()
peak = [0]
def sample(stop):
    while not stop.is_set():
        peak[0] = max(peak[0], process.memory_info().rss); time.sleep(0.005)
def measured(run):  # (seconds, MB of peak resident size above the start, result)
    before = peak[0] = process.memory_info().rss
    stop = threading.Event(); thread = threading.Thread(target=sample, args=(stop,)); thread.start()
    start = time.perf_counter(); result = run(); seconds = time.perf_counter() - start
    stop.set(); thread.join()
    return seconds, (peak[0] - before) / 2**20, result
def pruned(base):  # the hierarchy's own pruning to the end, given the cells' measures
    return h.with_cell_measures(dict(hypervolume=base))._pruning("hypervolume")[1]
out = dict(measures=float("inf"), prune=float("inf"), measures_mb=0.0, prune_mb=0.0)
for _ in range({repeat}):
    seconds, mb, base = measured(lambda: _measures.cell_measures(h, "hypervolume"))
    out["measures"] = min(out["measures"], seconds)
    out["measures_mb"] = max(out["measures_mb"], mb)
    seconds, mb, extinction = measured(lambda: pruned(base))
    out["prune"] = min(out["prune"], seconds)
    out["prune_mb"] = max(out["prune_mb"], mb)
    del base
np.save({out!r}, extinction)
print(json.dumps(dict(out, maxima=len(h.maxima))))
"""


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="git revision of the previous cut")
    p.add_argument("--sizes", nargs="+", type=int, default=[256, 512])
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--blockwise", action="store_true", help="the hierarchy of a Dask field")
    p.add_argument("--sigma", type=float, default=3.0, help="the noise's smoothing")
    args = p.parse_args()
    with worktree(args.base) as base, tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            path = str(Path(tmp) / f"curvature{n}.npy")
            run(INPUT, ROOT, sigma=args.sigma, n=n, path=path)
            got = {}
            for name, tree in (("base", base), ("now", ROOT)):
                out = str(Path(tmp) / f"extinction_{name}.npy")
                got[name] = run(CUT, tree, sigma=args.sigma, path=path, out=out, repeat=args.repeat,
                                blockwise=args.blockwise)
                got[name]["extinction"] = out
            import numpy as np

            a, b = np.load(got["base"]["extinction"]), np.load(got["now"]["extinction"])
            same = np.array_equal(a, b)
            # Since the pruning adds fixed-point integers (issue 30) a revision before
            # it differs where float sums rounded: a few events, by about 1e-16.
            off = np.abs(a - b) > 1e-9 * np.maximum(np.abs(a), np.abs(b))
            old, new = got["base"], got["now"]
            print(f"{n}^3 ({new['maxima']} maxima){' blockwise' if args.blockwise else ''}: "
                  f"measures base {old['measures']:.2f} s, now {new['measures']:.2f} s "
                  f"({old['measures'] / new['measures']:.2f}x); prune base {old['prune']:.2f} s, "
                  f"now {new['prune']:.2f} s ({old['prune'] / new['prune']:.2f}x); peak memory "
                  f"above the hierarchy: measures base {old['measures_mb']:.0f} MB, now "
                  f"{new['measures_mb']:.0f} MB; prune base {old['prune_mb']:.0f} MB, now "
                  f"{new['prune_mb']:.0f} MB; same extinctions: {same} (beyond 1e-9: "
                  f"{int(off.sum())} of {len(a)}); now "
                  f"{1e6 * (new['measures'] + new['prune']) / new['maxima']:.2f} us per maximum",
                  flush=True)
            if off.mean() > 1e-3:
                raise SystemExit("the revisions' extinctions differ")


if __name__ == "__main__":
    main()
