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

Two kinds of secret, kept apart because they grow differently:

* a few long-lived strings (the exercise's key, the teacher's token), given to
  :func:`keep_out_of_logs`: one small regular expression, rebuilt only when a
  new one arrives;
* every student's hidden values, given to :func:`register_student` when a page
  starts and released with its :class:`Registration` when the page ends: each
  printed form of each number (:func:`number_forms`) is a key of one dict.
  A message is cut into numbers by one fixed expression and each is looked up,
  so neither a registration nor a log line costs more with 500 students than
  with one (``benchmarks/bench_redaction.py``: the former single expression of
  every form took 2.1 s a registration at 100 students).

A number is hidden where it is not part of a longer number or word (nothing of
``[\\w.]`` before it, nothing of ``\\w`` after it), whole or by its integer part.

>>> keep_out_of_logs(4500.291346)
>>> redact("M = 4500.291346 kg, or 4500.3 kg, or 4.5003e+03 kg; B = 1500")
'M = [hidden] kg, or [hidden] kg, or [hidden] kg; B = 1500'
>>> page = register_student("lab-3", "ada", [0.031416926])
>>> redact("Af = 0.031417 m2, Af/2 = 0.015708463 m2.")
'Af = [hidden] m2, Af/2 = 0.015708463 m2.'
>>> page.release()
>>> redact("Af = 0.031417 m2")
'Af = 0.031417 m2'
"""

from __future__ import annotations

import logging
import math
import numbers
import re
import threading
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["keep_out_of_logs", "register_student", "Registration", "registry_stats", "RegistryStats",
           "SecretRegistry", "redact", "RedactingFilter", "redact_server_logs", "number_forms",
           "HIDDEN", "MAX_MESSAGE_CHARS"]

HIDDEN = "[hidden]"
#: A record longer than this is cut: a failed callback's log line once held a whole uploaded file.
MAX_MESSAGE_CHARS = 4000

# Every form number_forms gives is one of these (sign, digits, fraction, Python's signed exponent), so a
# registered form can only match where this does: from the same start, either the whole of it or, before
# its ".", its integer part. The lookahead captures the next character if it is a word character: then the
# whole does not count ("4500.3kg"), as it did not for the former expression's (?![\w]).
_NUMBER = re.compile(r"(?<![\w.])-?\d+(?P<fraction>\.\d+)?(?:e[-+]\d+)?(?=(?P<word>\w)?)")
# A message cut in the middle of a number or a key would show its first digits unrounded (4500.29|1346 shows
# 4500.29, which is no registered form): the cut moves back to the start of such a run, if it is this near.
_RUN_END = re.compile(r"[\w.]+\Z")
_RUN_BACK_CHARS = 256


def _is_number(value) -> bool:
    # a bool is an int to Python, but True is no secret worth hiding every "1" of the log for
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def number_forms(value: float, min_digits: int = 5) -> set[str]:
    """How a number may be written with at least ``min_digits`` significant digits.

    Parameters
    ----------
    value : float
        The number.
    min_digits : int
        The fewest significant digits that still give the number away.

    Returns
    -------
    set of str
        ``repr``, ``str``, ``%g`` and ``%e`` at ``min_digits`` to 17 digits.

    Examples
    --------
    >>> sorted(number_forms(4500.291346), key=len)[:3]
    ['4500.3', '4500.29', '4500.291']
    >>> {"4.5003e+03", "4500.29", "4500.2913", "4500.291346"} <= number_forms(4500.291346)
    True
    """
    forms = {repr(value), str(value)}
    for digits in range(min_digits, 18):
        forms.add(f"{value:.{digits}g}")
        forms.add(f"{value:.{digits - 1}e}")
    return forms


@dataclass(frozen=True)
class RegistryStats:
    """What a :class:`SecretRegistry` holds: ``students`` registered (exercise, student, values),
    ``pages`` (their registrations not yet released), ``forms`` (distinct printed numbers hidden,
    the permanent ones included) and ``strings`` (long-lived string secrets)."""

    students: int
    pages: int
    forms: int
    strings: int


class _Student:
    """One registered student: how many of their pages hold it, and their numbers' forms."""

    __slots__ = ("pages", "forms")

    def __init__(self, forms: tuple[str, ...]) -> None:
        self.pages = 1
        self.forms = forms


class Registration:
    """A page's hold on its student's hidden numbers; :meth:`release` it when the page ends.

    Returned by :meth:`SecretRegistry.register_student`. Releasing twice is harmless (a page's
    cleanup may run twice); it is also a context manager. Its ``repr`` names the student only:
    the exercise's key may be secret.
    """

    __slots__ = ("_registry", "_key", "_released")

    def __init__(self, registry: SecretRegistry, key: tuple) -> None:
        self._registry = registry
        self._key = key
        self._released = False

    @property
    def student(self) -> str:
        """The student this registration is for."""
        return self._key[1]

    @property
    def released(self) -> bool:
        """Whether :meth:`release` was called."""
        return self._released

    def release(self) -> None:
        """Drop this page's hold: the student's numbers leave the registry with their last page's."""
        self._registry._release(self)

    def __enter__(self) -> Registration:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __repr__(self) -> str:
        return f"<Registration of {self.student!r}{' (released)' if self._released else ''}>"


class SecretRegistry:
    """The secrets to keep out of a log, and :meth:`redact` to do it.

    The module's functions use one process-wide instance, like the log it guards; a test may make
    its own. Readers take no lock: a lookup in a dict that another thread changes under the lock
    sees it before or after the change (the GIL, or free-threaded CPython's per-dict locks).

    Examples
    --------
    >>> registry = SecretRegistry()
    >>> a = registry.register_student("lab-3", "ada", [4123.456789])
    >>> b = registry.register_student("lab-3", "ada", [4123.456789])      # ada's second page
    >>> a.release(); registry.redact("M = 4123.46 kg")      # the second page still holds it
    'M = [hidden] kg'
    >>> b.release(); registry.redact("M = 4123.46 kg")
    'M = 4123.46 kg'
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._forms: dict[str, int] = {}            # form -> how many students (and the permanent set) hold it
        self._students: dict[tuple, _Student] = {}
        self._kept_numbers: set[float] = set()      # keep()'s numbers and their forms: held for good
        self._kept_forms: set[str] = set()
        self._strings: frozenset[str] = frozenset()
        self._strings_pattern: re.Pattern | None = None

    # -- registering -----------------------------------------------------------------------------
    def register_student(self, exercise_key: str, student: str, values: Iterable[float]) -> Registration:
        """Hide a student's numbers for as long as one of their pages holds them.

        Parameters
        ----------
        exercise_key : str
            Identifies the exercise (its file's path, a hash of its key: it is never printed).
        student : str
            The student's normalised id.
        values : iterable of real numbers
            Their hidden values; non-finite ones are skipped. With other values for the same
            exercise and student (a changed exercise), the registration is counted apart.

        Returns
        -------
        Registration
            This page's hold; the numbers are dropped when the student's last one is released.
            Registering a student already held only counts the page.
        """
        numbers_ = []
        for v in values:
            if not _is_number(v):
                raise TypeError(f"a student's hidden value must be a number, not {type(v).__name__}")
            if math.isfinite(v):
                numbers_.append(float(v))
        key = (str(exercise_key), str(student), tuple(numbers_))
        with self._lock:
            entry = self._students.get(key)
            if entry is not None:
                entry.pages += 1
                return Registration(self, key)
        # computed outside the lock (tens of microseconds): the lock is held for dict updates only
        forms = tuple({form for v in numbers_ for form in number_forms(v)})
        with self._lock:
            entry = self._students.get(key)
            if entry is not None:                   # another page of the student got here first
                entry.pages += 1
            else:
                self._students[key] = _Student(forms)
                for form in forms:
                    self._forms[form] = self._forms.get(form, 0) + 1
        return Registration(self, key)

    def _release(self, registration: Registration) -> None:
        with self._lock:
            if registration._released:
                return
            registration._released = True
            entry = self._students[registration._key]
            entry.pages -= 1
            if entry.pages:
                return
            del self._students[registration._key]
            for form in entry.forms:
                self._drop_form(form)

    def _drop_form(self, form: str) -> None:
        left = self._forms[form] - 1
        if left:
            self._forms[form] = left
        else:
            del self._forms[form]

    def keep(self, *values) -> None:
        """Hide ``values`` for good: strings (4 characters or more) as they are, numbers in every
        form of :func:`number_forms`. For the few long-lived secrets; a student's numbers go to
        :meth:`register_student`, which lets them go."""
        strings = {v for v in values if isinstance(v, str) and len(v) >= 4}
        kept = {float(v) for v in values if _is_number(v) and math.isfinite(v)
                and float(v) not in self._kept_numbers}
        if strings <= self._strings and not kept:   # a page's every start passes the same secrets again
            return
        forms = {form for v in kept for form in number_forms(v)}
        with self._lock:
            self._kept_numbers |= kept
            for form in forms - self._kept_forms:
                self._forms[form] = self._forms.get(form, 0) + 1
            self._kept_forms |= forms
            if not strings <= self._strings:
                self._strings = self._strings | strings
                # longest first, so that a key is hidden whole rather than a shorter one inside it
                alternatives = "|".join(re.escape(s) for s in sorted(self._strings, key=len, reverse=True))
                self._strings_pattern = re.compile(rf"(?<![\w.])(?:{alternatives})(?![\w])")

    def stats(self) -> RegistryStats:
        """How many students, pages, forms and strings the registry holds."""
        with self._lock:
            return RegistryStats(students=len(self._students),
                                 pages=sum(s.pages for s in self._students.values()),
                                 forms=len(self._forms), strings=len(self._strings))

    # -- hiding ----------------------------------------------------------------------------------
    def redact(self, text: str) -> str:
        """``text`` with every registered secret replaced by ``[hidden]``."""
        if not text:
            return text
        pattern = self._strings_pattern
        if pattern is not None:
            text = pattern.sub(HIDDEN, text)
        if self._forms:
            text = self._hide_numbers(text)
        return text

    def _hide_numbers(self, text: str) -> str:
        forms, search = self._forms, _NUMBER.search
        pieces: list[str] = []
        done = pos = 0
        while (m := search(text, pos)) is not None:
            start = m.start()
            if m.group("word") is None and m.group() in forms:
                end = m.end()
            elif m.group("fraction") and text[start:m.start("fraction")] in forms:
                end = m.start("fraction")           # a registered 4500 in 4500.5, as the former expression did
            else:
                pos = start + 1                     # then without its sign ("-4500.3" holds 4500.3), or the next
                continue
            pieces += (text[done:start], HIDDEN)
            done = pos = end
        if not pieces:
            return text
        pieces.append(text[done:])
        return "".join(pieces)


_registry = SecretRegistry()


def register_student(exercise_key: str, student: str, values: Iterable[float]) -> Registration:
    """Hide a student's numbers in the server's log until their last page releases them
    (:meth:`SecretRegistry.register_student` of the process-wide registry).

    Parameters
    ----------
    exercise_key : str
        Identifies the exercise (never printed).
    student : str
        The student's normalised id.
    values : iterable of real numbers
        Their hidden values.

    Returns
    -------
    Registration
        This page's hold: call its ``release()`` when the page ends.
    """
    return _registry.register_student(exercise_key, student, values)


def keep_out_of_logs(*values) -> None:
    """Register secrets for good: strings as they are, numbers in every form of :func:`number_forms`
    (:meth:`SecretRegistry.keep` of the process-wide registry)."""
    _registry.keep(*values)


def registry_stats() -> RegistryStats:
    """What the process-wide registry holds."""
    return _registry.stats()


def redact(text: str) -> str:
    """``text`` with every secret of the process-wide registry replaced by ``[hidden]``."""
    return _registry.redact(text)


def _cut(message: str) -> str:
    if len(message) <= MAX_MESSAGE_CHARS:
        return message
    cut = MAX_MESSAGE_CHARS
    run = _RUN_END.search(message, cut - _RUN_BACK_CHARS, cut)
    if run is not None and _RUN_END.match(message, cut, cut + 1) and run.start() > cut - _RUN_BACK_CHARS:
        cut = run.start()
    return message[:cut] + f"… ({len(message) - cut} characters more)"


class RedactingFilter(logging.Filter):
    """Redact a record's message and traceback before any handler writes it.

    Parameters
    ----------
    registry : SecretRegistry, optional
        Whose secrets to hide; the process-wide registry by default.
    """

    def __init__(self, registry: SecretRegistry | None = None) -> None:
        super().__init__()
        self.registry = _registry if registry is None else registry

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except Exception:  # noqa: BLE001 - a broken format: let the handler report it as usual
            return True
        redact_ = self.registry.redact
        record.msg, record.args = redact_(_cut(message)), None
        if record.exc_info and not record.exc_text:
            record.exc_text = logging.Formatter().formatException(record.exc_info)
        if record.exc_text:
            record.exc_text = redact_(record.exc_text)
        if record.stack_info:
            record.stack_info = redact_(record.stack_info)
        return True


_filter = RedactingFilter()


def redact_server_logs() -> None:
    """Put :class:`RedactingFilter` on every handler of the root logger and of the app's logger
    (Bokeh, Tornado and Panel log through the root's); calling it again does nothing."""
    for logger in (logging.getLogger(), logging.getLogger("eha_app")):
        for handler in logger.handlers:
            if _filter not in handler.filters:
                handler.addFilter(_filter)
