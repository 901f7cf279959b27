"""volseg: segment volumes by the discrete mean curvature of their graph in R^4.

The data flow is file -> `Volume` -> curvature field -> Morse hierarchy -> labels ->
metrics, and every stage is usable on its own::

    volume = volseg.read_volume("fuel_64x64x64_uint8.raw")
    curvature = volseg.grid_curvature(volume, "weighted")
    hierarchy = volseg.descending_complex(curvature)
    labels = hierarchy.segment(n_regions=30)

Submodules load on first use, so ``import volseg`` stays cheap.
"""

from importlib import import_module

from ._version import __version__

_PUBLIC = {
    "Volume": "volseg.io",
    "read_volume": "volseg.io",
    "write_volume": "volseg.io",
    "vertex_curvature": "volseg.curvature",
    "grid_curvature": "volseg.curvature",
    "default_value_scale": "volseg.curvature",
    "bending_angles": "volseg.curvature",
    "cotangent_weights": "volseg.curvature",
    "descending_complex": "volseg.morse",
    "MorseHierarchy": "volseg.morse",
    "segment_volume": "volseg.segment",
    "Segmentation": "volseg.segment",
    "segment_mesh": "volseg.segment",
    "isosurface": "volseg.tessellation",
    "hamming_similarity": "volseg.metrics",
    "compare": "volseg.metrics",
    "directional_hamming": "volseg.metrics",
    "region_ratio": "volseg.metrics",
    "variation_of_information": "volseg.metrics",
    "foreground_mask": "volseg.masks",
    "VolumeFileError": "volseg.io",
    "DatasetError": "volseg.datasets",
    "fetch": "volseg.datasets",
}
_SUBMODULES = {"io", "mesh", "curvature", "tessellation", "morse", "metrics", "masks",
               "segment", "analytic", "noise", "outputs", "blockwise", "datasets", "files",
               "errors", "spacetime", "cli"}

__all__ = ["__version__", *_PUBLIC, *sorted(_SUBMODULES)]


def __getattr__(name):
    if name in _PUBLIC:
        value = getattr(import_module(_PUBLIC[name]), name)
    elif name in _SUBMODULES:
        value = import_module(f"volseg.{name}")
    else:
        raise AttributeError(f"module 'volseg' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
