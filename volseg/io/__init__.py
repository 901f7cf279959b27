"""Volumes in and out: readers that refuse bad files clearly, writers that keep the
input's frame, and the all-or-nothing writer of a result's output files.

- `read_volume` -> `Volume` (array [x, y, z] + `Frame`); `VolumeFileError` for
  every malformed input;
- `write_volume` (NIfTI, NRRD, .npy, raw), atomically; `read_zarr` / `write_zarr`
  for volumes larger than memory (lazy, block by block); `write_vti` /
  `write_vts` (ParaView's own image and structured-grid formats, several volumes in one
  file, streamed; the grid for an oblique scan); `write_ngff` (an OME-Zarr
  image with its labels and pyramids, for napari and neuroglancer);
- `OutputSet`: lock, check, stage and commit the files of one result.
"""

from .ngff import write_ngff
from .output_set import FolderLock, OutputError, OutputSet, recover
from .readers import DTYPES, read_volume, volume_of_image
from .volume import Frame, Volume, VolumeFileError
from .vtk_image import write_vti, write_vts
from .writers import atomic_path, write_volume
from .zarr_store import read_zarr, write_zarr

__all__ = ["Volume", "Frame", "VolumeFileError", "read_volume", "volume_of_image", "write_volume",
           "atomic_path",
           "OutputSet", "OutputError", "FolderLock", "recover", "DTYPES", "read_zarr",
           "write_zarr", "write_vti", "write_vts", "write_ngff"]
