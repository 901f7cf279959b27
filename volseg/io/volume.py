"""The `Volume` (an array indexed [x, y, z] with its voxel-to-world frame) and the
error every reader raises for a malformed file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import VolumeFileError  # noqa: F401 (re-exported)

__all__ = ["Volume", "Frame", "VolumeFileError", "LENGTH_UNITS", "METRES", "length_unit"]


#: NIfTI xform codes: 0 unknown, 1 scanner, 2 aligned, 3 Talairach, 4 MNI, 5 template.
_CODES = range(0, 6)

#: The length units of OME-Zarr (NGFF 0.4 / 0.5, UDUNITS-2 names) that volseg keeps.
LENGTH_UNITS = ("angstrom", "nanometer", "micrometer", "millimeter", "centimeter", "meter",
                "kilometer", "inch", "foot")
#: Each length unit in metres: an image whose axes differ in unit is read in its finest.
METRES = {"angstrom": 1e-10, "nanometer": 1e-9, "micrometer": 1e-6, "millimeter": 1e-3,
          "centimeter": 1e-2, "meter": 1.0, "kilometer": 1e3, "inch": 0.0254,
          "foot": 0.3048}
#: Other spellings headers use (NIfTI's 'mm' and 'micron', NRRD's 'mm', 'um', 'µm').
UNIT_ALIASES = {"mm": "millimeter", "micron": "micrometer", "um": "micrometer",
                "µm": "micrometer", "μm": "micrometer", "nm": "nanometer", "cm": "centimeter",
                "m": "meter", "km": "kilometer", "in": "inch", "ft": "foot"}


def length_unit(name) -> str | None:
    """A header's length unit as a `LENGTH_UNITS` name, or None (unknown, unlisted)."""
    if not isinstance(name, str):
        return None
    name = name.strip().lower()
    name = UNIT_ALIASES.get(name, name)
    return name if name in LENGTH_UNITS else None


@dataclass(frozen=True, eq=False)
class Frame:
    """Voxel-to-world geometry: voxel (i, j, k) sits at ``affine @ (i, j, k, 1)``.

    World coordinates are NIfTI's RAS+ (x to the right, y anterior, z superior);
    NRRD's left-posterior-superior directions are converted on reading.

    Attributes
    ----------
    affine : (4, 4) ndarray of float
        The voxel-to-world affine (NIfTI's sform where it is coded, else its qform).
    sform_code, qform_code : int
        NIfTI's codes (0 unknown, 1 scanner, 2 aligned, ...), kept from a NIfTI
        input and written back unchanged.
    qform : (4, 4) ndarray or None
        NIfTI's qform where it differs from `affine`; None means the same.
    unit : str or None
        The length unit of world coordinates, as OME-Zarr names it (``"millimeter"``,
        ``"micrometer"``, ``"meter"``, ...; `LENGTH_UNITS`), from the input's header;
        None when the input does not say (raw files, .npy).
    """

    affine: NDArray[np.float64]
    sform_code: int = 2
    qform_code: int = 0
    qform: NDArray[np.float64] | None = None
    unit: str | None = None

    def __post_init__(self):
        affine = np.array(self.affine, dtype=np.float64)
        if affine.shape != (4, 4):
            raise ValueError(f"`affine` must be a finite 4 x 4 matrix, got shape {affine.shape}")
        if not np.isfinite(affine).all():
            raise ValueError(f"`affine` must be a finite 4 x 4 matrix, got {affine.tolist()}")
        if abs(np.linalg.det(affine[:3, :3])) < 1e-12 * max(1.0, np.abs(affine[:3, :3]).max()) ** 3:
            raise ValueError("`affine` is singular: its voxel axes do not span 3-D space")
        object.__setattr__(self, "affine", affine)
        for name in ("sform_code", "qform_code"):
            if int(getattr(self, name)) not in _CODES:
                raise ValueError(f"`{name}` must be a NIfTI xform code 0..5, got "
                                 f"{getattr(self, name)}")
            object.__setattr__(self, name, int(getattr(self, name)))
        if self.unit is not None and self.unit not in LENGTH_UNITS:
            raise ValueError(f"`unit` must be one of {', '.join(LENGTH_UNITS)} or None, got "
                             f"{self.unit!r}")

    @classmethod
    def from_spacing(cls, spacing, unit: str | None = None) -> Frame:
        """The axis-aligned frame of a format that stores only voxel sizes."""
        return cls(np.diag([*(float(s) for s in spacing), 1.0]), unit=unit)

    def with_unit(self, unit: str | None) -> Frame:
        """The same frame with the world's length `unit`."""
        return Frame(self.affine, self.sform_code, self.qform_code, self.qform, unit)

    def same_grid(self, other: Frame) -> bool:
        """Whether `other` places every voxel where this frame does: equal affines
        within a millionth of the largest voxel size, and the same unit."""
        tolerance = 1e-6 * max(max(self.spacing), max(other.spacing))
        return self.unit == other.unit and bool(
            np.allclose(self.affine, other.affine, rtol=0, atol=tolerance))

    def agrees_with(self, other: Frame) -> bool:
        """Whether two files' voxels may be compared one by one: `same_grid`, where a
        frame that carries no geometry (unit-less voxels of 1 at the origin: a .npy, a
        raw grid) agrees with any, and a unit that only one of them says is ignored."""
        a, b = self, other
        if any(f.unit is None and np.array_equal(f.affine, np.eye(4)) for f in (a, b)):
            return True
        if a.unit is None or b.unit is None:
            a, b = a.with_unit(None), b.with_unit(None)
        return a.same_grid(b)

    @property
    def axis_aligned(self) -> bool:
        """Whether voxel axis i runs along world axis i, forwards: no rotation, no flip
        (what an OME-Zarr's scale and translation can hold)."""
        linear = self.affine[:3, :3]
        return bool(np.all(linear[~np.eye(3, dtype=bool)] == 0) and np.all(np.diag(linear) > 0))

    @property
    def spacing(self) -> tuple:
        """Voxel sizes: the lengths of the affine's three voxel axes."""
        return tuple(float(s) for s in np.linalg.norm(self.affine[:3, :3], axis=0))


class Volume:
    """A 3-D scalar field on a regular grid.

    Parameters and attributes
    -------------------------
    data : (X, Y, Z) ndarray
        Indexed [x, y, z].
    spacing : (3,) sequence of float, optional
        Voxel sizes, for an axis-aligned frame; give this or `frame`.
    frame : Frame, optional
        Voxel-to-world geometry; every volume written from this one (labels,
        curvature) carries it. Curvature uses only the voxel sizes (`spacing`, the
        lengths of the affine's columns): a rotated, flipped or translated scan has
        the same graph in R^4.
    name : str
        Short name for outputs (the file name without size and type).
    source : str
        How it was read (format, byte order, header), for `volseg info`.
    path : Path or None
        The file named by the user.
    files : tuple of Path
        Every file whose bytes were read (a detached header and its data file), in
        reading order; the input checksum covers them all.
    """

    def __init__(self, data, spacing=None, *, frame: Frame | None = None, name: str = "volume",
                 source: str = "", path: Path | None = None, files: tuple = ()):
        if frame is None:
            frame = Frame.from_spacing((1.0, 1.0, 1.0) if spacing is None else spacing)
        elif spacing is not None and not np.allclose(frame.spacing, spacing):
            raise ValueError(f"`spacing` {tuple(spacing)} disagrees with the frame's "
                             f"{frame.spacing}")
        self.data = data
        self.frame = frame
        self.name = name
        self.source = source
        self.path = path
        self.files = tuple(files)

    def __repr__(self):
        return (f"Volume(name={self.name!r}, shape={self.shape}, dtype={self.dtype}, "
                f"spacing={self.spacing})")

    @property
    def spacing(self) -> tuple:
        """The voxel sizes (dx, dy, dz) in the frame's unit."""
        return self.frame.spacing

    @property
    def affine(self) -> NDArray[np.float64]:
        """The 4x4 voxel-to-world affine."""
        return self.frame.affine

    @property
    def shape(self) -> tuple:
        """The array's (X, Y, Z) shape."""
        return self.data.shape

    @property
    def dtype(self):
        """The array's data type."""
        return self.data.dtype

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.data, dtype=dtype)
