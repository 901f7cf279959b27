"""`write_ngff`: a result as an OME-Zarr (NGFF 0.5) image, for napari, neuroglancer and
every NGFF viewer: the curvature as a multiscale image, the labels as its NGFF labels
image ``labels/regions``, axes z, y, x, the input's voxel sizes, origin and unit.

The metadata are written as ome-zarr-py (the NGFF reference implementation, which
napari-ome-zarr reads with) writes them, the arrays by Zarr, from pyramids made here:
labels by nearest sampling (every second voxel: labels are never blended, and the
level's voxel centres stay on level 0's), the curvature by 2 x 2 x 2 means (its
translation moved half a voxel, as NGFF wants). A Dask input is never whole in memory:
each level is written block by block from the one above; a numpy input's level 0 is
transposed one slab at a time, and the levels below are made from the slabs.

NGFF 0.5 has scale and translation only: a rotated or flipped frame is written axis
aligned (voxel sizes and the origin); the NIfTI and ``.vti`` outputs keep the rotation.
"""

from __future__ import annotations

import os
import shutil
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import OutputError, VolumeFileError
from .volume import Frame
from .zarr_store import ARRAY_CONFIG, compressors

__all__ = ["write_ngff", "write_labels_into", "recover_labels", "is_ome_image", "ome_levels",
           "pyramid_levels", "NGFF_CHUNK"]

#: Chunk edge of every level (64^3: 256 KB of uint8 labels, 1 MB of float32).
NGFF_CHUNK = 64
#: Edge of a numpy input's write blocks: each task writes 4^3 chunks (a Dask input's
#: blocks are kept, rounded up to whole chunks).
WRITE_BLOCK = 4 * NGFF_CHUNK
#: ome-zarr-py's storage options for the labels written into an input (`ARRAY_CONFIG`).
STORAGE = {"config": ARRAY_CONFIG}
#: Levels are added until the smallest axis is at most this many voxels.
SMALLEST_LEVEL = 64


def pyramid_levels(shape) -> int:
    """How many levels below level 0: halving until the smallest axis is at most
    `SMALLEST_LEVEL` voxels (0 for a small volume)."""
    levels, side = 0, min(shape)
    while side > SMALLEST_LEVEL and side // 2 >= 2:
        side //= 2
        levels += 1
    return levels


def _level0(array, order, blocks=None):
    """An (X, Y, Z) numpy or Dask array as a level 0: lazy, its axes in `order`, in
    NGFF chunks, or (`blocks`: a numpy input's edge) in write blocks
    (`_in_write_blocks`)."""
    import dask.array as da

    if not hasattr(array, "dask"):
        array = da.from_array(np.asarray(array), chunks=blocks or NGFF_CHUNK)
    level = array.transpose(*order)
    return level.rechunk(NGFF_CHUNK) if blocks is None else _in_write_blocks(level)


def _label_pyramid(labels, order, blocks=None) -> list:
    """`_level0` of `labels` and the levels below it, each every second voxel of the
    one above (labels are never blended; a level's first voxel centre stays level
    0's)."""
    levels = [_level0(labels, order, blocks)]
    for _ in range(pyramid_levels(levels[0].shape)):
        below = levels[-1][::2, ::2, ::2]
        levels.append(below.rechunk(NGFF_CHUNK) if blocks is None else _in_write_blocks(below))
    return levels


def _space_axes(names, units) -> list:
    """NGFF axis metadata: spatial axes `names`, each with its unit when known."""
    return [{"name": name, "type": "space", **({"unit": unit} if unit else {})}
            for name, unit in zip(names, units, strict=True)]


@contextmanager
def _with_translations():
    """ome-zarr 0.18 deprecates `coordinate_transformations` for `scale`, which has no
    translation: without it the images would not sit on the input's origin."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The 'coordinate_transformations' argument",
                                DeprecationWarning)
        yield


def _in_write_blocks(level):
    """`level` (Dask) in regular blocks of whole NGFF chunks (the last may be short):
    its own blocks' edge rounded up to a multiple of `NGFF_CHUNK`, so that no two tasks
    write one chunk and a task writes a block of them."""
    edges = tuple(max(-(-max(c) // NGFF_CHUNK), 1) * NGFF_CHUNK for c in level.chunks)
    return level.rechunk(edges)


def _written_levels(levels, group, axes) -> list:
    """Lazy writes of `levels` (Dask) as `group`'s arrays s0, s1, ... in `NGFF_CHUNK`
    chunks, each task a block of chunks (`_in_write_blocks`). Through ome-zarr-py's own
    writer each chunk of 64^3 was a task of its own, with the rechunks before it: 41 567
    tasks for a 1024^3 result's image, most of the run's tasks on a cluster. The arrays
    are made here (`_array`), as the in-memory writer makes them, and Dask stores into
    them: the codecs are set in one place whatever Dask's version passes on to Zarr."""
    import dask.array as da

    return [da.store(_in_write_blocks(level),
                     _array(group, f"s{i}", axes, shape=level.shape, dtype=level.dtype),
                     lock=False, compute=False)
            for i, level in enumerate(levels)]


def _chunks(shape) -> tuple:
    return tuple(min(NGFF_CHUNK, max(int(n), 1)) for n in shape)


def _array(group, name, axes, data=None, *, shape=None, dtype=None):
    """`group`'s array `name` (z, y, x) in NGFF chunks: holding `data` (numpy), or
    empty of `shape` and `dtype` for its chunks to be written."""
    spec = {"data": data} if data is not None else {"shape": shape, "dtype": dtype}
    return group.create_array(name, chunks=_chunks(spec.get("shape", np.shape(data))),
                              dimension_names=[a["name"] for a in axes],
                              compressors=compressors(), config=ARRAY_CONFIG, **spec)


def _level0_in_slabs(group, array, dtype, axes, below):
    """An (X, Y, Z) numpy `array` written as `group`'s level ``s0`` (z, y, x, of
    `dtype`) one chunk-thick z slab at a time, so that only a slab is ever copied
    transposed (the whole level's copy was 5 bytes a voxel beside everything the
    writers hold); returns the level below made from the slabs by `below` (their
    starts are even, so each 2 x 2 x 2 block lies in one slab), or None."""
    shape = array.shape[::-1]
    level = _array(group, "s0", axes, shape=shape, dtype=dtype)
    parts = []
    for start in range(0, shape[0], NGFF_CHUNK):
        slab = np.ascontiguousarray(array[:, :, start:start + NGFF_CHUNK].transpose(2, 1, 0),
                                    dtype=dtype)
        level[start:start + len(slab)] = slab
        if below is not None:
            parts.append(below(slab))
    return np.concatenate(parts) if below is not None else None


def _sampled(level):
    """A labels level below `level` (numpy): every second voxel."""
    return np.ascontiguousarray(level[::2, ::2, ::2])


def _coarsened(level):
    """A mean level below `level` (numpy or a Dask block, float32): each 2x2x2 block's
    mean in float64, rounded once, the excess edge voxels dropped. Its voxels are
    summed in one order, pairs along the last axis, then the second, then the first,
    whatever the blocks' shapes: a Dask level's blocks (even edges but the last) give
    the whole level's bytes. 3.3x faster than ``np.mean(..., axis=(1, 3, 5),
    dtype=np.float64)`` over the 2x2x2 view (its strided reduction), 0.039 against
    0.129 s for 256^3."""
    z, y, x = (n - n % 2 for n in level.shape)
    level = level[:z, :y, :x]
    sums = level[:, :, 0::2].astype(np.float64)
    sums += level[:, :, 1::2]
    sums = sums[:, 0::2] + sums[:, 1::2]
    sums = sums[0::2] + sums[1::2]
    return (sums / 8).astype(np.float32)


def _multiscales(group, transforms, axes, name, image_label=False) -> None:
    """NGFF 0.5 metadata of `group`'s levels s0, s1, ...: the ``ome`` block with its
    ``multiscales`` (and, for a labels image, ``image-label`` pointing at the image
    two groups up), as ome-zarr-py writes them."""
    ome = {"version": "0.5", "multiscales": [{
        "datasets": [{"path": f"s{i}", "coordinateTransformations": t}
                     for i, t in enumerate(transforms)],
        "name": name, "axes": axes}]}
    if image_label:
        ome["image-label"] = {"source": {"image": "../../"}, "version": "0.5"}
    group.attrs["ome"] = ome


def write_ngff(path, labels, curvature, frame: Frame, name: str = "curvature") -> Path:
    """Write `labels` and `curvature` ((X, Y, Z) numpy or Dask arrays, one shape) as
    the OME-Zarr (NGFF 0.5) image `path` (a new folder; its parent must exist); `name`:
    the image's multiscale name, the field it holds. Arrays in memory are written by
    Zarr alone (no Dask, no ome-zarr-py: a small run's write imported 0.6 s of them);
    Dask arrays block by block, the same bytes."""
    import zarr

    path = Path(path)
    if tuple(labels.shape) != tuple(curvature.shape) or len(labels.shape) != 3:
        raise ValueError(f"`labels` {labels.shape} and `curvature` {curvature.shape} must be "
                         "3-D volumes of one shape")
    spacing = np.array(frame.spacing)[::-1]            # z, y, x
    origin = frame.affine[:3, 3][::-1]
    axes = _space_axes("zyx", [frame.unit] * 3)
    lazy = hasattr(labels, "dask") or hasattr(curvature, "dask")
    if lazy:
        label_levels = _label_pyramid(labels, (2, 1, 0), WRITE_BLOCK)
        mean_levels = [_level0(curvature, (2, 1, 0), WRITE_BLOCK).astype(np.float32)]
        for _ in range(len(label_levels) - 1):
            above = mean_levels[-1]
            mean_levels.append(_in_write_blocks(above.map_blocks(
                _coarsened, dtype=np.float32,
                chunks=tuple(tuple(n // 2 for n in c) for c in above.chunks))))
        levels = len(label_levels) - 1
    else:
        levels = pyramid_levels(labels.shape[::-1])
    # Level i's voxel size is 2^i of level 0's; nearest sampling keeps level 0's first
    # voxel centre, a 2^i mean's centre is (2^i - 1) / 2 voxels further.
    label_transforms = [_transforms(spacing * 2**i, origin) for i in range(levels + 1)]
    mean_transforms = [_transforms(spacing * 2**i, origin + spacing * (2**i - 1) / 2)
                       for i in range(levels + 1)]
    root = zarr.open_group(str(path), mode="w-", zarr_format=3)
    regions = root.require_group("labels/regions")
    if lazy:
        import dask

        dask.compute(*_written_levels(mean_levels, root, axes),
                     *_written_levels(label_levels, regions, axes))
    else:
        for group, array, dtype, below in (
                (root, curvature, np.float32, _coarsened),
                (regions, labels, np.asarray(labels).dtype, _sampled)):
            level = _level0_in_slabs(group, np.asarray(array), dtype, axes,
                                     below if levels else None)
            for i in range(1, levels + 1):
                _array(group, f"s{i}", axes, level)
                if i < levels:
                    level = below(level)
    _multiscales(root, mean_transforms, axes, name)
    _multiscales(regions, label_transforms, axes, "regions", image_label=True)
    root["labels"].attrs["ome"] = {"version": "0.5", "labels": ["regions"]}
    return path


def _versioned_labels(labels_group) -> None:
    """NGFF 0.5 wants ``"version": "0.5"`` in the ``labels`` group's ``ome`` block, which
    ome-zarr-py 0.18's label writers leave out (ome-zarr-models then refuses the whole
    image); a 0.4 group keeps its ``labels`` list as it is."""
    attributes = labels_group.attrs.asdict()
    if "ome" in attributes and "version" not in attributes["ome"]:
        labels_group.attrs["ome"] = {"version": "0.5", **attributes["ome"]}


def _transforms(scale, translation) -> list:
    return [{"type": "scale", "scale": [float(s) for s in scale]},
            {"type": "translation", "translation": [float(t) for t in translation]}]


def ome_levels(path) -> int:
    """How many resolution levels the OME-Zarr (0.4 or 0.5) image `path` lists; 0 for
    anything that is not one (not a store, not a group, no ``multiscales``)."""
    import zarr

    from .zarr_store import multiscales_of

    try:
        multiscales = multiscales_of(zarr.open_group(str(path), mode="r").attrs.asdict())
        return len(multiscales[0]["datasets"]) if multiscales else 0
    except Exception:      # not a store, not a group, malformed: not an image to list
        return 0


def is_ome_image(path) -> bool:
    """A folder holding an OME-Zarr (0.4 or 0.5) image: a group with ``multiscales``."""
    return ome_levels(path) > 0


def recover_labels(image, name: str) -> None:
    """Undo what a killed `write_labels_into` left in ``image/labels``: a staging group
    is removed; a replaced labels image moved aside (``.<name>.volseg-old``) is moved
    back when the new one never arrived, else removed. Readers then see either the
    old labels image or the new one, whole. Under the lock `write_labels_into` takes."""
    root = Path(image) / "labels"
    if not root.is_dir():
        return
    with _labels_lock(root, name):
        _recover(root, name)


def _labels_lock(root: Path, name: str):
    from .output_set import FolderLock

    return FolderLock(root, f"{name}.labels", busy="another volseg is adding these labels")


def _listing_lock(root: Path):
    """The lock of ``labels/``'s own metadata (its listing), waited for."""
    from .output_set import FolderLock

    return FolderLock(root, "listing.labels", wait=True, busy="another volseg is listing")


def _recover(root: Path, name: str) -> None:
    staging, old, target = (root / f".{name}.volseg-staging", root / f".{name}.volseg-old",
                            root / name)
    for path in (staging, old, target):
        if path.is_symlink():
            raise OutputError(f"{path} is a link: volseg writes only groups it made")
    if staging.exists():
        shutil.rmtree(staging)
    if old.exists():
        if target.exists():
            shutil.rmtree(old)
        else:
            os.rename(old, target)


def write_labels_into(image, labels, *, name: str = "volseg", level: int = 0,
                      force: bool = False) -> Path:
    """Add `labels` ((X, Y, Z) numpy or Dask, the grid of the image's level `level`) to
    the OME-Zarr image `image` as its NGFF labels image ``labels/<name>``: the image's
    own NGFF version and axis order, level `level`'s scale and translation, a nearest
    pyramid; listed in ``labels/``'s metadata, where napari-ome-zarr and every NGFF
    viewer look for an image's labels.

    The pyramid is written into a hidden staging group beside it and renamed into place
    (one rename on a local filesystem), then listed; an existing ``labels/<name>`` is
    refused unless `force` (then replaced). Images with axes other than three spatial
    ones (channels, time) are refused: their labels would need those axes too. One
    writer at a time per image and name (a lock in ``labels/``); what a killed writer
    left is undone first (`recover_labels`).
    """
    import zarr

    from .zarr_store import _ome_level

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from ome_zarr.format import FormatV04, FormatV05

    image = Path(image)
    group = zarr.open_group(str(image), mode="r+")
    array, axes, factors, origin, units = _ome_level(group, image, level)
    if sorted(axes) != ["x", "y", "z"]:
        raise VolumeFileError(f"{image}: OME-Zarr image of axes {axes}: labels can be added "
                              "only to an image of three spatial axes (x, y, z)")
    order = ["xyz".index(a) for a in axes]             # the image's axes from x, y, z
    shape = tuple(labels.shape[i] for i in order)
    if shape != tuple(array.shape):
        raise VolumeFileError(f"{image}: level {level} has shape {tuple(array.shape)}, the "
                              f"labels {shape} in its axis order")
    fmt = FormatV05() if "ome" in group.attrs.asdict() else FormatV04()
    root = image / "labels"
    target = root / name
    root.mkdir(exist_ok=True)
    with _listing_lock(root):     # two first writers would each create (empty) labels/
        labels_group = group.require_group("labels")
    with _labels_lock(root, name):
        _recover(root, name)
        if target.exists() and not force:
            raise OutputError(f"{target} exists: give --force to replace it")
        _write_labels(labels, labels_group, root, name, order, fmt, axes, factors, origin, units)
    return target


def _write_labels(labels, labels_group, root, name, order, fmt, axes, factors, origin,
                  units) -> None:
    """`write_labels_into`'s writing, under its lock: staged, renamed, listed."""
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from ome_zarr.writer import add_metadata, get_metadata, write_multiscale

    target, staging = root / name, root / f".{name}.volseg-staging"
    levels = _label_pyramid(labels, order)
    transforms = [_transforms(np.array(factors) * 2**i, origin) for i in range(len(levels))]
    with _with_translations():
        write_multiscale(levels, labels_group.create_group(staging.name), fmt=fmt,
                         axes=_space_axes(axes, units), coordinate_transformations=transforms,
                         name=name, storage_options=STORAGE)
    staged = zarr.open_group(str(staging), mode="r+")
    add_metadata(staged, {"image-label": {"version": fmt.version,
                                          "source": {"image": "../../"}}}, fmt=fmt)
    old = root / f".{name}.volseg-old"
    if target.exists():
        os.rename(target, old)        # a kill here: `recover_labels` moves it back
    os.rename(staging, target)
    shutil.rmtree(old, ignore_errors=True)
    # The listing is one file every writer of this image rewrites: one at a time (the
    # per-name lock let two writers of different names lose each other's entry).
    with _listing_lock(root):
        group = zarr.open_group(str(root), mode="r+")          # the listing as it is now
        listed = list(get_metadata(group).get("labels", []))
        if name not in listed:
            add_metadata(group, {"labels": [*listed, name]}, fmt=fmt)
        _versioned_labels(group)
