import os
from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "volvis"


@pytest.fixture(scope="session")
def volvis_dir():
    """The real Volvis datasets beside the clone (../shared/data/volvis); tests that
    need them are skipped, with the reason, on a machine without that mirror."""
    if not (SHARED_DATA / "SHA256SUMS").exists():
        pytest.skip(f"the Volvis mirror is not beside the clone (expected {SHARED_DATA}); "
                    "CI has it")
    return SHARED_DATA


@pytest.fixture(autouse=True)
def _data_dir_env(monkeypatch, tmp_path_factory):
    """Point dataset look-ups at the shared mirror and the cache at a temp folder."""
    monkeypatch.setenv("VOLSEG_DATA_DIR", os.fspath(SHARED_DATA))
    monkeypatch.setenv("VOLSEG_CACHE_DIR", os.fspath(tmp_path_factory.getbasetemp() / "cache"))


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def smooth_random_field(shape, rng, sigma=2.0):
    """A smooth random field (Gaussian-filtered white noise), float64."""
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
