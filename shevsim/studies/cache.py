"""cache.py - the study evaluation cache: one committed SQLite row per finished evaluation.

Table ``evaluations``::

    key TEXT PRIMARY KEY      -- evaluation key (evaluate.py: inputs + scenario files + code version)
    inputs TEXT               -- JSON description of the evaluation
    outputs TEXT              -- JSON dict of outputs (metrics)
    wall_s REAL               -- wall time of the evaluation in its worker (s)
    created_utc TEXT          -- ISO time the row was written

Write pattern: a single writer (the study's client process) inserts a row and commits as each
evaluation's future completes, so a study stopped at any point (Ctrl-C, kill, crash) keeps every
finished evaluation and resumes without repeating it. The database runs in WAL mode with
``synchronous=FULL``; readers (e.g. a second process inspecting progress) do not block the writer.
Standard library only (``sqlite3``).
"""
from __future__ import annotations

import json
import sqlite3
import threading
from datetime import datetime, timezone
from pathlib import Path

from ..core.errors import ShevsimError

_SCHEMA = """
CREATE TABLE IF NOT EXISTS evaluations (
    key TEXT PRIMARY KEY,
    inputs TEXT NOT NULL,
    outputs TEXT NOT NULL,
    wall_s REAL,
    created_utc TEXT NOT NULL
)
"""


class EvaluationCache:
    """SQLite store of finished evaluations keyed by their deterministic key.

    Parameters
    ----------
    path : str or Path
        Database file (created with its folder if missing); ``":memory:"`` for a throw-away cache.
    """

    def __init__(self, path: str | Path):
        self.path = str(path)
        if self.path != ":memory:":
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        try:
            self._con = sqlite3.connect(self.path, timeout=30.0, isolation_level=None,
                                        check_same_thread=False)
            self._con.execute("PRAGMA journal_mode=WAL")
            self._con.execute("PRAGMA synchronous=FULL")
            self._con.execute(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise ShevsimError(f"{self.path}: cannot open the evaluation cache: {exc}") from exc
        self._lock = threading.Lock()

    # -- reading -----------------------------------------------------------------------------------
    def get(self, key: str) -> dict | None:
        """Outputs of a finished evaluation, or None."""
        with self._lock:
            row = self._con.execute("SELECT outputs FROM evaluations WHERE key = ?", (key,)).fetchone()
        return None if row is None else json.loads(row[0])

    def get_many(self, keys) -> dict[str, dict]:
        """``{key: outputs}`` for the keys that are in the cache."""
        keys = list(dict.fromkeys(keys))
        found: dict[str, dict] = {}
        with self._lock:
            for i in range(0, len(keys), 500):
                chunk = keys[i:i + 500]
                q = f"SELECT key, outputs FROM evaluations WHERE key IN ({','.join('?' * len(chunk))})"
                for k, o in self._con.execute(q, chunk):
                    found[k] = json.loads(o)
        return found

    def __contains__(self, key: str) -> bool:
        with self._lock:
            return self._con.execute("SELECT 1 FROM evaluations WHERE key = ?", (key,)).fetchone() is not None

    def __len__(self) -> int:
        with self._lock:
            return self._con.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0]

    def rows(self) -> list[dict]:
        """All rows (key, inputs, outputs, wall_s, created_utc) in insertion order."""
        with self._lock:
            cur = self._con.execute("SELECT key, inputs, outputs, wall_s, created_utc FROM evaluations ORDER BY rowid")
            return [{"key": k, "inputs": json.loads(i), "outputs": json.loads(o), "wall_s": w, "created_utc": c}
                    for k, i, o, w, c in cur]

    # -- writing -----------------------------------------------------------------------------------
    def put(self, key: str, inputs: dict, outputs: dict, wall_s: float | None = None) -> None:
        """Insert one finished evaluation and commit it (durable when this returns)."""
        row = (key, json.dumps(inputs, sort_keys=True, allow_nan=True, default=str),
               json.dumps(outputs, sort_keys=True, allow_nan=True, default=str),
               None if wall_s is None else float(wall_s), datetime.now(timezone.utc).isoformat(timespec="seconds"))
        with self._lock:
            self._con.execute("BEGIN IMMEDIATE")
            try:
                self._con.execute("INSERT OR REPLACE INTO evaluations VALUES (?, ?, ?, ?, ?)", row)
                self._con.execute("COMMIT")
            except BaseException:
                self._con.execute("ROLLBACK")
                raise

    def close(self) -> None:
        with self._lock:
            self._con.close()

    def __enter__(self) -> "EvaluationCache":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
