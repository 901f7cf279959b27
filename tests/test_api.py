"""The public face: every name `volseg.__all__` promises exists, every submodule imports."""

import importlib
import pkgutil
import sys
from pathlib import Path

import pytest

import volseg


def test_every_public_name_resolves():
    for name in volseg.__all__:
        assert getattr(volseg, name) is not None, name
    assert sorted(volseg.__all__) == dir(volseg)


def test_star_import_works():
    namespace = {}
    exec("from volseg import *", namespace)
    assert "segment_volume" in namespace and "descending_complex" in namespace


def test_every_module_of_the_package_imports():
    for module in pkgutil.walk_packages(volseg.__path__, "volseg."):
        if module.name == "volseg.__main__":  # runs the command line
            continue
        importlib.import_module(module.name)


def test_no_deprecated_alias_is_left():
    """Nothing is released yet, so nothing needs an alias: the old module names are
    gone, and no keyword of the front doors is an old name of another."""
    import inspect

    for name in ("preview", "engine", "spacetime_outputs"):
        with pytest.raises(AttributeError):
            getattr(volseg, name)
        assert importlib.util.find_spec(f"volseg.{name}") is None
    for function, old in ((volseg.segment_volume, "smooth"), (volseg.segment_volume, "boundary"),
                          (volseg.segment_mesh, "smooth"), (volseg.grid_curvature, "boundary")):
        assert old not in inspect.signature(function).parameters, (function, old)
    assert not hasattr(volseg.Segmentation, "smooth")


def test_the_package_does_not_claim_types_it_does_not_check():
    """`py.typed` would tell mypy users our annotations are complete; they are not
    (mypy is not run on the package), so it is not shipped."""
    assert not (Path(volseg.__file__).parent / "py.typed").exists()


def test_the_package_imports_where_fcntl_does_not_exist():
    """Windows has no `fcntl`: `volseg.io`, the output sets and the command line import
    without it (the lock takes its OS primitive when it is taken)."""
    import subprocess

    code = ("import sys\n"
            "sys.modules['fcntl'] = None\n"          # import fcntl -> ImportError
            "import volseg.io, volseg.io.output_set, volseg.cli, volseg.files\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_the_version_is_written_in_one_place():
    """pyproject takes it from `volseg._version` (dynamic); no other file repeats it."""
    root = Path(__file__).resolve().parents[1]
    if not (root / "CITATION.cff").exists():
        pytest.skip("run from the repository (the wheel's test copy has no sources)")
    pyproject = (root / "pyproject.toml").read_text()
    project = pyproject.split("[project]")[1].split("\n[")[0]
    assert 'dynamic = ["version"]' in project and "\nversion =" not in project
    assert 'version = { attr = "volseg._version.__version__" }' in pyproject
    assert "\nversion:" not in (root / "CITATION.cff").read_text()
