"""The blockwise path for volumes larger than memory: Dask + Zarr, stage by stage
through a work folder that lets a killed run resume.

- `BlockwiseStorage`: the storage of `volseg.segment.run_stages` that keeps each
  stage on disk for the next (`volseg.files.segment_to_files` uses it for a lazily
  read volume);
- `volseg.blockwise.engine`: where the blocks run (`Engine`: threads, a local
  dask.distributed cluster, or a scheduler's address);
- `WorkFolder`: the finished blocks kept on disk;
- `DEFAULT_CHUNKS`, `IN_MEMORY_BYTES_PER_VOXEL`, `DISK_BYTES_PER_VOXEL`: the sizes
  that choose the path and check the disk.
"""

from ._resume import WorkFolder
from ._storage import (
    DEFAULT_CHUNKS,
    DISK_BYTES_PER_VOXEL,
    IN_MEMORY_BYTES_PER_VOXEL,
    BlockwiseStorage,
)

__all__ = ["BlockwiseStorage", "WorkFolder", "DEFAULT_CHUNKS", "IN_MEMORY_BYTES_PER_VOXEL",
           "DISK_BYTES_PER_VOXEL"]
