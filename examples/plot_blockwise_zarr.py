"""
A blockwise run on a Zarr volume
================================

A volume stored as Zarr is read lazily and segmented block by block (the path
that runs 1024^3 on one machine); its labels equal the in-memory run's for any
chunking. The output set is the CLI's: Zarr labels and curvature, the OME-Zarr
image with its labels pyramid, the summary and the preview.
"""

from pathlib import Path

import numpy as np

from volseg import segment_volume
from volseg.datasets import demo_volume
from volseg.files import chunked, load_volume, segment_files
from volseg.io import Frame, write_zarr

values = demo_volume(40)
write_zarr("blobs.zarr", values, frame=Frame.from_spacing((1.0, 1.0, 2.0), unit="micrometer"))

volume = chunked(load_volume("blobs.zarr"), 16)     # lazy, in 16^3 blocks
print(volume, "blocks:", volume.data.numblocks)
summary, = segment_files([volume], Path("blockwise_out"), force=True, n_regions=8, mask="auto")
print(f"{summary['n_regions']} regions; wrote",
      ", ".join(Path(p).name for p in summary["outputs"].values()))

# %%
# The same volume in memory gives the same labels.
labels = load_volume("blockwise_out/blobs_labels.zarr").data.compute()
in_memory = segment_volume(np.asarray(load_volume("blobs.zarr")), spacing=(1.0, 1.0, 2.0),
                           n_regions=8)
assert np.array_equal(labels, in_memory.labels)
print("blockwise labels equal the in-memory labels")
