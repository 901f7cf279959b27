"""Sphinx configuration of volseg's documentation site (built by .ci/run with -W)."""

import os
import sys
from pathlib import Path

import volseg

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

project = "volseg"
copyright = "2026, the volseg developers"
version = release = volseg.__version__
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary",
              "sphinx.ext.napoleon", "sphinx.ext.viewcode", "sphinx_gallery.gen_gallery",
              "sphinx.ext.intersphinx", "cli_reference"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True       # dataclass fields: one description each
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_typehints = "none"        # the numpydoc "Parameters" sections say the types
autosummary_generate = False
exclude_patterns = ["_build", "results", "gallery/*.ipynb", "gallery/*.py"]
myst_heading_anchors = 3
# The guide's pages link files of the repository (code, figures) that are not pages.
suppress_warnings = ["myst.xref_missing", "myst.header"]
html_theme = "alabaster"
nitpicky = False

# The gallery: examples/ run and rendered with their figures and output. They read the
# Volvis mirror beside the clone (../shared/data/volvis, as the tests do); without it
# the examples that need a dataset are left out, and the page says which.
_MIRROR = DOCS.parent.parent / "shared" / "data" / "volvis"
if "VOLSEG_DATA_DIR" not in os.environ and (_MIRROR / "SHA256SUMS").exists():
    os.environ["VOLSEG_DATA_DIR"] = str(_MIRROR)
_NEEDS_MIRROR = ["plot_dataset_cut.py", "plot_compare.py", "plot_noise_stability.py"]
sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "ignore_pattern": ("__init__" if os.environ.get("VOLSEG_DATA_DIR")
                       else "|".join(_NEEDS_MIRROR)),
    "abort_on_example_error": True,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
}

# Names in single backticks are cross-references (volseg's own, and through intersphinx
# numpy's, scipy's, dask's ...); one that resolves nowhere is shown as code.
default_role = "py:obj"
# The API links into these projects' documentation when their inventories can be
# fetched. A build without the network (CI: only the package registries) leaves them
# out and says so: intersphinx would fail the warnings-as-errors build.
_INVENTORIES = {
    "python": "https://docs.python.org/3/",
    "numpy": "https://numpy.org/doc/stable/",
    "scipy": "https://docs.scipy.org/doc/scipy/",
    "dask": "https://docs.dask.org/en/stable/",
    "networkx": "https://networkx.org/documentation/stable/",
    "nibabel": "https://nipy.org/nibabel/",
    "zarr": "https://zarr.readthedocs.io/en/stable/",
}


def _reachable(url: str) -> bool:
    import urllib.request

    try:
        with urllib.request.urlopen(url + "objects.inv", timeout=3) as response:
            return response.status == 200
    except Exception:        # offline, refused, a proxy's error page: no links
        return False


if os.environ.get("VOLSEG_DOCS_OFFLINE"):
    intersphinx_mapping = {}
else:
    intersphinx_mapping = {name: (url, None) for name, url in _INVENTORIES.items()
                           if _reachable(url)}
_left_out = sorted(set(_INVENTORIES) - set(intersphinx_mapping))
if _left_out:
    print(f"volseg docs: no links into {', '.join(_left_out)} (their inventories are not "
          "reachable from here)")
