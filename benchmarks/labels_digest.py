"""Are the labels unchanged? Digests of the labels of the five shared datasets, for
every cut measure of the curvature and the default cut of the gradient and value
fields, in memory and on a Dask array in uneven chunks, by this tree and
by the code of another commit, side by side.

    python benchmarks/labels_digest.py --base 0b646ad      # compare with that commit
    python benchmarks/labels_digest.py --out digest.json   # this tree's digests only

The other commit runs from a temporary git worktree, in a subprocess whose
``PYTHONPATH`` puts it first; both use this environment's packages.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "volvis"
#: Uneven chunks: every block boundary case of the blockwise path.
CHUNKS = (23, 17, 29)


def digests(data: Path) -> dict:
    """{dataset/measure/path: sha256 prefix and region count} of this interpreter's volseg."""
    import dask.array as da
    import numpy as np

    from volseg import read_volume, segment_volume
    from volseg.morse import MEASURES

    out = {}
    # The curvature by every measure; the other fields by their own defaults.
    cases = [("curvature", m) for m in MEASURES] + [("gradient", None), ("value", None)]
    for path in sorted(data.glob("*.raw")):
        volume = read_volume(path)
        for field, measure in cases:
            for where in ("memory", "dask"):
                given = (volume if where == "memory"
                         else da.from_array(np.asarray(volume.data), chunks=CHUNKS))
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result = segment_volume(given, measure=measure, spacing=volume.spacing,
                                            field=field)
                labels = np.ascontiguousarray(np.asarray(result.labels), dtype=np.int64)
                key = f"{path.name.split('_')[0]}/{field}/{measure or 'default'}/{where}"
                out[key] = (hashlib.sha256(labels.tobytes()).hexdigest()[:16]
                            + f" k={int(labels.max())}")
                print(key, out[key], file=sys.stderr, flush=True)
    return out


def _of_commit(rev: str, data: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), rev],
                       check=True, capture_output=True)
        try:
            env = {**os.environ, "PYTHONPATH": str(tree)}
            run = subprocess.run([sys.executable, __file__, "--data", str(data)], env=env,
                                 cwd=tmp, check=True, capture_output=True, text=True)
            return json.loads(run.stdout)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                           check=False, capture_output=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="a commit to compare with")
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--out", type=Path, help="write this tree's digests here")
    args = parser.parse_args(argv)
    mine = digests(args.data)
    if args.out:
        args.out.write_text(json.dumps(mine, indent=1))
    if args.base is None:
        print(json.dumps(mine))
        return 0
    base = _of_commit(args.base, args.data)
    differ = sorted(k for k in base if base[k] != mine.get(k))
    print(f"{len(base)} cases; {len(differ)} differ from {args.base}"
          + (": " + ", ".join(differ) if differ else ""))
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
