"""The students' hand-ins of an exercise, and the rest of the lab's state, in its database: SQLite next
to the exercise file by default, or a PostgreSQL database every server of a course shares
(``eha serve --store postgresql://...``; :mod:`eha_app.runtime.store_backend`).

One row per hand-in: when, who (the normalised id), the estimates, the
verdicts, the score, where the data came from (the student's own actuator's
experiment, or an uploaded file with its name and digest) and the key its page
gave it (a hand-in sent again is stored once). Every hand-in is its own
transaction, serialised by the backend (the server hands in from worker
threads, several servers at once). The database outlives the server; the
teacher reads the results while students hand in.

Nothing here runs on the server's event loop (the callers use worker threads or
:mod:`eha_app.runtime.store_calls`), and nothing waits long on a lock: each
attempt gives up after :data:`BUSY_TIMEOUT_S` and is tried again, with a short
pause, until the call's patience is spent (:data:`WRITE_PATIENCE_S` for a
hand-in, which must land; less for a presence). A lock held by another program
(the teacher's ``sqlite3`` session, a backup, a large save) then delays only
the calls that need it, each on its own thread. A database that cannot be
reached raises :class:`StoreUnavailable` (a hand-in then waits to be saved:
:mod:`eha_app.runtime.outbox`).

A database that is not usable raises :class:`StoreError`, whose message says
what to do (and names a PostgreSQL database by its URL without the password).

>>> import tempfile, pathlib
>>> store = HandIns(pathlib.Path(tempfile.mkdtemp()) / "class.json").check()
>>> store.add("ada", {"M": 4100.0}, {"M": True})
1
>>> store.add("ada", {"M": 4100.0}, {"M": True}, key="page-1-handin-1"), store.add("ada", {"M": 1.0}, {"M": False},
...                                                                            key="page-1-handin-1")
(2, 2)
>>> [(r.student, r.score, r.source) for r in store.latest()]
[('ada', 1.0, {'kind': 'simulated'})]
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from .store_backend import BUSY_TIMEOUT_S, StoreError, StoreUnavailable, open_backend

__all__ = ["HandIns", "HandIn", "StoreError", "StoreUnavailable", "Refused", "handins_path", "CONTROL_KEYS",
           "BUSY_TIMEOUT_S", "WRITE_PATIENCE_S"]

log = logging.getLogger("eha_app")

#: How long a write keeps trying before it fails, saying the database is busy [s].
WRITE_PATIENCE_S = 30.0
#: The teacher's switches kept in the database (every server process and command sees the same).
CONTROL_KEYS = ("open", "deadline", "revealed", "token_nonce", "token_expires")


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
    source: dict = field(default_factory=lambda: {"kind": "simulated"})
    damaged: bool = False   # a row whose values could not be read (edited by hand, a disk fault)


@dataclass(frozen=True)
class Presence:
    """A student's presence: when they joined and were last seen, the live page's token ("" when
    none is open), how many pages they opened and how many of those while another was live."""

    joined: str
    last_seen: str
    page: str = ""
    pages: int = 0
    overlaps: int = 0


_COLUMNS = "id, time, student, estimates, verdicts, score, method, settings, conditions, errors, source"


def _loads(text) -> dict | None:
    """A stored JSON object, or None if the row's text is not one."""
    try:
        value = json.loads(text)
    except (TypeError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def _row(r) -> HandIn:
    """A stored row; one whose JSON cannot be read is kept, marked damaged, with what could be read."""
    parts = [_loads(t) for t in (r[3], r[4], r[7], r[8], r[9], r[10])]
    estimates, verdicts, settings, conditions, errors, source = (p if p is not None else {} for p in parts)
    try:
        score, bad_score = float(r[5]), False
    except (TypeError, ValueError):
        score, bad_score = 0.0, True
    return HandIn(r[0], str(r[1]), str(r[2]), estimates, verdicts, score, method=str(r[6]), settings=settings,
                  conditions=conditions, errors=errors, source=source or {"kind": "simulated"},
                  damaged=bad_score or any(p is None for p in parts))


def _now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


class HandIns:
    """The hand-ins of the exercise at ``exercise_path``, the teacher's switches (``control``: open or
    closed, an extended deadline, revealed, the dashboard token's nonce and expiry), the deadlines the
    teacher extended for single students (``extensions``), who has joined
    and when they were last seen, and the students' kept work (:mod:`eha_app.runtime.work_store`)."""

    def __init__(self, exercise_path: str | Path, store: str | None = None):
        self.backend = open_backend(exercise_path, store)
        self.exercise_path = str(Path(exercise_path).absolute())
        #: the SQLite file (None on PostgreSQL)
        self.path = getattr(self.backend, "path", None)
        #: what messages call the database: its path, or its URL without the password
        self.shown = self.backend.shown

    def check(self) -> HandIns:
        """Open the database (made if missing, brought to this version's schema) and check it:
        :class:`StoreError` if it is not usable. The server and the teacher's commands call it before
        anything else."""
        self.backend.check()
        return self

    def _unusable(self, what) -> StoreError:
        return self.backend.unusable(what)

    def _write(self, fn, patience: float = WRITE_PATIENCE_S, lock: str | None = None):
        """Run ``fn(db)`` in one serialised write transaction (with every write, or with those of the same
        ``lock``: one student's); :class:`StoreError` if the database cannot take it
        (:class:`StoreUnavailable` if it cannot be reached now)."""
        return self.backend.write(fn, patience, lock)

    def _snapshot(self, fn, patience: float = 5.0):
        """Run ``fn(db)`` in one read transaction (a consistent view; no write lock is taken or waited for)."""
        return self.backend.snapshot(fn, patience)

    def _read(self, sql: str, args=(), patience: float = 5.0) -> list:
        return self._snapshot(lambda db: db.execute(sql, args).fetchall(), patience)

    def add(self, student: str, estimates: dict, verdicts: dict, *, method: str = "lse", settings: dict | None = None,
            conditions: dict | None = None, errors: dict | None = None, source: dict | None = None,
            refusal=None, key: str = "", patience: float = WRITE_PATIENCE_S) -> int:
        """Store a hand-in; returns its row id. :class:`StoreError` if the database cannot take it.

        ``refusal(count, control)``, if given, is asked inside the transaction with the student's number
        of hand-ins so far and the teacher's switches as they are now, with the student's own deadline
        under ``"extension"`` when the teacher extended it (:meth:`control_for`; two pages of one student
        handing in at once cannot both take the last attempt; a reveal or an extension a moment ago
        holds): a message it returns is raised as :class:`Refused` and nothing is stored. ``source``:
        where the data came from (``{"kind": "simulated"}``, the default, or ``{"kind": "file", "name": ...,
        "sha256": ...}``). ``key``: the hand-in's own key, given by the page that made it; a hand-in
        whose key the student's hand-ins already have was stored before (sent again after a lost
        connection, or by a server that took over): its row id is returned and nothing is stored or
        counted again."""
        score = sum(bool(v) for v in verdicts.values()) / max(len(verdicts), 1)

        def insert(db):
            if key:
                row = db.execute("SELECT id FROM handins WHERE student = ? AND key = ?", (student, key)).fetchone()
                if row is not None:
                    return int(row[0])
            if refusal is not None:
                count = db.execute("SELECT COUNT(*) FROM handins WHERE student = ?", (student,)).fetchone()[0]
                why = refusal(count, _control_for(db, student))
                if why:
                    # the attempt is kept (the teacher sees it), the hand-in is not
                    db.execute("INSERT INTO refusals (time, student, method, why) VALUES (?, ?, ?, ?)",
                               (_now(), student, method, str(why)))
                    return Refused(why)
            row = db.execute("INSERT INTO handins (time, student, estimates, verdicts, score, method, settings, "
                             "conditions, errors, source, key) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) RETURNING id",
                             (_now(), student, json.dumps(estimates), json.dumps(verdicts), score, method,
                              json.dumps(settings or {}), json.dumps(conditions or {}), json.dumps(errors or {}),
                              json.dumps(source or {"kind": "simulated"}), str(key or ""))).fetchone()
            return int(row[0])
        out = self._write(insert, patience, lock=f"student:{student}")
        if isinstance(out, Refused):
            raise out
        return out

    def refusals(self) -> list[tuple[str, str, str, str]]:
        """The hand-ins the rules refused (too many, late, closed), oldest first: (time, student, method, why)."""
        return [tuple(r) for r in self._read("SELECT time, student, method, why FROM refusals ORDER BY id")]

    def all(self) -> list[HandIn]:
        return [_row(r) for r in self._read(f"SELECT {_COLUMNS} FROM handins ORDER BY id")]

    def of(self, student: str) -> list[HandIn]:
        """One student's hand-ins, oldest first."""
        return [_row(r) for r in self._read(f"SELECT {_COLUMNS} FROM handins WHERE student = ? ORDER BY id",
                                            (student,))]

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
        """``open`` ("1"/"0"), ``deadline`` (an extension, ISO-8601), ``revealed`` ("1"/"0"), and the
        dashboard token's ``token_nonce`` and ``token_expires`` (POSIX time), as set."""
        return dict(self._read("SELECT key, value FROM control"))

    def control_for(self, student: str) -> dict[str, str]:
        """The teacher's switches (:meth:`control`) as they hold for ``student``: with their own deadline
        under ``"extension"`` when the teacher extended it (:meth:`set_extension`), read together."""
        return self._snapshot(lambda db: _control_for(db, student))

    def set_extension(self, student: str, deadline: str) -> None:
        """Give ``student`` (the normalised id) a deadline of their own, ``deadline`` (ISO-8601, checked by
        the caller); "" takes it away (the class's deadline holds again)."""
        def write(db):
            if deadline:
                db.execute("INSERT INTO extensions (student, deadline, time) VALUES (?, ?, ?) ON CONFLICT(student) "
                           "DO UPDATE SET deadline = excluded.deadline, time = excluded.time",
                           (student, str(deadline), _now()))
            else:
                db.execute("DELETE FROM extensions WHERE student = ?", (student,))
        self._write(write, lock=f"student:{student}")

    def extensions(self) -> dict[str, tuple[str, str]]:
        """student -> (their own deadline, ISO-8601; when it was set), by id."""
        return {r[0]: (r[1], r[2]) for r in
                self._read("SELECT student, deadline, time FROM extensions ORDER BY student")}

    def extension(self, student: str) -> str:
        """The deadline of ``student``'s extension ("" if none)."""
        rows = self._read("SELECT deadline FROM extensions WHERE student = ?", (student,))
        return rows[0][0] if rows else ""

    def set_control(self, key: str, value: str) -> None:
        if key not in CONTROL_KEYS:
            raise ValueError(f"unknown switch {key!r}")
        self._write(lambda db: db.execute("INSERT INTO control (key, value) VALUES (?, ?) ON CONFLICT(key) DO "
                                          "UPDATE SET value = excluded.value", (key, str(value))))

    def set_controls(self, values: dict[str, str], keep=None):
        """Set several switches in one transaction (a reader sees all of them changed, or none).
        ``keep(control)``, if given, is asked first in the same transaction with the switches as they are:
        what it returns, if anything, is returned and nothing is written (e.g. a token another server
        issued a moment ago)."""
        unknown = set(values) - set(CONTROL_KEYS)
        if unknown:
            raise ValueError(f"unknown switch {sorted(unknown)[0]!r}")

        def write(db):
            if keep is not None:
                kept = keep(dict(db.execute("SELECT key, value FROM control").fetchall()))
                if kept:
                    return kept
            for key, value in values.items():
                db.execute("INSERT INTO control (key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = "
                           "excluded.value", (key, str(value)))
            return None
        return self._write(write)

    def seen(self, student: str, page: str = "", *, patience: float = 10.0) -> str:
        """The student is here now (joined the first time), on the page whose token is ``page``.
        Returns the token of the page that was live before ("" if none): another page of the same
        id, which gives way to this one."""
        now = _now()

        def write(db):
            row = db.execute("SELECT page FROM presence WHERE student = ?", (student,)).fetchone()
            before = row[0] if row else ""
            other = bool(page and before and before != page)
            db.execute("INSERT INTO presence (student, joined, last_seen, page, pages, \"overlaps\") "
                       "VALUES (?, ?, ?, ?, ?, 0) ON CONFLICT(student) DO UPDATE SET last_seen = excluded.last_seen, "
                       "page = CASE WHEN ? != '' THEN excluded.page ELSE presence.page END, "
                       "pages = presence.pages + ?, \"overlaps\" = presence.\"overlaps\" + ?",
                       (student, now, now, page, 1 if page else 0, page, 1 if page else 0, 1 if other else 0))
            return before if other else ""
        return self._write(write, patience, lock=f"student:{student}")

    def touch(self, student: str, page: str, *, patience: float = 2.0) -> None:
        """The student's live page ``page`` is still open: their "last seen" is now (the teacher's
        dashboard shows who is here)."""
        self._write(lambda db: db.execute("UPDATE presence SET last_seen = ? WHERE student = ? AND page = ?",
                                          (_now(), student, page)), patience, lock=f"student:{student}")

    def left(self, student: str, page: str, *, patience: float = 10.0) -> None:
        """The page ``page`` of ``student`` was closed: no page of theirs is live, unless another took over."""
        self._write(lambda db: db.execute("UPDATE presence SET page = '', last_seen = ? WHERE student = ? AND "
                                          "page = ?", (_now(), student, page)), patience, lock=f"student:{student}")

    def live_page(self, student: str) -> str:
        """The token of the student's live page ("" if none)."""
        rows = self._read("SELECT page FROM presence WHERE student = ?", (student,))
        return rows[0][0] if rows else ""

    def presence(self) -> dict[str, tuple[str, str]]:
        """student -> (joined, last seen)."""
        return {r[0]: (r[1], r[2]) for r in self._read("SELECT student, joined, last_seen FROM presence")}

    def presences(self) -> dict[str, Presence]:
        """student -> :class:`Presence` (pages and overlaps with it)."""
        return {r[0]: Presence(r[1], r[2], r[3], int(r[4]), int(r[5])) for r in
                self._read("SELECT student, joined, last_seen, page, pages, \"overlaps\" FROM presence")}

    def new_id_from(self, address: str, student: str, *, limit: int, window_s: float = 3600.0,
                    patience: float = 10.0) -> str | None:
        """May the client at ``address`` start ``student`` (an open exercise)? An id that has joined
        before (from anywhere) may always come back; a new one counts against the address's
        ``limit`` of new ids in ``window_s``. Returns why not, or None (and notes the id as the
        address's). ``limit`` 0: no limit."""
        now = time.time()

        def write(db):
            known = db.execute("SELECT 1 FROM presence WHERE student = ? UNION SELECT 1 FROM clients WHERE "
                               "student = ? LIMIT 1", (student, student)).fetchone()
            if known is None and limit:
                n = db.execute("SELECT COUNT(*) FROM clients WHERE address = ? AND first > ?",
                               (address, now - window_s)).fetchone()[0]
                if n >= limit:
                    return (f"this computer has started {n} new ids in this exercise in the last hour, the most "
                            "allowed; type the id you used before, or ask your teacher (several students behind "
                            "one network address need a higher limit: eha exercise new --ids-per-client)")
            db.execute("INSERT INTO clients (address, student, first) VALUES (?, ?, ?) ON CONFLICT DO NOTHING",
                       (address, student, now))
            return None
        return self._write(write, patience=patience, lock=f"address:{address}")

    def version(self) -> tuple:
        """Changes whenever a hand-in, a switch or a presence changes (what a live page polls)."""
        switches, pages, extended = (self.backend.concat(e) for e in ("key || '=' || value", "page",
                                                                       "student || '=' || deadline"))
        rows = self._read("SELECT (SELECT COUNT(*) FROM handins), (SELECT MAX(id) FROM handins), "
                          f"(SELECT {switches} FROM control), "
                          "(SELECT COUNT(*) FROM presence), (SELECT MAX(last_seen) FROM presence), "
                          f"(SELECT SUM(pages) FROM presence), (SELECT {pages} FROM presence), "
                          "(SELECT COUNT(*) FROM refusals), "
                          f"(SELECT {extended} FROM extensions)")
        return tuple(rows[0])


def _control_for(db, student: str) -> dict[str, str]:
    """The switches and ``student``'s extension, in the transaction of ``db``."""
    control = dict(db.execute("SELECT key, value FROM control").fetchall())
    row = db.execute("SELECT deadline FROM extensions WHERE student = ?", (student,)).fetchone()
    if row is not None:
        control["extension"] = row[0]
    return control


class Refused(StoreError):
    """A hand-in the exercise's rules refuse (deadline, attempts, closed): the message says which."""
