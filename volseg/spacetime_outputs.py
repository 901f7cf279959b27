"""Moved to `volseg.outputs.spacetime`; this name keeps working for one release (deprecated)."""

import warnings

from .outputs.spacetime import *  # noqa: F403
from .outputs.spacetime import __all__  # noqa: F401

warnings.warn("volseg.spacetime_outputs is deprecated: import "
              "volseg.outputs.spacetime", DeprecationWarning,
              stacklevel=2)
