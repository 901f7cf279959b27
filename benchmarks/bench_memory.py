"""Peak memory of `volseg segment` in memory, stage by stage, against another revision.

    python benchmarks/bench_memory.py --base fdd814d                # 512^3
    python benchmarks/bench_memory.py --base fdd814d --size 256 --dtype float32
    python benchmarks/bench_memory.py --base fdd814d --field gradient

The volume is a smoothed random one (`bench_segment.py`'s), 8-bit by default or of
`--dtype` (a float volume is not smoothed again by default), written once as .npy and
segmented through the command line with its defaults (the automatic mask and smoothing,
every output; the curvature field unless `--field`) by the base revision (a temporary
git worktree) and by today's code, each in a fresh interpreter. A thread samples the
process's resident memory every millisecond; the stages are told apart by wrapping
`run_stages`' timer and the writer, which both revisions have. Reported: the peak of
each stage and of the whole run in bytes per voxel (the whole run's from the kernel's
``ru_maxrss``, the interpreter and its imports included), and whether both wrote the
same labels.
"""

import argparse
import tempfile
from pathlib import Path

import nibabel
import numpy as np
from _common import run_filled as run
from _common import worktree

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

VOLUME = """
import numpy as np
from scipy.ndimage import gaussian_filter
rng = np.random.default_rng(0)
v = gaussian_filter(255 * rng.random(({n}, {n}, {n}), dtype=np.float32), 1.5)
np.save({path!r}, (255 * (v - v.min()) / np.ptp(v)).astype({dtype!r}))
"""

SEGMENT = """
import sys; sys.path.insert(0, {tree!r})
import contextlib, json, resource, threading, time
import numpy as np
import volseg
assert volseg.__file__.startswith({tree!r}), volseg.__file__
import volseg.cli, volseg.files, volseg.segment

stage, peaks = ["before"], {{}}

def sample():
    with open("/proc/self/statm") as statm:
        while True:
            statm.seek(0)
            rss = int(statm.read().split()[1]) * 4096
            peaks[stage[0]] = max(peaks.get(stage[0], 0), rss)
            time.sleep(0.001)

threading.Thread(target=sample, daemon=True).start()
timer, writer = volseg.segment._timed, volseg.files._write_result

@contextlib.contextmanager
def timed(timings, name, storage=None):
    stage[0] = name
    with timer(timings, name, storage):
        yield

def write(*args, **kwargs):
    stage[0] = "write"
    return writer(*args, **kwargs)

volseg.segment._timed, volseg.files._write_result = timed, write
stage[0] = "read, mask"
volseg.cli.main(["segment", {path!r}, "-o", {out!r}, "-q", "--field", {field!r}])
time.sleep(0.01)
whole = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps(dict(stages=peaks, whole=whole)))
"""


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="git revision to compare against")
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--dtype", default="uint8", help="the volume's numpy type")
    p.add_argument("--field", default="curvature", help="the field segmented (--field)")
    args = p.parse_args()
    voxels = args.size**3
    with worktree(args.base) as base, tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "volume.npy")
        run(VOLUME, n=args.size, path=path, dtype=args.dtype)
        results = {}
        for name, tree in (("base", base), ("now", ROOT)):
            results[name] = run(SEGMENT, tree=str(tree), path=path, out=str(Path(tmp) / name),
                                field=args.field)
        same = all(
            np.array_equal(*(np.asarray(nibabel.load(Path(tmp) / side / f"volume_{kind}.nii.gz")
                                        .dataobj) for side in ("base", "now")))
            for kind in ("labels", args.field))
    print(f"volseg segment --field {args.field}, {args.size}^3 {args.dtype} .npy, "
          "bytes per voxel (resident):")
    print(f"    {'stage':12s} {'base':>7s} {'now':>7s}")
    for stage in results["now"]["stages"]:
        old = results["base"]["stages"].get(stage, float("nan")) / voxels
        print(f"    {stage:12s} {old:7.1f} {results['now']['stages'][stage] / voxels:7.1f}")
    old, new = (results[side]["whole"] / voxels for side in ("base", "now"))
    print(f"    {'whole run':12s} {old:7.1f} {new:7.1f}   ({old / new:.2f}x less); "
          f"labels and {args.field} the same: {same}")


if __name__ == "__main__":
    main()
