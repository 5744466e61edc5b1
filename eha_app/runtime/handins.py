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
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["HandIns", "HandIn", "StoreError", "Refused", "handins_path"]

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
CREATE TABLE IF NOT EXISTS control (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS presence (student TEXT PRIMARY KEY, joined TEXT NOT NULL, last_seen TEXT NOT NULL);
"""
#: Columns added since the first version (a database made by it gets them at the next start).
_ADDED = (("method", "TEXT NOT NULL DEFAULT 'lse'"), ("settings", "TEXT NOT NULL DEFAULT '{}'"),
          ("conditions", "TEXT NOT NULL DEFAULT '{}'"), ("errors", "TEXT NOT NULL DEFAULT '{}'"))


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
    method: str = "lse"
    settings: dict = field(default_factory=dict)
    conditions: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)      # relative errors against the truth: the teacher's only


_COLUMNS = "id, time, student, estimates, verdicts, score, method, settings, conditions, errors"


def _row(r) -> HandIn:
    return HandIn(r[0], r[1], r[2], json.loads(r[3]), json.loads(r[4]), r[5], method=r[6],
                  settings=json.loads(r[7]), conditions=json.loads(r[8]), errors=json.loads(r[9]))


def _now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


class HandIns:
    """The hand-ins of the exercise at ``exercise_path``, the teacher's switches (``control``: open or
    closed, an extended deadline, revealed) and who has joined and when they were last seen."""

    def __init__(self, exercise_path: str | Path):
        self.path = handins_path(exercise_path)
        self._opened = False

    def check(self) -> HandIns:
        """Open the database (made if missing) and check it: :class:`StoreError` if it is not usable.
        The server and the teacher's commands call it before anything else."""
        if self.path.parent.exists() and not os.access(self.path.parent, os.W_OK):
            raise StoreError(f"the folder {str(self.path.parent)!r} of the hand-in database is read-only; the "
                             "server could not store a single hand-in: serve from a folder you can write to")
        try:
            with closing(self._connect()) as db:
                db.execute("PRAGMA journal_mode=WAL")
                self._schema(db)
                problem = db.execute("PRAGMA quick_check").fetchone()[0]
        except sqlite3.Error as exc:
            raise self._unusable(exc) from None
        if problem != "ok":
            raise self._unusable(problem)
        self._opened = True
        return self

    @staticmethod
    def _schema(db) -> None:
        db.executescript(_SCHEMA)           # a database made again since has no table yet
        have = {r[1] for r in db.execute("PRAGMA table_info(handins)")}
        for name, decl in _ADDED:
            if name not in have:
                try:
                    db.execute(f"ALTER TABLE handins ADD COLUMN {name} {decl}")
                except sqlite3.OperationalError:
                    pass                    # another process added it meanwhile

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

    def _write(self, fn):
        """Run ``fn(db)`` in one immediate transaction; :class:`StoreError` if the database cannot take it."""
        try:
            db = self._connect()
        except sqlite3.Error as exc:
            raise self._unusable(exc) from None
        try:
            self._schema(db)
            db.execute("BEGIN IMMEDIATE")
            out = fn(db)
            db.execute("COMMIT")
            return out
        except sqlite3.Error as exc:
            try:
                if db.in_transaction:
                    db.execute("ROLLBACK")
            except sqlite3.Error:
                pass
            raise self._unusable(exc) from None
        finally:
            db.close()

    def _read(self, sql: str, args=()) -> list:
        try:
            with closing(self._connect()) as db:
                self._schema(db)
                return db.execute(sql, args).fetchall()
        except sqlite3.Error as exc:
            raise self._unusable(exc) from None

    def add(self, student: str, estimates: dict, verdicts: dict, *, method: str = "lse", settings: dict | None = None,
            conditions: dict | None = None, errors: dict | None = None, refusal=None) -> int:
        """Store a hand-in; returns its row id. :class:`StoreError` if the database cannot take it.

        ``refusal(count)``, if given, is asked inside the transaction with the student's number of
        hand-ins so far (two pages of one student handing in at once cannot both take the last
        attempt): a message it returns is raised as :class:`Refused` and nothing is stored."""
        score = sum(bool(v) for v in verdicts.values()) / max(len(verdicts), 1)

        def insert(db):
            if refusal is not None:
                count = db.execute("SELECT COUNT(*) FROM handins WHERE student = ?", (student,)).fetchone()[0]
                why = refusal(count)
                if why:
                    raise Refused(why)
            cur = db.execute("INSERT INTO handins (time, student, estimates, verdicts, score, method, settings, "
                             "conditions, errors) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                             (_now(), student, json.dumps(estimates), json.dumps(verdicts), score, method,
                              json.dumps(settings or {}), json.dumps(conditions or {}), json.dumps(errors or {})))
            return int(cur.lastrowid)
        try:
            return self._write(insert)
        except Refused:
            raise

    def all(self) -> list[HandIn]:
        try:
            return [_row(r) for r in self._read(f"SELECT {_COLUMNS} FROM handins ORDER BY id")]
        except (ValueError, TypeError) as exc:
            raise self._unusable(exc) from None

    def of(self, student: str) -> list[HandIn]:
        """One student's hand-ins, oldest first."""
        try:
            return [_row(r) for r in self._read(f"SELECT {_COLUMNS} FROM handins WHERE student = ? ORDER BY id",
                                                (student,))]
        except (ValueError, TypeError) as exc:
            raise self._unusable(exc) from None

    def latest(self) -> list[HandIn]:
        """Each student's last hand-in (with how many they made), by id."""
        last: dict[str, HandIn] = {}
        counts: dict[str, int] = {}
        for h in self.all():
            last[h.student] = h
            counts[h.student] = counts.get(h.student, 0) + 1
        return [HandIn(**{**h.__dict__, "count": counts[s]}) for s, h in sorted(last.items())]

    # -- the teacher's switches and the class's presence ------------------------------------
    def control(self) -> dict[str, str]:
        """``open`` ("1"/"0"), ``deadline`` (an extension, ISO-8601) and ``revealed`` ("1"/"0"), as set."""
        return dict(self._read("SELECT key, value FROM control"))

    def set_control(self, key: str, value: str) -> None:
        if key not in ("open", "deadline", "revealed"):
            raise ValueError(f"unknown switch {key!r}")
        self._write(lambda db: db.execute("INSERT INTO control (key, value) VALUES (?, ?) ON CONFLICT(key) DO "
                                          "UPDATE SET value = excluded.value", (key, str(value))))

    def seen(self, student: str) -> None:
        """The student is here now (joined the first time)."""
        now = _now()
        self._write(lambda db: db.execute("INSERT INTO presence (student, joined, last_seen) VALUES (?, ?, ?) ON "
                                          "CONFLICT(student) DO UPDATE SET last_seen = excluded.last_seen",
                                          (student, now, now)))

    def presence(self) -> dict[str, tuple[str, str]]:
        """student -> (joined, last seen)."""
        return {r[0]: (r[1], r[2]) for r in self._read("SELECT student, joined, last_seen FROM presence")}

    def version(self) -> tuple:
        """Changes whenever a hand-in, a switch or a presence changes (what a live page polls)."""
        rows = self._read("SELECT (SELECT COUNT(*) FROM handins), (SELECT MAX(id) FROM handins), "
                          "(SELECT group_concat(key || '=' || value) FROM control), "
                          "(SELECT COUNT(*) FROM presence), (SELECT MAX(last_seen) FROM presence)")
        return tuple(rows[0])


class Refused(StoreError):
    """A hand-in the exercise's rules refuse (deadline, attempts, closed): the message says which."""
