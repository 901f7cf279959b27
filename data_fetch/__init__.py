"""Registry and fetch of the public datasets: the name the design card uses.

Everything lives in `volseg.datasets`; this package only re-exports it.
"""

from volseg.datasets import *  # noqa: F401,F403
from volseg.datasets import __all__  # noqa: F401
