"""Moved to `volseg.outputs.preview`; this name keeps working for one release (deprecated)."""

import warnings

from .outputs.preview import *  # noqa: F403
from .outputs.preview import __all__  # noqa: F401

warnings.warn("volseg.preview is deprecated: import volseg.outputs.preview", DeprecationWarning,
              stacklevel=2)
