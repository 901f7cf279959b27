"""The napari plugin's tests need napari, pytest-qt, a Qt binding and a display (the
virtual one pytest-xvfb starts when Xvfb is installed): `missing` names what is not
there, and the tests are skipped with that reason while the rest of the suite runs."""

import importlib
import os
import shutil


def missing() -> str | None:
    """Why the plugin's tests cannot run here, or None."""
    for module, what in (("napari", "napari (pip install -e '.[test]' or '.[napari]')"),
                         ("pytestqt", "pytest-qt"), ("PyQt6", "a Qt binding (PyQt6)")):
        try:
            importlib.import_module(module)
        except Exception:       # not installed, or broken (a binding without its Qt)
            return f"the napari plugin's tests need {what}"
    if not os.environ.get("DISPLAY") and os.environ.get("QT_QPA_PLATFORM") != "offscreen":
        # Checked before any test: Qt aborts the process when it opens no display.
        hint = "" if shutil.which("Xvfb") else " (Debian: apt-get install xvfb libxcb-cursor0)"
        return f"no X display for napari's canvas: install Xvfb{hint}; pytest-xvfb starts it"
    return None
