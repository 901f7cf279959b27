"""Sphinx configuration of volseg's API reference (built by .ci/run with -W)."""

import volseg

project = "volseg"
copyright = "2026, the volseg developers"
version = release = volseg.__version__
extensions = ["sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon",
              "sphinx.ext.viewcode"]
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True       # dataclass fields: one description each
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_typehints = "none"        # the numpydoc "Parameters" sections say the types
autosummary_generate = False
exclude_patterns = ["_build"]
html_theme = "alabaster"
nitpicky = False
