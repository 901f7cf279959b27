"""Today's kernels against another revision's, side by side in one run.

    python benchmarks/bench_versus.py --base 92e0004            # a commit, tag or branch
    python benchmarks/bench_versus.py --base 92e0004 --sizes 128 256 --repeat 3

The base revision is checked out into a temporary git worktree (removed afterwards)
and imported from there; the current tree is imported from this checkout. Each
measurement runs in a fresh interpreter with that tree first on sys.path, after a
warm-up call (numba compile and cache load are not timed), and the two trees
alternate so that drift of the machine hits both. Same inputs (a smooth random
8-bit field), best of `--repeat`. Prints seconds, voxels/s and new/old ratios.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import worktree

HERE = Path(__file__).resolve().parents[1]

CODE = """
import sys, json, time
sys.path.insert(0, {tree!r})
import numpy as np
from scipy.ndimage import gaussian_filter
import volseg
assert volseg.__file__.startswith({tree!r}), volseg.__file__
from volseg.curvature import grid_curvature
from volseg.morse import descending_complex
n = {n}
f = gaussian_filter(np.random.default_rng(0).standard_normal((n, n, n)), 3)
data = np.round(255 * (f - f.min()) / np.ptp(f)).astype(np.uint8)
warm = np.random.default_rng(1).random((12, 12, 12))
if {what!r} == "morse":
    field = grid_curvature(data, "weighted")
    run = lambda: descending_complex(field)
    descending_complex(warm)
else:
    run = lambda: grid_curvature(data, {what!r})
    grid_curvature(warm, {what!r})
best = float("inf")
for _ in range({repeat}):
    start = time.perf_counter(); result = run(); best = min(best, time.perf_counter() - start)
print(json.dumps(dict(t=best)))
"""


def measure(tree, what, n, repeat):
    out = subprocess.run([sys.executable, "-c", CODE.format(tree=str(tree), what=what, n=n,
                                                            repeat=repeat)],
                         capture_output=True, text=True, cwd=tempfile.gettempdir())
    if out.returncode:
        raise SystemExit(f"{tree}: {what} {n}^3 failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])["t"]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="git revision to compare against")
    p.add_argument("--sizes", nargs="+", type=int, default=[128, 256])
    p.add_argument("--what", nargs="+", default=["weighted", "laplace_beltrami", "morse"])
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    with worktree(args.base) as base:
        for what in args.what:
            for n in args.sizes:
                old = measure(base, what, n, args.repeat)
                new = measure(HERE, what, n, args.repeat)
                print(f"{what:17s} {n}^3: base {old:7.3f} s, now {new:7.3f} s "
                      f"({n**3 / new / 1e6:5.2f} M voxels/s); now/base = {new / old:.2f}",
                      flush=True)


if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", str(os.cpu_count()))
    main()
