"""Reading and writing volumes: raw (Volvis names), .dat, NRRD, NIfTI, .npy.

Every array is indexed [x, y, z] so that its shape reads like the file name
(``fuel_64x64x64_uint8.raw`` -> shape (64, 64, 64)); raw data are stored x fastest.
Non-finite values are refused (the curvature of a graph with holes is undefined):
the error gives their count and the first position.
"""

from __future__ import annotations

import gzip
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["Volume", "read_volume", "write_volume", "atomic_path", "DTYPES"]

#: dtype names accepted in raw file names and by ``dtype=``.
DTYPES = {
    "uint8": "u1", "int8": "i1", "uint16": "u2", "int16": "i2", "uint32": "u4", "int32": "i4",
    "uint64": "u8", "int64": "i8", "float32": "f4", "float64": "f8",
    "uchar": "u1", "char": "i1", "ushort": "u2", "short": "i2", "float": "f4", "double": "f8",
}
_RAW_NAME = re.compile(r"^(?P<name>.+?)_(?P<x>\d+)x(?P<y>\d+)x(?P<z>\d+)_(?P<dtype>[a-z0-9]+)$",
                       re.IGNORECASE)


@dataclass
class Volume:
    """A 3-D scalar field on a regular grid.

    Attributes
    ----------
    data : (X, Y, Z) ndarray
        Indexed [x, y, z].
    spacing : tuple of 3 float
    name : str
        Short name for outputs (the file name without size and type).
    source : str
        How it was read (format, byte order, header), for `volseg info`.
    """

    data: NDArray
    spacing: tuple = (1.0, 1.0, 1.0)
    name: str = "volume"
    source: str = ""
    path: Path | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple:
        return self.data.shape

    @property
    def dtype(self):
        return self.data.dtype

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.data, dtype=dtype)


def _dtype(name: str, byte_order: str | None, path) -> np.dtype:
    code = DTYPES.get(str(name).lower())
    if code is None:
        try:
            code = np.dtype(name).str[1:]
        except TypeError:
            raise ValueError(
                f"{path}: unknown dtype {name!r}; use one of {', '.join(sorted(set(DTYPES)))}"
            ) from None
    prefix = {None: "<", "little": "<", "big": ">", "<": "<", ">": ">"}.get(byte_order)
    if prefix is None:
        raise ValueError(f"`byte_order` must be 'little' or 'big', got {byte_order!r}")
    return np.dtype(prefix + code)


def _from_bytes(path, buffer, shape, dtype, offset=0) -> NDArray:
    """Array [x, y, z] from x-fastest bytes, checking the size first."""
    expected = int(np.prod(shape)) * dtype.itemsize
    actual = len(buffer) - offset
    if actual != expected:
        raise ValueError(
            f"{path}: expected {expected} bytes for shape {tuple(shape)} of {dtype.name} "
            f"(+{offset} header bytes), found {actual}"
        )
    flat = np.frombuffer(buffer, dtype=dtype, count=int(np.prod(shape)), offset=offset)
    return flat.reshape(tuple(shape)[::-1]).transpose(2, 1, 0).astype(dtype.newbyteorder("="))


def _check(path, data: NDArray) -> NDArray:
    data = np.asarray(data)
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    if data.ndim != 3:
        raise ValueError(f"{path}: a volume must be 3-D, got shape {data.shape}")
    if min(data.shape) < 2:
        raise ValueError(f"{path}: need at least 2 samples along each axis, got shape {data.shape}")
    if data.dtype.kind not in "uif":
        raise ValueError(f"{path}: voxel type {data.dtype} is not a real number type")
    if data.dtype.kind == "f":
        bad = ~np.isfinite(data)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"{path}: {int(bad.sum())} voxels are NaN or infinite (first at [x, y, z] = "
                f"{first}); replace them (e.g. numpy.nan_to_num) before segmenting"
            )
    return data


def _read_raw(path: Path, shape, dtype, byte_order):
    match = _RAW_NAME.match(path.stem)
    if shape is None:
        if match is None:
            raise ValueError(
                f"{path}: no shape available; name the file like name_XxYxZ_uint8.raw "
                "or give the shape (--shape X Y Z, or shape=(X, Y, Z))"
            )
        shape = tuple(int(match[a]) for a in "xyz")
    if dtype is None:
        dtype = match["dtype"] if match else "uint8"
    dt = _dtype(dtype, byte_order, path)
    name = match["name"] if match else path.stem
    data = _from_bytes(path, path.read_bytes(), shape, dt)
    return data, (1.0, 1.0, 1.0), name, f"raw {dt.name} {'big' if dt.str[0] == '>' else 'little'}-endian, x fastest"


def _read_dat(path: Path, shape, dtype, byte_order):
    raw = path.read_bytes()
    head = raw[:4096]
    if b"Resolution" in head or b"ObjectFileName" in head:
        text = raw.decode("latin-1")
        fields = {}
        for line in text.splitlines():
            if ":" in line:
                key, value = line.split(":", 1)
                fields[key.strip().lower()] = value.strip()
        if "objectfilename" not in fields:
            raise ValueError(f"{path}: .dat header has no ObjectFileName")
        data_path = path.parent / fields["objectfilename"]
        if not data_path.exists():
            raise FileNotFoundError(f"{path}: its data file {data_path} does not exist")
        res = shape or tuple(int(v) for v in fields.get("resolution", "").split())
        if len(res) != 3:
            raise ValueError(f"{path}: .dat header needs 'Resolution: X Y Z', got {fields.get('resolution')!r}")
        spacing = tuple(float(v) for v in fields.get("slicethickness", "1 1 1").split()) or (1.0,) * 3
        dt = _dtype(dtype or fields.get("format", "uchar"), byte_order, path)
        data = _from_bytes(data_path, data_path.read_bytes(), res, dt)
        return data, spacing, data_path.stem.split("_")[0], f".dat header + raw {dt.name}"
    # Old binary .dat: three uint16 sizes, then the voxels (uint16 unless the size says uint8).
    if len(raw) < 6:
        raise ValueError(f"{path}: too short for a .dat file ({len(raw)} bytes)")
    sizes = tuple(int(v) for v in np.frombuffer(raw[:6], dtype="<u2"))
    count = int(np.prod(sizes))
    if dtype is None:
        dtype = "uint8" if count and len(raw) - 6 == count else "uint16"
    dt = _dtype(dtype, byte_order, path)
    data = _from_bytes(path, raw, shape or sizes, dt, offset=6)
    return data, (1.0, 1.0, 1.0), path.stem, f"binary .dat, {dt.name}"


_NRRD_TYPES = {
    "uchar": "u1", "unsigned char": "u1", "uint8": "u1", "uint8_t": "u1",
    "signed char": "i1", "int8": "i1", "int8_t": "i1", "char": "i1",
    "ushort": "u2", "unsigned short": "u2", "uint16": "u2", "uint16_t": "u2",
    "short": "i2", "signed short": "i2", "int16": "i2", "int16_t": "i2",
    "uint": "u4", "unsigned int": "u4", "uint32": "u4", "uint32_t": "u4",
    "int": "i4", "signed int": "i4", "int32": "i4", "int32_t": "i4",
    "float": "f4", "double": "f8",
}


def _read_nrrd(path: Path, shape, dtype, byte_order):
    raw = path.read_bytes()
    if not raw.startswith(b"NRRD"):
        raise ValueError(f"{path}: not an NRRD file (no 'NRRD' magic)")
    end = raw.find(b"\n\n")
    header = raw[: end if end >= 0 else len(raw)].decode("latin-1").splitlines()
    fields = {}
    for line in header[1:]:
        if line.startswith("#") or ":" not in line:
            continue
        key, value = line.split(":", 1)
        fields[key.strip().lower()] = value.lstrip("=").strip()
    try:
        sizes = tuple(int(v) for v in fields["sizes"].split())
        type_name = fields["type"].lower()
    except KeyError as missing:
        raise ValueError(f"{path}: NRRD header has no {missing.args[0]!r} field") from None
    if type_name not in _NRRD_TYPES:
        raise ValueError(f"{path}: unsupported NRRD type {type_name!r}")
    endian = fields.get("endian", "little")
    dt = np.dtype(("<" if endian == "little" else ">") + _NRRD_TYPES[type_name])
    encoding = fields.get("encoding", "raw").lower()
    if "data file" in fields or "datafile" in fields:
        data_path = path.parent / fields.get("data file", fields.get("datafile"))
        payload = data_path.read_bytes()
    else:
        data_path, payload = path, raw[end + 2:] if end >= 0 else b""
    if encoding in ("gzip", "gz"):
        payload = gzip.decompress(payload)
    elif encoding != "raw":
        raise ValueError(f"{path}: unsupported NRRD encoding {encoding!r} (raw and gzip are read)")
    skip = int(fields.get("byte skip", 0))
    spacing = (1.0, 1.0, 1.0)
    if "spacings" in fields:
        spacing = tuple(float(v) for v in fields["spacings"].split()[-3:])
    elif "space directions" in fields:
        vectors = re.findall(r"\(([^)]*)\)", fields["space directions"])
        spacing = tuple(float(np.linalg.norm([float(x) for x in v.split(",")])) for v in vectors)
    if skip == -1:
        skip = len(payload) - int(np.prod(sizes)) * dt.itemsize
    data = _from_bytes(data_path, payload, shape or sizes, dt, offset=skip)
    return data, spacing, path.name.split(".")[0], f"NRRD {encoding} {dt.name}"


def _read_nifti(path: Path, shape, dtype, byte_order):
    import nibabel

    image = nibabel.load(path)
    data = np.asanyarray(image.dataobj)
    spacing = tuple(float(z) for z in image.header.get_zooms()[:3])
    name = path.name[: -len(".nii.gz")] if path.name.endswith(".nii.gz") else path.stem
    return data, spacing, name, f"NIfTI {data.dtype}"


def _read_npy(path: Path, shape, dtype, byte_order):
    try:
        data = np.load(path, allow_pickle=False)
    except ValueError as err:
        raise ValueError(f"{path}: not a plain .npy array ({err})") from None
    return data, (1.0, 1.0, 1.0), path.stem, f"npy {data.dtype}"


def read_volume(path, *, shape=None, dtype=None, byte_order=None) -> Volume:
    """Read a volume from a file, by extension.

    Parameters
    ----------
    path : str or Path
        ``.raw`` (shape and dtype from a name like ``fuel_64x64x64_uint8.raw``, or
        given), ``.dat`` (Volvis text header, or the old binary header of three
        uint16 sizes), ``.nrrd`` / ``.nhdr``, ``.nii`` / ``.nii.gz``, ``.npy``.
    shape : (3,) tuple of int, optional
        (X, Y, Z), x fastest; overrides what the name or header says.
    dtype : str, optional
        Voxel type of raw data (``uint8``, ``uint16``, ``int16``, ``float32``, ...).
    byte_order : {'little', 'big'}, optional
        Of raw data; little-endian by default.

    Returns
    -------
    Volume

    Raises
    ------
    FileNotFoundError
        If the file (or a detached data file) does not exist.
    ValueError
        Size mismatch (expected and actual bytes), unknown dtype, no shape, NaN or
        infinite values, fewer than 2 samples along an axis; the file is named.

    Examples
    --------
    >>> volume = read_volume("fuel_64x64x64_uint8.raw")  # doctest: +SKIP
    >>> volume.shape, volume.dtype  # doctest: +SKIP
    ((64, 64, 64), dtype('uint8'))
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a volume file")
    if shape is not None:
        shape = tuple(int(s) for s in shape)
        if len(shape) != 3 or min(shape) < 1:
            raise ValueError(f"`shape` must be three positive sizes (X, Y, Z), got {shape}")
    name = path.name.lower()
    if name.endswith((".nii", ".nii.gz")):
        reader = _read_nifti
    elif name.endswith((".nrrd", ".nhdr")):
        reader = _read_nrrd
    elif name.endswith(".npy"):
        reader = _read_npy
    elif name.endswith(".dat"):
        reader = _read_dat
    else:
        reader = _read_raw
    data, spacing, short, source = reader(path, shape, dtype, byte_order)
    data = _check(path, data)
    spacing = tuple(float(s) for s in spacing)
    if len(spacing) != 3 or not all(s > 0 for s in spacing):
        raise ValueError(f"{path}: spacing must be three positive numbers, got {spacing}")
    return Volume(data, spacing, short, source, path)


def atomic_path(path: Path):
    """A temporary file beside `path` (same folder, so renaming it is atomic)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs should read like any file
    return Path(tmp)


def write_volume(path, data, *, spacing=(1.0, 1.0, 1.0)) -> Path:
    """Write a label or curvature volume, atomically (temporary file, then rename).

    The format follows the extension: ``.nii.gz`` / ``.nii`` (NIfTI, default, with
    the spacing in its affine), ``.npy``, ``.nrrd``, ``.raw`` (x fastest, native
    little-endian, no header).
    """
    path = Path(path)
    data = np.asarray(data)
    name = path.name.lower()
    tmp = atomic_path(path)
    try:
        if name.endswith((".nii", ".nii.gz")):
            import nibabel

            image = nibabel.Nifti1Image(data, np.diag(list(spacing) + [1.0]))
            image.header.set_xyzt_units("mm")
            # nibabel picks gzip from the name: write under a .nii(.gz) temporary name.
            real_tmp = tmp.with_name(tmp.name + (".nii.gz" if name.endswith(".gz") else ".nii"))
            nibabel.save(image, real_tmp)
            os.replace(real_tmp, tmp)
        elif name.endswith(".npy"):
            with open(tmp, "wb") as handle:
                np.save(handle, data)
        elif name.endswith(".nrrd"):
            kind = {v: k for k, v in _NRRD_TYPES.items() if "_" not in k and " " not in k}
            code = data.dtype.str[1:]
            header = (
                f"NRRD0004\ntype: {kind[code]}\ndimension: 3\n"
                f"sizes: {' '.join(map(str, data.shape))}\nspacings: {' '.join(map(str, spacing))}\n"
                f"endian: little\nencoding: raw\n\n"
            )
            with open(tmp, "wb") as handle:
                handle.write(header.encode())
                handle.write(np.ascontiguousarray(data.transpose(2, 1, 0)).astype(data.dtype.newbyteorder("<")).tobytes())
        elif name.endswith(".raw"):
            with open(tmp, "wb") as handle:
                handle.write(np.ascontiguousarray(data.transpose(2, 1, 0)).tobytes())
        else:
            raise ValueError(f"{path}: unknown output format; use .nii.gz, .nii, .npy, .nrrd or .raw")
        os.replace(tmp, path)
    finally:
        for leftover in tmp.parent.glob(tmp.name + "*"):
            leftover.unlink(missing_ok=True)
    return path
