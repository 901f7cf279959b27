"""Atomic writers for pipeline outputs: a temporary file beside the target, then a
rename, so a killed run never leaves a half-written CSV, figure or text."""

from __future__ import annotations

import csv
import os
from contextlib import contextmanager
from pathlib import Path

from volseg.io import atomic_path


@contextmanager
def replacing(path):
    """Yield a temporary path beside `path`; rename it onto `path` if the block ends
    without an error, remove it otherwise."""
    path = Path(path)
    temporary = atomic_path(path)
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def write_csv(path, rows, first=()) -> Path:
    """Rows (dictionaries) as CSV; columns `first`, then every other key in order seen."""
    fields = list(first)
    for row in rows:
        fields += [k for k in row if k not in fields]
    with replacing(path) as temporary, open(temporary, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    return Path(path)


def save_figure(fig, path) -> Path:
    with replacing(path) as temporary:
        fig.savefig(temporary, format="png")
    return Path(path)


def write_text(path, text) -> Path:
    with replacing(path) as temporary:
        Path(temporary).write_text(text)
    return Path(path)
