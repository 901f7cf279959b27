"""Strict JSON for everything volseg writes: no NaN or Infinity tokens (which most
JSON parsers refuse); a non-finite float is written as null, numpy scalars and
arrays as plain numbers and lists."""

from __future__ import annotations

import json
import math

import numpy as np


def plain(value):
    """`value` with numpy types made Python ones and non-finite floats made None."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(value, **kwargs) -> str:
    """``json.dumps`` of `plain(value)`, refusing anything that would not be strict JSON."""
    return json.dumps(plain(value), allow_nan=False, **kwargs)
