"""MetaImage (``.mha``, ``.mhd`` + its data file) through SimpleITK and TIFF stacks
(one multi-page file, or a folder of single-page slices) through tifffile: the formats
of CT and microscopy, with the refusals of the other readers.

Each header is read without its pixels first (SimpleITK's `ReadImageInformation`,
tifffile's page list), and the declared size is checked against the file (raw data
must be as large as declared; a compressed one is bounded by `MAX_DECLARED_BYTES`)
before anything is allocated, so a 200-byte header cannot cost gigabytes.

Frames: MetaImage's origin, spacing and direction (ITK's LPS world, turned into
RAS+ like NRRD's); TIFF has no 3-D geometry of its own: ImageJ's ``spacing`` (z) and
``unit`` and the X/Y resolution tags (in pixels per unit) where present, else voxel
size 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._files import regular_file_size
from .volume import Frame, VolumeFileError, length_unit

__all__ = ["read_metaimage", "read_tiff", "MAX_DECLARED_BYTES"]

#: A compressed MetaImage or TIFF declaring more bytes than this is refused from its
#: header (the pixels are decompressed whole: at most this much memory).
MAX_DECLARED_BYTES = 16 * 2**30


def read_metaimage(path: Path, allow_external: bool = False):
    """(data [x, y, z], frame, name, source, files) of a ``.mha`` / ``.mhd``."""
    import SimpleITK as sitk

    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    reader.SetImageIO("MetaImageIO")
    try:
        reader.ReadImageInformation()
    except RuntimeError as err:
        raise VolumeFileError(f"{path}: not a readable MetaImage header ({_first_line(err)})") \
            from None
    size, dimension = reader.GetSize(), reader.GetDimension()
    if dimension != 3 or reader.GetNumberOfComponents() != 1:
        raise VolumeFileError(f"{path}: a {dimension}-D MetaImage of "
                              f"{reader.GetNumberOfComponents()} components per voxel; volseg "
                              "needs a 3-D volume of one value per voxel")
    fields, header = _metaimage_fields(path)
    data_file = fields.get("elementdatafile", "LOCAL")
    files = ((path,) if data_file.upper() == "LOCAL"
             else (path, _data_file(path, data_file, allow_external)))
    itemsize = np.dtype(sitk.GetArrayViewFromImage(sitk.Image(1, 1, 1,
                        reader.GetPixelID())).dtype).itemsize
    declared = int(np.prod(size)) * itemsize
    compressed = fields.get("compresseddata", "false").lower() == "true"
    stored = regular_file_size(files[-1]) - (header if len(files) == 1 else 0)
    if compressed and declared > MAX_DECLARED_BYTES:
        raise VolumeFileError(f"{path}: declares {declared / 1e9:.3g} GB of compressed voxels, "
                              f"over the {MAX_DECLARED_BYTES / 2**30:.0f} GiB volseg reads whole")
    if not compressed and stored < declared:
        raise VolumeFileError(f"{path}: declares {size[0]}x{size[1]}x{size[2]} voxels of "
                              f"{itemsize} bytes ({declared} bytes), but {files[-1].name} holds "
                              f"{stored}")
    try:
        image = reader.Execute()
    except RuntimeError as err:
        raise VolumeFileError(f"{path}: unreadable MetaImage data ({_first_line(err)})") from None
    try:
        data, frame = sitk_image_arrays(image)
    except ValueError as err:
        raise VolumeFileError(f"{path}: the MetaImage geometry: {err}") from None
    name = path.name.rsplit(".", 1)[0]
    return data, frame, name, f"MetaImage {data.dtype}", files


def sitk_image_arrays(image) -> tuple:
    """(data indexed [x, y, z], `Frame` in RAS+) of a 3-D SimpleITK image: ITK's
    (z, y, x) array transposed, its LPS direction, spacing and origin as the affine."""
    import SimpleITK as sitk

    data = sitk.GetArrayFromImage(image).transpose(2, 1, 0)     # ITK's (z, y, x) -> x, y, z
    direction = np.array(image.GetDirection(), dtype=np.float64).reshape(3, 3)
    affine = np.eye(4)
    affine[:3, :3] = direction * np.array(image.GetSpacing())
    affine[:3, 3] = image.GetOrigin()
    affine[:2] *= -1.0                                          # LPS -> RAS+
    return data, Frame(affine, sform_code=1, qform_code=1, unit="millimeter")


def _metaimage_fields(path: Path) -> tuple[dict, int]:
    """The header's ``Key = Value`` lines (lower-case keys), up to ElementDataFile,
    and the header's length in bytes (where a LOCAL file's voxels start)."""
    fields = {}
    with open(path, "rb") as handle:
        for raw in iter(lambda: handle.readline(4096), b""):
            key, _, value = raw.decode("latin-1").partition("=")
            fields[key.strip().lower()] = value.strip()
            if key.strip().lower() == "elementdatafile":
                break
        return fields, handle.tell()


def _data_file(path: Path, name: str, allow_external: bool) -> Path:
    try:
        target = (path.parent / name).resolve()
    except (ValueError, OSError):        # a NUL byte, a name too long
        raise VolumeFileError(f"{path}: its ElementDataFile {name!r} is not a file "
                              "name") from None
    if target.parent != path.parent.resolve() and not allow_external:
        raise VolumeFileError(f"{path}: ElementDataFile {name!r} is outside its folder "
                              "(--allow-external-data to read it)")
    try:
        regular_file_size(target)
    except OSError as err:
        raise VolumeFileError(f"{path}: its ElementDataFile {name!r}: "
                              f"{err.strerror or err}") from None
    return target


def read_tiff(path: Path):
    """(data [x, y, z], frame, name, source, files) of a multi-page TIFF (z pages of
    (y, x)) or a folder of single-page TIFF slices in name order."""
    import tifffile

    path = Path(path)
    files = (sorted(p for p in path.iterdir() if p.suffix.lower() in (".tif", ".tiff"))
             if path.is_dir() else [path])
    if not files:
        raise VolumeFileError(f"{path}: a folder without .tif / .tiff slices")
    shape, dtype, pages, compressed, imagej, resolution = _tiff_header(files[0])
    kept = tuple(n for n in shape if n != 1)            # a series' singleton axes dropped
    if len(files) > 1:
        if len(kept) != 2 or pages != 1:
            raise VolumeFileError(f"{files[0]}: a slice of shape {shape} in {pages} pages; a "
                                  "folder of slices needs one 2-D page per file")
        kept = (len(files), *kept)
    elif len(kept) != 3:
        raise VolumeFileError(f"{files[0]}: a TIFF image of shape {shape}; volseg needs a "
                              "single-channel z stack of y, x slices")
    declared = int(np.prod(kept)) * dtype.itemsize
    if declared > MAX_DECLARED_BYTES or (not compressed and len(files) == 1
                                         and regular_file_size(files[0]) < declared):
        raise VolumeFileError(f"{path}: declares {'x'.join(map(str, kept[::-1]))} {dtype} "
                              f"voxels ({declared} bytes), more than the file holds or "
                              f"{MAX_DECLARED_BYTES / 2**30:.0f} GiB")
    try:
        if len(files) == 1:
            with tifffile.TiffFile(files[0]) as first:
                data = first.series[0].asarray()
        else:
            data = tifffile.TiffSequence(files).asarray()
    except MemoryError:
        raise VolumeFileError(f"{path}: the TIFF's voxels do not fit in memory") from None
    except Exception as err:  # noqa: BLE001 - tifffile on hostile bytes fails in any way
        raise VolumeFileError(f"{path}: unreadable TIFF data ({_first_line(err)})") from None
    if data.size != int(np.prod(kept)):
        raise VolumeFileError(f"{path}: slices of different shapes or types ({data.shape}); "
                              f"expected {kept}")
    data = data.reshape(kept)
    if data.dtype.kind == "b":                 # a bilevel (1-bit) stack: 0 / 1
        data = data.astype(np.uint8)
    if data.dtype.kind not in "uif":
        raise VolumeFileError(f"{path}: TIFF samples of type {data.dtype}; volseg needs real "
                              "numbers")
    depth = kept[0]
    # ImageJ writes the resolution tags in pixels per its unit; without ImageJ's unit
    # they are usually a print resolution (72 per inch), not a voxel size.
    unit = length_unit(imagej.get("unit"))
    xy = resolution if (resolution and unit) else (1.0, 1.0)
    spacing = (*xy, float(imagej.get("spacing", 1.0)))
    try:
        frame = Frame.from_spacing(spacing, unit=unit)
    except ValueError as err:
        raise VolumeFileError(f"{path}: the TIFF voxel sizes {spacing}: {err}") from None
    name = path.name if path.is_dir() else path.name.rsplit(".", 1)[0]
    return (data.transpose(2, 1, 0), frame, name,
            f"TIFF {dtype}, {depth} {'pages' if len(files) == 1 else 'slices'}", tuple(files))


def _tiff_header(path: Path) -> tuple:
    """(series shape, type, page count, compressed, ImageJ metadata, x/y resolution)
    of a TIFF, without its pixels."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tiff:
            series = tiff.series[0]
            return (tuple(series.shape), np.dtype(series.dtype), len(tiff.pages),
                    tiff.pages[0].compression != 1, tiff.imagej_metadata or {},
                    _resolution(tiff.pages[0]))
    except Exception as err:  # noqa: BLE001 - tifffile on hostile bytes fails in any way
        raise VolumeFileError(f"{path}: not a readable TIFF ({_first_line(err)})") from None


def _resolution(page):
    """(x, y) pixel sizes from the resolution tags (pixels per unit), or None."""
    sizes = []
    for tag in ("XResolution", "YResolution"):
        value = page.tags.get(tag)
        if value is None:
            return None
        numerator, denominator = value.value
        if not numerator or not denominator:
            return None
        sizes.append(denominator / numerator)
    return tuple(sizes)


def _first_line(err) -> str:
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    return lines[-1] if lines else type(err).__name__
