"""Results of batch runs in SQLite: one row per task, committed as each task ends.

A run is resumable because the row is the record of completion: a task whose row
says ``done`` is never run again; killing the process loses only the tasks in flight
(SQLite commits are atomic, so there is never a half-written row).
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from volseg import _json

__all__ = ["ResultStore"]


class ResultStore:
    """Rows keyed by a task's defining parameters, in ``<folder>/<name>.sqlite``.

    Parameters
    ----------
    path : str or Path
        The database file (created with its folder).
    key_columns : sequence of str
        The columns that define a task (the primary key). Every other field of a
        recorded row is stored in a JSON column, so pipelines can add metrics
        without a schema change; it is strict JSON (a non-finite number is null).
    """

    def __init__(self, path, key_columns):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.key_columns = tuple(key_columns)
        self._db = sqlite3.connect(self.path, timeout=60)
        self._db.execute("PRAGMA journal_mode=WAL")
        columns = ", ".join(f'"{c}"' for c in self.key_columns)
        self._db.execute(
            f"CREATE TABLE IF NOT EXISTS tasks ({columns}, status TEXT NOT NULL, "
            f"error TEXT, data TEXT NOT NULL, PRIMARY KEY ({columns}))"
        )
        self._db.execute("CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, data TEXT)")
        self._db.commit()
        found = [row[1] for row in self._db.execute("PRAGMA table_info(tasks)")]
        if tuple(found[: len(self.key_columns)]) != self.key_columns:
            self._db.close()
            raise ValueError(
                f"{self.path} keys its tasks by {found[:-3]}, not {list(self.key_columns)} "
                "(written by another version of this pipeline); use a new output folder"
            )

    def close(self):
        self._db.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def key(self, row: dict) -> tuple:
        return tuple(row[c] for c in self.key_columns)

    def done_keys(self) -> set:
        """Keys of the tasks that finished without error."""
        columns = ", ".join(f'"{c}"' for c in self.key_columns)
        return {tuple(r) for r in self._db.execute(
            f"SELECT {columns} FROM tasks WHERE status = 'done'")}

    def record(self, row: dict, *, status="done", error=None):
        """Insert or replace one task's row and commit it at once."""
        data = {k: v for k, v in row.items() if k not in self.key_columns}
        marks = ", ".join("?" * (len(self.key_columns) + 3))
        self._db.execute(f"INSERT OR REPLACE INTO tasks VALUES ({marks})",
                         (*self.key(row), status, error, _json.dumps(data)))
        self._db.commit()

    def set_meta(self, name: str, value):
        self._db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (name, _json.dumps(value)))
        self._db.commit()

    def meta(self, name: str, default=None):
        found = self._db.execute("SELECT data FROM meta WHERE name = ?", (name,)).fetchone()
        return json.loads(found[0]) if found else default

    def rows(self, status=None) -> list[dict]:
        """All rows as dictionaries (key columns, status, error and the data fields)."""
        query = "SELECT * FROM tasks" + (" WHERE status = ?" if status else "")
        cursor = self._db.execute(query, (status,) if status else ())
        names = [d[0] for d in cursor.description]
        out = []
        for values in cursor:
            record = dict(zip(names, values, strict=True))
            record.update(json.loads(record.pop("data")))
            out.append(record)
        return out

    def export_csv(self, path) -> Path:
        """Write every row to `path` as CSV (atomically: temporary file, then rename)."""
        from ._output import write_csv

        return write_csv(path, self.rows(), first=[*self.key_columns, "status", "error"])
