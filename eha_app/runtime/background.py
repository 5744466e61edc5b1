"""Long background computations (a study) in a process of their own, at the lowest priority.

A study of 500 seeds in a worker thread of the server shared the server's
interpreter with the event loop that answers every student: its Python code
held the GIL in turns with the loop's, and each student's click waited for
it (with one student running a study, the others' short steps took 10-60 ms
longer, 1.2-1.5x). The study paused between its seeds for the others' runs,
but a seed in flight could not be paused.

Here such work runs in one child process per server process, started when
first needed and kept: no GIL in common with the server, and an OS priority
of "idle" (Linux's ``SCHED_IDLE``: it runs only on a core that nothing else
wants, and gives it up at once), so the child computes with the cores the
class leaves idle. Nice 19 was not enough: a nice-19 process busy beside a
class of 30 made their least squares 0.12 -> 0.28 s at the median and the
first show of tab 2 1.50 -> 1.79 s; an idle-policy one left them as they were
(0.11, 1.44; ``bench_classroom.py --sessions 30`` beside a busy loop of each).

The server's thread that asked (the job queue's background thread) waits for
the answer without holding the GIL; the work's progress, a cancel and a
request to wait cross over in three shared integers:

- ``progress(done, total)`` calls in the child set the count of seeds done;
  the waiting thread reads it every :data:`POLL_S` and calls the caller's
  ``progress`` in the server;
- a cancel of the caller's :class:`~eha_core.cancel.CancelToken` sets the
  cancel flag, which the child's token reads at each of its checks (between
  integration chunks and estimator iterations): it stops within one.
- while the class is at work (a student's run computes or waits, a page
  change is made or waits: ``give_way``), a third shared byte asks the child
  to wait at its checks (a few ms apart in a least-squares seed). Set at once
  when a request or a page change arrives (:func:`give_way_now`), cleared by
  the waiting thread once nothing is left; never more than
  :data:`MAX_PAUSE_S` in a row, so that a study still progresses on a server
  that is never idle. Even at the idle priority, a child computing beside the
  class took the cores' caches and a share of the memory bus: with a study
  running beside 30 students, their least squares took 1.26x, their
  frequency experiment 1.29x and "Compare both" 1.75x (p95) of the time
  without; waiting, every step's p50 and p95 are within 1.09x but Compare
  both's p95 (``bench_classroom.py --sessions 30 --hog study
  --hog-repeats 4``). That last one was not the child's doing: with the
  child stopped outright (SIGSTOP) it stayed (1.44x), and the server's log
  of its garbage collections showed a full one (25-35 ms) brought by the
  study's page into the middle of the burst of clicks; smaller, more
  frequent full collections (:func:`eha_app.runtime.patches.collect_often`)
  made every step within 1.05x. A call that gives way does not even begin
  while the class is at work (a study's set-up computes before its first
  check): a student pressing the study's run and cancel buttons every 0.3 s
  had made the others' frequency experiment 1.31x at the median, each press
  a set-up computed beside the class; with it, every step within 1.09x
  (``--hog spam --hog-repeats 6``).

The child exits when the server does (it watches its parent) and after
:data:`IDLE_S` unused (about 200 MB given back); a child that died (killed,
out of memory) is replaced at the next call, the call it was running said
failed. Where no child can start at all (a limit on processes, a main script
it cannot import), the work runs in the caller's thread, and the log says so.
"""

from __future__ import annotations

import atexit
import logging
import multiprocessing
import os
import pickle
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout  # the builtin's alias from Python 3.11 on
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from eha_core.cancel import Cancelled, CancelToken
from eha_core.errors import ComputationError

__all__ = ["BackgroundProcess", "background_process", "give_way_now", "CHILD_NICE", "POLL_S", "MAX_PAUSE_S"]

log = logging.getLogger("eha_app")

#: The child's OS priority where the idle policy is not available: the lowest, below the
#: workers' (10) and the event loop's (0).
CHILD_NICE = 19
#: How often the waiting thread reads the child's progress and passes on a cancel [s].
POLL_S = 0.02
#: How often the child checks that its server still runs [s].
PARENT_CHECK_S = 0.5
#: While the server asks it to give way, the child waits at each check of its token at most this
#: long in a row [s] ...
MAX_PAUSE_S = 2.0
#: ... then computes at least this long before it waits again [s] ...
MIN_RUN_S = 0.1
#: ... looking again this often [s].
PAUSE_STEP_S = 0.005
#: After no child could start, the calls run in the caller's thread this long before a child is
#: tried again [s].
NO_CHILD_RETRY_S = 60.0
#: A child unused this long is stopped (its memory, about 200 MB, given back); the next call starts
#: another (about 1 s) [s].
IDLE_S = 300.0


# -- in the child ---------------------------------------------------------------------------
_cancel_flag = None
_done_count = None
_pause_flag = None


class _FlagToken(CancelToken):
    """The child's side of the caller's token: cancelled when the server sets the shared flag, and
    a moment to wait at each check while the server asks the child to give way."""

    def __init__(self, flag, pause=None):
        super().__init__()
        self._flag = flag
        self._pause = pause
        self._free_until = 0.0

    def _poll(self) -> None:
        if not self._event.is_set() and self._flag.value:
            super().cancel("cancelled")

    @property
    def cancelled(self) -> bool:
        self._poll()
        return self._event.is_set()

    def check(self) -> None:
        self._poll()
        if self._pause is not None and self._pause.value:
            self._give_way()
        super().check()

    def _give_way(self) -> None:
        now = time.monotonic()
        if now < self._free_until:
            return
        start = now
        while self._pause.value and not self._flag.value and now - start < MAX_PAUSE_S:
            time.sleep(PAUSE_STEP_S)
            now = time.monotonic()
        if now - start >= MAX_PAUSE_S:
            # a server busy without a break: the work still goes on, a little at a time
            self._free_until = now + MIN_RUN_S
        self._poll()


def _child_start(flag, done, pause, parent: int, nice: int) -> None:
    global _cancel_flag, _done_count, _pause_flag
    _cancel_flag, _done_count, _pause_flag = flag, done, pause
    # the libraries loaded before the priority drops: a child starting on a busy server is ready soon
    import numpy as np

    try:
        import numba

        numba.set_num_threads(1)   # one core: the class's other work runs beside it
    except Exception:  # noqa: BLE001 - numba missing or no threading layer: nothing to limit
        pass
    np.seterr(all="ignore")        # as in the workers: the core says what overflowed, not numpy's warnings
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except (AttributeError, OSError):  # not Linux, or not permitted: run at the priority given
        pass
    try:
        # this thread's policy, inherited by any thread the work starts
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):  # not Linux: the nice value alone
        pass

    def watch_parent() -> None:
        # a server killed without a goodbye (SIGKILL, a crash) leaves no one to stop this process
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(0)

    threading.Thread(target=watch_parent, name="eha-parent-watch", daemon=True).start()


def _progress(done: int, _total: int = 0) -> None:
    _done_count.value = int(done)


def _child_call(fn: Callable, args: tuple, kwargs: dict, with_cancel: bool, with_progress: bool,
                with_give_way: bool = False):
    """Run ``fn`` in the child; an outcome the server can always read: ("ok", result),
    ("cancelled", None) or ("error", (exception or None, its type's name, its message))."""
    _done_count.value = 0           # the call has begun (a child dying now fails it)
    if with_cancel:
        kwargs = {**kwargs, "cancel": _FlagToken(_cancel_flag, _pause_flag if with_give_way else None)}
    if with_progress:
        kwargs = {**kwargs, "progress": _progress}
    try:
        if with_cancel and with_give_way:
            # not even begun while the class is at work: a study's set-up (its plan, the nominal
            # run) computes before its first check
            kwargs["cancel"].check()
        return "ok", fn(*args, **kwargs)
    except Cancelled:
        return "cancelled", None
    except Exception as exc:  # noqa: BLE001 - every failure goes back to the server, said there
        try:
            pickle.loads(pickle.dumps(exc))
            sent = exc
        except Exception:  # noqa: BLE001 - an exception that does not cross processes: its words do
            sent = None
        return "error", (sent, type(exc).__name__, str(exc))


def _child_ready() -> int:
    return os.getpid()


# -- in the server --------------------------------------------------------------------------
class _NotBegun(Exception):
    """The child died before it began the call."""


class BackgroundProcess:
    """One child process that runs calls one at a time (see the module docstring)."""

    def __init__(self, nice: int = CHILD_NICE, idle_s: float = IDLE_S):
        self._nice = nice
        self._idle_s = float(idle_s)
        self._last_used = time.monotonic()
        self._reaper: threading.Thread | None = None
        self._lock = threading.Lock()          # one call at a time
        self._pool: ProcessPoolExecutor | None = None
        self._flag = self._done = self._pause = None
        self._giving_way = False                # a call with give_way() runs
        self.pid: int | None = None
        self.calls = 0
        self.restarts = 0
        self.without_child = False      # the last call found no child to run it (it ran in the caller)
        self._no_child_until = 0.0
        self._exit_hooked = False

    def _ensure(self, cancel: CancelToken | None) -> ProcessPoolExecutor:
        if self._pool is None:
            # spawn, not fork: the server has threads (its event loop, the workers) whose locks a
            # forked child would inherit held
            ctx = multiprocessing.get_context("spawn")
            self._flag, self._done = ctx.Value("b", 0, lock=False), ctx.Value("q", -1, lock=False)
            self._pause = ctx.Value("b", 0, lock=False)
            self._pool = ProcessPoolExecutor(1, mp_context=ctx, initializer=_child_start,
                                             initargs=(self._flag, self._done, self._pause, os.getpid(),
                                                       self._nice))
            ready = self._pool.submit(_child_ready)
            while True:
                try:
                    self.pid = ready.result(timeout=POLL_S)
                    break
                except FutureTimeout:
                    if cancel is not None:
                        cancel.check()      # the child goes on starting, for the next call
            if not self._exit_hooked:
                # before the pool's own exit hook (registered earlier, run later), which would wait
                # for the part in flight: a server told to stop stops its child at once
                register = getattr(threading, "_register_atexit", None)
                (register or atexit.register)(self._stop_now)
                self._exit_hooked = True
            if self._reaper is None or not self._reaper.is_alive():
                self._reaper = threading.Thread(target=self._stop_when_idle, name="eha-background-reaper",
                                                daemon=True)
                self._reaper.start()
        return self._pool

    def _stop_when_idle(self) -> None:
        while True:
            time.sleep(min(10.0, self._idle_s / 4))
            # a call running holds the lock: never stopped under it
            if not self._lock.acquire(blocking=False):
                continue
            try:
                if self._pool is None:
                    return
                if time.monotonic() - self._last_used >= self._idle_s:
                    pool, self._pool, self.pid = self._pool, None, None
                    _shut(pool, wait=True)
                    log.info("the process for long computations stopped after %.0f s unused", self._idle_s)
                    return
            finally:
                self._lock.release()

    def call(self, fn: Callable, *args, cancel: CancelToken | None = None,
             progress: Callable[[int, int], object] | None = None, total: int = 0,
             give_way: Callable[[], bool] | None = None, **kwargs) -> Any:
        """``fn(*args, **kwargs)`` in the child (``fn`` and its arguments picklable), with a ``cancel``
        token and a ``progress(done, total)`` callback passed through when given. Returns its result;
        raises what it raised (:class:`~eha_core.cancel.Cancelled` once cancelled, if ``fn`` stops by
        raising it). ``give_way()``, asked every :data:`POLL_S` in the server (and at once when
        :func:`give_way_now` is called): while it holds, the child waits at its token's checks (at
        most :data:`MAX_PAUSE_S` in a row)."""
        with self._lock:
            if cancel is not None:
                cancel.check()
            self.calls += 1
            for attempt in range(2):
                future = self._start_call(fn, args, kwargs, cancel, progress, give_way)
                if future is None:
                    break
                try:
                    status, value = self._wait(future, cancel, progress, total, give_way)
                    break
                except _NotBegun:
                    # the child had died since the last call (the pool had not noticed yet): another
                    # child takes the call, which had not begun
                    if attempt:
                        raise ComputationError("the server's process for long computations could not start; "
                                               "try again") from None
            self._last_used = time.monotonic()
        if future is None:
            # no child process to be had (a main script the child cannot import, a limit on
            # processes): the work is done here, as it would be without this module
            return fn(*args, **kwargs, **({"cancel": cancel} if cancel is not None else {}),
                      **({"progress": lambda done, _total=0: progress(done, total)} if progress is not None
                         else {}))
        if status == "ok":
            return value
        if status == "cancelled":
            raise Cancelled(cancel.reason if cancel is not None else "cancelled")
        exc, name, message = value
        raise exc if exc is not None else ComputationError(f"{name}: {message}")

    def _start_call(self, fn, args, kwargs, cancel, progress, give_way):
        """The call sent to the child (a child that died since the last call replaced first), or None
        when no child can start."""
        if time.monotonic() < self._no_child_until:
            return None
        for attempt in range(2):
            try:
                pool = self._ensure(cancel)
                self.without_child = False
                # -1: not begun; waiting from the start if the class is at work now
                self._flag.value, self._done.value = 0, -1
                self._pause.value = 1 if give_way is not None and give_way() else 0
                return pool.submit(_child_call, fn, args, kwargs, cancel is not None, progress is not None,
                                   give_way is not None)
            except (BrokenProcessPool, OSError) as exc:
                self._drop()
                if attempt:
                    self._no_child(exc)
        return None

    def _wait(self, future, cancel, progress, total, give_way):
        """The child's outcome of ``future``, passing on progress, a cancel and the requests to wait."""
        seen, passed = 0, False
        self._giving_way = give_way is not None
        try:
            while True:
                try:
                    outcome = future.result(timeout=POLL_S)
                except FutureTimeout:
                    outcome = None
                if cancel is not None and cancel.cancelled and not passed:
                    self._flag.value, passed = 1, True
                if give_way is not None:
                    self._pause.value = 1 if outcome is None and give_way() else 0
                done = self._done.value
                if progress is not None and done > seen:      # the last count too, before the result
                    seen = done
                    progress(seen, total)
                if outcome is not None:
                    return outcome
        except BrokenProcessPool:
            begun = self._done.value >= 0
            self._drop()
            if not begun:
                raise _NotBegun from None
            # the child died in the call's middle (killed, out of memory): the call failed
            raise ComputationError("the server's process for long computations stopped during this run; "
                                   "try again") from None
        except BaseException:
            # the server's side failed (a page gone, a callback's fault): the child stops too, not
            # left computing a call nobody waits for
            if not future.done():
                self._stop_now()
            raise
        finally:
            self._giving_way = False

    def _no_child(self, exc: BaseException) -> None:
        if not self.without_child:
            log.warning("no process for long computations could start (%s: %s): they run in the server's "
                        "threads for the next %.0f s", type(exc).__name__, exc, NO_CHILD_RETRY_S)
        self.without_child = True
        self._no_child_until = time.monotonic() + NO_CHILD_RETRY_S

    def _stop_now(self) -> None:
        """Stop the child at once (the server exits, or a call's waiting failed)."""
        if self._pool is None:
            return
        try:
            self._flag.value, self._pause.value = 1, 0
        except Exception:  # noqa: BLE001 - the shared values are gone with the process: nothing to tell
            pass
        self._kill()

    def _drop(self) -> None:
        """Forget a child that failed (killed if it still runs); the next call starts another."""
        self.restarts += 1
        self._kill()

    def _kill(self) -> None:
        pool, pid = self._pool, self.pid
        self._pool, self.pid = None, None
        if pid is not None:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:             # gone already
                pass
        if pool is not None:
            _shut(pool, wait=False)

    def shutdown(self) -> None:
        """Stop the child (tests; a server's end stops it anyway)."""
        with self._lock:
            pool, self._pool, self.pid = self._pool, None, None
        if pool is not None:
            _shut(pool, wait=True)


def _shut(pool: ProcessPoolExecutor, wait: bool) -> None:
    """Shut ``pool`` down. Python 3.11's executor can raise from its wake-up pipe when its manager thread
    closed it a moment before (a child that died or was killed: OSError "handle is closed"), as one
    test session's end did: the child is gone then, and there is nothing left to stop."""
    try:
        pool.shutdown(wait=wait, cancel_futures=True)
    except (OSError, ValueError) as exc:
        log.info("the process for long computations was gone at its shutdown (%s)", type(exc).__name__)


_default: BackgroundProcess | None = None
_default_lock = threading.Lock()


def give_way_now() -> None:
    """A student's request or page change has just come: the child (if a call that gives way runs)
    waits from its next check on, without waiting for the next look of :meth:`BackgroundProcess.call`
    (:data:`POLL_S`), which lets it go on once nothing is left to do. Cheap: one shared byte."""
    bp = _default
    if bp is not None and bp._giving_way and bp._pause is not None:
        bp._pause.value = 1


def background_process() -> BackgroundProcess:
    """The server process's child for long computations (started at its first call)."""
    global _default
    with _default_lock:
        if _default is None:
            _default = BackgroundProcess()
        return _default
