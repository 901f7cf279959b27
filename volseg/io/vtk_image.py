"""`write_vti`: volumes as one VTK XML image (``.vti``), the format ParaView and VTK open
without a plugin (ParaView's NIfTI reader is a plugin, off by default, and reads no
``.nii.gz``; it has no Zarr reader).

The file is VTK's ImageData with ``Origin``, ``Spacing`` and ``Direction`` from the
frame (VTK 9 reads the direction; ParaView 5.10 and later show it), and one point array
per volume, in raw appended binary (no base64, no compression: the arrays are written
as they are, a z-slab at a time, so a Dask array is never whole in memory). No
well-kept library writes image data without VTK itself (meshio writes meshes only;
pyevtk has no direction), and VTK is 100 MB: VTK's own reader checks this writer in
the tests.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._atomic import temporary_beside
from .volume import Frame

__all__ = ["write_vti", "VTK_TYPES"]

#: numpy type -> VTK's name of it.
VTK_TYPES = {"int8": "Int8", "uint8": "UInt8", "int16": "Int16", "uint16": "UInt16",
             "int32": "Int32", "uint32": "UInt32", "int64": "Int64", "uint64": "UInt64",
             "float32": "Float32", "float64": "Float64"}

#: A slab of this many bytes per array at most is read and written at a time.
SLAB_BYTES = 64 * 2**20


def write_vti(path, arrays: dict, frame: Frame, *, scalars: str | None = None) -> Path:
    """Write `arrays` (name -> (X, Y, Z) numpy or Dask array, one shape) as point data
    of one ``.vti`` image in `frame`'s world coordinates, atomically.

    `scalars` names the array ParaView colours by first (default the first)."""
    path = Path(path)
    if not arrays:
        raise ValueError("`arrays` must hold at least one volume")
    shapes = {tuple(a.shape) for a in arrays.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3:
        raise ValueError(f"`arrays` must be 3-D volumes of one shape, got {sorted(shapes)}")
    shape = next(iter(shapes))
    types = {}
    for name, array in arrays.items():
        kind = np.dtype(array.dtype)
        if kind.kind == "b":
            kind = np.dtype(np.uint8)
        if kind.name not in VTK_TYPES:
            raise ValueError(f"`{name}`: VTK image data cannot hold {array.dtype}")
        types[name] = kind
    spacing = np.linalg.norm(frame.affine[:3, :3], axis=0)
    direction = frame.affine[:3, :3] / spacing            # unit columns: the voxel axes
    voxels = int(np.prod(shape))
    offsets, at = {}, 0
    for name, kind in types.items():
        offsets[name] = at
        at += 8 + voxels * kind.itemsize
    extent = " ".join(f"0 {n - 1}" for n in shape)
    arrays_xml = "".join(
        f'        <DataArray type="{VTK_TYPES[kind.name]}" Name="{name}" '
        f'NumberOfComponents="1" format="appended" offset="{offsets[name]}"/>\n'
        for name, kind in types.items())
    header = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64">\n'
        f'  <ImageData WholeExtent="{extent}" Origin="{_numbers(frame.affine[:3, 3])}" '
        f'Spacing="{_numbers(spacing)}" Direction="{_numbers(direction.ravel())}">\n'
        f'    <Piece Extent="{extent}">\n'
        f'      <PointData Scalars="{scalars or next(iter(arrays))}">\n{arrays_xml}'
        '      </PointData>\n    </Piece>\n  </ImageData>\n'
        '  <AppendedData encoding="raw">\n   _')
    tmp = temporary_beside(path)
    try:
        with open(tmp, "wb") as handle:
            handle.write(header.encode())
            for name, kind in types.items():
                handle.write(np.uint64(voxels * kind.itemsize).tobytes())
                _write_x_fastest(handle, arrays[name], kind.newbyteorder("<"))
            handle.write(b"\n  </AppendedData>\n</VTKFile>\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _numbers(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def _write_x_fastest(handle, array, kind) -> None:
    """`array` (X, Y, Z) in VTK's point order (x fastest), a z-slab at a time."""
    nx, ny, nz = array.shape
    depth = max(1, SLAB_BYTES // max(nx * ny * kind.itemsize, 1))
    for start in range(0, nz, depth):
        slab = np.asarray(array[:, :, start:start + depth])
        handle.write(np.ascontiguousarray(slab.transpose(2, 1, 0), dtype=kind).tobytes())
