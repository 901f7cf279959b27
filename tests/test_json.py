import json

import numpy as np
import pytest

from volseg import _json


def test_non_finite_numbers_become_null_and_numpy_scalars_plain_numbers():
    text = _json.dumps({"p": [float("inf"), np.float32(1.5), np.nan, np.int64(3)]})
    assert json.loads(text) == {"p": [None, 1.5, None, 3]}
    assert "Infinity" not in text and "NaN" not in text


def test_strict_parsers_accept_the_output():
    text = _json.dumps({"a": -np.inf, "b": [np.bool_(True)]})
    json.loads(text, parse_constant=lambda name: pytest.fail(f"non-standard {name}"))
