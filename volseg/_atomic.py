"""Atomic file writes, a leaf shared by the io writers, the work folder and the
blockwise Morse build: a file appears by rename once complete, so a process killed
while writing leaves no partial file under the final name."""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
from pathlib import Path

__all__ = ["write_atomically", "temporary_beside", "file_identity", "remove_tree"]


def temporary_beside(path) -> Path:
    """A new temporary file beside `path` (same folder, so renaming it is atomic),
    readable like any file the user's umask allows (mkstemp makes 0600)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    return Path(tmp)


def file_identity(info: os.stat_result) -> tuple:
    """What tells a file from another at the same path, or from itself rewritten:
    device, inode, size and modification time (of ``os.stat(path)`` or of an open
    file's ``os.fstat``)."""
    return info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns


def write_atomically(path, save, *args, durable: bool = False, **kwargs) -> None:
    """``save(file, *args, **kwargs)`` into a temporary file beside `path`, then renamed
    to it. The temporary (``<path>.<pid>.<thread>.tmp``) matches no ``*.npys`` or
    ``*.npy`` count of finished blocks, so a leftover of a killed run never looks
    finished. `durable`: the file is fsynced before the rename (a power loss then
    leaves it whole or absent, not renamed and empty)."""
    temporary = f"{path}.{os.getpid()}.{threading.get_ident()}.tmp"
    try:
        with open(temporary, "wb") as file:
            save(file, *args, **kwargs)
            if durable:
                file.flush()
                os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException:
        try:
            os.unlink(temporary)
        except OSError:
            pass
        raise


#: `remove_tree` unlinks a tree's files in threads from this many files up.
_PARALLEL_FROM = 16


def remove_tree(path) -> None:
    """``shutil.rmtree(path, ignore_errors=True)``, its files unlinked by several
    threads first when there are many: what a blockwise run leaves (its work folder,
    moved into the committed set's staging folder) is thousands of block files of
    16-32 MB, and the kernel frees each one's pages as it is unlinked (`unlink`
    releases the GIL). 4 GB in 512 files: 0.35 s against 0.60 one by one, here (2
    cores); the commit of a 512^3 run waited 1.4 s for it, its last serial step. A
    link is removed, never followed (``os.walk`` lists a link to a folder among the
    folders and does not enter it; ``shutil.rmtree`` then removes it as a link); a
    link at `path` itself is left, as ``shutil.rmtree`` leaves it."""
    path = os.fspath(path)
    if not os.path.islink(path):
        files = [os.path.join(top, name)
                 for top, _, names in os.walk(path, followlinks=False) for name in names]
        if len(files) >= _PARALLEL_FROM:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(min(8, os.cpu_count() or 1)) as pool:
                list(pool.map(_unlink, files, chunksize=8))
    shutil.rmtree(path, ignore_errors=True)


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:                   # gone already, or not ours to remove: rmtree's call
        pass


#: CPython 3.11's AST constructor keeps one recursion depth per interpreter, so two
#: threads parsing at once can fail with "SystemError: AST constructor recursion depth
#: mismatch" (python/cpython#106905). numpy parses every .npy header with
#: `ast.literal_eval`, so the threaded engine's workers parse the headers of the
#: blocks they read back one at a time (the work folder's blocks: only the headers,
#: `blockwise._resume._read_array`; a path-ends file whole).
NPY_READ_LOCK = threading.Lock()
