"""volseg in napari: the npe2 plugin (`napari.yaml`), installed with the ``napari`` extra.

- `_layers`: a `Volume` as napari layer data and back (axes z, y, x as OME-Zarr has
  them; the frame as the layer's scale and translation, or its affine);
- `_reader`: volseg's output sets, its OME-Zarr output and every input it reads
  (`open_in` opens any of them by name; `_open`: the File menu's entries for it);
- `_live`: the segmentation of a layer and its cuts, without Qt (what the widget and
  its tests drive);
- `_widget`: the dock widget: parameters, a cancellable run in a thread, the live cut
  (region-count and threshold sliders beside the curve), region details, output set.

Importing this package imports nothing of napari or Qt; napari imports the modules
named in the manifest when it needs them.
"""

__all__ = ["open_in"]


def open_in(viewer, path) -> list:
    """Open `path` (any file or folder volseg reads) in `viewer` with volseg's reader;
    returns the layers added. The reader's patterns claim only what no other napari
    reader opens; this (and File > IO Utilities > Open a file with volseg) opens the
    rest by name."""
    from ._reader import open_in as opened

    return opened(viewer, path)
