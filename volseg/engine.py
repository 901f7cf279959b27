"""Moved to `volseg.blockwise.engine`; this name keeps working for one release (deprecated)."""

import warnings

from .blockwise.engine import *  # noqa: F403
from .blockwise.engine import __all__  # noqa: F401

warnings.warn("volseg.engine is deprecated: import volseg.blockwise.engine", DeprecationWarning,
              stacklevel=2)
