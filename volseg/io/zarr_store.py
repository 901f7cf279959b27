"""Zarr in and out: volumes larger than memory, read and written block by block.

`read_zarr` opens a Zarr array (v2 or v3), or an OME-Zarr image's level 0, as a
`Volume` whose data is a lazy Dask array with the store's chunks; nothing is read
until a block is computed. Checked up front: a 3-D real array (OME-Zarr's singleton
t / c axes dropped, its axes reordered to [x, y, z]), at least 2 samples per axis,
every chunk present (Zarr would silently fill a missing one with its fill value).
A chunk that does not decode raises `VolumeFileError` naming it when it is read.

`write_zarr` writes a Dask (or numpy) array as a Zarr v3 array with the spacing and
the voxel-to-world affine in its attributes (``volseg``: axes, spacing, affine),
every chunk written, so that `read_zarr` reads it back with its frame.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from ..errors import MissingChunksError
from .volume import METRES, Frame, Volume, VolumeFileError, length_unit

__all__ = ["read_zarr", "write_zarr", "is_zarr", "compressors", "ZSTD_LEVEL", "ARRAY_CONFIG"]

#: The zstd level of every Zarr v3 array volseg writes (plain Zarr and OME-Zarr).
#: Zarr's default, 3, compressed a 512^3 blockwise run's float curvature at 170 MB/s:
#: 17 of the run's 170 CPU-s. Level 1 runs at 350-960 MB/s; its files are as small on a
#: real volume's curvature (tooth, float32: 93 % of the bytes at either level) and larger
#: on a synthetic 8-bit staircase's, full of repeated values (512^3: 87 % of the bytes
#: against 67 %; 1024^3: the curvature store 3.6 GB against 2.2). zstd, not blosc: a
#: chunk cut short fails to decode instead of reading as garbage (`_check_blosc_lengths`).
ZSTD_LEVEL = 1
#: Every chunk of every array volseg writes is written, all-zero ones too: Zarr skips
#: chunks of the fill value by default, and volseg's reader refuses a store with missing
#: chunks (one that was never written whole reads as zeros), so it would refuse its own
#: output's background.
ARRAY_CONFIG = {"write_empty_chunks": True}


def compressors() -> tuple:
    """The codecs after the bytes of every array volseg writes (`ZSTD_LEVEL`)."""
    from zarr.codecs import ZstdCodec

    return (ZstdCodec(level=ZSTD_LEVEL),)


def is_zarr(path) -> bool:
    """A folder holding Zarr metadata (``zarr.json``, ``.zarray`` or ``.zgroup``)."""
    path = Path(path)
    try:
        return path.is_dir() and any((path / name).is_file()
                                     for name in ("zarr.json", ".zarray", ".zgroup", ".zattrs"))
    except OSError:   # a name too long, a loop: not a store; the file readers say why
        return False


def multiscales_of(attrs: dict):
    """The ``multiscales`` list of an OME-Zarr group's attributes: NGFF 0.4 keeps it at
    the top, 0.5 under ``ome``; None when there is none."""
    return attrs.get("multiscales") or (attrs.get("ome") or {}).get("multiscales")


def _ome_level(group, path, level=None):
    """(the array, its axis names, voxel sizes, origin and length units per axis) of
    an OME-Zarr image's level `level` (default 0): NGFF 0.4 or 0.5
    (`multiscales_of`), the dataset's scale and translation composed with the
    multiscale's own."""
    multiscales = multiscales_of(group.attrs.asdict())
    if not multiscales:
        raise VolumeFileError(f"{path}: a Zarr group without OME-Zarr 'multiscales' metadata; "
                              "give the path of the array inside it")
    try:
        scale = multiscales[0]
        datasets = scale["datasets"]
        index = 0 if level is None else int(level)
        if isinstance(level, bool) or not 0 <= index < len(datasets):
            raise VolumeFileError(f"{path}: --ome-level {level} is not one of its "
                                  f"{len(datasets)} levels (0 to {len(datasets) - 1})")
        axes_meta = scale.get("axes", [])
        axes = [a["name"] if isinstance(a, dict) else a for a in axes_meta]
        units = [a.get("unit") if isinstance(a, dict) else None for a in axes_meta]
        _check_axis_types(path, axes_meta)
        factors, origin = [1.0] * len(axes), [0.0] * len(axes)
        for transforms in (datasets[index].get("coordinateTransformations", []),
                           scale.get("coordinateTransformations", [])):
            for transform in transforms:        # the dataset's, then the multiscale's
                if transform.get("type") == "scale":
                    step = [float(f) for f in transform["scale"]]
                    factors = [f * g for f, g in zip(factors, step, strict=True)]
                    origin = [o * g for o, g in zip(origin, step, strict=True)]
                elif transform.get("type") == "translation":
                    shift = [float(t) for t in transform["translation"]]
                    origin = [o + t for o, t in zip(origin, shift, strict=True)]
        array = group[datasets[index]["path"]]
    except VolumeFileError:
        raise
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as err:
        raise VolumeFileError(f"{path}: malformed OME-Zarr 'multiscales' metadata "
                              f"({type(err).__name__}: {err})") from None
    if not hasattr(array, "ndim"):
        raise VolumeFileError(f"{path}: the OME-Zarr level-{index} dataset "
                              f"{datasets[index]['path']!r} is a group, not an array")
    if not axes:
        axes = ["t", "c", "z", "y", "x"][-array.ndim:]
        units = [None] * array.ndim
    if len(axes) != array.ndim or len(factors) != array.ndim:
        raise VolumeFileError(f"{path}: OME-Zarr axes {axes} / scale {factors} do not match "
                              f"the level-{index} array's {array.ndim} dimensions")
    if not all(np.isfinite(v) for v in [*factors, *origin]):
        raise VolumeFileError(f"{path}: OME-Zarr scale {factors} / translation {origin} must "
                              "be finite numbers")
    return array, axes, factors, origin, units


#: NGFF axis types and the units each may carry (UDUNITS-2 names; time's for "time").
_TIME_UNITS = ("attosecond", "centisecond", "day", "decisecond", "exasecond", "femtosecond",
               "gigasecond", "hectosecond", "hour", "kilosecond", "megasecond", "microsecond",
               "millisecond", "minute", "nanosecond", "petasecond", "picosecond", "second",
               "terasecond", "yoctosecond", "yottasecond", "zeptosecond", "zettasecond")


def _check_axis_types(path, axes_meta) -> None:
    """An axis named x, y or z must be of type space (or untyped) with a length unit
    (or none): a time or channel axis named z, or seconds on a space axis, is refused
    rather than read as a length."""
    for axis in axes_meta:
        if not isinstance(axis, dict):
            continue
        name, kind, unit = axis.get("name"), axis.get("type"), axis.get("unit")
        if name in ("x", "y", "z") and kind not in (None, "space"):
            raise VolumeFileError(f"{path}: OME-Zarr axis {name!r} is of type {kind!r}; "
                                  "x, y and z must be space axes")
        if kind == "space" and unit is not None and length_unit(unit) is None:
            what = "a time unit" if str(unit).lower() in _TIME_UNITS else "not a length unit"
            raise VolumeFileError(f"{path}: OME-Zarr space axis {name!r} has unit {unit!r}, "
                                  f"{what}")


def _common_unit(path, units) -> tuple:
    """(the unit of the frame, the factor taking each axis's sizes to it): the axes'
    common length unit; axes in different units are taken to the finest of them (z in
    millimetres, x and y in micrometres: micrometres); no unit on any axis: None. Some
    axes with a unit and others without are refused (their ratio is unknown)."""
    named = [length_unit(u) for u in units]
    if all(u is None for u in named):
        return None, [1.0, 1.0, 1.0]
    if any(u is None for u in named):
        raise VolumeFileError(f"{path}: OME-Zarr spatial axes with units {units}: some have a "
                              "length unit and others none, so their voxel sizes cannot be "
                              "compared")
    finest = min(named, key=METRES.get)
    return finest, [METRES[u] / METRES[finest] for u in named]


#: A store declaring more chunks than this is refused before any is listed (the
#: count alone bounds the time of the checks; 4096^3 in 16^3 chunks is 2^24).
MAX_CHUNKS = 2**24


def _array_of(node, path, channel=None, level=None):
    """(the array, the order of its x, y, z axes or None, its frame or None, the index
    of each other axis) of an opened Zarr node: an OME-Zarr image's `level` (default 0;
    its `channel`, or its only one), or an array with volseg's attributes."""
    import zarr

    frame = None
    if level is not None and not isinstance(node, zarr.Group):
        raise VolumeFileError(f"{path}: a plain Zarr array has no levels (--ome-level "
                              "applies to OME-Zarr images)")
    if isinstance(node, zarr.Group):
        array, axes, factors, shift, units = _ome_level(node, path, level)
        keep = [i for i, name in enumerate(axes) if name in ("x", "y", "z")]
        pick = _other_axes(path, axes, array.shape, channel)
        if len(keep) != 3 or sorted(set(axes)) != sorted(axes):
            raise VolumeFileError(f"{path}: OME-Zarr image of axes {axes} and shape {array.shape}: "
                                  "volseg needs three spatial axes x, y, z")
        order = [keep[[axes[i] for i in keep].index(name)] for name in ("x", "y", "z")]
        unit, to_unit = _common_unit(path, [units[i] for i in order])
        affine = np.diag([*(factors[i] * f for i, f in zip(order, to_unit, strict=True)), 1.0])
        affine[:3, 3] = [shift[i] * f for i, f in zip(order, to_unit, strict=True)]
        try:
            frame = Frame(affine, unit=unit)
        except ValueError as err:
            raise VolumeFileError(f"{path}: OME-Zarr scale: {err}") from None
    else:
        array, pick = node, {}
        if channel is not None:
            raise VolumeFileError(f"{path}: a plain Zarr array has no channels (--channel "
                                  "applies to OME-Zarr images)")
        attrs = dict(array.attrs).get("volseg", {})
        if not isinstance(attrs, dict):
            raise VolumeFileError(f"{path}: the 'volseg' attribute must be an object (axes, "
                                  f"spacing, affine), got {type(attrs).__name__}")
        order = None
        if attrs.get("axes", "xyz") != "xyz":
            raise VolumeFileError(f"{path}: volseg axes attribute {attrs.get('axes')!r}; expected "
                                  "'xyz'")
        if "affine" in attrs:
            try:
                frame = Frame(np.asarray(attrs["affine"], dtype=np.float64))
            except (ValueError, TypeError) as err:
                raise VolumeFileError(f"{path}: the 'affine' attribute: {err}") from None
    return array, order, frame, pick


def _other_axes(path, axes, shape, channel) -> dict:
    """Axis position -> the index read along it, for the non-spatial axes: `channel`
    along ``c`` (needed when there are several), 0 along an axis of size 1."""
    pick = {}
    for i, name in enumerate(axes):
        if name in ("x", "y", "z"):
            continue
        if name == "c" and (shape[i] > 1 or channel is not None):
            if channel is None:
                raise VolumeFileError(f"{path}: the image has {shape[i]} channels; choose one "
                                      f"with --channel (0 to {shape[i] - 1})")
            if isinstance(channel, bool) or not 0 <= int(channel) < shape[i]:
                raise VolumeFileError(f"{path}: --channel {channel} is not one of its "
                                      f"{shape[i]} channels (0 to {shape[i] - 1})")
            pick[i] = int(channel)
        elif shape[i] != 1:
            raise VolumeFileError(f"{path}: OME-Zarr axis {name!r} has {shape[i]} entries; "
                                  "volseg reads one 3-D volume (a time series: one step per "
                                  "store, or volseg isosurface)")
        else:
            pick[i] = 0
    if channel is not None and "c" not in axes:
        raise VolumeFileError(f"{path}: the image has no channel axis ('c'); drop --channel")
    return pick


def _checked_array(node, path, allow_external_data, channel, level=None,
                   fill_missing_chunks=False):
    """`_array_of`, then every check that needs no chunk's values (see the module)."""
    array, order, frame, pick = _array_of(node, path, channel, level)
    if array.ndim != 3 and order is None:
        raise VolumeFileError(f"{path}: the Zarr array is {array.ndim}-D (shape {array.shape}); "
                              "volseg needs a 3-D volume")
    dtype = np.dtype(array.dtype)
    if dtype.kind not in "biuf":
        raise VolumeFileError(f"{path}: voxel type {dtype} is not a real number type")
    _check_layout(array, path, order)
    if not allow_external_data:
        _refuse_links_out(path)
    if fill_missing_chunks:
        return array, order, frame, pick
    if array.nchunks_initialized < array.nchunks:
        raise MissingChunksError(
            f"{path}: {array.nchunks - array.nchunks_initialized} of {array.nchunks} chunks are "
            f"missing; Zarr would read them as the fill value {array.fill_value!r}. A copy "
            "cut short looks like this; so does a store whose writer skipped chunks of the "
            "fill value (Zarr's default): then give --fill-missing-chunks")
    if getattr(array, "shards", None) is not None:
        _check_shards(array, path)
    elif _is_blosc(array):
        _check_blosc_lengths(array, path)
    return array, order, frame, pick


def _is_blosc(array) -> bool:
    return any(type(c).__name__ in ("Blosc", "BloscCodec")
               for c in getattr(array, "compressors", ()) or ())


#: A blosc chunk's header: 16 bytes, its compressed length ``cbytes`` (uint32, little
#: endian) at byte 12.
_BLOSC_HEADER = 16


def _check_blosc_lengths(array, path) -> None:
    """Every stored chunk holds as many bytes as its blosc header says (``cbytes``).

    A chunk cut short still decodes: blosc copies ``nbytes`` from a buffer shorter than
    its header's ``cbytes`` (a chunk stored raw, "memcpyed", as noise is), reading past
    its end, so the voxels are garbage and differ from one read to the next. Checked
    here, file by file, before any chunk is decoded (16 bytes read per chunk)."""
    grid = [range(-(-n // c)) for n, c in zip(array.shape, array.chunks, strict=True)]
    for where in itertools.product(*grid):
        file = Path(path) / array.metadata.encode_chunk_key(where)
        try:
            with open(file, "rb") as handle:
                header = handle.read(_BLOSC_HEADER)
                size = handle.seek(0, 2)
        except (FileNotFoundError, IsADirectoryError):
            continue              # missing chunks are the fill value's business, above
        if len(header) < _BLOSC_HEADER:
            raise VolumeFileError(f"{file}: a blosc chunk of {size} bytes is shorter than "
                                  f"its {_BLOSC_HEADER}-byte header: cut short")
        declared = int.from_bytes(header[12:16], "little")
        if declared != size:
            raise VolumeFileError(f"{file}: its blosc header says {declared} bytes, the file "
                                  f"holds {size}: the chunk was cut short or altered; "
                                  "copy the store again")


def read_zarr(path, *, allow_external_data: bool = False, channel=None,
              ome_level=None, fill_missing_chunks: bool = False) -> Volume:
    """Open a Zarr array or OME-Zarr image as a lazily read `Volume` (see the module).

    `allow_external_data`: let the store hold links to files outside it (refused by
    default: a store from elsewhere cannot make volseg read, and publish a checksum
    of, any file). `channel`: of an OME-Zarr image with several; `ome_level`: the
    resolution level of an OME-Zarr image (default 0, the full resolution).
    `fill_missing_chunks`: read chunks that were never written as the fill value, as
    Zarr's specification says (refused by default: an interrupted copy looks the same,
    but writers that skip chunks of the fill value, Zarr's and ome-zarr-py's default,
    make such stores on purpose)."""
    import dask.array as da
    import zarr

    path = Path(path)
    try:
        node = zarr.open(str(path), mode="r")
    except Exception as err:  # noqa: BLE001 - any failure to open is the store's
        raise VolumeFileError(f"{path}: not a readable Zarr store ({type(err).__name__}: "
                              f"{err})") from None
    try:
        array, order, frame, pick = _checked_array(node, path, allow_external_data, channel,
                                                   ome_level, fill_missing_chunks)
    except VolumeFileError:
        raise
    except Exception as err:  # noqa: BLE001 - hostile metadata breaks Zarr in any way
        raise VolumeFileError(f"{path}: unreadable Zarr metadata ({type(err).__name__}: "
                              f"{' '.join(str(err).split())})") from None
    dtype = np.dtype(array.dtype)
    lazy = da.from_array(_Checked(array, path), chunks=array.chunks, asarray=True,
                         fancy=False, name=f"zarr-{path.name}-{id(array)}")
    if order is not None:
        lazy = lazy[tuple(pick.get(i, slice(None)) for i in range(array.ndim))]
        remaining = sorted(order)
        lazy = lazy.transpose([remaining.index(i) for i in order])
    if min(lazy.shape) < 2:
        raise VolumeFileError(f"{path}: the volume needs at least 2 samples along each axis, "
                              f"got shape {lazy.shape}")
    name = path.name[:-5] if path.name.endswith(".zarr") else path.name
    name = name[:-4] if name.endswith(".ome") and len(name) > 4 else name
    return Volume(lazy, frame=frame or Frame.from_spacing((1.0, 1.0, 1.0)), name=name,
                  source=f"Zarr {dtype} chunks {array.chunks}", path=path, files=(path,))


def _check_layout(array, path, order):
    """Shape and chunks from the metadata alone, before any chunk is listed: every
    axis at least 1 (the spatial ones 2), chunks at least 1, at most `MAX_CHUNKS`."""
    shape, chunks = tuple(array.shape), tuple(array.chunks)
    spatial = range(array.ndim) if order is None else order
    if any(s < 1 for s in shape) or any(shape[i] < 2 for i in spatial):
        raise VolumeFileError(f"{path}: the volume needs at least 2 samples along each axis, "
                              f"got shape {shape}")
    if len(chunks) != len(shape) or any(c < 1 for c in chunks):
        raise VolumeFileError(f"{path}: chunk shape {list(chunks)} for shape {list(shape)}: "
                              "every chunk size must be at least 1")
    count = int(np.prod([-(-s // c) for s, c in zip(shape, chunks, strict=True)], dtype=object))
    if count > MAX_CHUNKS:
        raise VolumeFileError(f"{path}: {count} chunks of {list(chunks)} declared (at most "
                              f"{MAX_CHUNKS}); rechunk the store into larger chunks")


def _refuse_links_out(path):
    """A link in the store that leads outside it is refused (without following links
    into folders: a link to a folder is itself checked)."""
    import os

    root = os.path.realpath(path)
    for top, folders, files in os.walk(path):
        for name in folders + files:
            entry = os.path.join(top, name)
            if os.path.islink(entry):
                target = os.path.realpath(entry)
                if os.path.commonpath([root, target]) != root:
                    raise VolumeFileError(
                        f"{entry}: a link to {target}, outside the store; copy the data into "
                        "the store, or pass --allow-external-data")


def _check_shards(array, path):
    """Every inner chunk of a sharded (Zarr v3) array present: Zarr counts shards, and
    fills an inner chunk missing from its shard's index with the fill value. Each
    shard's index (16 bytes per inner chunk, at its start or end) is read."""
    codec = array.metadata.codecs[0]
    inner = tuple(codec.chunk_shape)
    shard = tuple(array.shards)
    per = tuple(s // c for s, c in zip(shard, inner, strict=True))
    n_inner = int(np.prod(per))
    crc = any(type(c).__name__ == "Crc32cCodec" for c in codec.index_codecs)
    index_bytes = 16 * n_inner + (4 if crc else 0)
    at_end = str(getattr(codec.index_location, "value", codec.index_location)) == "end"
    missing = 0
    grid = [range(-(-n // s)) for n, s in zip(array.shape, shard, strict=True)]
    for where in itertools.product(*grid):
        # Inner chunks of this shard that lie inside the array (an edge shard has fewer).
        inside = np.ones(per, dtype=bool)
        for axis, (w, s, c, n) in enumerate(zip(where, shard, inner, array.shape, strict=True)):
            starts = w * s + np.arange(per[axis]) * c
            view = [slice(None)] * len(per)
            view[axis] = starts >= n
            inside[tuple(view)] = False
        file = path / array.metadata.encode_chunk_key(where)
        try:
            with open(file, "rb") as handle:
                size = handle.seek(0, 2)
                if size < index_bytes:
                    raise VolumeFileError(f"{file}: a shard of {size} bytes cannot hold its "
                                          f"index of {index_bytes} bytes")
                handle.seek(size - index_bytes if at_end else 0)
                index = np.frombuffer(handle.read(16 * n_inner), dtype="<u8")
        except FileNotFoundError:
            missing += int(inside.sum())
            continue
        empty = (index.reshape(per + (2,)) == np.iinfo(np.uint64).max).all(axis=-1)
        missing += int((empty & inside).sum())
    if missing:
        raise MissingChunksError(
            f"{path}: {missing} inner chunks of its shards are missing; Zarr would read them "
            f"as the fill value {array.fill_value!r} (give --fill-missing-chunks if its writer "
            "skipped chunks of the fill value)")


class _Checked:
    """Array-like view of a Zarr array whose reads raise `VolumeFileError` naming the
    chunk that does not decode."""

    def __init__(self, array, path):
        self.array, self.path = array, path
        self.shape, self.dtype, self.ndim = array.shape, np.dtype(array.dtype), array.ndim

    def __getitem__(self, key):
        try:
            return self.array[key]
        except Exception as err:  # noqa: BLE001 - codec errors have no common type
            where = ", ".join(f"{k.start}:{k.stop}" if isinstance(k, slice) else str(k)
                              for k in key)
            raise VolumeFileError(f"{self.path}: the chunk at [{where}] is unreadable "
                                  f"({type(err).__name__}: {err})") from None


def write_zarr(path, data, *, frame: Frame | None = None, chunks=None, compute=None) -> Path:
    """Write `data` (Dask or numpy, [x, y, z]) as a Zarr v3 array at `path` with its
    frame. `compute(delayed)`, if given, runs the writes (e.g. with a progress bar)."""
    import dask.array as da
    import zarr

    lazy = (data if isinstance(data, da.Array)
            else da.from_array(np.asarray(data), chunks=chunks or "auto"))
    # Regular chunks, equal to the store's: each block then writes whole store chunks
    # of its own (no two blocks share one, so no lock is needed).
    lazy = lazy.rechunk(chunks if chunks is not None else tuple(c[0] for c in lazy.chunks))
    frame = frame or Frame.from_spacing((1.0, 1.0, 1.0))
    store = zarr.create_array(str(path), shape=lazy.shape, chunks=tuple(c[0] for c in lazy.chunks),
                              dtype=lazy.dtype, fill_value=0, overwrite=True,
                              compressors=compressors(), config=ARRAY_CONFIG)
    store.attrs["volseg"] = {"axes": "xyz", "spacing": list(frame.spacing),
                             "affine": np.asarray(frame.affine).tolist()}
    if compute is None:
        da.store(lazy, store, lock=False)
    else:
        compute(da.store(lazy, store, lock=False, compute=False))
    return Path(path)
