"""The class database, called off the server's event loop.

The event loop serves every page of the process: one call that waits there on
SQLite (a lock held by the teacher's ``sqlite3`` session, a backup, another
process's large save) stops every student's page for as long. A join once took
10 s while another connection held the write lock, and a bystander's round
trip went from 0.01 to 10 s with it.

So every read and write of the hand-in store made for a page (a student
joining, the periodic look at whether their result may be shown, the
teacher's switches) goes through :func:`call`: the database is called on one
of a few threads of its own, and what the page shows of the answer is applied
under the page's lock in turn (:func:`~eha_app.runtime.tasks.apply_locked`).
A held lock then delays only the call that waits for it, on its own thread;
the pages go on. The threads are few and the calls short (each attempt gives
up after :data:`~eha_app.runtime.handins.BUSY_TIMEOUT_S` and tries again), so
one slow call does not hold up the others for long; and no computation's
worker is taken.

Without a server (tests, a notebook) the call runs at once in the caller's thread.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from .tasks import apply_locked, served_document

__all__ = ["call", "STORE_THREADS"]

log = logging.getLogger("eha_app")

#: Threads that call the database: a held lock ties up the calls waiting for it, not the next join.
STORE_THREADS = 4

_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=STORE_THREADS, thread_name_prefix="eha-store")
        return _pool


def call(fn: Callable[[], Any], then: Callable[[Any], None] | None = None, *, fail: Callable[[Exception], None]
         | None = None, doc=None) -> None:
    """``fn()`` on a database thread, then ``then(result)`` (or ``fail(exception)``) under the page's
    lock. ``doc``: the page's document (by default the current session's). Without a server, all at once
    here."""
    doc = doc if doc is not None else served_document()
    if doc is None:
        try:
            out = fn()
        except Exception as exc:  # noqa: BLE001 - the caller says what a failure means
            if fail is None:
                raise
            fail(exc)
            return
        if then is not None:
            then(out)
        return

    def run() -> None:
        try:
            out = fn()
        except Exception as exc:  # noqa: BLE001 - shown on the page, or logged: never lost
            if fail is not None:
                apply_locked(lambda exc=exc: fail(exc), doc)
            else:
                log.warning("a call of the class database failed: %s", exc)
            return
        if then is not None:
            apply_locked(lambda: then(out), doc)

    _executor().submit(run)
