"""A blockwise run's finished blocks, kept on disk so that a killed run resumes.

``WorkFolder(folder, key)`` is ``<out>/.<stem>.volseg-work`` (under the output set's
lock). `key` is every input of the run that changes a block's result (the input
files' checksum, operator, boundary, value scale, chunks, connectivity, volseg's
version); it is kept in ``key.json``, and a folder holding another key is emptied
before use, so a block is only ever reused by the run that would compute it again
bit for bit.

``wrap(stage, function)`` returns the per-block `function(*blocks, block_id=...)`
with its result (an array or a tuple of arrays) saved as
``<stage>/<i>_<j>_<k>.npz`` when computed, and loaded instead of computed when
present. A file appears by atomic rename once complete, so a run killed mid-write
leaves no block that looks finished, and it is fsynced first, so a power loss
leaves it whole or absent; a torn block found anyway (empty, truncated: its zip
CRCs disagree) is removed and computed again. The pipeline removes the folder once
its outputs are committed.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from .._atomic import NPY_READ_LOCK, write_atomically

__all__ = ["WorkFolder"]


class WorkFolder:
    def __init__(self, folder, key: dict):
        self.folder = Path(folder)
        self.key = json.loads(json.dumps(key))        # as stored: lists, not tuples
        stored = self.folder / "key.json"
        try:
            same = json.loads(stored.read_text()) == self.key
        except (OSError, ValueError):
            same = False
        if not same:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder.mkdir(parents=True)
            temporary = stored.with_suffix(".tmp")
            temporary.write_text(json.dumps(self.key, indent=1))
            os.replace(temporary, stored)
        self.resumed = same

    def finished(self, stage: str) -> int:
        """How many blocks of `stage` are on disk."""
        folder = self.folder / stage
        return sum(1 for p in folder.glob("*.npz")) if folder.is_dir() else 0

    def wrap(self, stage: str, function):
        folder = self.folder / stage
        folder.mkdir(exist_ok=True)
        return _Cached(str(folder), function)

    def array(self, stage: str, chunks, dtype):
        """A lazy Dask array of `stage`'s blocks as saved by `wrap` (each block an
        array), read back; a block that is not on disk is an error."""
        import dask.array as da

        return da.map_blocks(_Cached(str(self.folder / stage), _not_saved), chunks=chunks,
                             dtype=dtype, meta=np.empty((0,) * len(chunks), dtype))

    def remove(self):
        shutil.rmtree(self.folder, ignore_errors=True)


class _Cached:
    """A per-block function whose results are kept in a folder (picklable, for
    distributed workers: a path and the function)."""

    def __init__(self, folder: str, function):
        self.folder, self.function = folder, function

    def __call__(self, *blocks, block_id=None):
        path = os.path.join(self.folder, "_".join(map(str, block_id)) + ".npz")
        if os.path.exists(path):
            saved = _load(path)
            if saved is not None:
                return saved
        result = self.function(*blocks, block_id=block_id)
        items = ({"array": result} if isinstance(result, np.ndarray)
                 else {f"item{i}": np.asarray(r) for i, r in enumerate(result)})
        write_atomically(path, np.savez, durable=True, **items)
        return result


def _load(path):
    """A saved block, or None (the file removed) when it is torn: empty, truncated or
    not what `_Cached` writes (what a power loss or a full disk leaves). Its zip
    members carry CRCs, so a torn block is not read as data."""
    import zipfile

    try:
        # (closed on any error)
        with NPY_READ_LOCK, open(path, "rb") as file, np.load(file) as saved:
            if "array" in saved.files:
                return saved["array"]
            items = tuple(saved[f"item{i}"] for i in range(len(saved.files)))
            if not items:
                raise ValueError("no arrays")
            return items
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
        try:
            os.unlink(path)
        except OSError:
            pass
        return None


def _not_saved(*blocks, block_id=None):
    raise RuntimeError(f"block {block_id} was expected in the work folder but is not there")
