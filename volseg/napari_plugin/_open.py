"""File > IO Utilities > Open with volseg: any file or folder volseg reads, by name
(the reader's patterns claim only what no other napari reader opens)."""

from __future__ import annotations

import napari
from qtpy.QtWidgets import QFileDialog

from ._reader import open_in

__all__ = ["open_file_with_volseg", "open_folder_with_volseg"]


def open_file_with_volseg(viewer: napari.viewer.Viewer) -> None:
    """Ask for a file (NIfTI, NRRD, MetaImage, TIFF, .npy, .raw ...) and open it with
    volseg's reader: a refused file is shown as napari shows errors."""
    path, _ = QFileDialog.getOpenFileName(None, "Open a file with volseg")
    if path:
        open_in(viewer, path)


def open_folder_with_volseg(viewer: napari.viewer.Viewer) -> None:
    """Ask for a folder (a Zarr or OME-Zarr store, a TIFF series) and open it with
    volseg's reader."""
    path = QFileDialog.getExistingDirectory(None, "Open a folder with volseg")
    if path:
        open_in(viewer, path)
