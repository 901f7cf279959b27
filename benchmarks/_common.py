"""Helpers for the side-by-side benchmarks (run by hand, not by CI)."""

import contextlib
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def timed(function, *args, repeat=1, **kwargs):
    """(best wall seconds over `repeat` runs, last result)."""
    best, result = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function(*args, **kwargs)
        best = min(best, time.perf_counter() - start)
    return best, result


def in_fresh_process(code: str) -> dict:
    """Run `code` (which prints one JSON object) in a new interpreter; peak memory is its own."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_filled(code: str, **fields):
    """Run `code` with `fields` filled in (``str.format``) in a new interpreter, from the
    temporary folder; the JSON object on its last line of output, or None."""
    out = subprocess.run([sys.executable, "-c", code.format(**fields)], capture_output=True,
                         text=True, cwd=tempfile.gettempdir())
    if out.returncode:
        raise SystemExit(f"failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1]) if out.stdout.strip() else None


@contextlib.contextmanager
def worktree(revision):
    """A temporary git worktree of `revision` of this repository (removed afterwards)."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "base"
        subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", "-q", str(path),
                        revision], check=True)
        try:
            yield path
        finally:
            subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(path)],
                           check=False)
