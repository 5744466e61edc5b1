"""Running one session's computations on the shared queue and showing their results.

:class:`SessionRunner` hands a computation to the process's
:class:`~eha_app.jobs.JobQueue` (a worker thread computes; nothing in it
touches Bokeh, HoloViews or Panel objects) and, when it ends, applies the
result to the session's own document in one callback on the event loop, under
the document's lock, with the document's events held and combined: the
browser receives one message per result instead of one per changed property
(a first "Compare both" used to send 76).

Two details learnt the hard way:

- Panel must know which session it updates: the callback runs under
  ``set_curdoc(doc)`` (with a bare Bokeh next-tick callback about one update
  in 25 never reached the browser).
- The document is captured when the user's event arrives; by the time a
  result is ready Panel's "current document" may belong to another session.

Without a server (tests, a notebook) the computation runs at once in the
calling thread and its result is shown directly.
"""

from __future__ import annotations

import logging
from functools import partial
from typing import Any, Callable, Hashable, Sequence

import panel as pn
from panel.io.document import hold
from panel.io.state import set_curdoc

from eha_core.cancel import Cancelled, CancelToken

from .jobs import Job, JobQueue, default_queue

__all__ = ["SessionRunner", "apply_locked", "LOADING_DELAY_S", "served_document"]

log = logging.getLogger("eha_app")

#: Show the loading indicator only when a result takes longer than this: toggling
#: it re-lays-out the plots, which costs more than a 20 ms simulation.
LOADING_DELAY_S = 0.2


def served_document():
    """The current session's document when running in a server, else None."""
    doc = pn.state.curdoc
    if doc is not None and getattr(doc, "session_context", None) is not None:
        return doc
    return None


def apply_locked(fn: Callable[[], None], doc=None) -> None:
    """Run ``fn`` on the session's document: now if there is no server, else on
    its event loop, under its lock, with its events held and combined."""
    doc = doc if doc is not None else served_document()
    if doc is None:
        fn()
        return

    def locked():
        with set_curdoc(doc), hold(doc):
            fn()

    try:
        doc.add_next_tick_callback(locked)
    except Exception as exc:  # noqa: BLE001 - the session was closed meanwhile: nobody to show it to
        log.debug("result not shown, the session is gone: %s", exc)


def _message(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


class SessionRunner:
    """Runs a session's computations one at a time on the shared queue."""

    def __init__(self, owner: Hashable, queue: JobQueue | None = None):
        self.owner = owner
        self._queue = queue

    @property
    def queue(self) -> JobQueue:
        return self._queue if self._queue is not None else default_queue()

    def run(self, label: str, compute: Callable[[CancelToken], Any], show: Callable[[Any, Job], None], *,
            fail: Callable[[str], None], busy: Sequence = (), note: Callable[[str], None] | None = None) -> Job:
        """Compute ``compute(token)`` and then call ``show(result, job)`` on the page.

        ``fail(message)`` instead when it raised; ``busy`` are Panel components
        shown as loading while the user waits; ``note(text)`` tells the user
        about the queue ("waiting: 3 runs ahead", "replaced") and is called
        with "" when there is nothing to say.
        """
        note = note or (lambda _text: None)
        doc = served_document()
        if doc is None:
            return self._run_here(label, compute, show, fail, note)

        def done(job: Job) -> None:        # a worker thread, or the submitting thread for "replaced"
            apply_locked(partial(self._finish, job, show, fail, busy, note), doc)

        job, replaced = self.queue.submit(self.owner, compute, label=label, on_done=done)
        note(f"Your earlier request ({replaced.label}) was replaced by this one." if replaced is not None else "")

        def waiting() -> None:
            if job.finished:
                return
            with set_curdoc(doc), hold(doc):
                for c in busy:
                    c.loading = True
                ahead = self.queue.ahead_of(job)
                if job.state == "queued":
                    note(f"Waiting for the server: {ahead} run{'s' if ahead != 1 else ''} ahead of yours."
                         if ahead else "Waiting for a free worker: yours is next.")

        try:
            doc.add_timeout_callback(waiting, int(LOADING_DELAY_S * 1000))
        except Exception:  # noqa: BLE001 - the session is closing
            pass
        return job

    def cancel(self, reason: str = "cancelled") -> None:
        """Cancel this session's waiting and running computations."""
        self.queue.cancel_owner(self.owner, reason)

    # -- internals -------------------------------------------------------------------
    @staticmethod
    def _finish(job: Job, show, fail, busy, note) -> None:
        try:
            if job.state == "done":
                show(job.result, job)
                note("")
            elif job.state == "failed":
                log.debug("job %s failed", job.label)
                fail(_message(job.error))
                note("")
            elif job.state == "replaced":
                return          # its successor owns the indicators now
            else:               # cancelled
                note(f"Stopped: {job.token.reason or 'cancelled'}.")
        finally:
            if job.state != "replaced":
                for c in busy:
                    if c.loading:
                        c.loading = False

    def _run_here(self, label, compute, show, fail, note) -> Job:
        job = Job(owner=self.owner, label=label, fn=compute)
        job.state = "running"
        job.started_at = job.submitted_at
        try:
            job.result = compute(job.token)
            job.state = "done"
        except Cancelled as exc:
            job.state, job.error = "cancelled", exc
        except Exception as exc:  # noqa: BLE001 - shown in the page, as in a server
            job.state, job.error = "failed", exc
            log.warning("computation %r failed: %s", label, exc, exc_info=True)
        import time

        job.finished_at = time.perf_counter()
        self._finish(job, show, fail, (), note)
        return job
