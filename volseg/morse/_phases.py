"""Wall time per phase of a Morse build."""

from __future__ import annotations

import time

__all__ = []


class _Phases:
    """Wall time per phase of the build, in the order they ran (`MorseHierarchy.timings`)."""

    def __init__(self):
        self.times = {}
        self._last = time.perf_counter()

    def done(self, name):
        now = time.perf_counter()
        self.times[name] = self.times.get(name, 0.0) + now - self._last
        self._last = now
