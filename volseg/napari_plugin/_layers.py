"""A `Volume` as napari layer data, and a napari layer as a `Volume`.

napari shows the last two axes of a layer as the screen's rows and columns and
OME-Zarr images come as z, y, x: volseg's [x, y, z] arrays are shown transposed (a
view, no copy), and the frame's affine is permuted the same way, so a volseg layer
overlays the NGFF output opened by napari-ome-zarr and the input opened by anyone.
"""

from __future__ import annotations

import re

import numpy as np

from ..io import Frame, Volume

__all__ = ["to_layer", "frame_kwargs", "LayerVolume"]

#: The axes of every layer volseg makes.
AXES = ("z", "y", "x")


def to_layer(array):
    """An [x, y, z] array (numpy or Dask) as napari's [z, y, x] (a view)."""
    return array.transpose(2, 1, 0)


def frame_kwargs(frame: Frame) -> dict:
    """Layer keywords that place [z, y, x] data where `frame` puts its voxels: scale and
    translate for an axis-aligned frame, else the whole affine; the unit when known."""
    affine = frame.affine
    linear = affine[:3, :3][::-1, ::-1]
    offset = affine[:3, 3][::-1]
    diagonal = np.diag(linear)
    if np.array_equal(linear, np.diag(diagonal)) and (diagonal > 0).all():
        kwargs = {"scale": tuple(float(s) for s in diagonal),
                  "translate": tuple(float(t) for t in offset)}
    else:
        matrix = np.eye(4)
        matrix[:3, :3], matrix[:3, 3] = linear, offset
        kwargs = {"affine": matrix}
    kwargs["axis_labels"] = AXES
    if frame.unit:
        kwargs["units"] = (frame.unit,) * 3
    return kwargs


class LayerVolume:
    """The `Volume` behind an image layer and how its results become layers.

    A layer volseg's reader made carries its `Volume` (``metadata["volseg_volume"]``):
    that volume is segmented, exactly as ``volseg segment`` reads the file, and the
    results are shown transposed. Any other layer is a volume in its own axis order,
    its scale the voxel sizes and its translation the origin.
    """

    def __init__(self, layer):
        data = layer.data[0] if getattr(layer, "multiscale", False) else layer.data
        if len(data.shape) != 3:
            raise ValueError(f"layer {layer.name!r} has {len(data.shape)} dimensions "
                             f"{tuple(data.shape)}: volseg segments 3-D volumes")
        known = layer.metadata.get("volseg_volume")
        if isinstance(known, Volume) and tuple(to_layer(known.data).shape) == tuple(data.shape):
            self.volume, self.transposed = known, True
        else:
            self.volume, self.transposed = Volume(data, frame=_layer_frame(layer),
                                                  name=_stem(layer.name),
                                                  source=f"napari layer {layer.name!r}"), False
        self.layer_kwargs = _transform_kwargs(layer)

    def shown(self, array):
        """A result array ([x, y, z] of the volume) as data of a layer over the image."""
        return to_layer(array) if self.transposed else array

    def place(self, voxel) -> tuple:
        """(the layer's index, the world position) of a volume voxel, both in the
        layer's axis order (what napari's status bar shows)."""
        world = (self.volume.frame.affine @ [*voxel, 1.0])[:3]
        if self.transposed:
            return tuple(int(v) for v in voxel[::-1]), tuple(float(w) for w in world[::-1])
        return tuple(int(v) for v in voxel), tuple(float(w) for w in world)


def _transform_kwargs(layer) -> dict:
    kwargs = {"scale": tuple(layer.scale), "translate": tuple(layer.translate),
              "rotate": np.asarray(layer.rotate), "shear": np.asarray(layer.shear),
              "affine": np.asarray(layer.affine.affine_matrix)}
    if getattr(layer, "axis_labels", None) is not None:
        kwargs["axis_labels"] = tuple(layer.axis_labels)
    return kwargs


def _layer_frame(layer) -> Frame:
    """The data-to-world affine of a 3-D layer (its scale, translation, rotation,
    shear and affine composed as napari composes them) as a `Frame`."""
    from napari.utils.transforms import Affine

    physical = Affine(scale=layer.scale, translate=layer.translate, rotate=layer.rotate,
                      shear=layer.shear).affine_matrix
    return Frame(np.asarray(layer.affine.affine_matrix) @ physical)


def _stem(name: str) -> str:
    """A layer name as a file stem (the output set's file names)."""
    return re.sub(r"[^\w.-]+", "_", name).strip("._") or "layer"
