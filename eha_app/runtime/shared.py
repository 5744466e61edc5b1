"""Pure computations shared by the sessions of one server process.

Thirty students who press "Run least squares" with the same inputs (the
defaults, at the start of a lab) ask the server for thirty identical
computations. :class:`SharedResults` computes each one once: the first request
with a key computes it, requests with the same key that arrive meanwhile wait
for that result instead of computing it again, and later ones take it from a
small least-recently-used store.

Only what is a function of its key alone goes through it (a simulation of
given parameters and inputs, an estimate on that simulation), and its results
are never changed by their users: they are shared by every student with the
same inputs. The key holds every input, the actuator's parameters included, so
an exercise's hidden actuator (each student's own) is shared with no one else;
nor could a hit tell anything: it is the result the student would compute.

A waiting request checks its own cancel token (its page may close), and if the
computation it waited for failed or was cancelled (the first page closed), it
computes the result itself: one student's closed page never fails another's
run.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable, Hashable
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout

from eha_core.cancel import CancelToken, check

__all__ = ["SharedResults", "shared_results"]


class SharedResults:
    """A process-wide store of pure results by key (see the module docstring).

    ``maxsize`` results are kept (least recently used dropped first); ``hits``,
    ``joins`` (a wait for a computation under way) and ``misses`` count the
    requests, for the benchmarks.
    """

    #: A waiting request looks at its own cancel token this often [s].
    POLL_S = 0.05

    def __init__(self, maxsize: int = 48):
        self.maxsize = int(maxsize)
        self._done: collections.OrderedDict = collections.OrderedDict()
        self._running: dict[Hashable, Future] = {}
        self._lock = threading.Lock()
        self.hits = self.joins = self.misses = 0

    def get(self, key: Hashable, compute: Callable[[CancelToken | None], object],
            token: CancelToken | None = None):
        """``compute(token)``'s result for ``key``: stored, awaited from another request, or computed."""
        with self._lock:
            if key in self._done:
                self._done.move_to_end(key)
                self.hits += 1
                return self._done[key]
            future = self._running.get(key)
            owner = future is None
            if owner:
                future = self._running[key] = Future()
                self.misses += 1
            else:
                self.joins += 1
        if owner:
            return self._compute(key, future, compute, token)
        while True:
            check(token)
            try:
                return future.result(timeout=self.POLL_S)
            except FutureTimeout:
                continue
            except BaseException:  # noqa: BLE001 - the other request's failure or cancel is not this one's
                return compute(token)

    def _compute(self, key, future: Future, compute, token):
        try:
            value = compute(token)
        except BaseException as exc:
            with self._lock:
                self._running.pop(key, None)
            future.set_exception(exc)
            raise
        with self._lock:
            self._running.pop(key, None)
            self._done[key] = value
            while len(self._done) > self.maxsize:
                self._done.popitem(last=False)
        future.set_result(value)
        return value

    def clear(self) -> None:
        with self._lock:
            self._done.clear()


#: The server's store (every session of the process shares it).
shared_results = SharedResults()
