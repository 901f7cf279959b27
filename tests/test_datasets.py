"""volseg.datasets: the registry, the mirror -> cache -> network order, checksums."""

import numpy as np
import pooch
import pytest

from volseg import datasets
from volseg.datasets import REGISTRY, DatasetError, available_locally, fetch, resolve


def test_registry_file_names_and_urls():
    fuel = REGISTRY["fuel"]
    assert fuel.filename == "fuel_64x64x64_uint8.raw"
    assert fuel.url.endswith("/fuel/fuel_64x64x64_uint8.raw")
    assert set(REGISTRY) == {"fuel", "neghip", "silicium", "nucleon", "tooth"}


def test_the_mirror_is_used_first_and_checked(volvis_dir):
    path = fetch("nucleon", download=False)
    assert path.parent == volvis_dir
    assert datasets.sha256(path) == REGISTRY["nucleon"].sha256 == pooch.file_hash(str(path))


def test_a_verified_cache_copy_is_used_when_there_is_no_mirror(tmp_path, monkeypatch, volvis_dir):
    monkeypatch.setenv("VOLSEG_DATA_DIR", str(tmp_path / "no-mirror"))
    monkeypatch.setenv("VOLSEG_CACHE_DIR", str(tmp_path / "cache"))
    assert available_locally("nucleon") is None
    (tmp_path / "cache").mkdir()
    name = REGISTRY["nucleon"].filename
    (tmp_path / "cache" / name).write_bytes((volvis_dir / name).read_bytes())
    assert fetch("nucleon", download=False) == tmp_path / "cache" / name
    # A corrupt cached copy is not used (pooch would download it again).
    (tmp_path / "cache" / name).write_bytes(b"\0" * 10)
    assert available_locally("nucleon") is None
    with pytest.raises(DatasetError, match="put it at .*cache"):
        fetch("nucleon", download=False)


def test_a_corrupt_mirror_file_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("VOLSEG_DATA_DIR", str(tmp_path))
    (tmp_path / REGISTRY["tooth"].filename).write_bytes(b"not a tooth")
    with pytest.raises(DatasetError, match="checksum mismatch for tooth"):
        fetch("tooth")


def test_unknown_names_and_paths(tmp_path):
    with pytest.raises(DatasetError, match="unknown dataset 'bonsai'"):
        fetch("bonsai")
    with pytest.raises(DatasetError, match="not a dataset name"):
        resolve("bonsai")
    missing = tmp_path / "missing.raw"
    assert resolve(str(missing)) == missing  # the reader names a missing path


def test_demo_volume_is_built_in():
    volume = datasets.demo_volume(16)
    assert volume.shape == (16, 16, 16) and volume.dtype == np.uint8
    assert volume.max() == 255 and 0.3 < np.mean(volume == 0) < 0.7
