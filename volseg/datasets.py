"""The public Volvis datasets (Open SciVis Datasets): registry and verified local copies.

Look-up order for a dataset file:

1. ``$VOLSEG_DATA_DIR`` (a local mirror folder, read only; CI points it at
   ``../shared/data/volvis``);
2. the cache folder, ``$VOLSEG_CACHE_DIR`` or the user cache (``pooch.os_cache``);
3. a download into the cache, by pooch (temporary file, checked, then moved).

Every file is checked against its SHA-256 before use (hashlib); a corrupt
mirror file is refused, a corrupt cached file is downloaded again.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DatasetError  # noqa: F401 (re-exported)

__all__ = ["Dataset", "REGISTRY", "DatasetError", "fetch", "resolve", "cache_dir", "sha256",
           "available_locally", "demo_volume"]

BASE_URL = "https://klacansky.com/open-scivis-datasets"


@dataclass(frozen=True)
class Dataset:
    """A public dataset: its name, grid, type, size and SHA-256."""

    name: str
    shape: tuple
    dtype: str
    sha256: str
    description: str

    @property
    def filename(self) -> str:
        """The file name, as the Volvis archive names it."""
        x, y, z = self.shape
        return f"{self.name}_{x}x{y}x{z}_{self.dtype}.raw"

    @property
    def url(self) -> str:
        """Where the dataset is downloaded from."""
        return f"{BASE_URL}/{self.name}/{self.filename}"


REGISTRY = {
    d.name: d
    for d in [
        Dataset("fuel", (64, 64, 64), "uint8",
                "349321dc4668d034bc7a299340d651033b44cb759c0d67b4b43c6faa7d485728",
                "simulation of fuel injection into a combustion chamber"),
        Dataset("neghip", (64, 64, 64), "uint8",
                "72cfeacbc7e5d6612198a169a3f2d6df09d78f67506ffa83b0f34498d9d85872",
                "electron probability distribution in a high-potential protein molecule"),
        Dataset("silicium", (98, 34, 34), "uint8",
                "adbf15c3d292e222f81464050c04fac923d416af20e8bb5eb83bd374d79a1e54",
                "simulation of a silicium grid"),
        Dataset("nucleon", (41, 41, 41), "uint8",
                "6fe2992a994f6150d7300c3c5a143ba9e8aa4bb9f38c77ce0d9b512ebd286c60",
                "two-body distribution probability of a nucleon in 16O"),
        Dataset("tooth", (103, 94, 161), "uint8",
                "1ae7d4681ad9b58c3778af0742f3c585354625a6aed232a181c93c669522172e",
                "CT scan of a tooth"),
    ]
}



def sha256(path) -> str:
    """SHA-256 of a file, hex (hashlib's, as `pooch.file_hash` computes it; pooch's
    import alone costs a run from the mirror 47 ms)."""
    import hashlib

    with open(path, "rb") as handle:
        return hashlib.file_digest(handle, "sha256").hexdigest()


def cache_dir() -> Path:
    """Where downloads go: ``$VOLSEG_CACHE_DIR``, else the user cache."""
    import pooch

    return Path(os.environ.get("VOLSEG_CACHE_DIR") or pooch.os_cache("volseg"))


def _pooch():
    import pooch

    pooch.get_logger().setLevel("WARNING")
    return pooch.create(
        path=cache_dir(), base_url=f"{BASE_URL}/",
        registry={d.filename: f"sha256:{d.sha256}" for d in REGISTRY.values()},
        urls={d.filename: d.url for d in REGISTRY.values()},
    )


def _dataset(name: str) -> Dataset:
    dataset = REGISTRY.get(name)
    if dataset is None:
        raise DatasetError(f"unknown dataset {name!r}; known: {', '.join(REGISTRY)}")
    return dataset


def _mirror_copy(dataset: Dataset) -> Path | None:
    mirror = os.environ.get("VOLSEG_DATA_DIR")
    path = Path(mirror) / dataset.filename if mirror else None
    if path is None or not path.exists():
        return None
    actual = sha256(path)
    if actual != dataset.sha256:
        raise DatasetError(
            f"{path}: checksum mismatch for {dataset.name} (sha256 {actual}, expected "
            f"{dataset.sha256}); the file is corrupt or not the published one: replace it"
        )
    return path


def available_locally(name: str) -> Path | None:
    """The verified mirror or cache copy of dataset `name`, or None (never downloads)."""
    dataset = _dataset(name)
    path = _mirror_copy(dataset)
    if path is not None:
        return path
    cached = cache_dir() / dataset.filename
    return cached if cached.exists() and sha256(cached) == dataset.sha256 else None


def fetch(name: str, *, download: bool = True) -> Path:
    """Path of a verified local copy of dataset `name`, downloading it if needed.

    Raises
    ------
    DatasetError
        Unknown name, a mirror file with the wrong checksum, or no copy and no
        network (the message says where to put the file).
    """
    dataset = _dataset(name)
    local = available_locally(name)
    if local is not None:
        return local
    where = f"{cache_dir() / dataset.filename} (or into a folder named by VOLSEG_DATA_DIR)"
    if not download:
        raise DatasetError(f"{dataset.filename} is not available locally; put it at {where}")
    try:
        return Path(_pooch().fetch(dataset.filename, progressbar=False))
    except ValueError as err:  # pooch's hash mismatch after download
        raise DatasetError(f"{dataset.url}: {err}") from None
    except Exception as err:  # network errors of any kind
        raise DatasetError(
            f"could not download {dataset.url} ({type(err).__name__}: {err}); "
            f"download it by hand and put it at {where}"
        ) from None


def resolve(spec: str) -> Path:
    """A volume path as given, or the verified local file of dataset name `spec`.

    Raises
    ------
    DatasetError
        `spec` is neither an existing file nor a known name, and does not look like a
        path (no folder separator, no extension); see also `fetch`. A missing path
        is returned as is, so the reader names it.
    """
    path = Path(spec)
    if path.exists() or spec not in REGISTRY:
        if not path.exists() and os.sep not in spec and "." not in spec:
            raise DatasetError(f"{spec}: no such file, and not a dataset name "
                               f"(known: {', '.join(REGISTRY)})")
        return path
    return fetch(spec)


def demo_series(n: int = 24, steps: int = 12):
    """The built-in time series (`volseg demo --time`): two Gaussian blobs that drift
    toward each other and merge, (n, n, n, steps) float32 in [0, 1]; its isosurface
    at 0.5 is two spheres that join into one over time. No file, no network."""
    axis = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    out = np.empty((n, n, n, steps), dtype=np.float32)
    for t in range(steps):
        s = t / (steps - 1)
        centre = 0.55 * (1 - s) + 0.12 * s           # half the separation, closing in
        wobble = 0.15 * np.sin(np.pi * s)           # and drifting up while they do
        f = (np.exp(-((x - centre) ** 2 + (y - wobble) ** 2 + z ** 2) / (2 * 0.22 ** 2))
             + 0.9 * np.exp(-((x + centre) ** 2 + (y + 0.5 * wobble) ** 2 + z ** 2)
                            / (2 * 0.2 ** 2)))
        out[..., t] = f
    return out


def demo_volume(n: int = 48):
    """The built-in demo volume (`volseg demo`): three Gaussian blobs and a curved ridge,
    uint8, n^3 voxels, about half of them 0. No file, no network."""
    axis = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    f = np.zeros_like(x)
    for (cx, cy, cz), w, a in [((-0.4, -0.3, 0.1), 0.25, 1.0), ((0.45, 0.3, -0.2), 0.2, 0.8),
                               ((0.1, 0.5, 0.5), 0.15, 0.6)]:
        f += a * np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (2 * w * w))
    ridge = np.exp(-((y + 0.5 * x**2 - 0.55) ** 2 + (z + 0.5) ** 2) / (2 * 0.08**2))
    f += 0.5 * ridge
    return np.round(255 * f / f.max()).astype(np.uint8)
