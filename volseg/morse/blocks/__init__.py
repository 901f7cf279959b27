"""The Morse stage of `volseg.morse` on a Dask array, block by block (docs/design.md
section 10): the same cells, events and cuts as in memory, exactly.

Per block, the steepest ascent with a one-voxel halo gives local cells and exit voxels
(`_build`, `_kernels`); on the workers the maxima are numbered by a sample sort
(`_ranks`), the exits resolved by pointer jumping (`_exits`), and the elder-rule
union-find decided in a tree of block groups (`volseg.morse._group_tree`). The
hierarchy stays on the workers in buckets of maximum ids (`_buckets`,
`HierarchyOnWorkers`); a cut runs there (`_cut`, `_bucket_cut`, `_bucket_prune` with
`_merge_groups` for the size measures) and only its small result reaches the client.
Imported by `volseg.morse.descending_complex` when its field is a Dask array.
"""

from ._build import dask_hierarchy
from ._on_workers import HierarchyOnWorkers

__all__ = ["dask_hierarchy", "HierarchyOnWorkers"]
