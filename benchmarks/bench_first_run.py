"""The first run after an install against the second, side by side (issue 28): the
first compiles numba's kernels (and says so in one line), the second loads them.

    python benchmarks/bench_first_run.py [--rev HEAD] [--base REV] [--rounds 3]

It checks `--rev` (and `--base`, if given) out into temporary git worktrees, and in
each round runs ``volseg demo`` of each twice in fresh processes (the same built-in
volume, no network) with a numba cache of its own, empty at the first run: a clean
install's state. It prints the wall and CPU seconds of both runs, their difference
(the compilation), and whether the first run printed the compilation note and the
second did not; revisions alternate within a round, so a busy machine slows both.
`volseg._jit_cache.FIRST_RUN_NOTE` quotes these figures, rounded.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path

from _common import worktree  # benchmarks/ is the script's folder: first on sys.path

NOTE = "compiling the numba kernels"


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _run(tree: Path, out: Path, cache: Path) -> tuple[float, float, str]:
    """(wall s, CPU s, stderr) of one ``volseg demo`` from `tree` with numba's cache in
    `cache`."""
    env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": str(cache)}
    cpu, started = _children_cpu(), time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "volseg", "demo", "-o", str(out), "--force"],
                          cwd=out.parent, env=env, capture_output=True, text=True)
    seconds, cpu = time.perf_counter() - started, _children_cpu() - cpu
    if done.returncode:
        raise SystemExit(f"volseg demo failed ({done.returncode}): {done.stderr}")
    return seconds, cpu, done.stderr


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="HEAD")
    parser.add_argument("--base", help="another revision, run alternately with --rev")
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args()
    revs = [args.rev] + ([args.base] if args.base else [])
    with ExitStack() as stack:
        trees = {rev: stack.enter_context(worktree(rev)) for rev in revs}
        for round_ in range(args.rounds):
            for rev, tree in trees.items():
                with tempfile.TemporaryDirectory() as folder:
                    folder = Path(folder)
                    first = _run(tree, folder / "a", folder / "cache")
                    second = _run(tree, folder / "b", folder / "cache")
                print(f"round {round_ + 1} {rev}: first run {first[0]:.1f} s wall, "
                      f"{first[1]:.1f} CPU-s (note printed: {NOTE in first[2]}); second "
                      f"{second[0]:.1f} s, {second[1]:.1f} CPU-s (note printed: "
                      f"{NOTE in second[2]}); compilation about {first[0] - second[0]:.1f} s "
                      f"wall, {first[1] - second[1]:.1f} CPU-s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
