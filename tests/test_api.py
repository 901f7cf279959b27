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


#: Deprecated aliases of moved modules: they import, with a DeprecationWarning.
MOVED = {"volseg.preview", "volseg.engine", "volseg.spacetime_outputs"}


def test_every_module_of_the_package_imports():
    for module in pkgutil.walk_packages(volseg.__path__, "volseg."):
        if module.name == "volseg.__main__":  # runs the command line
            continue
        if module.name in MOVED:
            sys.modules.pop(module.name, None)
            with pytest.warns(DeprecationWarning, match="is deprecated"):
                importlib.import_module(module.name)
        else:
            importlib.import_module(module.name)


def test_the_package_says_it_is_typed():
    assert (Path(volseg.__file__).parent / "py.typed").exists()
