"""The students' hand-ins of an exercise, in SQLite next to the exercise file.

One row per hand-in: when, who (the normalised id), the estimates, the
verdicts and the score. Every hand-in is its own transaction on its own
connection (the server hands in from worker threads): SQLite serialises the
writers, and with a busy timeout two students handing in at the same moment
both land. The database outlives the server; WAL mode lets the teacher read
the results while students hand in.

The file is the teacher's, like the exercise file: it is created readable by
its owner only (SQLite gives its journal files the same permissions). A file
that is not a usable database raises :class:`StoreError`, whose message says
what to do; one deleted while the server runs is made again at the next
hand-in (the server's log says so).

>>> import tempfile, pathlib
>>> store = HandIns(pathlib.Path(tempfile.mkdtemp()) / "class.json").check()
>>> store.add("ada", {"M": 4100.0}, {"M": True})
1
>>> [(r.student, r.score) for r in store.latest()]
[('ada', 1.0)]
"""

from __future__ import annotations

import json
import logging
import os
import sqlite3
import time
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

__all__ = ["HandIns", "HandIn", "StoreError", "handins_path"]

log = logging.getLogger("eha_app")


class StoreError(RuntimeError):
    """The hand-in database cannot be used: what is wrong and what to do."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS handins (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    time TEXT NOT NULL,
    student TEXT NOT NULL,
    estimates TEXT NOT NULL,
    verdicts TEXT NOT NULL,
    score REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS handins_student ON handins (student, id);
"""


def handins_path(exercise_path: str | Path) -> Path:
    """``class.json`` -> ``class.handins.sqlite`` beside it."""
    p = Path(exercise_path)
    return p.with_name(p.stem + ".handins.sqlite")


@dataclass(frozen=True)
class HandIn:
    id: int
    time: str
    student: str
    estimates: dict
    verdicts: dict
    score: float
    count: int = 1          # hand-ins of this student so far (in :meth:`HandIns.latest`)


class HandIns:
    """The hand-ins of the exercise at ``exercise_path``."""

    def __init__(self, exercise_path: str | Path):
        self.path = handins_path(exercise_path)
        self._opened = False

    def check(self) -> HandIns:
        """Open the database (made if missing) and check it: :class:`StoreError` if it is not usable.
        The server and the teacher's commands call it before anything else."""
        try:
            with closing(self._connect()) as db:
                db.execute("PRAGMA journal_mode=WAL")
                db.executescript(_SCHEMA)
                problem = db.execute("PRAGMA quick_check").fetchone()[0]
        except sqlite3.Error as exc:
            raise self._unusable(exc) from None
        if problem != "ok":
            raise self._unusable(problem)
        self._opened = True
        return self

    def _unusable(self, what) -> StoreError:
        return StoreError(f"the hand-in database {str(self.path)!r} cannot be used ({what}); move it away to start "
                          "an empty one, or put back a copy")

    def _connect(self) -> sqlite3.Connection:
        """A connection to the database, made (readable by its owner only) if it is missing."""
        if not self.path.exists():
            try:
                os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            except FileExistsError:
                pass                            # another thread or process made it meanwhile
            except OSError as exc:
                raise StoreError(f"the hand-in database {str(self.path)!r} cannot be made ({exc.strerror})") from None
            if self._opened:                    # it was deleted while the server ran
                log.warning("the hand-in database %s was missing: an empty one was made", self.path.name)
        return sqlite3.connect(self.path, timeout=30.0, isolation_level=None)

    def add(self, student: str, estimates: dict, verdicts: dict) -> int:
        """Store a hand-in; returns its row id. :class:`StoreError` if the database cannot take it."""
        score = sum(bool(v) for v in verdicts.values()) / max(len(verdicts), 1)
        now = time.strftime("%Y-%m-%d %H:%M:%S")
        try:
            db = self._connect()
        except sqlite3.Error as exc:
            raise self._unusable(exc) from None
        try:
            db.executescript(_SCHEMA)           # a database made again since has no table yet
            db.execute("BEGIN IMMEDIATE")
            cur = db.execute("INSERT INTO handins (time, student, estimates, verdicts, score) VALUES (?, ?, ?, ?, ?)",
                             (now, student, json.dumps(estimates), json.dumps(verdicts), score))
            db.execute("COMMIT")
            return int(cur.lastrowid)
        except sqlite3.Error as exc:
            try:
                if db.in_transaction:
                    db.execute("ROLLBACK")
            except sqlite3.Error:
                pass
            raise self._unusable(exc) from None
        finally:
            db.close()

    def all(self) -> list[HandIn]:
        try:
            with closing(self._connect()) as db:
                db.executescript(_SCHEMA)
                rows = db.execute("SELECT id, time, student, estimates, verdicts, score FROM handins "
                                  "ORDER BY id").fetchall()
            return [HandIn(r[0], r[1], r[2], json.loads(r[3]), json.loads(r[4]), r[5]) for r in rows]
        except (sqlite3.Error, ValueError, TypeError) as exc:
            raise self._unusable(exc) from None

    def latest(self) -> list[HandIn]:
        """Each student's last hand-in (with how many they made), by id."""
        last: dict[str, HandIn] = {}
        counts: dict[str, int] = {}
        for h in self.all():
            last[h.student] = h
            counts[h.student] = counts.get(h.student, 0) + 1
        return [HandIn(**{**h.__dict__, "count": counts[s]}) for s, h in sorted(last.items())]
