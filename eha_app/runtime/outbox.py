"""Hand-ins waiting to be saved: the lab's database could not be reached when a student handed in (a
PostgreSQL server restarting, the network), so the server keeps the hand-in and tries again until the
database takes it. The student's page says "your hand-in is waiting to be saved", and then what
became of it.

A hand-in waits with the key its page gave it (:meth:`~eha_app.runtime.handins.HandIns.add`): tried
again after a connection lost just after the database took it, it is stored once. The rules (the
attempts, the deadline, the teacher's switches) are judged when the database takes it, in the
hand-in's own transaction, as for any hand-in; the deadline is the one the student handed in before,
so that a database down at the deadline does not make a hand-in late.

Each waiting hand-in is also written to a spool file (``EHA_SPOOL``, by default
``eha-waiting-handins.jsonl`` in the server's working directory, readable by its owner only; the
processes of one ``eha serve --num-procs N`` share it under a lock), so that a server stopped or
killed while the database is down saves them at its next start (:func:`replay`; a hand-in another
live process also tries is stored once, under its key).

>>> import tempfile, pathlib
>>> from eha_app.runtime.handins import HandIns
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> box = Outbox(folder / "spool.jsonl", retry_s=0.05)
>>> store = HandIns(folder / "class.json").check()
>>> saved = []
>>> box.put(store, dict(student="ada", estimates={"M": 1.0}, verdicts={"M": True}, key="k1"),
...         on_done=lambda row, why: saved.append((row, why)))
>>> box.wait_empty(5.0), saved, box.waiting("ada")
(True, [(1, '')], 0)
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

try:
    import fcntl
except ImportError:             # Windows
    fcntl = None

__all__ = ["Outbox", "outbox", "replay", "RETRY_S"]

log = logging.getLogger("eha_app")

#: How often a waiting hand-in is tried again [s].
RETRY_S = 5.0


@dataclass
class _Waiting:
    store: object
    kwargs: dict
    on_done: Callable[[int | None, str], None] | None
    since: float = field(default_factory=time.time)
    tries: int = 0


class Outbox:
    """The hand-ins this server keeps until the database takes them (one thread tries them in turn)."""

    def __init__(self, spool: str | Path | None = None, retry_s: float = RETRY_S):
        self.spool = Path(spool) if spool else None
        self.retry_s = float(retry_s)
        self._cond = threading.Condition()
        self._items: dict[tuple[str, str], _Waiting] = {}
        self._thread: threading.Thread | None = None

    # -- asking -------------------------------------------------------------------------------------
    def put(self, store, kwargs: dict, on_done: Callable[[int | None, str], None] | None = None,
            refusal_spec: dict | None = None) -> None:
        """Keep the hand-in ``store.add(**kwargs)`` (``kwargs["key"]`` set) until the database takes it;
        then ``on_done(row_id, "")``, or ``on_done(None, why)`` when the lab's rules refused it.
        ``refusal_spec``: what the spool keeps of the rules (see :func:`replay`)."""
        key = (str(kwargs["student"]), str(kwargs.get("key") or ""))
        if not key[1]:
            raise ValueError("a waiting hand-in needs its page's key (it could be stored twice)")
        with self._cond:
            self._items[key] = _Waiting(store, dict(kwargs), on_done)
            self._write_spool(store, kwargs, refusal_spec)
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._work, name="eha-outbox", daemon=True)
                self._thread.start()
            self._cond.notify_all()

    def waiting(self, student: str | None = None) -> int:
        """How many hand-ins wait (of ``student``, or in all)."""
        with self._cond:
            return sum(1 for k in self._items if student is None or k[0] == student)

    def wait_empty(self, timeout: float) -> bool:
        """Wait until nothing waits (tests; a server stopping); whether that came."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._items and time.monotonic() < deadline:
                self._cond.wait(timeout=0.05)
            return not self._items

    # -- the thread ------------------------------------------------------------------------------------
    def _work(self) -> None:
        from .handins import Refused, StoreUnavailable

        while True:
            with self._cond:
                while not self._items:
                    self._cond.wait()
                items = list(self._items.items())
            for key, item in items:
                item.tries += 1
                row, why = None, ""
                try:
                    row = item.store.add(**item.kwargs, patience=min(self.retry_s, 5.0))
                except Refused as exc:
                    why = str(exc)
                except StoreUnavailable:
                    continue                                 # still down: the next round
                except Exception as exc:  # noqa: BLE001 - a damaged database: kept, said, tried again
                    if item.tries in (1, 10) or item.tries % 100 == 0:
                        log.error("a waiting hand-in could not be saved (%s); it is tried again", exc)
                    continue
                with self._cond:
                    self._items.pop(key, None)
                    self._drop_from_spool(key)
                    self._cond.notify_all()
                log.info("a hand-in waiting %.0f s was %s", time.time() - item.since,
                         "saved" if row is not None else "refused by the lab's rules")
                if item.on_done is not None:
                    try:
                        item.on_done(row, why)
                    except Exception:  # noqa: BLE001 - a closed page: the hand-in is saved all the same
                        log.exception("telling a page its waiting hand-in was saved failed")
            with self._cond:
                if self._items:
                    self._cond.wait(timeout=self.retry_s)

    # -- the spool file ------------------------------------------------------------------------------
    def _spool_lines(self) -> list[dict]:
        if self.spool is None or not self.spool.exists():
            return []
        out = []
        for line in self.spool.read_text(encoding="utf-8").splitlines():
            try:
                out.append(json.loads(line))
            except ValueError:
                log.error("a line of the waiting hand-ins' file %s cannot be read: kept aside", self.spool)
        return out

    def _rewrite_spool(self, lines: list[dict]) -> None:
        if self.spool is None:
            return
        if not lines:
            try:
                self.spool.unlink()
            except FileNotFoundError:
                pass
            return
        tmp = self.spool.with_name(f"{self.spool.name}.{os.getpid()}.tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            for line in lines:
                f.write(json.dumps(line) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.spool)

    @contextlib.contextmanager
    def _spool_locked(self):
        """The spool file to itself: the processes of one ``eha serve --num-procs N`` share it (a lock file
        beside it; where there is no fcntl, as on Windows, one process per working directory)."""
        if fcntl is None:
            yield
            return
        fd = os.open(self.spool.with_name(self.spool.name + ".lock"), os.O_WRONLY | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            os.close(fd)

    def _write_spool(self, store, kwargs: dict, refusal_spec: dict | None) -> None:
        if self.spool is None:
            return
        key = (kwargs["student"], kwargs["key"])
        # (the store's URL is not written: it may hold a password; the next run's own store is used)
        line = {"exercise": getattr(store, "exercise_path", None),
                "kwargs": {k: v for k, v in kwargs.items() if k != "refusal"},
                "rules": refusal_spec or {}, "since": time.time()}
        try:
            with self._spool_locked():
                self._rewrite_spool([*self._other_lines(key), line])
        except OSError as exc:
            log.error("a waiting hand-in could not be written to %s (%s): it waits in memory only", self.spool, exc)

    def _drop_from_spool(self, key: tuple[str, str]) -> None:
        if self.spool is None:
            return
        try:
            with self._spool_locked():
                self._rewrite_spool(self._other_lines(key))
        except OSError as exc:
            log.error("the waiting hand-ins' file %s could not be rewritten (%s)", self.spool, exc)

    def _other_lines(self, key: tuple[str, str]) -> list[dict]:
        return [line for line in self._spool_lines()
                if (line["kwargs"]["student"], line["kwargs"].get("key")) != tuple(key)]


def _default_spool() -> Path:
    return Path(os.environ.get("EHA_SPOOL") or "eha-waiting-handins.jsonl").absolute()


_outbox: Outbox | None = None
_outbox_lock = threading.Lock()


def outbox() -> Outbox:
    """This server process's outbox."""
    global _outbox
    with _outbox_lock:
        if _outbox is None:
            _outbox = Outbox(_default_spool())
        return _outbox


def replay(exercise, store, refusal_for: Callable[[dict], Callable]) -> int:
    """Put back the hand-ins a previous run of this server left waiting in its spool file (for this
    exercise's store), each judged by ``refusal_for(rules)`` when saved. Returns how many."""
    box = outbox()
    n = 0
    with box._cond:
        lines = box._spool_lines()
    for line in lines:
        if line.get("exercise") not in (None, getattr(store, "exercise_path", None)):
            continue
        kwargs = dict(line["kwargs"])
        kwargs["refusal"] = refusal_for(line.get("rules") or {})
        box.put(store, kwargs, None, refusal_spec=line.get("rules") or {})
        n += 1
    if n:
        log.warning("%d hand-in(s) left waiting by this server's last run are saved as soon as the database "
                    "answers", n)
    return n
