"""Cooperative cancellation of long computations.

A web server runs students' computations in worker threads; when a page is
closed, or a newer request replaces a waiting one, the work should stop. The
long-running functions of the core take ``cancel=`` (a :class:`CancelToken`)
and call :meth:`CancelToken.check` at points where stopping is cheap (between
integration chunks, estimator iterations); a cancelled token raises
:class:`Cancelled` there.

>>> from eha_core.cancel import CancelToken, Cancelled
>>> token = CancelToken()
>>> token.check()
>>> token.cancel("the page was closed")
>>> token.cancelled, token.reason
(True, 'the page was closed')
>>> try:
...     token.check()
... except Cancelled as exc:
...     print(exc)
the page was closed
"""

from __future__ import annotations

import threading

__all__ = ["Cancelled", "CancelToken", "check"]


class Cancelled(Exception):
    """The caller asked to stop."""


class CancelToken:
    """A flag one thread sets and another checks (thread-safe).

    Any thread may call :meth:`cancel`, any number of times: the first reason
    given is kept. Checking is one read of a :class:`threading.Event`, cheap
    enough for every iteration of an estimator.
    """

    def __init__(self):
        self._event = threading.Event()
        self._lock = threading.Lock()
        self._reason = ""

    def cancel(self, reason: str = "") -> None:
        """Ask the computation holding this token to stop (``reason`` tells the user why)."""
        # the lock makes "first reason wins" hold when two threads cancel at
        # once; the reason is written before the event, so a checker that sees
        # the event also sees its reason
        with self._lock:
            if not self._event.is_set():
                self._reason = reason or "cancelled"
                self._event.set()

    @property
    def cancelled(self) -> bool:
        """True once :meth:`cancel` was called."""
        return self._event.is_set()

    @property
    def reason(self) -> str:
        """The reason given to the first :meth:`cancel` ("cancelled" if none), or ""."""
        return self._reason

    def check(self) -> None:
        """Raise :class:`Cancelled` if cancellation was asked for."""
        if self._event.is_set():
            raise Cancelled(self._reason)


def check(token: CancelToken | None) -> None:
    """``token.check()`` when a ``token`` was given: raise :class:`Cancelled` if it was cancelled; None never raises."""
    if token is not None:
        token.check()
