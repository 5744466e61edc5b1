"""Keeping an exercise's secrets, and anything long, out of the server's log.

The first line of defence is that nothing secret is ever formatted into a log
line: the exercise and a session's state leave their secrets out of ``repr``,
and a failed computation is logged by its label and its session's number, not
by the objects it belongs to. This module is the second: every record of the
server's log passes :class:`RedactingFilter`, which replaces any registered
secret (the exercise's key, each student's hidden values as the numbers
they would be printed as) with ``[hidden]``, in the message and in the
traceback alike, and cuts a message longer than :data:`MAX_MESSAGE_CHARS`
(Panel logs a failed callback with the whole value it was given).

The registry is process-wide, like the log it guards: every student's hidden
values are added when their session starts, and only ever compared against.

>>> keep_out_of_logs(4500.291346)
>>> redact("M = 4500.291346 kg, or 4500.3 kg, or 4.5003e+03 kg; B = 1500")
'M = [hidden] kg, or [hidden] kg, or [hidden] kg; B = 1500'
"""

from __future__ import annotations

import logging
import math
import re
import threading

__all__ = ["keep_out_of_logs", "redact", "RedactingFilter", "redact_server_logs", "number_forms"]

HIDDEN = "[hidden]"
#: A record longer than this is cut: a failed callback's log line once held a whole uploaded file.
MAX_MESSAGE_CHARS = 4000
_lock = threading.Lock()
_secrets: set[str] = set()
_pattern: re.Pattern | None = None


def number_forms(value: float, min_digits: int = 5) -> set[str]:
    """How a number may be written with at least ``min_digits`` significant digits: ``repr``,
    ``%g`` and ``%e`` at 5 to 17 digits (``4500.3``, ``4500.29``, ``4.5003e+03``, ...)."""
    forms = {repr(value), str(value)}
    for digits in range(min_digits, 18):
        forms.add(f"{value:.{digits}g}")
        forms.add(f"{value:.{digits - 1}e}")
    return forms


def keep_out_of_logs(*values) -> None:
    """Register secrets: strings as they are, numbers in every form of :func:`number_forms`."""
    global _pattern
    new = set()
    for v in values:
        if isinstance(v, str):
            if len(v) >= 4:
                new.add(v)
        elif isinstance(v, (int, float)) and math.isfinite(v):
            new |= number_forms(float(v))
    with _lock:
        if new <= _secrets:
            return
        _secrets.update(new)
        # longest first, so that 4500.2913 is hidden whole rather than as [hidden]13;
        # a number is hidden only where it is not part of a longer number
        alternatives = "|".join(re.escape(s) for s in sorted(_secrets, key=len, reverse=True))
        _pattern = re.compile(rf"(?<![\w.])(?:{alternatives})(?![\w])")


def redact(text: str) -> str:
    """``text`` with every registered secret replaced by ``[hidden]``."""
    pattern = _pattern
    if pattern is None or not text:
        return text
    return pattern.sub(HIDDEN, text)


class RedactingFilter(logging.Filter):
    """Redact a record's message and traceback before any handler writes it."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except Exception:  # noqa: BLE001 - a broken format: let the handler report it as usual
            return True
        if len(message) > MAX_MESSAGE_CHARS:
            message = message[:MAX_MESSAGE_CHARS] + f"… ({len(message) - MAX_MESSAGE_CHARS} characters more)"
        record.msg, record.args = redact(message), None
        if record.exc_info and not record.exc_text:
            record.exc_text = logging.Formatter().formatException(record.exc_info)
        if record.exc_text:
            record.exc_text = redact(record.exc_text)
        if record.stack_info:
            record.stack_info = redact(record.stack_info)
        return True


_filter = RedactingFilter()


def redact_server_logs() -> None:
    """Put :class:`RedactingFilter` on every handler of the root logger and of the app's logger
    (Bokeh, Tornado and Panel log through the root's); calling it again does nothing."""
    for logger in (logging.getLogger(), logging.getLogger("eha_app")):
        for handler in logger.handlers:
            if _filter not in handler.filters:
                handler.addFilter(_filter)
