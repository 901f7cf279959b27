"""Sphinx configuration of volseg's documentation site (built by .ci/run with -W)."""

import volseg

project = "volseg"
copyright = "2026, the volseg developers"
version = release = volseg.__version__
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary",
              "sphinx.ext.napoleon", "sphinx.ext.viewcode"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True       # dataclass fields: one description each
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_typehints = "none"        # the numpydoc "Parameters" sections say the types
autosummary_generate = False
exclude_patterns = ["_build", "results"]
myst_heading_anchors = 3
# The guide's pages link files of the repository (code, figures) that are not pages.
suppress_warnings = ["myst.xref_missing", "myst.header"]
html_theme = "alabaster"
nitpicky = False
