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
CRCs disagree) is removed and computed again, and so is a block whose digest (the
run's key, the stage, the block's index and its values) is not its own. The digest of
a file is checked once per process (`_CHECKED`: a file with another inode, size or
change time is checked again). A folder
holding a link anywhere is emptied, the link removed, never followed. The pipeline
removes the folder once its outputs are committed.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np

from .._atomic import NPY_READ_LOCK, file_identity, write_atomically

__all__ = ["WorkFolder"]


class WorkFolder:
    def __init__(self, folder, key: dict):
        self.folder = Path(folder)
        self.key = json.loads(json.dumps(key))        # as stored: lists, not tuples
        stored = self.folder / "key.json"
        try:
            same = _only_own_entries(self.folder) and json.loads(stored.read_text()) == self.key
        except (OSError, ValueError):
            same = False
        if not same:
            if self.folder.is_symlink():              # a link is removed, never followed
                self.folder.unlink()
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder.mkdir(parents=True)
            temporary = stored.with_suffix(".tmp")
            temporary.write_text(json.dumps(self.key, indent=1))
            os.replace(temporary, stored)
        self.resumed = same
        self.digest = hashlib.sha256(json.dumps(self.key, sort_keys=True).encode()).hexdigest()

    def finished(self, stage: str) -> int:
        """How many blocks of `stage` are on disk."""
        folder = self.folder / stage
        return sum(1 for p in folder.glob("*.npz")) if folder.is_dir() else 0

    def wrap(self, stage: str, function):
        folder = self.folder / stage
        folder.mkdir(exist_ok=True)
        return _Cached(str(folder), function, f"{self.digest}/{stage}")

    def array(self, stage: str, chunks, dtype):
        """A lazy Dask array of `stage`'s blocks as saved by `wrap` (each block an
        array), read back; a block that is not on disk is an error."""
        import dask.array as da

        return da.map_blocks(_Cached(str(self.folder / stage), _not_saved,
                                     f"{self.digest}/{stage}"), chunks=chunks,
                             dtype=dtype, meta=np.empty((0,) * len(chunks), dtype))

    def remove(self):
        shutil.rmtree(self.folder, ignore_errors=True)
        _forget(self.folder)


class _Cached:
    """A per-block function whose results are kept in a folder (picklable, for
    distributed workers: a path and the function)."""

    def __init__(self, folder: str, function, tag: str = ""):
        self.folder, self.function, self.tag = folder, function, tag

    def __call__(self, *blocks, block_id=None):
        name = "_".join(map(str, block_id))
        path = os.path.join(self.folder, name + ".npz")
        if os.path.lexists(path):
            saved = _load(path, f"{self.tag}/{name}")
            if saved is not None:
                return saved
        result = self.function(*blocks, block_id=block_id)
        items = ({"array": result} if isinstance(result, np.ndarray)
                 else {f"item{i}": np.asarray(r) for i, r in enumerate(result)})
        items[DIGEST] = np.frombuffer(_digest(f"{self.tag}/{name}", items), np.uint8)
        write_atomically(path, np.savez, durable=True, **items)
        _CHECKED[path] = _identity(path, f"{self.tag}/{name}")
        return result


#: The member of a saved block holding its digest: SHA-256 of the run's key, the stage,
#: the block's index and its arrays, so a block of another run, stage or place, or with
#: other values, is computed again rather than reused.
DIGEST = "_digest"


def _digest(tag: str, items: dict) -> bytes:
    digest = hashlib.sha256(tag.encode())
    for member in sorted(k for k in items if k != DIGEST):
        array = np.ascontiguousarray(items[member])
        digest.update(f"{member}:{array.dtype.str}:{array.shape}".encode())
        digest.update(array.reshape(-1).view(np.uint8))     # its bytes, not a copy
    return digest.digest()


#: The saved blocks whose digest this process wrote or checked: path -> `_identity`.
#: A block is read several times in a run (each pass over a stage, and each neighbour's
#: halo), and SHA-256 over every read was 2-8 % of a 512^3 run's CPU time. A file
#: that is not the one checked (replaced, rewritten: another inode, size or change
#: time) is checked again; only a writer racing this process, rewriting a block in
#: place to the same size within one tick of the file system's clock, would not be.
_CHECKED: dict = {}


def _identity(file, tag: str) -> tuple:
    """What tells a saved block's file from any other at its path: the tag it was
    saved for, its `file_identity` and its change time (`file`: a path or an open
    file's descriptor)."""
    info = os.stat(file)
    return tag, *file_identity(info), info.st_ctime_ns


def _forget(folder: Path) -> None:
    """Drop the checked blocks under `folder` (a work folder removed)."""
    inside = os.path.join(str(folder), "")
    for path in [p for p in _CHECKED if p.startswith(inside)]:
        _CHECKED.pop(path, None)


def _only_own_entries(folder: Path) -> bool:
    """True when `folder` is a real folder whose entries are all real files and folders
    (no link: a planted one would make the run write where it points)."""
    if folder.is_symlink() or not folder.is_dir():
        return False
    for root, folders, files in os.walk(folder, followlinks=False):
        for entry in (*folders, *files):
            path = os.path.join(root, entry)
            if os.path.islink(path) or not (os.path.isdir(path) or os.path.isfile(path)):
                return False
    return True


def _load(path, tag: str = ""):
    """A saved block, or None (the file removed) when it is torn: empty, truncated or
    not what `_Cached` writes (what a power loss or a full disk leaves), a link, or
    its digest not that of this run's block with these values. Its zip members carry
    CRCs, so a torn block is not read as data."""
    import zipfile

    try:
        if os.path.islink(path) or not os.path.isfile(path):
            raise ValueError("not a regular file")
        # (closed on any error)
        with NPY_READ_LOCK, open(path, "rb") as file, np.load(file) as saved:
            identity = _identity(file.fileno(), tag)    # of the file read, not the path's
            members = {k: saved[k] for k in saved.files}
        stored = members.pop(DIGEST, None)
        if stored is None:
            raise ValueError("no digest")
        if _CHECKED.get(path) != identity:
            if stored.tobytes() != _digest(tag, members):
                raise ValueError("digest")
            _CHECKED[path] = identity
        if "array" in members:
            return members["array"]
        items = tuple(members[f"item{i}"] for i in range(len(members)))
        if not items:
            raise ValueError("no arrays")
        return items
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
        _CHECKED.pop(path, None)
        try:
            os.unlink(path)
        except OSError:
            pass
        return None


def _not_saved(*blocks, block_id=None):
    raise RuntimeError(f"block {block_id} was expected in the work folder but is not there")
