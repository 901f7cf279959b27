"""Registry and fetch of the public Volvis datasets (Open SciVis Datasets).

Look-up order for a dataset file:

1. ``$VOLSEG_DATA_DIR`` (a local mirror folder; CI points it at
   ``../shared/data/volvis``);
2. the cache folder, ``$VOLSEG_CACHE_DIR`` or the user cache (``pooch.os_cache``);
3. a download into the cache (pooch: temporary file, checked, then moved).

Every file is checked against its SHA-256 before use; a mismatch is refused.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Dataset", "REGISTRY", "DatasetError", "fetch", "cache_dir", "sha256"]

BASE_URL = "https://klacansky.com/open-scivis-datasets"


class DatasetError(ValueError):
    """A dataset cannot be had: unknown name, offline, or a checksum mismatch."""


@dataclass(frozen=True)
class Dataset:
    name: str
    shape: tuple
    dtype: str
    sha256: str
    description: str

    @property
    def filename(self) -> str:
        x, y, z = self.shape
        return f"{self.name}_{x}x{y}x{z}_{self.dtype}.raw"

    @property
    def url(self) -> str:
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


def sha256(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def cache_dir() -> Path:
    if os.environ.get("VOLSEG_CACHE_DIR"):
        return Path(os.environ["VOLSEG_CACHE_DIR"])
    import pooch

    return Path(pooch.os_cache("volseg"))


def _checked(path: Path, dataset: Dataset) -> Path:
    actual = sha256(path)
    if actual != dataset.sha256:
        raise DatasetError(
            f"{path}: checksum mismatch for {dataset.name} (sha256 {actual}, expected "
            f"{dataset.sha256}); the file is corrupt or not the published one: delete it"
        )
    return path


def fetch(name: str, *, download: bool = True) -> Path:
    """Path of a verified local copy of dataset `name`, downloading it if needed.

    Raises
    ------
    DatasetError
        Unknown name, checksum mismatch, or no copy and no network (the message
        says where to put the file).
    """
    dataset = REGISTRY.get(name)
    if dataset is None:
        raise DatasetError(f"unknown dataset {name!r}; known: {', '.join(REGISTRY)}")
    mirror = os.environ.get("VOLSEG_DATA_DIR")
    if mirror and (Path(mirror) / dataset.filename).exists():
        return _checked(Path(mirror) / dataset.filename, dataset)
    cached = cache_dir() / dataset.filename
    if cached.exists():
        return _checked(cached, dataset)
    where = f"{cached} (or into a folder named by VOLSEG_DATA_DIR)"
    if not download:
        raise DatasetError(f"{dataset.filename} is not available locally; put it at {where}")
    import pooch

    pooch.get_logger().setLevel("WARNING")
    try:
        path = pooch.retrieve(dataset.url, known_hash=f"sha256:{dataset.sha256}",
                              fname=dataset.filename, path=cached.parent, progressbar=False)
    except ValueError as err:  # pooch's hash mismatch
        raise DatasetError(f"{dataset.url}: {err}") from None
    except Exception as err:  # network errors of any kind
        raise DatasetError(
            f"could not download {dataset.url} ({type(err).__name__}: {err}); "
            f"download it by hand and put it at {where}"
        ) from None
    return Path(path)
