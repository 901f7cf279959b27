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

from pathlib import Path

import numpy as np

from .volume import Frame, Volume, VolumeFileError

__all__ = ["read_zarr", "write_zarr", "is_zarr"]


def is_zarr(path) -> bool:
    """A folder holding Zarr metadata (``zarr.json``, ``.zarray`` or ``.zgroup``)."""
    path = Path(path)
    try:
        return path.is_dir() and any((path / name).is_file()
                                     for name in ("zarr.json", ".zarray", ".zgroup", ".zattrs"))
    except OSError:   # a name too long, a loop: not a store; the file readers say why
        return False


def _ome_level0(group, path):
    multiscales = group.attrs.get("multiscales")
    if not multiscales:
        raise VolumeFileError(f"{path}: a Zarr group without OME-Zarr 'multiscales' metadata; "
                              "give the path of the array inside it")
    try:
        scale = multiscales[0]
        level = scale["datasets"][0]
        axes = [a["name"] if isinstance(a, dict) else a for a in scale.get("axes", [])]
        factors = [1.0] * len(axes)
        for transform in level.get("coordinateTransformations", []):
            if transform.get("type") == "scale":
                factors = [float(f) for f in transform["scale"]]
        array = group[level["path"]]
    except (KeyError, IndexError, TypeError, ValueError) as err:
        raise VolumeFileError(f"{path}: malformed OME-Zarr 'multiscales' metadata "
                              f"({err})") from None
    if not axes:
        axes = ["t", "c", "z", "y", "x"][-array.ndim:]
    if len(axes) != array.ndim or len(factors) != array.ndim:
        raise VolumeFileError(f"{path}: OME-Zarr axes {axes} / scale {factors} do not match "
                              f"the level-0 array's {array.ndim} dimensions")
    return array, axes, factors


def read_zarr(path) -> Volume:
    """Open a Zarr array or OME-Zarr image as a lazily read `Volume` (see the module)."""
    import dask.array as da
    import zarr

    path = Path(path)
    try:
        node = zarr.open(str(path), mode="r")
    except Exception as err:  # noqa: BLE001 - any failure to open is the store's
        raise VolumeFileError(f"{path}: not a readable Zarr store ({type(err).__name__}: "
                              f"{err})") from None
    frame = None
    if isinstance(node, zarr.Group):
        array, axes, factors = _ome_level0(node, path)
        keep = [i for i, name in enumerate(axes) if name in ("x", "y", "z")]
        extra = [i for i, name in enumerate(axes) if name not in ("x", "y", "z")]
        if len(keep) != 3 or any(array.shape[i] != 1 for i in extra):
            raise VolumeFileError(f"{path}: OME-Zarr image of axes {axes} and shape {array.shape}: "
                                  "volseg needs three spatial axes x, y, z (other axes of size 1)")
        order = [keep[[axes[i] for i in keep].index(name)] for name in ("x", "y", "z")]
        spacing = tuple(factors[i] for i in order)
        frame = Frame.from_spacing(spacing)
    else:
        array = node
        attrs = dict(array.attrs).get("volseg", {})
        order = None
        if attrs.get("axes", "xyz") != "xyz":
            raise VolumeFileError(f"{path}: volseg axes attribute {attrs.get('axes')!r}; expected "
                                  "'xyz'")
        if "affine" in attrs:
            try:
                frame = Frame(np.asarray(attrs["affine"], dtype=np.float64))
            except (ValueError, TypeError) as err:
                raise VolumeFileError(f"{path}: the 'affine' attribute: {err}") from None
    if array.ndim != 3 and order is None:
        raise VolumeFileError(f"{path}: the Zarr array is {array.ndim}-D (shape {array.shape}); "
                              "volseg needs a 3-D volume")
    dtype = np.dtype(array.dtype)
    if dtype.kind not in "biuf":
        raise VolumeFileError(f"{path}: voxel type {dtype} is not a real number type")
    if array.nchunks_initialized < array.nchunks:
        raise VolumeFileError(
            f"{path}: {array.nchunks - array.nchunks_initialized} of {array.nchunks} chunks are "
            f"missing; Zarr would read them as the fill value {array.fill_value!r} (rewrite the "
            "store with every chunk written)")
    lazy = da.from_array(_Checked(array, path), chunks=array.chunks, asarray=True,
                         fancy=False, name=f"zarr-{path.name}-{id(array)}")
    if order is not None:
        lazy = lazy.squeeze(axis=tuple(i for i in range(array.ndim) if i not in order))
        remaining = sorted(order)
        lazy = lazy.transpose([remaining.index(i) for i in order])
    if min(lazy.shape) < 2:
        raise VolumeFileError(f"{path}: the volume needs at least 2 samples along each axis, "
                              f"got shape {lazy.shape}")
    name = path.name[:-5] if path.name.endswith(".zarr") else path.name
    return Volume(lazy, frame=frame or Frame.from_spacing((1.0, 1.0, 1.0)), name=name,
                  source=f"Zarr {dtype} chunks {array.chunks}", path=path, files=(path,))


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
                              config={"write_empty_chunks": True})
    store.attrs["volseg"] = {"axes": "xyz", "spacing": list(frame.spacing),
                             "affine": np.asarray(frame.affine).tolist()}
    if compute is None:
        da.store(lazy, store, lock=False)
    else:
        compute(da.store(lazy, store, lock=False, compute=False))
    return Path(path)
