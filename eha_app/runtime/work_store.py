"""A student's work in an exercise, kept in the exercise's database so that it survives a reload
or a restart of the server.

One row per student (the normalised id the hand-ins carry) in the table ``work`` of the hand-in
database (:func:`~eha_app.runtime.handins.handins_path`): the session's settings (the JSON a
settings file holds), which results were on the page (to be computed again: the runs are
deterministic, so the same inputs give the same numbers), and when. The student's uploaded
records go to ``work_files``, one row per upload (its bytes, file name and column mapping):
a settings change then rewrites a few kilobytes, not a 20 MB file, which is written again only
when it changed.

Every write is its own transaction on its own connection, through the hand-in store's helpers
(busy timeout, a file readable by its owner only, WAL): a damaged database raises the same
:class:`~eha_app.runtime.handins.StoreError` with the same advice as a hand-in would.

Writes and reads run on one thread of their own (:func:`submit`), never on the server's event
loop and never on the workers that compute: a student's save does not wait behind the class's
experiments, and a computation does not wait behind a disk. Saves of one student that pile up
while the disk is busy are coalesced (the latest is written).

>>> import tempfile, pathlib
>>> from eha_app.runtime.handins import HandIns
>>> store = WorkStore(HandIns(pathlib.Path(tempfile.mkdtemp()) / "class.json"), quota_bytes=100)
>>> store.save(Work("ada", b'{"format": "eha-settings/1"}', {"least_squares": {"views": ["lse"]}},
...                 (StoredFile("least_squares", "run.csv", b"t,x\\n0,0\\n", {"x": "pos"}),)))
[]
>>> store.save(Work("alan", b'{}', {}, (StoredFile("record", "big.csv", b"0" * 95),)))  # past the class's quota
['big.csv']
>>> w = store.load("ada")
>>> w.runs, w.files[0].name, w.files[0].mapping, store.load("alan").files, store.load("bob")
({'least_squares': {'views': ['lse']}}, 'run.csv', {'x': 'pos'}, (), None)
"""

from __future__ import annotations

import atexit
import hashlib
import json
import logging
import threading
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

from eha_core.data import MAX_DATA_BYTES

from .handins import HandIns
from .store_backend import take_lock

__all__ = ["Work", "StoredFile", "WorkStore", "submit", "drain", "MAX_WORK_FILE_BYTES"]

log = logging.getLogger("eha_app")

#: The most bytes of uploaded records kept per student (all of their uploads together): the
#: largest file the page takes.
MAX_WORK_FILE_BYTES = MAX_DATA_BYTES
#: How long the saves rest when the database cannot be reached, before they are tried again [s].
RETRY_UNAVAILABLE_S = 5.0


@dataclass(frozen=True)
class StoredFile:
    """A record the student uploaded to a section (``slot``: the section's key), with the column
    mapping they chose (None: the file's own names were used)."""

    slot: str
    name: str
    data: bytes = field(repr=False)
    mapping: dict | None = None

    def digest(self) -> str:
        return hashlib.sha256(self.data).hexdigest()


@dataclass(frozen=True)
class Work:
    """What is kept of one student's session: the settings file's JSON, the results to compute again
    (``{section key: {"views": [...], ...what the section needs to run it}}``), their uploads."""

    student: str
    settings: bytes
    runs: dict = field(default_factory=dict)
    files: tuple[StoredFile, ...] = ()
    time: str = ""


def _now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


class WorkStore:
    """The students' work in the exercise's database (the hand-ins' file and helpers)."""

    def __init__(self, handins: HandIns, quota_bytes: int | None = None):
        self.handins = handins
        self.quota_bytes = quota_bytes

    def _transaction(self, fn, student: str):
        """``fn(db)`` in one transaction with the other writes of ``student`` (the tables are the hand-in
        store's); StoreError if it fails."""
        return self.handins._write(fn, lock=f"student:{student}")

    def save(self, work: Work) -> list[str]:
        """Keep ``work`` as the student's (replacing what was kept); an upload is written only when
        its bytes, name or mapping changed. Returns the names of uploads not kept because the class's
        kept uploads would pass :attr:`quota_bytes` (a slot whose new file is not kept keeps nothing:
        an older file would come back in its place)."""
        files = {f.slot: f for f in work.files}
        digests = {slot: f.digest() for slot, f in files.items()}       # before the transaction: 20 MB takes a while
        quota = self.quota_bytes
        refused: list[str] = []

        def write(db):
            db.execute("INSERT INTO work (student, time, settings, runs) VALUES (?, ?, ?, ?) ON CONFLICT(student) "
                       "DO UPDATE SET time = excluded.time, settings = excluded.settings, runs = excluded.runs",
                       (work.student, _now(), work.settings.decode("utf-8"), json.dumps(work.runs)))
            kept = {r[0]: (r[1], r[2], r[3]) for r in db.execute(
                "SELECT slot, name, mapping, digest FROM work_files WHERE student = ?", (work.student,))}
            for slot in kept.keys() - files.keys():
                db.execute("DELETE FROM work_files WHERE student = ? AND slot = ?", (work.student, slot))
            refused.clear()
            for slot, f in files.items():
                row = (f.name, json.dumps(f.mapping), digests[slot])
                if kept.get(slot) == row:
                    continue
                if quota is not None:
                    take_lock(db, "kept uploads")       # the class's quota: one upload's check at a time
                    used = db.execute("SELECT COALESCE(SUM(size), 0) FROM work_files WHERE NOT (student = ? AND "
                                      "slot = ?)", (work.student, slot)).fetchone()[0]
                    if used + len(f.data) > quota:
                        db.execute("DELETE FROM work_files WHERE student = ? AND slot = ?", (work.student, slot))
                        refused.append(f.name)
                        continue
                db.execute("INSERT INTO work_files (student, slot, name, mapping, digest, data, size) VALUES (?, ?, ?, "
                           "?, ?, ?, ?) ON CONFLICT (student, slot) DO UPDATE SET name = excluded.name, mapping = "
                           "excluded.mapping, digest = excluded.digest, data = excluded.data, size = excluded.size",
                           (work.student, slot, *row, f.data, len(f.data)))
        self._transaction(write, work.student)
        return list(refused)

    def load(self, student: str) -> Work | None:
        """The student's kept work, or None if there is none."""
        def read(db):
            row = db.execute("SELECT time, settings, runs FROM work WHERE student = ?", (student,)).fetchone()
            files = db.execute("SELECT slot, name, mapping, data FROM work_files WHERE student = ? ORDER BY slot",
                               (student,)).fetchall()
            return row, files
        row, files = self.handins._snapshot(read)
        if row is None:
            return None
        try:
            runs = json.loads(row[2])
            stored = tuple(StoredFile(slot, name, bytes(data), json.loads(mapping))
                           for slot, name, mapping, data in files)
        except (ValueError, TypeError) as exc:
            raise self.handins._unusable(exc) from None
        return Work(student, row[1].encode("utf-8"), runs if isinstance(runs, dict) else {}, stored, time=row[0])

    def forget(self, student: str) -> None:
        """Drop what is kept of the student (a fresh start)."""
        def delete(db):
            db.execute("DELETE FROM work WHERE student = ?", (student,))
            db.execute("DELETE FROM work_files WHERE student = ?", (student,))
        self._transaction(delete, student)


class _Writer:
    """One thread that runs the stores' reads and writes in turn; a write submitted again under the
    same key before it ran replaces the waiting one (the latest state of a student is what counts)."""

    def __init__(self):
        self._cond = threading.Condition()
        self._pending: dict[Hashable, Callable[[], None]] = {}
        self._thread: threading.Thread | None = None
        self._busy = False

    def submit(self, key: Hashable, fn: Callable[[], None]) -> None:
        with self._cond:
            self._pending[key] = fn             # a waiting one keeps its place in the line
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._work, name="eha-work-store", daemon=True)
                self._thread.start()
            self._cond.notify()

    def _work(self) -> None:
        while True:
            with self._cond:
                while not self._pending:
                    self._busy = False
                    self._cond.notify_all()
                    self._cond.wait()
                self._busy = True
                key = next(iter(self._pending))
                fn = self._pending.pop(key)
            if not self._run(fn):
                # the database cannot be reached (PostgreSQL restarting): the save waits, unless a newer
                # one of the same student came meanwhile, and the line rests a moment before it goes on
                with self._cond:
                    self._pending.setdefault(key, fn)
                    self._cond.wait(timeout=RETRY_UNAVAILABLE_S)

    @staticmethod
    def _run(fn) -> bool:
        """Run ``fn()``; False when the database could not be reached (worth trying again)."""
        from .handins import StoreUnavailable

        try:
            fn()
        except StoreUnavailable as exc:
            log.warning("a save of a student's work waits: %s", exc)
            return False
        except Exception:  # noqa: BLE001 - one student's save must not stop the others'
            log.exception("a save of a student's work failed")
        return True

    def drain(self, timeout: float = 10.0) -> None:
        """Wait until what was submitted has run (the server stopping; tests)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            alive = self._thread is not None and self._thread.is_alive()
            while alive and (self._pending or self._busy) and time.monotonic() < deadline:
                self._cond.wait(timeout=0.1)
            if alive:
                return
            rest = list(self._pending.values())
            self._pending.clear()
        for fn in rest:
            self._run(fn)


_writer = _Writer()
#: the saves still waiting when the server stops are written before the process ends
atexit.register(_writer.drain)


def submit(key: Hashable, fn: Callable[[], None]) -> None:
    """Run ``fn()`` on the store's thread; a waiting ``fn`` of the same ``key`` is replaced."""
    _writer.submit(key, fn)


def drain(timeout: float = 10.0) -> None:
    """Wait for the store's thread to run what was submitted."""
    _writer.drain(timeout)
