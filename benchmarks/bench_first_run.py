"""The first run after an install against the second, side by side (issue 28): the
first compiles numba's kernels (and says so in one line), the second loads them.

    python benchmarks/bench_first_run.py [--rev HEAD]

It checks `--rev` out into a temporary git worktree (no __pycache__: a clean
install's state), runs ``volseg demo`` there twice in fresh processes (the same
built-in volume, no network), and prints both wall times, their difference (the
compilation) and whether the first run printed the compilation note and the second
did not. `volseg._jit_cache.FIRST_RUN_SECONDS` is this difference, rounded.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import worktree  # benchmarks/ is the script's folder: first on sys.path


def _run(tree: Path, out: Path) -> tuple[float, str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    env.pop("NUMBA_CACHE_DIR", None)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "volseg", "demo", "-o", str(out), "--force"],
                          cwd=out.parent, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if done.returncode:
        raise SystemExit(f"volseg demo failed ({done.returncode}): {done.stderr}")
    return seconds, done.stderr


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="HEAD")
    args = parser.parse_args()
    with worktree(args.rev) as tree, tempfile.TemporaryDirectory() as folder:
        first, said_first = _run(tree, Path(folder) / "a")
        second, said_second = _run(tree, Path(folder) / "b")
    note = "compiling the numba kernels"
    print(f"first run {first:.1f} s (note printed: {note in said_first}), second run "
          f"{second:.1f} s (note printed: {note in said_second}); compilation about "
          f"{first - second:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
