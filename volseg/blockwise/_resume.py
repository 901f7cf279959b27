"""A blockwise run's finished blocks, kept on disk so that a killed run resumes.

``WorkFolder(folder, key)`` is ``<out>/.<stem>.volseg-work`` (under the output set's
lock). `key` is every input of the run that changes a block's result (the input
files' checksum, operator, boundary, value scale, chunks, connectivity, volseg's
version); it is kept in ``key.json``, and a folder holding another key is emptied
before use, so a block is only ever reused by the run that would compute it again
bit for bit.

``wrap(stage, function)`` returns the per-block `function(*blocks, block_id=...)`
with its result (an array or a tuple of arrays) saved as
``<stage>/<i>_<j>_<k>.npys`` when computed, and loaded instead of computed when
present: .npy arrays one after another (`_save`; ``np.load`` called again on the open
file reads the next), the digest first. A file appears by atomic rename once
complete, so a run killed mid-write leaves no block that looks finished, and it is
fsynced first, so a power loss leaves it whole or absent; a torn block found anyway
(empty, truncated, bytes after its last array) is removed and computed again, and so
is a block whose digest (the run's key, the stage, the block's index and its values)
is not its own. The digest of a file is checked once per process (`_CHECKED`: a file
with another inode, size or change time is checked again). A folder
holding a link anywhere is emptied, the link removed, never followed. The pipeline
removes the folder once its outputs are committed.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path

import numpy as np

from .._atomic import NPY_READ_LOCK, file_identity, remove_tree, write_atomically

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
            remove_tree(self.folder)                  # another run's blocks
            self.folder.mkdir(parents=True)
            temporary = stored.with_suffix(".tmp")
            temporary.write_text(json.dumps(self.key, indent=1))
            os.replace(temporary, stored)
        self.resumed = same
        self.digest = hashlib.sha256(json.dumps(self.key, sort_keys=True).encode()).hexdigest()

    def finished(self, stage: str) -> int:
        """How many blocks of `stage` are on disk."""
        folder = self.folder / stage
        return sum(1 for p in folder.glob("*" + SUFFIX)) if folder.is_dir() else 0

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
        remove_tree(self.folder)
        _forget(self.folder)


class _Cached:
    """A per-block function whose results are kept in a folder (picklable, for
    distributed workers: a path and the function)."""

    def __init__(self, folder: str, function, tag: str = ""):
        self.folder, self.function, self.tag = folder, function, tag

    def __call__(self, *blocks, block_id=None):
        name = "_".join(map(str, block_id))
        path = os.path.join(self.folder, name + SUFFIX)
        if os.path.lexists(path):
            saved = _load(path, f"{self.tag}/{name}")
            if saved is not None:
                return saved
        result = self.function(*blocks, block_id=block_id)
        single = isinstance(result, np.ndarray)
        arrays = [result] if single else [np.asarray(r) for r in result]
        digest = np.frombuffer(_digest(f"{self.tag}/{name}", _members(arrays, single)),
                               np.uint8)
        write_atomically(path, _save, digest, -1 if single else len(arrays), arrays,
                         durable=True)
        _CHECKED[path] = _identity(path, f"{self.tag}/{name}")
        return result


#: A saved block's file name ends so (`_save`).
SUFFIX = ".npys"


def _save(file, digest, count: int, arrays) -> None:
    """A block's file: `digest` (SHA-256 of the run's key, the stage, the block's index
    and its arrays: a block of another run, stage or place, or with other values, is
    computed again rather than reused), the `count` of arrays (-1: one array, not a
    tuple), the arrays; each as a .npy. Read back 5x faster than a zip of the same
    arrays (.npz: CRC-32 over every byte, and a copy) and written in 40 % of its CPU
    time, for a 128^3 block of 25 MB; the digest guards its contents."""
    for array in (digest, np.array([count], dtype=np.int64), *arrays):
        np.save(file, array, allow_pickle=False)


def _members(arrays, single: bool) -> dict:
    """A block's arrays by the names its digest covers: ``array`` for one array, else
    ``item0``, ``item1``, ... for a tuple's."""
    return {"array": arrays[0]} if single else {f"item{i}": a for i, a in enumerate(arrays)}


def _digest(tag: str, items: dict) -> bytes:
    digest = hashlib.sha256(tag.encode())
    for member in sorted(items):
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
    its digest not that of this run's block with these values."""
    try:
        if os.path.islink(path) or not os.path.isfile(path):
            raise ValueError("not a regular file")
        with open(path, "rb") as file:                   # (closed on any error)
            identity = _identity(file.fileno(), tag)    # of the file read, not the path's
            stored = _read_array(file)
            count = int(_read_array(file)[0])           # -1: one array, not a tuple
            arrays = [_read_array(file) for _ in range(1 if count == -1 else count)]
            if file.read(1):
                raise ValueError("bytes after the last array")
        members = _members(arrays, count == -1)
        if not members:
            raise ValueError("no arrays")
        if _CHECKED.get(path) != identity:
            if stored.tobytes() != _digest(tag, members):
                raise ValueError("digest")
            _CHECKED[path] = identity
        return arrays[0] if count == -1 else tuple(arrays)
    except (OSError, ValueError, EOFError, IndexError):
        _CHECKED.pop(path, None)
        try:
            os.unlink(path)
        except OSError:
            pass
        return None


def _read_array(file) -> np.ndarray:
    """The next .npy array of an open block file. Only its header is parsed under
    `NPY_READ_LOCK` (numpy parses it with `ast.literal_eval`); the bytes are read
    into the array at once, outside it. A short read (a truncated file) fails in the
    reshape; an object array cannot be read (``np.fromfile`` refuses it)."""
    fmt = np.lib.format
    with NPY_READ_LOCK:
        version = fmt.read_magic(file)
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f".npy version {version}")
        header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, fortran, dtype = header(file)
    array = np.fromfile(file, dtype=dtype, count=math.prod(shape))
    return array.reshape(shape[::-1]).T if fortran else array.reshape(shape)


def _not_saved(*blocks, block_id=None):
    raise RuntimeError(f"block {block_id} was expected in the work folder but is not there")
