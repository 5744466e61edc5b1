"""The server's computations: a fair queue shared by every session of the process.

A class of thirty shares a few cores. Without rules one student clicking a
heavy experiment eight times held all of the default executor's threads and
another student's 0.08 s simulation waited 78 s. The rules here:

- **One run per session at a time.** A session has at most one job running
  and at most one waiting; a new request while one runs replaces the waiting
  one (which is dropped, and the page says so).
- **Sessions take turns.** A free worker takes, among the sessions that have
  nothing running, the one served least recently (then the longest waiting):
  no session can hold more than one worker, and one that was just served goes
  behind those still waiting. A session is one *place* whatever runs for it:
  its model board's jobs and its tabs' runs (each a runner of its own, so
  that one does not replace another's request) wait in that one place.
- **Long work runs beside, never instead.** A long job cut in parts (a study)
  is *background* work: its parts run on a thread of their own, one at a
  time, the sessions' studies taking turns, and compute in a child process
  at the lowest OS priority (:mod:`eha_app.runtime.background`). It holds no
  worker and no session's place, and shares neither the GIL nor a core with
  the class: the cores it uses are the ones the others leave idle, and it
  waits while any request runs or waits (:meth:`JobQueue.requests_pending`). (Run on a
  worker, pausing between its seeds for the others' runs, a 500-seed study
  still made the other students' short steps 1.2-1.5x slower: a seed in
  flight held the GIL in turns with the event loop.)
- **Work for nobody is stopped.** Closing the page cancels the session's jobs
  (:meth:`JobQueue.cancel_owner`); a running job stops at its next check of
  its :class:`~eha_core.cancel.CancelToken` (between integration chunks,
  estimator iterations).
- **The event loop comes first.** Workers are threads (the compiled kernels
  release the GIL) running at a lower OS priority than the server's event
  loop, with numba limited to one thread each, so a student typing is served
  before anyone's computation.

Per-request limits (steps and memory) are checked before a job is queued, in
the tabs, with :mod:`eha_app.runtime.limits`.
"""

from __future__ import annotations

import enum
import itertools
import logging
import os
import threading
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

from eha_core.cancel import Cancelled, CancelToken
from eha_core.errors import ComputationError, not_allowed

from .background import give_way_now

__all__ = ["Job", "JobState", "JobQueue", "default_queue", "worker_count", "session_name", "log_failure",
           "EXPECTED_FAILURES"]

log = logging.getLogger("eha_app")

#: Nice value of the worker threads (Linux applies it per thread): computations
#: yield the CPU to the event loop that serves every student's clicks.
WORKER_NICE = 10


def worker_count() -> int:
    """Worker threads per server process: ``EHA_WORKERS``, else one per core."""
    env = os.environ.get("EHA_WORKERS", "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            raise not_allowed("EHA_WORKERS", env, "use a whole number >= 1") from None
        if n < 1:
            raise not_allowed("EHA_WORKERS", env, "use a whole number >= 1")
        return n
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


class JobState(str, enum.Enum):
    """Where a job stands. Code branches on these, never on a message's words."""

    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"
    REPLACED = "replaced"        # a newer request of the same session took its place before it ran

    @property
    def finished(self) -> bool:
        return self not in (JobState.QUEUED, JobState.RUNNING)


#: Failures that are outcomes of what the student asked (a refused value or file, parameters that
#: make a simulation diverge): the page says them; the log notes them, without a traceback, below
#: warnings, which are kept for faults of the server's own code.
EXPECTED_FAILURES = (ValueError, ArithmeticError, ComputationError)


def log_failure(label: str, who: str, exc: BaseException) -> None:
    """Log a computation that raised: a note for an expected outcome, a warning with its traceback
    for anything else."""
    if isinstance(exc, EXPECTED_FAILURES):
        log.info("job %r of %s ended without a result: %s", label, who, " ".join(str(exc).split()))
    else:
        log.warning("job %r of %s failed: %s", label, who, exc, exc_info=exc)


def session_name(owner: Hashable) -> str:
    """How the log names a job's session: a number, the same for a session's sub-runners
    (``(owner, "board")``), never the owner's repr (it may hold an exercise's secrets)."""
    while isinstance(owner, tuple) and owner:
        owner = owner[0]
    return f"session {id(owner) % 0xFFFFFF:06x}"


@dataclass(eq=False, repr=False)
class Job:
    """One computation for one session.

    ``state`` goes ``queued`` -> ``running`` -> ``done`` / ``failed`` /
    ``cancelled``; a queued job replaced by a newer request of the same session
    ends as ``replaced``. ``result`` or ``error`` hold the outcome.
    """

    owner: Hashable
    label: str
    fn: Callable[[CancelToken], Any]
    on_done: Callable[[Job], None] | None = None
    place: Hashable = None          # the session it runs for (its turn in the queue); None: its owner
    background: bool = False        # a part of a long job: runs on the background thread, beside the workers
    token: CancelToken = field(default_factory=CancelToken)
    state: JobState = JobState.QUEUED
    seq: int = 0
    submitted_at: float = field(default_factory=time.perf_counter)
    started_at: float | None = None
    finished_at: float | None = None
    result: Any = None
    error: BaseException | None = None
    #: Set once the page has handled the job's end (shown, said, or dropped as replaced), and what
    #: waits for that moment (:meth:`eha_app.runtime.tasks.SessionRunner.then`): both the page's.
    settled: bool = False
    then: list = field(default_factory=list)

    def __repr__(self) -> str:
        # not the dataclass's: its owner, function and result are no business of a log line
        return f"<Job {self.label!r} {self.state}>"

    @property
    def finished(self) -> bool:
        return self.state.finished

    @property
    def wait_s(self) -> float:
        """Seconds spent waiting for a worker."""
        end = self.started_at if self.started_at is not None else (self.finished_at or time.perf_counter())
        return end - self.submitted_at

    @property
    def run_s(self) -> float:
        """Seconds of computation (0 if it never started)."""
        if self.started_at is None:
            return 0.0
        return (self.finished_at or time.perf_counter()) - self.started_at

    @property
    def elapsed_s(self) -> float:
        """From the request to the result."""
        return (self.finished_at or time.perf_counter()) - self.submitted_at


class JobQueue:
    """Worker threads and the fair queue described in the module docstring."""

    def __init__(self, workers: int | None = None, *, nice: int = WORKER_NICE, name: str = "eha-worker"):
        self.workers = worker_count() if workers is None else int(workers)
        if self.workers < 1:
            raise not_allowed("workers", workers, "use 1 or more")
        self._nice = nice
        self._cond = threading.Condition()
        self._queued: dict[Hashable, Job] = {}
        self._running: dict[Hashable, Job] = {}
        self._seq = itertools.count()
        # by kind of work (False: requests, True: background), by place
        self._last_served: dict[bool, dict[Hashable, int]] = {False: {}, True: {}}
        self._busy_places: dict[bool, dict[Hashable, int]] = {False: {}, True: {}}   # place -> jobs running
        self._closed = False
        self.completed = 0
        self._threads = [threading.Thread(target=self._work, args=(False,), name=f"{name}-{i}", daemon=True)
                         for i in range(self.workers)]
        self._threads.append(threading.Thread(target=self._work, args=(True,), name=f"{name}-background",
                                              daemon=True))
        for t in self._threads:
            t.start()

    # -- asking -------------------------------------------------------------------
    def submit(self, owner: Hashable, fn: Callable[[CancelToken], Any], *, label: str = "",
               on_done: Callable[[Job], None] | None = None, place: Hashable = None,
               background: bool = False) -> tuple[Job, Job | None]:
        """Queue ``fn(token)`` for ``owner``; returns the job and the queued job it replaced, if any.

        ``place``: the session the job runs for, whose one turn in the queue it takes (default: the
        owner itself); ``background``: a part of a long job, run on the background thread (its
        sessions taking turns there), never on a worker.
        ``on_done(job)`` is called in the worker thread once the job has ended in any
        state (including ``replaced``, from the submitting thread).
        """
        job = Job(owner=owner, label=label, fn=fn, on_done=on_done, place=owner if place is None else place,
                  background=bool(background))
        with self._cond:
            if self._closed:
                raise RuntimeError("the job queue is shut down")
            job.seq = next(self._seq)
            replaced = self._queued.pop(owner, None)
            if replaced is not None:
                replaced.state = JobState.REPLACED
                replaced.finished_at = time.perf_counter()
                replaced.token.cancel("replaced by a newer request")
            self._queued[owner] = job
            self._cond.notify_all()     # the workers and the background thread wait on the same condition
        if not job.background:
            give_way_now()              # a study computing beside waits from now on
        if replaced is not None:
            self._notify(replaced)
        return job, replaced

    def cancel_owner(self, owner: Hashable, reason: str = "cancelled") -> list[Job]:
        """Cancel the owner's waiting and running jobs (e.g. its page was closed)."""
        with self._cond:
            jobs = [j for j in (self._queued.pop(owner, None), self._running.get(owner)) if j is not None]
            for served in self._last_served.values():
                served.pop(owner, None)             # a session's own runner is its place: forgotten
            for j in jobs:
                j.token.cancel(reason)
                if j.state == JobState.QUEUED:
                    j.state = JobState.CANCELLED
                    j.finished_at = time.perf_counter()
        for j in jobs:
            if j.state == JobState.CANCELLED:
                self._notify(j)
        return jobs

    def requests_pending(self) -> bool:
        """Whether a request (not background work) is running or waiting: the class is at work."""
        with self._cond:
            return (any(not j.background for j in self._running.values())
                    or any(not j.background for j in self._queued.values()))

    def ahead_of(self, job: Job) -> int:
        """About how many jobs start before ``job`` (0 when it is running or next)."""
        with self._cond:
            if job.state != JobState.QUEUED:
                return 0
            served = self._last_served[job.background]
            mine = (served.get(job.place, -1), job.seq)
            return sum(1 for j in self._queued.values()
                       if j is not job and j.background == job.background
                       and (served.get(j.place, -1), j.seq) < mine)

    def snapshot(self) -> dict:
        """Counts for monitoring: queued, running, completed, workers."""
        with self._cond:
            return {"queued": len(self._queued), "running": len(self._running), "completed": self.completed,
                    "workers": self.workers}

    def shutdown(self) -> None:
        """Stop the workers after their current jobs (tests)."""
        with self._cond:
            self._closed = True
            for j in self._queued.values():
                j.token.cancel("the server is stopping")
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=30)

    # -- the workers ---------------------------------------------------------------
    def _next(self, background: bool) -> Job | None:
        """The next job of its kind (a request for a worker, background work for the background
        thread) to start (call with the lock): among places (sessions) with nothing of that kind
        running, the place served least recently, then the longest waiting."""
        best, best_key = None, None
        busy, served = self._busy_places[background], self._last_served[background]
        for job in self._queued.values():
            if job.background != background or job.place in busy:
                continue
            key = (served.get(job.place, -1), job.seq)
            if best is None or key < best_key:
                best, best_key = job, key
        return best

    def _work(self, background: bool) -> None:
        self._lower_priority()
        busy, served = self._busy_places[background], self._last_served[background]
        while True:
            with self._cond:
                job = self._next(background)
                while job is None:
                    if self._closed:
                        return
                    self._cond.wait()
                    job = self._next(background)
                del self._queued[job.owner]
                self._running[job.owner] = job
                busy[job.place] = busy.get(job.place, 0) + 1
                served[job.place] = next(self._seq)
                job.state = JobState.RUNNING
                job.started_at = time.perf_counter()
            try:
                job.token.check()
                job.result = job.fn(job.token)
                job.state = JobState.DONE
            except Cancelled as exc:
                job.state, job.error = JobState.CANCELLED, exc
            except Exception as exc:  # noqa: BLE001 - a failure is the job's outcome, shown in its page
                job.state, job.error = JobState.FAILED, exc
                # by its session's number: the owner's repr is no business of the log
                log_failure(job.label, session_name(job.owner), exc)
            job.finished_at = time.perf_counter()
            with self._cond:
                if self._running.get(job.owner) is job:
                    del self._running[job.owner]
                left = busy.get(job.place, 1) - 1
                if left > 0:
                    busy[job.place] = left
                else:
                    busy.pop(job.place, None)
                self.completed += 1
                self._cond.notify_all()
            self._notify(job)

    @staticmethod
    def _notify(job: Job) -> None:
        if job.on_done is None:
            return
        try:
            job.on_done(job)
        except Exception:  # noqa: BLE001 - a broken page must not stop a worker
            log.exception("showing the result of job %r failed", job.label)

    def _lower_priority(self) -> None:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), self._nice)
        except (AttributeError, OSError):  # not Linux, or not permitted: run at normal priority
            pass
        try:
            import numba

            numba.set_num_threads(1)  # per calling thread: one core per job, jobs in parallel
        except Exception:  # noqa: BLE001 - numba missing or no threading layer: nothing to limit
            pass
        # A student's extreme values overflow (inf, nan): the core checks what it computes and says so
        # in the page; numpy's warnings of it (per worker thread: numpy's error state is the thread's)
        # would only fill the server's log
        import numpy as np

        np.seterr(all="ignore")


_default: JobQueue | None = None
_default_lock = threading.Lock()


def default_queue() -> JobQueue:
    """The process's queue, created on first use (after the server has forked its processes)."""
    global _default
    with _default_lock:
        if _default is None:
            _default = JobQueue()
        return _default
