"""The in-memory Morse build against another revision, alternating, phase by phase.

    python benchmarks/bench_morse_build.py --base 728641a             # 256^3, 5 rounds
    python benchmarks/bench_morse_build.py --base 728641a --size 128 --rounds 9
    python benchmarks/bench_morse_build.py --base 728641a --field smooth

The field is `bench_kernels.py`'s: the weighted curvature of an 8-bit smoothed random
volume (389,020 maxima at 256^3), or with `--field smooth` that smoothed volume itself
before quantizing (11,599 maxima at 256^3: few large cells, like TTK's anchor field and
a gradient's basins), made once and read from .npy by both sides. Each round runs the
base revision (a temporary git worktree) and today's code in two fresh interpreters,
one after the other (which goes first alternates from round to round), each timing two
builds after a warm-up (compiled kernels load from numba's cache; nothing is compiled
in the timed calls). The machine is shared and its speed drifts by 30 % within
minutes, so only the rounds' paired ratios and the medians of wall and CPU time are
reported, never one run's time.
"""

import argparse
import statistics
import tempfile
from pathlib import Path

from _common import run_filled as run
from _common import worktree

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

FIELD = """
import sys; sys.path.insert(0, {tree!r})
import numpy as np
from scipy.ndimage import gaussian_filter
from volseg.curvature import grid_curvature
f = gaussian_filter(np.random.default_rng(0).standard_normal(({n}, {n}, {n})), 3.0)
if {smooth}:
    np.save({path!r}, f)
else:
    f = np.round(255 * (f - f.min()) / np.ptp(f)).astype(np.uint8)
    np.save({path!r}, grid_curvature(f, "weighted"))
"""

BUILD = """
import sys; sys.path.insert(0, {tree!r})
import json, time
import numpy as np
import volseg
assert volseg.__file__.startswith({tree!r}), volseg.__file__
from volseg.morse import descending_complex
field = np.load({path!r})
descending_complex(np.random.default_rng(1).random((9, 10, 11))).segment(n_regions=2)
runs = []
for _ in range(2):
    wall, cpu = time.perf_counter(), time.process_time()
    h = descending_complex(field)
    runs.append(dict(wall=time.perf_counter() - wall, cpu=time.process_time() - cpu,
                     phases=h.timings, maxima=len(h.maxima), events=len(h.young)))
print(json.dumps(min(runs, key=lambda r: r["wall"])))
"""


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="git revision to compare against")
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--field", choices=("curvature", "smooth"), default="curvature")
    args = p.parse_args()
    with worktree(args.base) as base, tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "field.npy")
        run(FIELD, tree=str(ROOT), n=args.size, path=path, smooth=args.field == "smooth")
        old, new = [], []
        for k in range(args.rounds):
            # Which side runs first alternates: a run right after another (or after a
            # pause) can be systematically faster or slower.
            pair = [(old, str(base)), (new, str(ROOT))]
            for results, tree in pair[::-1] if k % 2 else pair:
                results.append(run(BUILD, tree=tree, path=path))
            assert (old[-1]["maxima"], old[-1]["events"]) == (new[-1]["maxima"], new[-1]["events"])
            print(f"round {k + 1}: base {old[-1]['wall']:.2f} s ({old[-1]['cpu']:.2f} CPU-s), "
                  f"now {new[-1]['wall']:.2f} s ({new[-1]['cpu']:.2f} CPU-s): "
                  f"{old[-1]['wall'] / new[-1]['wall']:.2f}x", flush=True)
    ratios = [o["wall"] / n["wall"] for o, n in zip(old, new, strict=True)]
    cpu = [o["cpu"] / n["cpu"] for o, n in zip(old, new, strict=True)]
    med = statistics.median
    print(f"{args.size}^3, {new[0]['maxima']} maxima: now / base wall {med(ratios):.2f}x "
          f"faster (rounds {min(ratios):.2f}-{max(ratios):.2f}), CPU {med(cpu):.2f}x; "
          f"medians base {statistics.median(o['wall'] for o in old):.2f} s, "
          f"now {statistics.median(n['wall'] for n in new):.2f} s")
    for name in new[0]["phases"]:
        b = [o["phases"].get(name, float("nan")) for o in old]
        n = [r["phases"][name] for r in new]
        print(f"    {name:45s} base {med(b):6.3f} s, now {med(n):6.3f} s")


if __name__ == "__main__":
    main()
