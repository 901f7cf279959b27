"""`write_vti` and `write_vts`: volumes as one VTK XML file, the formats ParaView and VTK
open without a plugin (ParaView's NIfTI reader is a plugin, off by default, and reads
no ``.nii.gz``; it has no Zarr reader).

An axis-aligned volume is VTK's ImageData (``.vti``) with ``Origin`` and ``Spacing``.
An oblique or flipped one is a StructuredGrid (``.vts``) with every point's world
position: an ImageData's ``Direction`` is read by VTK 9 and ParaView 5.10+, but their
Contour filter ignores it and draws the isosurface unrotated, outside the scan. Both
carry the frame's unit as field data, and one point array per volume, in raw appended
binary (no base64, no compression: the arrays are written
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

__all__ = ["write_vti", "write_vts", "VTK_TYPES"]

#: numpy type -> VTK's name of it.
VTK_TYPES = {"int8": "Int8", "uint8": "UInt8", "int16": "Int16", "uint16": "UInt16",
             "int32": "Int32", "uint32": "UInt32", "int64": "Int64", "uint64": "UInt64",
             "float32": "Float32", "float64": "Float64"}

#: A slab of this many bytes per array at most is read and written at a time.
SLAB_BYTES = 64 * 2**20


def write_vti(path, arrays: dict, frame: Frame, *, scalars: str | None = None) -> Path:
    """Write `arrays` (name -> (X, Y, Z) numpy or Dask array, one shape) as point data
    of one ``.vti`` image in `frame`'s world coordinates, atomically; the frame's unit
    as the field data ``unit``.

    `scalars` names the array ParaView colours by first (default the first). An
    oblique or flipped frame is written as its ``Direction``, which ParaView's Contour
    (and VTK's `vtkContourFilter`) ignore: `write_vts` places such a volume for every
    filter."""
    shape, types = _checked(arrays)
    spacing = np.linalg.norm(frame.affine[:3, :3], axis=0)
    direction = frame.affine[:3, :3] / spacing            # unit columns: the voxel axes
    grid = (f'ImageData WholeExtent="{_extent(shape)}" Origin="{_numbers(frame.affine[:3, 3])}" '
            f'Spacing="{_numbers(spacing)}" Direction="{_numbers(direction.ravel())}"')
    return _write_xml(path, "ImageData", grid, shape, arrays, types, frame, scalars)


def write_vts(path, arrays: dict, frame: Frame, *, scalars: str | None = None) -> Path:
    """`write_vti`'s volumes as a ``.vts`` structured grid: every point's world position
    written out (x fastest), so an oblique or flipped scan lands where it is with every
    ParaView filter, Contour included. The points are float32 when that places each
    within a thousandth of the smallest voxel size of where float64 does, else float64."""
    shape, types = _checked(arrays)
    points = np.dtype(np.float32 if _float32_places(frame, shape) else np.float64)
    grid = f'StructuredGrid WholeExtent="{_extent(shape)}"'
    return _write_xml(path, "StructuredGrid", grid, shape, arrays, types, frame, scalars,
                      points=points)


def _checked(arrays: dict) -> tuple:
    """(shape, name -> numpy type written) of `arrays`, or the refusal."""
    if not arrays:
        raise ValueError("`arrays` must hold at least one volume")
    shapes = {tuple(a.shape) for a in arrays.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3:
        raise ValueError(f"`arrays` must be 3-D volumes of one shape, got {sorted(shapes)}")
    types = {}
    for name, array in arrays.items():
        kind = np.dtype(array.dtype)
        if kind.kind == "b":
            kind = np.dtype(np.uint8)
        if kind.name not in VTK_TYPES:
            raise ValueError(f"`{name}`: VTK image data cannot hold {array.dtype}")
        types[name] = kind
    return next(iter(shapes)), types


def _extent(shape) -> str:
    return " ".join(f"0 {n - 1}" for n in shape)


def _float32_places(frame: Frame, shape) -> bool:
    """Whether float32 world positions of every voxel of `shape` are within 1e-3 of the
    smallest voxel size (float32's half-ulp at the largest coordinate)."""
    corners = np.array([[i, j, k, 1.0] for i in (0, shape[0] - 1) for j in (0, shape[1] - 1)
                        for k in (0, shape[2] - 1)])
    largest = float(np.abs(corners @ frame.affine[:3].T).max())
    return largest * 2.0**-24 <= 1e-3 * min(frame.spacing)


def field_data(unit: str | None) -> str:
    """A length `unit` as VTK XML field data (a string array ``unit``; ParaView's
    Information panel lists it): VTK's own files have no unit. Empty for None."""
    if not unit:
        return ""
    codes = " ".join(str(b) for b in unit.encode("utf-8")) + " 0"
    return ('    <FieldData>\n      <Array type="String" Name="unit" NumberOfTuples="1" '
            f'format="ascii">\n        {codes}\n      </Array>\n    </FieldData>\n')


def _write_xml(path, kind: str, grid: str, shape, arrays: dict, types: dict, frame: Frame,
               scalars, points=None) -> Path:
    """One VTK XML file of `kind` (its opening tag `grid`): the point arrays, and the
    grid's points when `points` (their numpy type) is given, in raw appended binary."""
    path = Path(path)
    voxels = int(np.prod(shape))
    offsets, at = {}, 0
    for name, dtype in types.items():
        offsets[name] = at
        at += 8 + voxels * dtype.itemsize
    arrays_xml = "".join(
        f'        <DataArray type="{VTK_TYPES[dtype.name]}" Name="{name}" '
        f'NumberOfComponents="1" format="appended" offset="{offsets[name]}"/>\n'
        for name, dtype in types.items())
    points_xml = ("" if points is None else
                  f'      <Points>\n        <DataArray type="{VTK_TYPES[points.name]}" '
                  f'NumberOfComponents="3" format="appended" offset="{at}"/>\n'
                  '      </Points>\n')
    extent = _extent(shape)
    header = (
        '<?xml version="1.0"?>\n'
        f'<VTKFile type="{kind}" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64">\n'
        f'  <{grid}>\n{field_data(frame.unit)}'
        f'    <Piece Extent="{extent}">\n'
        f'      <PointData Scalars="{scalars or next(iter(arrays))}">\n{arrays_xml}'
        f'      </PointData>\n{points_xml}    </Piece>\n  </{kind}>\n'
        '  <AppendedData encoding="raw">\n   _')
    tmp = temporary_beside(path)
    try:
        with open(tmp, "wb") as handle:
            handle.write(header.encode())
            for name, dtype in types.items():
                handle.write(np.uint64(voxels * dtype.itemsize).tobytes())
                _write_x_fastest(handle, arrays[name], dtype.newbyteorder("<"))
            if points is not None:
                handle.write(np.uint64(3 * voxels * points.itemsize).tobytes())
                _write_points(handle, frame, shape, points.newbyteorder("<"))
            handle.write(b"\n  </AppendedData>\n</VTKFile>\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _numbers(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def _write_points(handle, frame: Frame, shape, dtype) -> None:
    """The world position of every voxel, x fastest, a z-slab at a time (computed in
    float64, then cast)."""
    nx, ny, nz = shape
    depth = max(1, SLAB_BYTES // max(nx * ny * 24, 1))
    linear, origin = frame.affine[:3, :3], frame.affine[:3, 3]
    plane = (np.arange(ny)[:, None, None] * linear[:, 1]
             + np.arange(nx)[None, :, None] * linear[:, 0])          # (y, x, 3)
    for start in range(0, nz, depth):
        k = np.arange(start, min(start + depth, nz))[:, None, None, None]
        slab = origin + k * linear[:, 2] + plane[None]               # (z, y, x, 3)
        handle.write(np.ascontiguousarray(slab, dtype=dtype).tobytes())


def _write_x_fastest(handle, array, kind) -> None:
    """`array` (X, Y, Z) in VTK's point order (x fastest), a z-slab at a time."""
    nx, ny, nz = array.shape
    depth = max(1, SLAB_BYTES // max(nx * ny * kind.itemsize, 1))
    for start in range(0, nz, depth):
        slab = np.asarray(array[:, :, start:start + depth])
        handle.write(np.ascontiguousarray(slab.transpose(2, 1, 0), dtype=kind).tobytes())
