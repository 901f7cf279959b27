"""Bounded access to input files: only regular files, only what a header names, never
more bytes than declared.

Every reader goes through these, so a hostile or careless file (a device, a pipe,
a header declaring terabytes, a gzip stream that does not end, a data file named
by an absolute path) is refused before anything large is allocated.
"""

from __future__ import annotations

import os
import stat
import zlib
from pathlib import Path

import numpy as np

from .volume import VolumeFileError

#: Largest header read before its end marker must have appeared (NRRD, .dat text).
MAX_HEADER_BYTES = 1 << 20
_PIECE = 1 << 20

_KINDS = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFIFO: "a named pipe", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}


def regular_file_size(path: Path) -> int:
    """Size of `path` in bytes; refuses anything that is not a regular file.

    Uses ``stat`` only, so a FIFO is refused without being opened (opening one
    blocks until a writer appears).
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such file") from None
    except OSError as err:  # ENAMETOOLONG, ELOOP, EACCES on a parent ...
        raise VolumeFileError(f"{path}: cannot be read ({err.strerror})") from None
    kind = stat.S_IFMT(info.st_mode)
    if kind != stat.S_IFREG:
        raise VolumeFileError(f"{path}: is {_KINDS.get(kind, 'not a regular file')}, not a volume "
                              "file")
    return info.st_size


def read_head(path: Path, end_marker: bytes, limit: int = MAX_HEADER_BYTES) -> tuple[bytes, int]:
    """(header bytes, offset of the data) for a header that ends at `end_marker`.

    Reads at most `limit` bytes; a header that has not ended by then is refused.
    Returns (all bytes read, -1) when the file ends before the marker.
    """
    with open(path, "rb") as handle:
        head = handle.read(limit + len(end_marker))
    end = head.find(end_marker)
    if end < 0:
        if len(head) > limit:
            raise VolumeFileError(f"{path}: no end of header within the first {limit} bytes")
        return head, -1
    return head[:end], end + len(end_marker)


def confined(header: Path, name: str, field: str, allow_external: bool) -> Path:
    """The data file a detached header names, which must lie in its folder or below.

    Raises
    ------
    VolumeFileError
        The file does not exist, or the name is empty, absolute or climbs out of the
        header's folder (``..``, a symbolic link), unless `allow_external` is true.
    """
    name = name.strip()
    if not name:
        raise VolumeFileError(f"{header}: the {field!r} field is empty")
    if "\0" in name:
        raise VolumeFileError(f"{header}: the {field!r} field holds a NUL byte")
    target = header.parent / name
    try:
        exists = target.exists()
    except OSError as err:
        raise VolumeFileError(f"{header}: its {field!r} {name!r} cannot be read "
                              f"({err.strerror})") from None
    if not exists:
        raise VolumeFileError(f"{header}: its {field!r} {name!r} does not exist ({target})")
    if allow_external:
        return target
    base = header.parent.resolve()
    try:
        inside = target.resolve().is_relative_to(base)
    except (OSError, RuntimeError) as err:  # too long, a symlink loop
        raise VolumeFileError(f"{header}: its {field!r} {name!r} cannot be resolved "
                              f"({err})") from None
    if not inside:
        raise VolumeFileError(
            f"{header}: its {field!r} {name!r} lies outside the header's folder {base}; "
            "pass allow_external_data=True (--allow-external-data) to read it anyway"
        )
    return target


def expected_bytes(path, shape, dtype: np.dtype) -> int:
    """Bytes of an array of `shape` and `dtype`, refusing sizes that are not sizes."""
    count = 1
    for size in shape:
        if size < 1:
            raise VolumeFileError(f"{path}: sizes must be positive, got {tuple(shape)}")
        count *= int(size)
    return count * dtype.itemsize


def read_exact(path: Path, offset: int, shape, dtype: np.dtype, mapped: bool = False) -> np.ndarray:
    """The flat array of `shape` x `dtype` stored at `offset`, checked against the file size
    before anything is allocated (file order, no reshape). With `mapped`, a read-only
    memory map of it (`MappedArray` reads it block by block)."""
    expected = expected_bytes(path, shape, dtype)
    size = regular_file_size(path)
    if offset < 0 or size - offset != expected:
        raise VolumeFileError(
            f"{path}: expected {expected} bytes for shape {tuple(shape)} of {dtype.name} "
            f"(+{offset} header bytes), found {size - offset}"
        )
    if mapped:
        return np.memmap(path, dtype=dtype, mode="r", offset=offset,
                         shape=(expected // dtype.itemsize,))
    with open(path, "rb") as handle:
        handle.seek(offset)
        flat = np.fromfile(handle, dtype=dtype, count=expected // dtype.itemsize)
    if flat.size * dtype.itemsize != expected:  # the file shrank while we read it
        raise VolumeFileError(f"{path}: ended after {flat.size * dtype.itemsize} of {expected} "
                              "bytes")
    return flat


#: Bytes a NIfTI's gzip stream may hold past its voxels (decompressed to reach the
#: trailer's CRC, then dropped).
GZIP_SLACK = 1 << 20


def gunzip_bounded(path: Path, offset: int, expected: int, *, exact: bool = True) -> bytes:
    """Decompress the gzip (or zlib) stream at `offset`, in pieces, stopping as soon as
    it yields more than `expected` bytes; a shorter stream is refused, and so is a
    longer one when `exact` (else only the first `expected` bytes are kept).

    Concatenated gzip members are read as one stream, as gzip does. The stream must
    end with its trailer, whose CRC and length zlib checks: a truncated file is
    refused even when its first `expected` bytes are there. Without `exact`, up to
    `GZIP_SLACK` more bytes are decompressed (and dropped) to reach it.
    """
    out = bytearray()
    kept = expected
    if not exact:
        expected += GZIP_SLACK
    decoder = zlib.decompressobj(wbits=47)  # gzip or zlib header, detected
    try:
        with open(path, "rb") as handle:
            handle.seek(offset)
            pending = b""
            while True:
                if not pending:
                    pending = handle.read(_PIECE)
                    if not pending:
                        break
                out += decoder.decompress(pending, expected + 1 - len(out))
                pending = decoder.unconsumed_tail
                if len(out) > expected:
                    raise VolumeFileError(
                        f"{path}: the compressed data hold more than the {kept} bytes "
                        "the header declares" + ("" if exact else f" (+{GZIP_SLACK})"))
                if decoder.eof:  # another gzip member may follow; anything else ends it
                    pending = decoder.unused_data + pending
                    if len(pending) < 2:
                        pending += handle.read(2)
                    if not pending.startswith(b"\x1f\x8b"):
                        break
                    decoder = zlib.decompressobj(wbits=47)
    except zlib.error as err:
        raise VolumeFileError(f"{path}: corrupt compressed data ({err})") from None
    except OverflowError:
        raise VolumeFileError(f"{path}: the header declares a size the decompressor cannot "
                              "take") from None
    if len(out) < kept or (exact and len(out) != kept):
        raise VolumeFileError(
            f"{path}: expected {kept} bytes after decompression, found {len(out)}")
    if not decoder.eof:
        raise VolumeFileError(f"{path}: the compressed stream ends before its gzip trailer "
                              "(a truncated file; its checksum cannot be verified)")
    return bytes(out[:kept])


class MappedArray:
    """A read-only view of a memory-mapped file (a reshaped / transposed `np.memmap`)
    as an array-like for `dask.array.from_array`: each read maps the file and copies
    out one block, so nothing holds the whole volume, and it pickles as the file name
    and the view's layout (for distributed workers), not as the data."""

    def __init__(self, view: np.memmap):
        low, high = np.lib.array_utils.byte_bounds(view)
        self.filename, self.file_offset = str(view.filename), int(view.offset)
        self.extent = high - low
        self.start = view.__array_interface__["data"][0] - low
        self.shape, self.dtype, self.strides = view.shape, view.dtype, view.strides
        self.ndim = view.ndim

    def __getitem__(self, key):
        try:
            mapping = np.memmap(self.filename, dtype=np.uint8, mode="r",
                                offset=self.file_offset, shape=(self.extent,))
        except (ValueError, OSError) as err:    # truncated (or removed) since it was opened
            raise VolumeFileError(f"{self.filename}: can no longer be read as it was opened "
                                  f"(truncated or replaced while volseg read it: {err})") from None
        view = np.ndarray(self.shape, self.dtype, buffer=mapping, offset=self.start,
                          strides=self.strides)
        return np.array(view[key])
