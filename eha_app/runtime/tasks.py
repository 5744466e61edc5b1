"""Running one session's computations on the shared queue and showing their results.

:class:`SessionRunner` hands a computation to the process's
:class:`~eha_app.runtime.jobs.JobQueue` (a worker thread computes; nothing in it
touches Bokeh, HoloViews or Panel objects) and, when it ends, applies the
result to the session's own document in one callback on the event loop, under
the document's lock, with the document's events held and combined: the
browser receives one message per result instead of one per changed property
(a first "Compare both" used to send 76).

Three details learnt the hard way:

- Panel must know which session it updates: the callback runs under
  ``set_curdoc(doc)`` (with a bare Bokeh next-tick callback about one update
  in 25 never reached the browser).
- The document is captured when the user's event arrives; by the time a
  result is ready Panel's "current document" may belong to another session.
- One message is not one layout: the browser (Bokeh's BokehJS) lays out the
  whole page again, synchronously, for every changed property that can move
  something (a class, a visibility, a size), 60-150 ms each on tab 3. The
  twelve out-of-date marks a frequency-domain result clears cost the browser
  a second. The page lays itself out once per message instead
  (:data:`eha_app.runtime.patches.LAYOUT_ONCE_JS`, installed by every page's
  :class:`~eha_app.runtime.connection.ConnectionWatch`).

Without a server (tests, a notebook) the computation runs at once in the
calling thread and its result is shown directly.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Hashable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial, wraps
from typing import Any

import panel as pn
from panel.io.document import hold
from panel.io.state import set_curdoc

from eha_core.cancel import Cancelled, CancelToken

from .background import give_way_now
from .jobs import Job, JobQueue, JobState, default_queue, log_failure, session_name

# what reads Bokeh's and asyncio's internals lives in patches.py, with the check of their shape
from .patches import holds_lock, lazy_freeze, loop_has_work, note_loop_thread

__all__ = ["SessionRunner", "PageUpdates", "PageProgress", "apply_locked", "frozen_models", "held",
           "LOADING_DELAY_S", "served_document", "holds_lock", "locked", "watch", "on_click", "note_loop_thread"]

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


def locked(fn: Callable) -> Callable:
    """``fn`` run under the page's lock: at once when the caller holds it (a click, a locked
    callback), else on the event loop's next turn, which takes the lock (Panel handles a form's
    keystrokes without it: a change made there broke the page). Returns None when deferred."""
    @wraps(fn)
    def run(*args, **kwargs):
        doc = served_document()
        if doc is None or holds_lock(doc):
            return fn(*args, **kwargs)
        doc.add_next_tick_callback(partial(fn, *args, **kwargs))
        return None
    return run


def watch(obj, fn: Callable, *names: str):
    """``obj.param.watch(fn, names)``, ``fn`` run under the page's lock (:func:`locked`)."""
    return obj.param.watch(locked(fn), list(names))


def on_click(button, fn: Callable) -> None:
    """``button.on_click(fn)``, ``fn`` run under the page's lock (:func:`locked`)."""
    button.on_click(locked(fn))


@contextmanager
def frozen_models():
    """Recompute the session document's model graph once, after a block of changes."""
    doc = served_document()
    if doc is None:
        yield
        return
    with lazy_freeze(doc):
        yield


@contextmanager
def held():
    """Send the session's changes of a block as one message (events held and combined, the
    model graph recomputed once); no-op without a server. For changes made outside
    :func:`apply_locked`, e.g. in a watcher of a widget the student typed into."""
    doc = served_document()
    if doc is None:
        yield
        return
    with hold(doc), lazy_freeze(doc):
        yield


class PageUpdates:
    """The server's big page changes, one at a time, when the event loop is idle.

    Building a tab or showing a result costs the event loop 20-250 ms of Bokeh
    model building and serialisation. When thirty students click at once,
    thirty such callbacks back to back would hold every other message for
    seconds: a student typing waited 3.8 s while ten others opened tab 2. And
    merely taking turns is not enough, because one small interaction (a
    keystroke: read the message, take the session's lock, update, write the
    answer) spans several turns of the loop, and a big change could slip into
    each of them. So the changes wait in a line, worked off by one task of the
    event loop, and the next one starts only when nothing else is ready to run
    (or after ``MAX_DEFER_S``, so that a busy server still makes progress):
    small interactions always go first, and wait for at most the one big
    change already running.

    Each change runs under its session document's lock (Bokeh's
    ``with_locked_document``; a closed session's changes are dropped), as
    Panel's current document, with the document's events held and combined
    (one message to the browser) and its model graph recomputed once at the
    end (``models.freeze``).
    """

    #: Look for an idle loop this often [s] ...
    POLL_S = 0.002
    #: ... but never defer a change longer than this [s].
    MAX_DEFER_S = 0.5

    def __init__(self):
        self._pending: collections.deque = collections.deque()
        self._lock = threading.Lock()
        self._loop = None
        self._task = None
        self._applying = False
        self.done = 0

    def submit(self, doc, fn: Callable[[], None]) -> None:
        """Run ``fn`` on ``doc`` in turn (callable from any thread)."""
        import asyncio

        with self._lock:
            self._pending.append((doc, fn))
        give_way_now()                  # a study computing beside waits from now on
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
        if loop is not None:
            self._loop = loop
            self._start()
        elif self._loop is not None:
            self._loop.call_soon_threadsafe(self._start)
        else:       # a worker thread before any page event reached this process: ask the document
            doc.add_next_tick_callback(self._start)

    def busy(self) -> bool:
        """Whether a page change is being made or waits (callable from any thread)."""
        with self._lock:
            return bool(self._pending) or self._applying

    def _start(self) -> None:
        import asyncio

        self._loop = asyncio.get_running_loop()
        if self._task is None or self._task.done():
            self._task = self._loop.create_task(self._work())

    def _loop_busy(self) -> bool:
        return loop_has_work(self._loop)

    async def _work(self) -> None:
        import asyncio

        while True:
            with self._lock:
                if not self._pending:
                    return
                doc, fn = self._pending.popleft()
            waited = 0.0
            await asyncio.sleep(0)
            while self._loop_busy() and waited < self.MAX_DEFER_S:
                await asyncio.sleep(self.POLL_S)
                waited += self.POLL_S
            context = getattr(doc, "session_context", None)
            if context is None or context.destroyed:
                continue            # the page was closed: nobody to show it to

            async def locked(locked_doc, fn=fn):
                with set_curdoc(locked_doc), hold(locked_doc), lazy_freeze(locked_doc):
                    fn()

            self._applying = True
            try:
                await context.with_locked_document(locked)
            except Exception:  # noqa: BLE001 - one page's failure must not stop the others'
                log.exception("a page update failed")
            finally:
                self._applying = False
            self.done += 1


_updates = PageUpdates()


def pages_busy() -> bool:
    """Whether the event loop makes or has waiting a page change (a tab's build, a result shown)."""
    return _updates.busy()


def apply_locked(fn: Callable[[], None], doc=None) -> None:
    """Run ``fn`` on the session's document: now if there is no server, else in
    turn through :class:`PageUpdates` (locked, held, frozen)."""
    doc = doc if doc is not None else served_document()
    if doc is None:
        fn()
        return
    _updates.submit(doc, fn)


class PageProgress:
    """A computation's progress on its page: call it from the worker thread, as often as the work
    likes; ``show(*args)`` runs on the session's document (:func:`apply_locked`: under its lock, in
    turn with the other pages' changes) with the latest arguments, at most ``hz`` times a second.

    A report held back by that limit is not lost: it is shown when the interval has passed (a timer
    of the event loop, not another thread), so the page never says a stage is running long after it
    ended. :meth:`close` (on the page, once the result is shown) drops any update still on its way.
    Without a server (tests, a notebook) every report is shown at once, in the calling thread.
    """

    def __init__(self, show: Callable[..., None], *, hz: float = 4.0, doc=None):
        self._show = show
        self._min_s = 1.0 / hz
        self._doc = doc if doc is not None else served_document()
        self._lock = threading.Lock()
        self._latest: tuple | None = None
        self._pending = False           # an update is on its way to the page: it will show the latest
        self._shown_at = -float("inf")
        self._closed = False

    def __call__(self, *args) -> None:
        if self._doc is None:
            if not self._closed:
                self._show(*args)
            return
        with self._lock:
            if self._closed:
                return
            self._latest = args
            if self._pending:
                return
            self._pending = True
            wait_s = self._shown_at + self._min_s - time.perf_counter()
        if wait_s > 0:
            doc = self._doc
            # the timer is set on the event loop's thread (Bokeh's documents are not thread-safe)
            try:
                doc.add_next_tick_callback(lambda: doc.add_timeout_callback(
                    lambda: apply_locked(self._flush, doc), max(1, int(wait_s * 1000))))
            except Exception:  # noqa: BLE001 - the session is closing: nobody to show it to
                pass
        else:
            apply_locked(self._flush, self._doc)

    def _flush(self) -> None:
        with self._lock:
            args, self._pending = self._latest, False
            self._shown_at = time.perf_counter()
            if self._closed or args is None:
                return
        self._show(*args)

    def close(self) -> None:
        """Show nothing more (the result, a failure or a cancel is on the page now)."""
        with self._lock:
            self._closed = True


def _message(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


class SessionRunner:
    """Runs a session's computations one at a time on the shared queue."""

    def __init__(self, owner: Hashable, queue: JobQueue | None = None):
        self.owner = owner
        self._queue = queue
        self._root = self
        self._subs: set = set()
        self._after_each: list[Callable[[Job], None]] = []
        self.background = False

    def sub(self, name: str, *, background: bool = False) -> SessionRunner:
        """A runner of the same session whose requests do not replace this one's (a preview, the
        model board, a study): its owner is ``(owner, name)``, cancelled by :meth:`cancel_all`, in
        the session's one place in the queue; ``background``: its jobs (a long job's parts) run on
        the queue's background thread instead, beside the workers and the session's place."""
        child = SessionRunner((self.owner, name), self._queue)
        child.background = background
        child._root = self._root
        self._root._subs.add(child.owner)
        return child

    def after_each(self, fn: Callable[[Job], None]) -> None:
        """Call ``fn(job)`` on the page once each job of the session (its sub-runners' included) has been
        handled there: its result shown, its failure said, or it was replaced."""
        self._root._after_each.append(fn)

    @staticmethod
    def then(job: Job, fn: Callable[[Job], None]) -> None:
        """Call ``fn(job)`` on the page once ``job`` has been handled there (now, if it was): what
        depends on a run's result being on the page waits for it (the next job of a sequence would
        otherwise replace this one in the queue, or read the page before the result is on it)."""
        if job.settled:
            fn(job)
        else:
            job.then.append(fn)

    def _settled(self, job: Job) -> None:
        for fn in [*self._root._after_each, *job.then]:
            try:
                fn(job)
            except Exception:  # noqa: BLE001 - what follows a run must not break the page
                log.exception("what follows the job %r failed", job.label)
        job.then.clear()

    def cancel_all(self, reason: str = "cancelled") -> list[Job]:
        """Cancel every computation of the session, its sub-runners' included (its page was closed).

        The queue forgets the owners too: nothing of a closed session stays referenced."""
        root = self._root
        jobs = root.queue.cancel_owner(root.owner, reason)
        for owner in list(root._subs):
            jobs += root.queue.cancel_owner(owner, reason)
        return jobs

    @property
    def queue(self) -> JobQueue:
        return self._queue if self._queue is not None else default_queue()

    def run(self, label: str, compute: Callable[[CancelToken], Any], show: Callable[[Any, Job], None], *,
            fail: Callable[[str], None], busy: Sequence = (), note: Callable[[str], None] | None = None,
            failed: Callable[[BaseException], None] | None = None,
            cancelled: Callable[[Job], None] | None = None) -> Job:
        """Compute ``compute(token)`` and then call ``show(result, job)`` on the page.

        ``fail(message)`` instead when it raised (``failed(error)`` instead, when
        given: the error itself, for code that acts on which field it names);
        ``cancelled(job)`` when it was cancelled; ``busy`` are Panel components
        shown as loading while the user waits; ``note(text)`` tells the user
        about the queue ("waiting: 3 runs ahead", "replaced") and is called
        with "" when there is nothing to say.
        """
        note = note or (lambda _text: None)
        outcome = _Outcome(show, fail, failed, cancelled, tuple(busy), note, self._settled)
        doc = served_document()
        if doc is None:
            return self._run_here(label, compute, outcome)

        def done(job: Job) -> None:        # a worker thread, or the submitting thread for "replaced"
            apply_locked(partial(self._finish, job, outcome), doc)

        job, replaced = self.queue.submit(self.owner, compute, label=label, on_done=done, place=self._root.owner,
                                          background=self.background)
        note(f"Your earlier request ({replaced.label}) was replaced by this one." if replaced is not None else "")

        def waiting() -> None:
            if job.finished:
                return
            with set_curdoc(doc), hold(doc), lazy_freeze(doc):
                for c in busy:
                    c.loading = True
                ahead = self.queue.ahead_of(job)
                if job.state == JobState.QUEUED:
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
    def _finish(job: Job, outcome: _Outcome) -> None:
        try:
            if job.state == JobState.DONE:
                try:
                    outcome.show(job.result, job)
                except Exception as exc:  # noqa: BLE001 - a fault of the page's code: said there, logged
                    # caught here, inside the page's update, so that what it changed so far still
                    # reaches the browser whole (an error escaping it left pages that later failed)
                    log.warning("showing the result of %r failed: %s", job.label, exc, exc_info=exc)
                    outcome.fail(f"the result could not be shown ({type(exc).__name__}); the server's log says "
                                 "more")
                outcome.note("")
            elif job.state == JobState.FAILED:
                log.debug("job %s failed", job.label)
                if outcome.failed is not None:
                    outcome.failed(job.error)
                else:
                    outcome.fail(_message(job.error))
                outcome.note("")
            elif job.state == JobState.REPLACED:
                return          # its successor owns the indicators now
            elif job.state == JobState.CANCELLED:
                outcome.note(f"Stopped: {job.token.reason or 'cancelled'}.")
                if outcome.cancelled is not None:
                    outcome.cancelled(job)
        finally:
            if job.state != JobState.REPLACED:
                for c in outcome.busy:
                    if c.loading:
                        c.loading = False
            job.settled = True
            if outcome.settled is not None:
                outcome.settled(job)

    def _run_here(self, label, compute, outcome: _Outcome) -> Job:
        job = Job(owner=self.owner, label=label, fn=compute)
        job.state = JobState.RUNNING
        job.started_at = job.submitted_at
        try:
            job.result = compute(job.token)
            job.state = JobState.DONE
        except Cancelled as exc:
            job.state, job.error = JobState.CANCELLED, exc
        except Exception as exc:  # noqa: BLE001 - shown in the page, as in a server
            job.state, job.error = JobState.FAILED, exc
            log_failure(label, session_name(self.owner), exc)
        job.finished_at = time.perf_counter()
        self._finish(job, outcome)
        return job


@dataclass(frozen=True)
class _Outcome:
    """What :meth:`SessionRunner.run` does with a job's end, by its :class:`~eha_app.runtime.jobs.JobState`."""

    show: Callable[[Any, Job], None]
    fail: Callable[[str], None]
    failed: Callable[[BaseException], None] | None
    cancelled: Callable[[Job], None] | None
    busy: tuple
    note: Callable[[str], None]
    settled: Callable[[Job], None] | None = None
