"""The two kernels against another revision and against the floor, side by side (issue 16).

    python benchmarks/bench_kernels.py --base 2118216       # the commit before the work
    python benchmarks/bench_kernels.py --base 2118216 --sizes 128 256 384 --morse 256 512
    python benchmarks/bench_kernels.py --base 0ff3c76 --sigma 1 --morse   # a rougher field

Grid curvature (weighted, Laplace-Beltrami) at each size: the base revision's kernel
(a temporary git worktree), today's, and the floor kernel (`_floor.py`, the weighted
operator's unavoidable arithmetic): voxels/s, today/base, and the fraction of the
floor's speed reached. Then bytes per voxel beyond the input at 256^3 for both
kernels (peak RSS of a fresh process that only loaded the input from .npy), and the
Morse build (on the weighted curvature of the same field) for the
base and today, with today's time per phase. Every figure comes from a fresh
interpreter after a warm-up call (numba compile and cache load are not timed); best
of --repeat; base and today alternate.
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import worktree

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

SETUP = """
import sys, json, time, resource
sys.path.insert(0, {tree!r}); sys.path.insert(0, {bench!r})
import numpy as np
from scipy.ndimage import gaussian_filter
import volseg
assert volseg.__file__.startswith({tree!r}), volseg.__file__
from volseg.curvature import grid_curvature
from volseg.morse import descending_complex
def field(n):
    f = gaussian_filter(np.random.default_rng(0).standard_normal((n, n, n)), {sigma})
    return np.round(255 * (f - f.min()) / np.ptp(f)).astype(np.uint8)
def best(run, repeat):
    t = float("inf")
    for _ in range(repeat):
        s = time.perf_counter(); run(); t = min(t, time.perf_counter() - s)
    return t
def rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
warm = np.random.default_rng(1).random((12, 12, 12))
"""

CURVATURE = SETUP + """
data = field({n})
grid_curvature(warm, {op!r})
print(json.dumps(dict(t=best(lambda: grid_curvature(data, {op!r}), {repeat}))))
"""

FLOOR = SETUP + """
from _floor import floor_kernel
fp = np.pad(field({n}).astype(np.float64), 1)
floor_kernel(warm, np.ones(3))
print(json.dumps(dict(t=best(lambda: floor_kernel(fp, np.ones(3)), {repeat}))))
"""

MEMORY = SETUP + """
data = np.load({path!r})  # made by the parent: nothing else has touched this process's peak
grid_curvature(warm, "weighted"); grid_curvature(warm, "laplace_beltrami"); descending_complex(warm)
before = rss()
if {what!r} == "morse":
    h = descending_complex(data)
else:
    c = grid_curvature(data, {what!r})
print(json.dumps(dict(extra=(rss() - before) / data.size)))
"""

INPUTS = SETUP + """
data = field({n})
np.save({volume!r}, data)
np.save({curvature!r}, grid_curvature(data, "weighted"))
print(json.dumps(dict()))
"""

MORSE = SETUP + """
data = field({n})
curvature = grid_curvature(data, "weighted")
descending_complex(warm)
t = best(lambda: descending_complex(curvature), {repeat})
out = dict(t=t, maxima=len(descending_complex(curvature).maxima))
if {phases}:

    out["phases"] = descending_complex(curvature).timings
print(json.dumps(out))
"""


def run(code, tree, **fields):
    text = code.format(tree=str(tree), bench=str(HERE), **fields)
    out = subprocess.run([sys.executable, "-c", text], capture_output=True, text=True,
                         cwd=tempfile.gettempdir())
    if out.returncode:
        raise SystemExit(f"{tree}: failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="git revision of the old kernels")
    p.add_argument("--sizes", nargs="+", type=int, default=[128, 256, 384])
    p.add_argument("--morse", nargs="*", type=int, default=[256, 512])
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--sigma", type=float, default=3.0,
                   help="the test field's smoothing in voxels (smaller: rougher, more "
                   "faces bent beyond the kernels' small-angle branch)")
    args = p.parse_args()
    with worktree(args.base) as base, tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            floor = run(FLOOR, ROOT, sigma=args.sigma, n=n, repeat=args.repeat)["t"]
            print(f"floor            {n}^3: {floor:7.3f} s ({n**3 / floor / 1e6:5.2f} M voxels/s)",
                  flush=True)
            for op in ["weighted", "laplace_beltrami"]:
                old = run(CURVATURE, base, sigma=args.sigma, n=n, op=op, repeat=args.repeat)["t"]
                new = run(CURVATURE, ROOT, sigma=args.sigma, n=n, op=op, repeat=args.repeat)["t"]
                print(f"{op:16s} {n}^3: base {old:7.3f} s, now {new:7.3f} s "
                      f"({n**3 / new / 1e6:5.2f} M voxels/s): {old / new:4.2f}x faster, "
                      f"{floor / new:4.0%} of the floor's speed", flush=True)
        volume, curvature = Path(tmp) / "volume.npy", Path(tmp) / "curvature.npy"
        run(INPUTS, ROOT, sigma=args.sigma, n=256, volume=str(volume), curvature=str(curvature))
        for what in ["weighted", "laplace_beltrami", "morse"]:
            path = str(curvature if what == "morse" else volume)
            old = run(MEMORY, base, sigma=args.sigma, what=what, path=path)["extra"]
            new = run(MEMORY, ROOT, sigma=args.sigma, what=what, path=path)["extra"]
            print(f"memory {what:16s} 256^3: base {old:5.1f}, now {new:5.1f} bytes/voxel "
                  "beyond the input", flush=True)
        for n in args.morse:
            old = run(MORSE, base, sigma=args.sigma, n=n, repeat=args.repeat, phases=False)
            new = run(MORSE, ROOT, sigma=args.sigma, n=n, repeat=args.repeat, phases=True)
            print(f"morse            {n}^3 ({new['maxima']} maxima): base {old['t']:7.3f} s, "
                  f"now {new['t']:7.3f} s: {old['t'] / new['t']:4.2f}x faster", flush=True)
            print("    phases now: " + ", ".join(f"{k} {v:.2f} s"
                                                 for k, v in new["phases"].items()), flush=True)


if __name__ == "__main__":
    main()
