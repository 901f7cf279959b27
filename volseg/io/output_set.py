"""Writing the files of one result (labels, curvature, summary, preview) as one set.

Guarantees, for a folder and a stem (``fuel`` -> ``fuel_labels.nii.gz``, ...):

- **one writer at a time**: an OS lock (``flock`` on POSIX, ``msvcrt.locking`` on
  Windows) on ``.<stem>.volseg-lock``
  in the folder, taken before anything is computed; a second process fails at once
  (or waits, with ``wait=True``). The lock file is removed on release;
- **checked up front**: existing outputs are refused unless ``force``, and a target
  that is not a regular file (a folder, a link to a device) is refused even with it;
- **all or nothing**: every file is written into a hidden staging folder; a
  ``COMMIT`` journal is written atomically; then old files are moved aside and new
  ones moved into place. A failure during that rolls back to the complete old set;
  a process killed during it (a window of a few renames) leaves the journal, and
  the next writer of that stem rolls the new set forward. A staging folder without
  a journal (killed while computing or writing) is simply removed by the next one;
- **what a reader can rely on**: the summary (the set's index) is moved aside first
  and placed last, after every other file is placed and everything stale of an older
  run is gone. A summary present with no journal beside it indexes a complete set of
  its run; a reader that finds no journal, reads, then finds the same summary file
  and still no journal read one run's set (`read_set`; the napari reader does).
"""

from __future__ import annotations

import errno
import json
import os
import re
import stat
import tempfile
import time
from pathlib import Path

from .._atomic import file_identity, remove_tree
from ..errors import OutputError  # noqa: F401 (re-exported)

__all__ = ["OutputSet", "OutputError", "FolderLock", "recover", "committing", "read_set"]

_STAGING = ".volseg-staging-"
_JOURNAL = "COMMIT"


class FolderLock:
    """An advisory lock (``flock``) on ``<folder>/.<name>.volseg-lock``, per name.

    Taken at once or refused with `OutputError` (unless ``wait``); the lock file is
    removed on release. A process that opened the file just as its holder removed it
    notices (the path no longer names its file) and takes the new one, so two
    processes never both hold it.
    """

    def __init__(self, folder, name: str, *, wait: bool = False, busy: str = "it is in use"):
        self.folder = Path(folder)
        self.path = self.folder / f".{name}.volseg-lock"
        self.wait = wait
        self.busy = busy
        self._fd = None

    @property
    def held(self) -> bool:
        """Whether this process holds the lock."""
        return self._fd is not None

    def __enter__(self) -> FolderLock:
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()

    def acquire(self):
        """Take the lock, waiting if `wait`, else an `OutputError` when it is held."""
        while self._fd is None:
            try:      # never through a planted link, never anything but a regular file
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            except OSError as err:
                if err.errno == errno.ELOOP:
                    raise OutputError(f"{self.path}: is a symbolic link, not volseg's lock "
                                      "file; remove it") from None
                raise OutputError(f"{self.folder}: cannot create a lock file there "
                                  f"({err.strerror})") from None
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                os.close(fd)
                raise OutputError(f"{self.path}: is not a regular file, not volseg's lock "
                                  "file; remove it")
            try:
                _lock_file(fd, self.wait)
            except OSError as err:
                os.close(fd)
                if err.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES,
                                     errno.EDEADLK):
                    raise
                raise OutputError(f"{self.folder}: {self.busy}; wait for it to finish, "
                                  "or use --wait") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.lstat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
            else:
                os.close(fd)

    def release(self):
        """Let the lock go and remove its file (only the one this process holds)."""
        if self._fd is not None:
            try:          # only the file this process holds (not one planted since)
                if os.path.samestat(os.fstat(self._fd), os.lstat(self.path)):
                    self.path.unlink()
            except FileNotFoundError:
                pass
            os.close(self._fd)
            self._fd = None


def _lock_file(fd: int, wait: bool) -> None:
    """Lock the open file `fd` for this process, waiting or not; OSError when another
    holds it. POSIX ``flock``, else Windows' ``msvcrt.locking`` of its first byte;
    imported here, so that `volseg.io` imports on every platform."""
    try:
        import fcntl
    except ImportError:                                    # Windows
        import msvcrt
        import time

        while True:
            try:
                msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
                return
            except OSError:
                if not wait:
                    raise
                time.sleep(0.05)
    fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))


def _staging_prefix(stem: str) -> str:
    return f"{_STAGING}{stem}-"


#: What `tempfile.mkdtemp` appends: 8 characters of this alphabet.
_STAGING_SUFFIX = re.compile(r"[a-z0-9_]{8}")


def _stagings(folder: Path, stem: str) -> list[Path]:
    """The staging folders of exactly `stem` (``scan``'s, not ``scan-2``'s)."""
    prefix = _staging_prefix(stem)
    return sorted(p for p in folder.iterdir() if p.name.startswith(prefix)
                  and _STAGING_SUFFIX.fullmatch(p.name[len(prefix):]))


def _journal(staging: Path, stem: str) -> dict | None:
    """The commit journal of a staging folder, checked: ``{"names": [...], "discard":
    [...]}`` (an older journal is the list of names), every entry a plain name of this
    stem's outputs (``<stem>_...``) or of its work folder (``.<stem>.volseg-work``).
    None without a journal; an `OutputError` naming it when it is anything else."""
    path = staging / _JOURNAL
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    problem = None if stat.S_ISREG(mode) else "is not a regular file"
    entry = None
    if problem is None:
        try:
            entry = json.loads(path.read_bytes()[:1 << 20])
        except (ValueError, UnicodeDecodeError):
            problem = "is not JSON"
    if problem is None:
        entry = {"names": entry, "discard": []} if isinstance(entry, list) else entry
        if (not isinstance(entry, dict) or set(entry) != {"names", "discard"}
                or not all(isinstance(v, list) for v in entry.values())):
            problem = "does not list the set's names"
        else:
            allowed = (all(_plain(n) and n.startswith(f"{stem}_") for n in entry["names"])
                       and all(n == f".{stem}.volseg-work" for n in entry["discard"]))
            problem = None if allowed else "names files that are not this set's"
    if problem is not None:
        raise OutputError(f"{path}: {problem}: not a commit journal volseg wrote. Check "
                          f"{staging.name}/new and /old (files of an interrupted commit), "
                          f"move what you need, then remove {staging}")
    return entry


def _plain(name) -> bool:
    """A file name with no path in it."""
    return (isinstance(name, str) and name not in ("", ".", "..") and "/" not in name
            and "\0" not in name)


def _real_dir(path: Path) -> bool:
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode)
    except FileNotFoundError:
        return False


def _remove(path: Path):
    """Remove a file, a link or a folder (never what a link points to)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        remove_tree(path)
    else:
        path.unlink(missing_ok=True)


def _place(new: Path, target: Path, aside: Path):
    """Move `new` onto `target`, the old `target` first moved to `aside` (a folder
    cannot be replaced in one rename)."""
    if os.path.lexists(target):
        if os.path.lexists(aside):
            _remove(aside)
        os.replace(target, aside)
    os.replace(new, target)


def recover(folder, stem: str) -> list[str]:
    """Finish or discard what killed writers of `stem` left in `folder`.

    Call it only while holding the stem's lock (`OutputSet` does). A staging folder
    with a journal is rolled forward: its new files and folders moved into place (the
    old ones aside, then removed) and what the journal discards (the set's work
    folder) removed; one without is removed. Returns what was done, one line per
    staging folder. A staging that is a link, or a journal volseg did not write, is
    refused with an `OutputError` naming it (nothing is moved).
    """
    folder = Path(folder)
    done = []
    for staging in _stagings(folder, stem):
        if not _real_dir(staging):
            raise OutputError(f"{staging}: is not a folder volseg made (a link?); remove it")
        journal = _journal(staging, stem)
        if journal is not None:
            old = staging / "old"
            if not _real_dir(old):
                os.mkdir(old)
            for name in journal["discard"]:       # first: nothing stale beside the index
                _remove(folder / name)
            for name in journal["names"]:         # in order: the index last
                new = staging / "new" / name
                if os.path.lexists(new):
                    _place(new, folder / name, old / name)
            done.append(f"{staging.name}: completed an interrupted commit of "
                        f"{len(journal['names'])} files")
        else:
            done.append(f"{staging.name}: removed the staging of an interrupted run")
        remove_tree(staging)
    return done


def committing(folder, stem: str) -> bool:
    """Whether a commit of `stem`'s set is under way in `folder`, or was interrupted (a
    staging folder with a journal: the next writer of the stem finishes it)."""
    try:
        return any(os.path.lexists(s / _JOURNAL) for s in _stagings(Path(folder), stem))
    except OSError:
        return False


def _identity(path: Path):
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    return file_identity(info)


def read_set(index, stem: str, read, *, tries: int = 40, pause: float = 0.05):
    """``read()`` of the set indexed by `index` (its summary) as one run wrote it.

    A commit moves the index aside first and places it last, under a journal: a read
    that starts with no journal and ends with the same index file and still no
    journal saw no commit, so every file it read is of the index's run. Otherwise it
    is read again (a commit is a few renames); `OutputError` when the set stays in a
    commit (an interrupted one: the next volseg run of the stem finishes it). An
    error of `read` while the set changed is retried; on a set that did not, raised.
    """
    index = Path(index)
    for _ in range(tries):
        before = None if committing(index.parent, stem) else _identity(index)
        if before is not None:
            try:
                value = read()
            except (OSError, ValueError):
                if _identity(index) == before and not committing(index.parent, stem):
                    raise
            else:
                if _identity(index) == before and not committing(index.parent, stem):
                    return value
        time.sleep(pause)
    raise OutputError(f"{index}: its set is being written (a commit of {stem}_* under way, "
                      "or interrupted: the next volseg run of that name finishes it); open "
                      "it again in a moment")


class OutputSet:
    """The output files of one stem in one folder, locked, checked and written as one.

    Parameters
    ----------
    folder : str or Path
        Must exist.
    stem : str
        The common name part; the lock and staging folders are per stem.
    names : dict of str -> str
        Kind -> file name (``{"labels": "fuel_labels.nii.gz", ...}``).
    force : bool
        Replace an existing set.
    wait : bool
        Wait for another writer of the same stem instead of failing at once.
    owns : iterable of str
        Every other file name a set of this stem can have (other options' outputs): an
        existing one is refused like a target without `force`, and removed with the
        commit, so no file of an older run stays beside the new set.
    last : str or None
        The kind that indexes the set (the summary): moved aside first and placed
        last, after every other file is placed and everything stale is gone. A
        reader's rule: `read_set` (or: no commit journal, then read, then the same
        index file and still no journal).

    Examples
    --------
    >>> with OutputSet(folder, "fuel", {"summary": "fuel_summary.json"}) as out:  # doctest: +SKIP
    ...     out.commit(lambda paths: paths["summary"].write_text("{}"))
    """

    def __init__(self, folder, stem: str, names: dict, *, force: bool = False, wait: bool = False,
                 owns=(), last: str | None = "summary"):
        self.folder = Path(folder)
        self.stem = stem
        self.last = last
        self.targets = {kind: self.folder / name for kind, name in names.items()}
        self.owned = [self.folder / name for name in sorted(set(owns) - set(names.values()))]
        self.force = force
        self.wait = wait
        self.recovered: list[str] = []
        #: Paths in the folder removed with the commit (the blockwise run's work
        #: folder): in the journal, so a commit finished by `recover` removes them too.
        self.discard: list[Path] = []
        self._lock = FolderLock(self.folder, stem, wait=wait,
                                busy=f"another volseg process is writing {stem}_* there")

    # ------------------------------------------------------------ lock

    def __enter__(self) -> OutputSet:
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()

    def acquire(self):
        """Take the lock, finish or remove stale staging, check the targets."""
        self._lock.acquire()
        try:
            self.recovered = recover(self.folder, self.stem)
            self.check()
        except BaseException:
            self._lock.release()
            raise

    def release(self):
        """Release the lock; first remove again every staging of this stem without a
        journal. Under the lock they are this process's: a commit that failed or was
        interrupted (a worker thread still writing a block can recreate files in it
        after the commit removed it; by now the engine has stopped its threads), or
        one interrupted between creating its folder and owning it."""
        try:
            for staging in _stagings(self.folder, self.stem) if self._lock.held else ():
                if _real_dir(staging) and not os.path.lexists(staging / _JOURNAL):
                    remove_tree(staging)
        except OSError:     # the folder gone or unreadable: nothing of ours to remove
            pass
        finally:
            self._lock.release()

    def check(self):
        """Refuse targets that exist (without `force`) or are not regular files (a
        ``.zarr`` target is a folder: a folder is accepted there, nothing else)."""
        existing = []
        for path in [*self.targets.values(), *self.owned]:
            try:
                mode = os.lstat(path).st_mode
            except FileNotFoundError:
                continue
            folder_ok = path.name.endswith(".zarr") and stat.S_ISDIR(mode)
            if not stat.S_ISREG(mode) and not folder_ok:
                raise OutputError(f"{path}: exists and is not a regular file; "
                                  "move it away (volseg replaces only files it wrote)")
            existing.append(path)
        if existing and not self.force:
            raise OutputError(f"{existing[0]} exists (and {len(existing) - 1} more outputs); "
                              "use --force to overwrite")

    # ------------------------------------------------------------ commit

    def commit(self, write) -> dict:
        """Write the set: ``write(paths)`` fills ``paths[kind]`` (staging files), then
        they replace the targets together. Returns kind -> final path."""
        if not self._lock.held:
            raise RuntimeError("OutputSet.commit needs the lock: use it in a `with` block")
        staging = Path(tempfile.mkdtemp(prefix=_staging_prefix(self.stem), dir=self.folder))
        try:
            (staging / "new").mkdir()
            (staging / "old").mkdir()
            paths = {kind: staging / "new" / t.name for kind, t in self.targets.items()}
            write(paths)
            missing = [str(p.name) for p in paths.values()
                       if not (p.is_file() or (p.name.endswith(".zarr") and p.is_dir()))]
            if missing:
                raise RuntimeError(f"the writer did not write {', '.join(missing)}")
            self.check()  # nothing appeared meanwhile (the lock keeps volseg out, not others)
            stale = [path for path in self.owned if os.path.lexists(path)]
            self.discard = [*self.discard, *stale]      # an older run's other outputs
            journal = staging / f".{_JOURNAL}.part"
            journal.write_text(json.dumps({"names": [t.name for t in self._in_order()],
                                           "discard": [p.name for p in self.discard]}))
            _fsync(journal)
            os.replace(journal, staging / _JOURNAL)
            _fsync(staging)
            self._swap(staging)
        finally:
            remove_tree(staging)            # the old set and the work folder: many files
        return dict(self.targets)

    def _in_order(self) -> list[Path]:
        """The targets in the order they are placed: the index (`last`) last."""
        index = self.targets.get(self.last)
        return [t for t in self.targets.values() if t != index] + (
            [index] if index is not None else [])

    def _swap(self, staging: Path):
        """Move the old set and what it leaves behind aside (the index first), then
        place the new set (the index last); undone on any failure. What is moved aside
        goes with the staging folder."""
        order = self._in_order()
        aside_names = {path: staging / "old" / path.name for path in order[::-1]}
        aside_names.update({path: staging / "old" / f"discarded-{path.name}"
                            for path in self.discard})
        moved_aside, placed = [], []
        try:
            for path, aside in aside_names.items():
                if os.path.lexists(path):
                    os.replace(path, aside)
                    moved_aside.append(path)
            for target in order:
                os.replace(staging / "new" / target.name, target)
                placed.append(target)
        except BaseException:
            for target in placed:
                os.replace(target, staging / "new" / target.name)
            for path in moved_aside:
                os.replace(aside_names[path], path)
            (staging / _JOURNAL).unlink(missing_ok=True)
            raise



def _fsync(path: Path):
    """Flush a file's or a folder's entry to disk (a journal must survive a power loss
    before anything is moved)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
