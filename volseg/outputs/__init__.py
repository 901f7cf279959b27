"""The files of one segmentation: their names, the summary, the writers, the previews
and the space-time files of an isosurface series.

- `output_names`: kind -> file name of a result's output set;
- `summary`, `result_summary`, `input_summary`, `files_sha256`: the summary JSON;
- `write_segmentation`: labels, curvature, summary and preview as one set;
- `volseg.outputs.preview`: the preview and persistence-curve PNGs;
- `volseg.outputs.spacetime`: the mesh, ParaView series and summary of a series.
"""

from ._summary import (
    BLOCKWISE_NIFTI_VOXELS,
    BLOCKWISE_SUFFIXES,
    LISTED_PERSISTENCES,
    NGFF_SUFFIX,
    OUTPUT_SUFFIXES,
    PARAVIEW_GRID_SUFFIX,
    PARAVIEW_SUFFIX,
    PARAVIEW_VOXELS,
    all_output_names,
    degenerate_cut_warning,
    files_sha256,
    input_files,
    input_summary,
    output_names,
    result_summary,
    result_title,
    summary,
)
from ._write import write_result_files, write_segmentation

__all__ = ["OUTPUT_SUFFIXES", "BLOCKWISE_SUFFIXES", "BLOCKWISE_NIFTI_VOXELS", "PARAVIEW_SUFFIX",
           "PARAVIEW_GRID_SUFFIX", "NGFF_SUFFIX", "PARAVIEW_VOXELS",
           "LISTED_PERSISTENCES", "output_names", "all_output_names", "files_sha256",
           "input_files", "summary",
           "result_summary", "input_summary", "result_title", "degenerate_cut_warning",
           "write_result_files",
           "write_segmentation"]
