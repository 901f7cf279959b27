"""volseg's Morse segmentation against TTK's, on the same fields, alternating.

    python benchmarks/bench_ttk.py --ttk /path/to/ttk_descending             # 128^3, 256^3
    python benchmarks/bench_ttk.py --ttk ./ttk_descending --sizes 256 --rounds 5 --threads 2

TTK's driver is built from `../shared/anchors/ttk/` (its README: TTK's C++ base layer,
then `build_driver.sh`). The fields are the anchor's (`make_field.py`: a Gaussian-
smoothed random float64 volume, sigma 3). Each round runs TTK's descending
segmentation and its persistence pipeline cut to 30 maxima (persistence diagram by
FTM, topological simplification, path compression again), then volseg's
`descending_complex` and ``segment(n_regions=30, measure="persistence")`` in a fresh
interpreter after a warm-up (nothing compiled in the timed call), both with `--threads`
threads. Reported: the fastest round of each (the machine is shared), their ratio,
and how far the results agree: maxima, the voxels in the same descending cell and in
the same region of the cut (each TTK region matched to the volseg label most of its
voxels carry).
"""

import argparse
import os
import re
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from _common import run_filled

FIELD = """
import numpy as np
from scipy.ndimage import gaussian_filter
f = gaussian_filter(np.random.default_rng(0).random(({n}, {n}, {n})), 3)
f.astype(np.float64).tofile({path!r})
"""

VOLSEG = """
import json, time
import numpy as np
from volseg.morse import descending_complex
field = np.fromfile({path!r}, dtype=np.float64).reshape(({n}, {n}, {n}))
descending_complex(np.random.default_rng(1).random((9, 10, 11))).segment(n_regions=2)
start = time.perf_counter()
h = descending_complex(field)
labels = h.segment(n_regions=30, measure="persistence")
seconds = time.perf_counter() - start
np.asarray(h.cells, dtype=np.int32).tofile({out!r} + "_cells.i32")
np.asarray(labels, dtype=np.int32).tofile({out!r} + "_cut.i32")
print(json.dumps(dict(seconds=seconds, maxima=len(h.maxima))))
"""


def ttk(binary, path, n, threads, out):
    """TTK's timings (desc: the descending segmentation; cut: the persistence pipeline
    to 30 maxima, grid set-up and preconditioning included), from its printout."""
    text = subprocess.run([binary, path, str(n), str(n), str(n), str(threads), "30", "1",
                           "ftm", out], capture_output=True, text=True, check=True).stdout
    number = {key: float(value) for key, value in re.findall(r"(\w+) (-?[\d.]+)", text)}
    return {"desc": number["total_desc_s"], "cut": number["total_simplified_s"],
            "maxima": int(number["maxima_desc_only"] or number["maxima_asc_desc"])}


def agreement(one, other) -> float:
    """The share of voxels whose label in `other` is the one most of their `one`
    region carries (1.0: the same partition up to renumbering, where `one` is finer or
    equal)."""
    pairs = np.unique(np.stack([one, other]), axis=1, return_counts=True)
    (a, _), counts = pairs
    best = {}
    for region, count in zip(a, counts, strict=True):
        best[region] = max(best.get(region, 0), count)
    return sum(best.values()) / len(one)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ttk", required=True, help="the anchor's ttk_descending binary")
    p.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args()
    os.environ.update(NUMBA_NUM_THREADS=str(args.threads), OMP_NUM_THREADS=str(args.threads))
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            path, ours, theirs = (str(Path(tmp) / f"{name}{n}") for name in
                                  ("field", "volseg", "ttk"))
            run_filled(FIELD, n=n, path=path)
            runs = []
            for _ in range(args.rounds):
                runs.append((ttk(args.ttk, path, n, args.threads, theirs),
                             run_filled(VOLSEG, n=n, path=path, out=ours)))
            best_ttk = {key: min(r[0][key] for r in runs) for key in ("desc", "cut")}
            best_volseg = min(r[1]["seconds"] for r in runs)

            def read(name):
                return np.fromfile(name, dtype=np.int32)

            # TTK's labels are in numpy's flat order already (the driver writes them so).
            cells = agreement(read(theirs + "_desc.i32"), read(ours + "_cells.i32"))
            cut = agreement(read(theirs + "_desc30.i32"), read(ours + "_cut.i32"))
            print(f"{n}^3, {args.threads} thread(s), best of {args.rounds}: volseg build + cut "
                  f"{best_volseg:.2f} s; TTK descending {best_ttk['desc']:.2f} s, "
                  f"persistence cut to 30 {best_ttk['cut']:.2f} s: "
                  f"{best_ttk['cut'] / best_volseg:.1f}x; maxima {runs[0][1]['maxima']} "
                  f"(TTK {runs[0][0]['maxima']}); same cell {cells:.4%}, "
                  f"same region of the cut {cut:.4%}", flush=True)


if __name__ == "__main__":
    main()
