"""pipelines.store.ResultStore, directly: keys, resumption, strict JSON, schema refusal."""

import json
import math

import pytest

from pipelines.store import ResultStore


def test_rows_are_keyed_replaced_and_survive_reopening(tmp_path):
    path = tmp_path / "r" / "results.sqlite"
    with ResultStore(path, ["dataset", "seed"]) as store:
        store.record({"dataset": "a", "seed": 1, "score": 0.5})
        store.record({"dataset": "a", "seed": 2, "score": math.inf}, status="error", error="boom")
        store.record({"dataset": "a", "seed": 1, "score": 0.75})  # replaces
        store.set_meta("threshold", {"a": 0.1})
    with ResultStore(path, ["dataset", "seed"]) as store:
        assert store.done_keys() == {("a", 1)}
        rows = {r["seed"]: r for r in store.rows()}
        assert rows[1]["score"] == 0.75 and rows[2]["score"] is None
        assert rows[2]["status"] == "error" and rows[2]["error"] == "boom"
        assert store.meta("threshold") == {"a": 0.1} and store.meta("nothing", 3) == 3
        csv = store.export_csv(tmp_path / "rows.csv").read_text().splitlines()
    assert csv[0].startswith("dataset,seed,status,error") and len(csv) == 3


def test_a_store_with_other_keys_is_refused(tmp_path):
    path = tmp_path / "results.sqlite"
    ResultStore(path, ["dataset", "seed"]).close()
    with pytest.raises(ValueError, match="keys its tasks by .*use a new output folder"):
        ResultStore(path, ["dataset", "mask", "seed"])


def test_stored_data_is_strict_json(tmp_path):
    import sqlite3

    path = tmp_path / "results.sqlite"
    with ResultStore(path, ["k"]) as store:
        store.record({"k": 1, "x": float("nan")})
    raw = sqlite3.connect(path).execute("SELECT data FROM tasks").fetchone()[0]
    assert json.loads(raw, parse_constant=lambda c: pytest.fail(c)) == {"x": None}
