"""The napari plugin's tests need napari, a Qt binding and a display (the virtual one
pytest-xvfb starts when Xvfb is installed); without them they are skipped, with the
reason, and the rest of the suite runs as before."""

import os
import shutil

import pytest

pytest.importorskip("napari", reason="the napari plugin's tests need napari "
                    "(pip install -e '.[test]' or '.[napari]')")
pytest.importorskip("pytestqt", reason="the napari plugin's tests need pytest-qt")
try:
    import qtpy  # noqa: F401
except Exception as err:  # qtpy raises its own error when no binding is installed
    pytest.skip(f"the napari plugin's tests need a Qt binding ({err})", allow_module_level=True)


@pytest.fixture(autouse=True)
def _display():
    """A display napari's canvas can draw on: pytest-xvfb's, or the user's."""
    if not os.environ.get("DISPLAY") and os.environ.get("QT_QPA_PLATFORM") != "offscreen":
        hint = "" if shutil.which("Xvfb") else " (Debian: apt-get install xvfb libxcb-cursor0)"
        pytest.skip(f"no X display for napari's canvas: install Xvfb{hint}; pytest-xvfb "
                    "then starts one")
