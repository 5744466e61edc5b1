"""A class exercise: every student identifies an actuator of their own, with some parameters hidden.

The teacher's exercise file holds a secret and the rules: which parameters are
hidden, how far each student's actuator varies around the paper's values, the
tolerance of a correct answer per parameter, the conditions of the experiment
(sensor noise floors, a disturbance the students cannot remove, the signals
measured, the record's limits, the methods allowed), the deadline, the number
of hand-ins and what a student is told after one.

A student's actuator is derived from the secret and the student's id
(HMAC-SHA256): the same id always gets the same actuator, different ids
different ones, and only the holder of the secret can compute any of them.

With a roster (``roster=[(id, name), ...]``) every student has a join code of
their own: ten characters drawn from the secret and a random nonce (so not
derivable from the id, and printable again by the teacher with the file); the
file keeps only the code's hash, which is all the server compares. Without a
roster the exercise is open: any id typed is taken as given (the teacher is
told so).

A hand-in is judged by the precision of the student's own record (``grading``
"zscore", the default): the value must lie within k standard errors of the
truth, the standard error the server computed on the record the student made,
and k standard errors must be within the parameter's tolerance (a record that
does not determine a parameter earns nothing for it, however close the value).
A better experiment earns a tighter acceptance. ``grading="relative"`` judges by
the tolerance alone.

The file is read only by the server and the teacher's command line; a verdict
says accepted or not, never the true value.

Examples
--------
>>> ex = Exercise.new(hide=("M", "B"), vary=0.25, tolerance=0.05, title="Lab 3", secret="00" * 32,
...                   roster=[("s1", "Ada Lovelace"), ("s2", "Alan Turing")])
>>> p = ex.student_params("s1")
>>> 0.75 * 4000 <= p.M <= 1.25 * 4000 and p.Af == 3000.0
True
>>> ex.verdicts("s1", {"M": p.M * 1.04, "B": p.B * 0.5},        # the standard errors of the student's record
...             {"M": 0.015 * p.M, "B": 0.01 * p.B})
{'M': True, 'B': False}
>>> code = ex.join_code("s1")
>>> len(code), ex.entry_for_code(code.lower().replace("-", " ")).name
(11, 'Ada Lovelace')
>>> ex.entry_for_code("AAAAA-AAAAA") is None            # a wrong code names no one
True
>>> "00" * 16 in repr(ex) or code in ex.to_json()       # neither the secret in its repr nor a code in the file
False
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import hashlib
import hmac
import io
import json
import math
import secrets
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from ._checks import not_allowed
from .param_table import FIELD_INFO
from .params import ActuatorParams

__all__ = ["Exercise", "Conditions", "RosterEntry", "HIDEABLE", "SIGNALS", "METHODS", "FEEDBACK", "SCORE_RULES",
           "SCORE_TEXT", "GRADINGS", "Judgement", "normalize_id", "normalize_code", "parse_deadline", "read_roster",
           "MAX_VARY", "MAX_ID_LENGTH"]

#: Every parameter of the actuator may be hidden (the blank-able p2(0) aside: it follows from the force balance).
HIDEABLE = tuple(n for n in FIELD_INFO if n != "p2_0")
#: A parameter whose paper value is 0 varies additively, by ``vary`` times this scale (SI).
_ADDITIVE_SCALE = {"d0": 2000.0, "pr": 1e6, "x0": 0.05, "v0": 0.01}
#: How far a student's actuator may vary around the paper's values (a fraction).
MAX_VARY = 0.5
MAX_ID_LENGTH = 64
MAX_ROSTER = 2000
#: An open exercise: new ids one client address may start in an hour (a lab PC used all day by
#: successive students starts a few; a script starting hundreds is stopped).
DEFAULT_IDS_PER_CLIENT = 4
#: The disk the class's kept uploads may take together (each student's at most the upload limit).
DEFAULT_KEPT_UPLOADS_MB = 1000
#: The measured signals (SI units) an exercise may put a noise floor on or leave out.
SIGNALS = {"x": "m", "v": "m/s", "p1": "Pa", "p2": "Pa"}
#: The routes a student can hand in from.
METHODS = {"lse": "least squares (tab 3, time domain)", "frequency": "transfer function and back-out (tab 3, "
           "frequency domain)", "greybox": "grey-box identification (tab 3)"}
FEEDBACK = {"verdict": "accepted or not, per parameter, after every hand-in",
            "none": "only that the hand-in was stored",
            "after-deadline": "the verdicts once the deadline has passed"}
#: Which hand-ins count, and how (the first is the default). Plain "best" of several hand-ins rewards
#: spraying guesses (three guesses of B at 0.84, 1.00 and 1.17 of the paper's value, no identification,
#: put B within 5 % for 58 % of students against 21 % for one guess): "last" and "mean" do not, and
#: "best-penalty" takes :attr:`Exercise.attempt_penalty` off a hand-in's score for each one before it
#: (spraying still pays below a penalty of about 85 points: tests/core/test_scoring.py).
SCORE_RULES = ("last", "mean", "best-penalty", "best")
SCORE_TEXT = {"last": "the last hand-in counts", "mean": "the mean of the hand-ins counts",
              "best-penalty": "the best hand-in counts, less {penalty} for each hand-in before it",
              "best": "the best hand-in counts"}
#: How a hand-in's value is judged against the truth (the first is the default of a new exercise).
#: "zscore": by the precision the student's own record gives (the standard error the server computed
#: on it): the value must lie within k standard errors of the truth (never narrower than ``floor`` of
#: it), and k standard errors must be within the parameter's tolerance (an experiment that does not
#: determine the parameter to the lab's precision is not accepted, whatever the value).
#: "relative": within the tolerance of the truth, whatever the record (an exercise file from before
#: the choice keeps it).
GRADINGS = {"zscore": "within k standard errors of the truth, the standard error of your own record",
            "relative": "within a fixed relative tolerance of the truth"}
#: The k of "zscore" grading: at 3 an honest estimate with an honest standard error is refused about
#: 0.3 % of the time.
DEFAULT_K = 3.0
#: The narrowest acceptance of "zscore" grading, relative to the truth: a model error of the route
#: below it is not held against a very precise record.
DEFAULT_FLOOR = 0.005
_FORMATS = ("eha-exercise/1", "eha-exercise/2")
_FORMAT = _FORMATS[-1]
#: Join codes: ten characters of an alphabet without look-alikes (0/O, 1/I/L), about 50 bits.
_CODE_ALPHABET = "23456789ABCDEFGHJKMNPQRSTUVWXYZ"
_CODE_LENGTH = 10


def normalize_id(student_id: str) -> str:
    """The id as compared and stored: ``student_id`` trimmed, inner spaces collapsed, lower case.

    A :class:`~eha_core._checks.FieldError` when it is empty, holds a control character or is
    longer than :data:`MAX_ID_LENGTH` characters.

    >>> normalize_id("  Ada  Lovelace ")
    'ada lovelace'
    >>> normalize_id("ada\x1b[2J")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    eha_core._checks.FieldError: student id = ada\\x1b[2j is not allowed: use letters, ... (it holds a control ...)
    """
    text = " ".join(str(student_id).split()).lower()
    if not text:
        raise not_allowed("student id", student_id, "enter your name or student id")
    if not text.isprintable():
        raise not_allowed("student id", text.encode("unicode_escape").decode("ascii")[:40],
                          "use letters, digits, spaces and punctuation (it holds a control character)")
    if len(text) > MAX_ID_LENGTH:
        raise not_allowed("student id", text[:20] + "…", f"at most {MAX_ID_LENGTH} characters")
    return text


def normalize_code(code: str) -> str:
    """A join ``code`` as typed, reduced to its characters: upper case, no spaces or dashes
    (``"abcde-fghjk"`` and ``"ABCDEFGHJK"`` are the same code).

    >>> normalize_code(" k7m2p-q9rst ")
    'K7M2PQ9RST'
    """
    return "".join(ch for ch in str(code).upper() if ch.isalnum())[:4 * _CODE_LENGTH]


def _code_hash(code: str) -> str:
    return hashlib.sha256(("eha-join\0" + normalize_code(code)).encode()).hexdigest()


def parse_deadline(text: str, name: str = "deadline") -> str:
    """An ISO-8601 date and time, kept as typed once checked (no zone: the server's local time).

    ``text`` is the deadline as typed (trimmed); a refusal names it ``name``.

    >>> parse_deadline("2026-12-01T17:00")
    '2026-12-01T17:00'
    >>> parse_deadline("next friday")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    eha_core._checks.FieldError: deadline = next friday is not allowed: give an ISO-8601 date and time, ...
    """
    text = str(text).strip()
    try:
        _dt.datetime.fromisoformat(text)
    except ValueError:
        raise not_allowed(name, text, "give an ISO-8601 date and time, e.g. 2026-12-01T17:00 or "
                                      "2026-12-01T17:00+01:00") from None
    return text


def _as_utc(text: str) -> float:
    """The deadline as a POSIX time (a zone-less one in the server's local time)."""
    when = _dt.datetime.fromisoformat(text)
    if when.tzinfo is None:
        when = when.astimezone()
    return when.timestamp()


@dataclass(frozen=True)
class RosterEntry:
    """One student of the roster: the id the results carry, the name the page shows, the nonce
    their code is drawn from and the code's hash (the code itself is not stored)."""

    id: str
    name: str
    nonce: str
    code_hash: str


def read_roster(text: str, name: str = "roster") -> list[tuple[str, str]]:
    """``(id, name)`` pairs of a CSV roster with columns ``id`` and ``name`` (more are ignored).

    ``text`` is the CSV file's text; a refusal names the file ``name``. Ids are normalised
    (:func:`normalize_id`) and must be unique; at most 2000 students.

    >>> read_roster("id,name,email\\ns1,Ada Lovelace,a@x\\n S2 ,Alan Turing,\\n")
    [('s1', 'Ada Lovelace'), ('s2', 'Alan Turing')]
    """
    rows = list(csv.reader(io.StringIO(text.lstrip("\ufeff"))))
    if not rows:
        raise not_allowed(name, "(empty)", "a CSV file with the columns id and name, one student per line")
    header = [h.strip().lower() for h in rows[0]]
    if "id" not in header or "name" not in header:
        raise not_allowed(name, ",".join(rows[0])[:60], "the first line must name the columns id and name")
    i, j = header.index("id"), header.index("name")
    out, seen = [], {}
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) <= max(i, j):
            raise not_allowed(name, ",".join(row)[:60], f"line {line} has no {'id' if len(row) <= i else 'name'}")
        try:
            sid = normalize_id(row[i])
        except ValueError as exc:
            raise not_allowed(name, row[i][:40], f"line {line}: {exc}") from None
        student_name = " ".join(row[j].split())
        if not student_name or not student_name.isprintable() or len(student_name) > 120:
            raise not_allowed(name, student_name[:40] or "(blank)", f"line {line}: a name of 1-120 printable "
                                                                    "characters")
        if sid in seen:
            raise not_allowed(name, sid, f"line {line} repeats the id of line {seen[sid]}; every id once")
        seen[sid] = line
        out.append((sid, student_name))
    if not out:
        raise not_allowed(name, "(no students)", "at least one line with an id and a name")
    if len(out) > MAX_ROSTER:
        raise not_allowed(name, f"{len(out)} students", f"at most {MAX_ROSTER}")
    return out


@dataclass(frozen=True)
class Conditions:
    """What the student cannot change: the experiment's conditions.

    ``noise``: σ per measured signal in SI (a floor: the student may raise it, not lower it);
    ``disturbance``: a load force d(t) in the app's signal grammar added to whatever the
    student simulates; ``measured``: the signals the student's sensors give (the others are
    not in their records); ``max_record_s`` and ``min_ts_s``: the longest record and the
    shortest sample time; ``methods``: the routes a hand-in may come from.
    """

    noise: Mapping[str, float] = field(default_factory=lambda: {"x": 1e-5, "v": 1e-3, "p1": 5e4, "p2": 5e4})
    disturbance: str = "none"
    measured: tuple[str, ...] = ("x", "v", "p1", "p2")
    max_record_s: float = 60.0
    min_ts_s: float = 1e-3
    methods: tuple[str, ...] = tuple(METHODS)

    def __post_init__(self):
        for k, s in dict(self.noise).items():
            if k not in SIGNALS:
                raise not_allowed("noise", k, f"name a signal of {', '.join(SIGNALS)}")
            if not (math.isfinite(float(s)) and float(s) >= 0):
                raise not_allowed("noise", f"{k}={s}", f"σ of {k} must be a number ≥ 0 {SIGNALS[k]}")
        for k in self.measured:
            if k not in SIGNALS:
                raise not_allowed("measured", ",".join(self.measured), f"{k} is not a signal; use {', '.join(SIGNALS)}")
        if "x" not in self.measured:
            raise not_allowed("measured", ",".join(self.measured), "the position x must be measured (every method "
                                                                   "needs it)")
        if not self.methods or any(m not in METHODS for m in self.methods):
            raise not_allowed("methods", ",".join(self.methods), f"name at least one of {', '.join(METHODS)}")
        if not (math.isfinite(self.max_record_s) and 1.0 <= self.max_record_s <= 3600.0):
            raise not_allowed("max record", f"{self.max_record_s:g} s", "must lie in [1, 3600] s")
        if not (math.isfinite(self.min_ts_s) and 1e-4 <= self.min_ts_s <= 0.1):
            raise not_allowed("min Ts", f"{1e3 * self.min_ts_s:g} ms", "must lie in [0.1, 100] ms")
        object.__setattr__(self, "noise", {k: float(v) for k, v in dict(self.noise).items()})
        object.__setattr__(self, "measured", tuple(self.measured))
        object.__setattr__(self, "methods", tuple(self.methods))

    def noise_floor(self, signal: str) -> float:
        """The σ (SI) a student's record of ``signal`` has at least."""
        return float(self.noise.get(signal, 0.0))

    def lse_refusal(self) -> str | None:
        """Why the least squares cannot run under these conditions (None: they can)."""
        if "lse" not in self.methods:
            return "this exercise does not use the least squares"
        missing = [s for s in ("p1", "p2") if s not in self.measured]
        if missing:
            return (f"the least squares need {' and '.join(missing)}, which this exercise does not measure; use "
                    "the frequency domain")
        return None

    def describe(self) -> str:
        """One line for the student's page and the teacher's table."""
        shown = {"x": ("mm", 1e-3), "v": ("mm/s", 1e-3), "p1": ("MPa", 1e6), "p2": ("MPa", 1e6)}
        noise = ", ".join(f"σ {k} ≥ {v / shown[k][1]:g} {shown[k][0]}" for k, v in self.noise.items() if v > 0)
        parts = [f"sensor noise {noise}" if noise else "no sensor noise"]
        if self.disturbance.strip().lower() not in ("", "none"):
            parts.append(f"a load disturbance d(t) = {self.disturbance} always acts")
        if tuple(self.measured) != tuple(SIGNALS):
            parts.append(f"measured: {', '.join(self.measured)} only")
        parts.append(f"records up to {self.max_record_s:g} s, Ts ≥ {1e3 * self.min_ts_s:g} ms")
        parts.append(f"hand in from: {', '.join(METHODS[m].split(' (')[0] for m in self.methods)}")
        return "; ".join(parts)

    def to_dict(self) -> dict:
        """The conditions as plain JSON-able values (the exercise file's ``conditions``)."""
        return {"noise": dict(self.noise), "disturbance": self.disturbance, "measured": list(self.measured),
                "max_record_s": self.max_record_s, "min_ts_s": self.min_ts_s, "methods": list(self.methods)}

    @classmethod
    def from_dict(cls, data: Mapping) -> Conditions:
        """The conditions written by :meth:`to_dict`: ``data``'s missing keys take their defaults."""
        return cls(noise=dict(data.get("noise", {})), disturbance=str(data.get("disturbance", "none")),
                   measured=tuple(data.get("measured", tuple(SIGNALS))),
                   max_record_s=float(data.get("max_record_s", 60.0)), min_ts_s=float(data.get("min_ts_s", 1e-3)),
                   methods=tuple(data.get("methods", tuple(METHODS))))


@dataclass(frozen=True)
class Judgement:
    """The verdict on one handed-in parameter, and why (the teacher's: ``error`` and ``z`` hold the truth).

    ``ok``: accepted. ``reason``: "within" (accepted), "outside" (too far from the truth), "imprecise"
    (zscore grading: k standard errors exceed the tolerance, the record does not determine it to the
    lab's precision), "no-error" (zscore grading: the route gave no standard error) or "missing".
    ``error``: relative error against the truth; ``z``: (estimate - truth - the route's own model error)
    / standard error; ``band``: the accepted half-width relative to the estimate (what the student can
    see: it comes from their record, not the truth); ``model_error``: the route's own error on the
    student's experiment without noise, relative to the truth (0 when not given).
    """

    ok: bool
    reason: str
    error: float | None = None
    z: float | None = None
    band: float | None = None
    std_error: float | None = None
    model_error: float = 0.0


#: The conditions of an exercise file of format 1 (before conditions existed): none.
_NO_CONDITIONS = {"noise": {}, "disturbance": "none"}


@dataclass(frozen=True)
class Exercise:
    """The rules of an exercise and its secret (``secret``: 64 hex digits; never shown to students).

    ``tolerance`` is the relative error of a correct answer; ``tolerances`` overrides it per
    parameter. ``attempts`` = 0: no limit. ``deadline``: ISO-8601 or "" (none). ``release_at``:
    ISO-8601 or "" (none), at or after the deadline: from then on every student sees their own true
    values and no hand-in is taken, as after the teacher's reveal (:meth:`released`).

    ``own_files``: hand-ins from a file the student uploaded are taken (labelled as such); by
    default only estimates from the student's own actuator's experiment count, since a file can
    be anyone's (a classmate's record). ``ids_per_client``: in an open exercise (no roster), how
    many new ids one client address may start per hour (0: no limit). ``kept_uploads_mb``: the
    disk the class's kept uploads may take in all (each student's at most the upload limit).
    """

    hide: tuple[str, ...]
    vary: float
    tolerance: float
    title: str
    secret: str = dataclasses.field(repr=False)       # never in a log line or a traceback
    created: str = ""
    tolerances: Mapping[str, float] = field(default_factory=dict)
    conditions: Conditions = field(default_factory=Conditions)
    deadline: str = ""
    #: ISO-8601 or "" (none): from then on every student sees their own true values, as after a reveal.
    release_at: str = ""
    attempts: int = 0
    feedback: str = "verdict"
    grading: str = "zscore"
    #: zscore grading: accepted within k standard errors of the truth (k >= 1).
    k: float = DEFAULT_K
    #: zscore grading: the narrowest acceptance, a fraction of the truth.
    floor: float = DEFAULT_FLOOR
    score_rule: str = "last"
    #: With score_rule "best-penalty": taken off a hand-in's score (a fraction of 1) per hand-in before it.
    attempt_penalty: float = 0.25
    roster: tuple[RosterEntry, ...] = field(default=(), repr=False)
    #: The pool each student's actuator is drawn from: names of :data:`eha_core.variants.VARIANTS`
    #: ("paper": the paper's model; "spool", "leakage", "stribeck": one effect it leaves out).
    variants: tuple[str, ...] = ("paper",)
    own_files: bool = False
    ids_per_client: int = DEFAULT_IDS_PER_CLIENT
    kept_uploads_mb: int = DEFAULT_KEPT_UPLOADS_MB

    def __post_init__(self):
        if not self.hide:
            raise not_allowed("hide", "", f"name at least one of {', '.join(HIDEABLE)}")
        for name in self.hide:
            if name not in HIDEABLE:
                raise not_allowed("hide", ",".join(self.hide), f"{name} cannot be hidden; use any of "
                                                               f"{', '.join(HIDEABLE)}")
        if len(set(self.hide)) != len(self.hide):
            raise not_allowed("hide", ",".join(self.hide), "name each parameter once")
        if not (math.isfinite(self.vary) and 0 <= self.vary <= MAX_VARY):
            raise not_allowed("vary", f"{100 * self.vary:g} %", f"must lie in [0, {100 * MAX_VARY:g}] %")
        for name, tol in {"": self.tolerance, **dict(self.tolerances)}.items():
            if name and name not in self.hide:
                raise not_allowed("tolerance", f"{name}={100 * tol:g}%", f"{name} is not hidden; give tolerances "
                                                                         f"of {', '.join(self.hide)}")
            if not (math.isfinite(tol) and 0 < tol < 1):
                raise not_allowed("tolerance", f"{(name + '=') if name else ''}{100 * tol:g} %",
                                  "must lie in (0, 100) %")
        self._check_rules()
        try:
            ok = len(bytes.fromhex(self.secret)) >= 16
        except ValueError:
            ok = False
        if not ok:
            raise not_allowed("secret", "(the file's secret)", "must be at least 32 hex digits: "
                              "make a new exercise file with `eha exercise new`")
        object.__setattr__(self, "tolerances", {k: float(v) for k, v in dict(self.tolerances).items()})
        ids = [e.id for e in self.roster]
        if len(set(ids)) != len(ids):
            raise not_allowed("roster", "(repeated id)", "every id once")
        object.__setattr__(self, "variants", tuple(self.variants))
        self._check_variants()

    def _check_variants(self) -> None:
        """Every name of the pool is a variant, each once, and each gives a valid actuator with the
        paper's values and with each hidden parameter at either end of its range (a draw that breaks a
        rule is drawn again, :meth:`student_params`; an effect that no draw can carry leaves its
        students without an actuator)."""
        from .variants import VARIANTS, variant_effects

        if not self.variants:
            raise not_allowed("variants", "(none)", f"name at least one of {', '.join(VARIANTS)}")
        if len(set(self.variants)) != len(self.variants):
            raise not_allowed("variants", ",".join(self.variants), "name each variant once")
        base = ActuatorParams()
        for name in self.variants:
            try:
                effects = variant_effects(name)
            except ValueError:
                raise not_allowed("variants", name, f"not a variant; use any of {', '.join(VARIANTS)}") from None
            if effects.off:
                continue                            # the paper's model: the draws' own rules hold
            try:
                base.replace(effects=effects)
            except ValueError as exc:
                raise not_allowed("variants", name, f"the actuator is not valid with it ({exc}); leave it out of "
                                                    "the pool") from None
            bad = []
            for values in ({n: v} for n in self.hide for v in self._ends(base, n)):
                try:
                    base.replace(**values)
                except ValueError:
                    continue                        # not a draw a student gets
                try:
                    base.replace(effects=effects, **values)
                except ValueError as exc:
                    bad.append(f"{next(iter(values))} = {next(iter(values.values())):.4g} ({exc})")
            if bad:
                raise not_allowed("variants", name, f"students drawn near {bad[0]} would have no valid actuator; "
                                                    "leave it out of the pool or vary less")

    def _ends(self, base: ActuatorParams, name: str) -> tuple[float, float]:
        """The two ends of the hidden parameter ``name``'s range (:meth:`_value`)."""
        b = getattr(base, name)
        if b == 0 and name in _ADDITIVE_SCALE:
            return b - self.vary * _ADDITIVE_SCALE[name], b + self.vary * _ADDITIVE_SCALE[name]
        return b * (1.0 - self.vary), b * (1.0 + self.vary)

    def _check_rules(self) -> None:
        if self.deadline:
            parse_deadline(self.deadline)
        if self.release_at:
            release = parse_deadline(self.release_at, name="release truth at")
            if self.deadline and _as_utc(release) < _as_utc(parse_deadline(self.deadline)):
                raise not_allowed("release truth at", self.release_at,
                                  f"it is before the deadline ({self.deadline}): students could hand in after seeing "
                                  "their true values; give a date and time at or after the deadline")
        if not (isinstance(self.attempts, int) and 0 <= self.attempts <= 1000):
            raise not_allowed("attempts", self.attempts, "a whole number of hand-ins in 0-1000 (0: no limit)")
        if self.feedback not in FEEDBACK:
            raise not_allowed("feedback", self.feedback, f"use {', '.join(FEEDBACK)}")
        if self.score_rule not in SCORE_RULES:
            raise not_allowed("score", self.score_rule, f"use {', '.join(SCORE_RULES)}")
        if self.grading not in GRADINGS:
            raise not_allowed("grading", self.grading, f"use {', '.join(GRADINGS)}")
        if not (isinstance(self.k, (int, float)) and math.isfinite(self.k) and 1.0 <= self.k <= 10.0):
            raise not_allowed("k", self.k, "a number of standard errors in [1, 10] (below 1 an honest estimate "
                                           "is refused a third of the time; 3 is the usual)")
        if not (isinstance(self.floor, (int, float)) and math.isfinite(self.floor) and 0.0 <= self.floor < 0.5):
            raise not_allowed("floor", f"{100 * self.floor:g} %", "a fraction of the truth in [0, 50) %")
        if not (isinstance(self.attempt_penalty, (int, float)) and math.isfinite(self.attempt_penalty)
                and 0 <= self.attempt_penalty <= 1):
            raise not_allowed("attempt penalty", self.attempt_penalty, "use a fraction in [0, 1] (0.25: 25 points)")
        if not (isinstance(self.ids_per_client, int) and 0 <= self.ids_per_client <= 10_000):
            raise not_allowed("ids per client", self.ids_per_client, "a whole number of ids in 0-10000 (0: no limit)")
        if not (isinstance(self.kept_uploads_mb, int) and 0 <= self.kept_uploads_mb <= 1_000_000):
            raise not_allowed("kept uploads", f"{self.kept_uploads_mb} MB", "a whole number of MB in 0-1000000 "
                                                                            "(0: no upload is kept)")

    # -- making, reading, writing --------------------------------------------------------
    @classmethod
    def new(cls, hide, vary: float = 0.25, tolerance: float | Mapping[str, float] = 0.05,
            title: str = "EHA identification exercise", secret: str | None = None, *,
            roster: Iterable[tuple[str, str]] | None = None, conditions: Conditions | None = None,
            deadline: str = "", release_at: str = "", attempts: int = 0, feedback: str = "verdict",
            score_rule: str = "last",
            attempt_penalty: float = 0.25, grading: str = "zscore", k: float = DEFAULT_K,
            floor: float = DEFAULT_FLOOR,
            own_files: bool = False, ids_per_client: int = DEFAULT_IDS_PER_CLIENT,
            kept_uploads_mb: int = DEFAULT_KEPT_UPLOADS_MB, variants: Iterable[str] = ("paper",)) -> Exercise:
        """A new exercise with a fresh random secret (``secrets.token_hex``) and, with a roster,
        a join code per student (see :meth:`join_code`).

        Parameters
        ----------
        hide : iterable of str
            The parameters hidden from the students, names of :data:`HIDEABLE`.
        vary : float
            How far each student's hidden parameters vary around the paper's values: a
            fraction in [0, :data:`MAX_VARY`] (0.25: +-25 %).
        tolerance : float or mapping of str to float
            The relative error of a correct answer, in (0, 1); a mapping gives it per hidden
            parameter (the others 0.05). Under zscore grading, the precision the lab asks for: k
            standard errors of the student's record must lie within it.
        title : str
            The exercise's title, shown to the students.
        secret : str, optional
            Hex digits (at least 32) the students' actuators and codes are drawn from; default a fresh
            random one of 64.
        roster : iterable of (str, str), optional
            ``(id, name)`` of each student (:func:`read_roster`); without one the exercise is open
            to any id.
        conditions : Conditions, optional
            The experiment's conditions; default :class:`Conditions`'s.
        deadline : str
            ISO-8601 date and time of the last hand-in (:func:`parse_deadline`), or "" for none.
        release_at : str
            ISO-8601 date and time from which every student sees their own true values, as after
            the teacher's reveal (no hand-in is taken from then on), or "" for none; not before
            ``deadline``.
        attempts : int
            Hand-ins allowed per student, 0 for no limit.
        feedback : str
            When a student sees the verdicts, a key of :data:`FEEDBACK`.
        score_rule : str
            Which hand-ins score, one of :data:`SCORE_RULES` (default "last": spraying guesses earns
            nothing).
        attempt_penalty : float
            With "best-penalty", the score taken off a hand-in for each one before it (0.25).
        grading : str
            How a value is judged, a key of :data:`GRADINGS` (default "zscore").
        k, floor : float
            zscore grading: accepted within ``k`` standard errors of the truth (default 3), never
            narrower than ``floor`` of the truth (default 0.005).
        own_files : bool
            Take hand-ins from a file the student uploaded (default: only from their own actuator's
            experiment).
        ids_per_client : int
            Open exercise: new ids one client address may start per hour (0: no limit).
        kept_uploads_mb : int
            The disk the class's kept uploads may take in all [MB] (0: no upload is kept).
        variants : iterable of str
            The pool each student's actuator is drawn from, names of
            :data:`eha_core.variants.VARIANTS` (default the paper's model alone).
        """
        secret = secret or secrets.token_hex(32)
        if isinstance(tolerance, Mapping):
            tolerances, default = dict(tolerance), 0.05
        else:
            tolerances, default = {}, float(tolerance)
        entries = []
        for sid, name in roster or ():
            nonce = secrets.token_hex(8)
            entries.append(RosterEntry(normalize_id(sid), str(name), nonce,
                                       _code_hash(_derive_code(secret, nonce))))
        return cls(hide=tuple(hide), vary=float(vary), tolerance=default, title=str(title), secret=secret,
                   created=time.strftime("%Y-%m-%dT%H:%M:%S"), tolerances=tolerances,
                   conditions=conditions if conditions is not None else Conditions(), deadline=deadline,
                   release_at=str(release_at).strip(),
                   attempts=int(attempts), feedback=feedback, score_rule=score_rule,
                   attempt_penalty=float(attempt_penalty), grading=grading, k=float(k), floor=float(floor),
                   roster=tuple(entries),
                   own_files=bool(own_files), ids_per_client=int(ids_per_client), kept_uploads_mb=int(kept_uploads_mb),
                   variants=tuple(variants))

    def replace(self, **changes) -> Exercise:
        """A copy with the fields named in ``**changes`` changed (checked again), as :func:`dataclasses.replace`."""
        return dataclasses.replace(self, **changes)

    def to_json(self) -> str:
        """The exercise file's text (JSON, the secret included: the teacher's, never the class's)."""
        data = {"format": _FORMAT, **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)}}
        data["conditions"] = self.conditions.to_dict()
        data["roster"] = [dataclasses.asdict(e) for e in self.roster]
        data["hide"] = list(self.hide)
        data["variants"] = list(self.variants)
        return json.dumps(data, indent=1, ensure_ascii=False)

    @classmethod
    def from_json(cls, text: str, name: str = "exercise file") -> Exercise:
        """The exercise of an exercise file's ``text`` (:meth:`to_json`; format 1 files too).

        A refusal names the file ``name``.
        """
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise not_allowed(name, "(not JSON)", f"not an exercise file (JSON text): line {exc.lineno}: "
                                                  f"{exc.msg}") from None
        if not isinstance(data, dict) or data.get("format") not in _FORMATS:
            raise not_allowed(name, "(no exercise)", f"not an exercise file (format {_FORMAT!r} expected); "
                              "make one with `eha exercise new`")
        try:
            conditions = Conditions.from_dict(data["conditions"] if "conditions" in data else _NO_CONDITIONS)
            return cls(hide=tuple(data["hide"]), vary=float(data["vary"]), tolerance=float(data["tolerance"]),
                       title=str(data.get("title", "")), secret=str(data["secret"]),
                       created=str(data.get("created", "")), tolerances=dict(data.get("tolerances", {})),
                       conditions=conditions, deadline=str(data.get("deadline", "")),
                       # an exercise file from before the release date releases nothing by itself
                       release_at=str(data.get("release_at", "")),
                       attempts=int(data.get("attempts", 0)), feedback=str(data.get("feedback", "verdict")),
                       # an exercise file from before the rule was a choice scored the best hand-in
                       score_rule=str(data.get("score_rule", "best")),
                       attempt_penalty=float(data.get("attempt_penalty", 0.25)),
                       # an exercise file from before the choice judged by the relative tolerance
                       grading=str(data.get("grading", "relative")), k=float(data.get("k", DEFAULT_K)),
                       floor=float(data.get("floor", DEFAULT_FLOOR)),
                       roster=tuple(RosterEntry(**e) for e in data.get("roster", ())),
                       own_files=bool(data.get("own_files", False)),
                       variants=tuple(data.get("variants", ("paper",))),
                       ids_per_client=int(data.get("ids_per_client", DEFAULT_IDS_PER_CLIENT)),
                       kept_uploads_mb=int(data.get("kept_uploads_mb", DEFAULT_KEPT_UPLOADS_MB)))
        except (KeyError, TypeError, AttributeError) as exc:
            raise not_allowed(name, "(incomplete)", f"missing or wrong field {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Exercise:
        """The exercise of the exercise file at ``path`` (UTF-8 JSON, :meth:`from_json`)."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            raise not_allowed(str(path), "(not text)", "not an exercise file (JSON text): it holds bytes that "
                                                       "are not UTF-8 text; make one with `eha exercise new`") from None
        return cls.from_json(text, name=str(path))

    def save(self, path: str | Path) -> None:
        """Write the exercise file to ``path`` (:meth:`to_json`), readable by its owner only."""
        path = Path(path)
        path.write_text(self.to_json(), encoding="utf-8")
        path.chmod(0o600)                   # the teacher's: the secret is not for the class

    # -- the roster and its codes ----------------------------------------------------------
    @property
    def has_roster(self) -> bool:
        return bool(self.roster)

    def entry(self, student_id: str) -> RosterEntry | None:
        """The roster entry of ``student_id`` (None if it is not in the roster)."""
        try:
            sid = normalize_id(student_id)
        except ValueError:
            return None
        return next((e for e in self.roster if e.id == sid), None)

    def join_code(self, student_id: str) -> str:
        """The join code of ``student_id``, ``XXXXX-XXXXX`` (the teacher's, from the secret and the entry's
        nonce); a refusal when the id is not in the roster."""
        e = self.entry(student_id)
        if e is None:
            raise not_allowed("student id", student_id, "not in the exercise's roster")
        code = _derive_code(self.secret, e.nonce)
        return f"{code[:5]}-{code[5:]}"

    def entry_for_code(self, code: str) -> RosterEntry | None:
        """The roster entry whose code is ``code`` as typed (None: no one's; the answer does not
        depend on which ids exist)."""
        wanted = _code_hash(code)
        found = None
        for e in self.roster:                   # every entry compared, in constant time
            if hmac.compare_digest(e.code_hash, wanted):
                found = e
        return found

    def teacher_token(self, nonce: str = "") -> str:
        """The token of the teacher's dashboard: drawn from the secret and ``nonce`` (kept in the class's
        database, and changed to rotate the token: ``eha exercise token --rotate``), so every server
        process of the exercise knows it and a restart keeps the teacher's link; it never reaches a
        student. Rotating it changes no student's actuator or code (those come from the secret alone).

        >>> ex = Exercise.new(hide=("M",), secret="00" * 32)
        >>> len(ex.teacher_token("a1")), ex.teacher_token("a1") == ex.teacher_token("b2")
        (40, False)
        """
        label = b"eha-teacher-dashboard" + (b"\0" + nonce.encode() if nonce else b"")
        digest = hmac.new(bytes.fromhex(self.secret), label, hashlib.sha256).digest()
        return digest[:20].hex()

    # -- a student's actuator --------------------------------------------------------------
    def _unit(self, student: str, name: str, attempt: int) -> float:
        salt = f"{student}\0{name}" + (f"\0{attempt}" if attempt else "")
        digest = hmac.new(bytes.fromhex(self.secret), salt.encode(), hashlib.sha256).digest()
        return int.from_bytes(digest[:8], "big") / 2.0**64          # uniform in [0, 1)

    def _value(self, base: ActuatorParams, student: str, name: str, attempt: int) -> float:
        w = self.vary * (2.0 * self._unit(student, name, attempt) - 1.0)
        b = getattr(base, name)
        return b + w * _ADDITIVE_SCALE[name] if b == 0 and name in _ADDITIVE_SCALE else b * (1.0 + w)

    def variant_of(self, student_id: str) -> str:
        """The variant of the pool (:attr:`variants`) the actuator of ``student_id`` is, drawn from the
        secret and the id (the teacher's: a student is never told)."""
        if len(self.variants) == 1:
            return self.variants[0]
        k = int(self._unit(normalize_id(student_id), "\0variant", 0) * len(self.variants))
        return self.variants[min(k, len(self.variants) - 1)]

    def student_params(self, student_id: str, base: ActuatorParams | None = None) -> ActuatorParams:
        """The actuator of ``student_id``: its variant's effects (:meth:`variant_of`), and each hidden
        parameter of ``base`` (the paper's) times a factor in [1 - vary, 1 + vary] drawn from the
        secret and the id (a parameter whose paper value is 0, d0 for one, moves by up to ``vary``
        times a scale of its own: 2000 N for d0). A draw that breaks a rule of the parameters (a rod
        wider than the bore) is drawn again."""
        from .variants import variant_effects

        base = base if base is not None else ActuatorParams()
        student = normalize_id(student_id)
        if self.variants != ("paper",):
            base = base.replace(effects=variant_effects(self.variant_of(student)))
        for attempt in range(64):
            try:
                return base.replace(**{n: self._value(base, student, n, attempt) for n in self.hide})
            except ValueError:
                continue
        return base

    def tolerance_of(self, name: str) -> float:
        """The relative tolerance of a correct answer for the parameter ``name``."""
        return float(self.tolerances.get(name, self.tolerance))

    def errors(self, student_id: str, estimates: Mapping) -> dict[str, float | None]:
        """Per hidden parameter: the estimate's relative error against the truth (the teacher's;
        for a parameter whose truth is near 0, relative to its scale); None for a missing one.

        Parameters
        ----------
        student_id : str
            The student, whose actuator is the truth (:meth:`student_params`).
        estimates : mapping of str to float
            The student's estimates by parameter name, in SI units.
        """
        truth = self.student_params(student_id)
        out = {}
        for n in self.hide:
            v = estimates.get(n)
            try:
                v = float(v)
            except (TypeError, ValueError):
                v = math.nan
            t = getattr(truth, n)
            scale = max(abs(t), self.vary * _ADDITIVE_SCALE.get(n, 0.0)) or 1.0
            out[n] = (v - t) / scale if math.isfinite(v) else None
        return out

    def judge(self, student_id: str, estimates: Mapping, std_errors: Mapping | None = None,
              model_errors: Mapping | None = None) -> dict[str, Judgement]:
        """Per hidden parameter: the :class:`Judgement` of the estimate by the exercise's grading.

        Parameters
        ----------
        student_id : str
            The student, whose actuator is the truth (:meth:`student_params`).
        estimates : mapping of str to float
            The student's estimates by parameter name, in SI units.
        std_errors : mapping of str to float, optional
            The standard error of each estimate (SI), as the server computed it on the student's
            record; zscore grading refuses an estimate without one.
        model_errors : mapping of str to float, optional
            The route's own error (SI, estimate minus truth) on the student's experiment without noise
            (:func:`eha_core.grading.lse_model_error`, :func:`~eha_core.grading.frequency_model_error`):
            zscore grading measures the estimate from the truth plus it, so a route's approximation
            (eq. 27's linearisation) is not held against the student; 0 when not given.

        >>> ex = Exercise.new(hide=("M", "B"), secret="00" * 32, tolerance={"M": 0.05, "B": 0.30})
        >>> m = ex.student_params("s1").M
        >>> j = ex.judge("s1", {"M": m * 1.01, "B": 1.0}, {"M": 0.005 * m, "B": 1.0})
        >>> j["M"].ok, round(j["M"].z, 1), j["B"].reason     # 2 standard errors off; B's record says nothing
        (True, 2.0, 'imprecise')
        """
        errors = self.errors(student_id, estimates)
        truth = self.student_params(student_id)
        std_errors = std_errors or {}
        out = {}
        for n, rel in errors.items():
            tol = self.tolerance_of(n)
            if rel is None:
                out[n] = Judgement(False, "missing")
                continue
            if self.grading == "relative":
                out[n] = Judgement(abs(rel) <= tol, "within" if abs(rel) <= tol else "outside", rel)
                continue
            try:
                se = float(std_errors.get(n))
            except (TypeError, ValueError):
                se = math.nan
            if not (math.isfinite(se) and se > 0):
                out[n] = Judgement(False, "no-error", rel)
                continue
            value, t = float(estimates[n]), getattr(truth, n)
            scale = max(abs(t), self.vary * _ADDITIVE_SCALE.get(n, 0.0)) or 1.0
            try:
                me = float((model_errors or {}).get(n, 0.0))
            except (TypeError, ValueError):
                me = 0.0
            me = me if math.isfinite(me) else 0.0
            z = (value - t - me) / se
            # the band the student sees: k standard errors relative to their own estimate
            band = self.k * se / max(abs(value), 1e-300)
            if band > tol:
                out[n] = Judgement(False, "imprecise", rel, z, band, se, me / scale)
                continue
            ok = abs(value - t - me) <= self.k * se or abs(value - t) <= self.floor * scale
            out[n] = Judgement(ok, "within" if ok else "outside", rel, z, band, se, me / scale)
        return out

    def verdicts(self, student_id: str, estimates: Mapping, std_errors: Mapping | None = None,
                 model_errors: Mapping | None = None) -> dict[str, bool]:
        """Per hidden parameter: is the estimate accepted by the exercise's grading (:meth:`judge`)?
        A missing or non-finite estimate is not; under zscore grading neither is one without a
        standard error (``std_errors``, SI, as the server computed them on the student's record).

        Parameters
        ----------
        student_id : str
            The student, whose actuator is the truth (:meth:`student_params`).
        estimates : mapping of str to float
            The student's estimates by parameter name, in SI units.
        std_errors : mapping of str to float, optional
            The standard error of each estimate (zscore grading).
        model_errors : mapping of str to float, optional
            The route's own error on the student's experiment (zscore grading, :meth:`judge`).
        """
        return {n: j.ok for n, j in self.judge(student_id, estimates, std_errors, model_errors).items()}

    def grading_text(self) -> str:
        """The grading in words, for the students and the teacher."""
        if self.grading == "relative":
            return "a value counts when it lies within its tolerance of the truth"
        return (f"a value counts when it lies within {self.k:g} standard errors of the truth (the standard "
                f"error of the student's own record, at least {100 * self.floor:g} % of the truth), and "
                f"{self.k:g} standard errors are within its tolerance: a better experiment earns a tighter "
                "acceptance")

    # -- the hand-in rules ------------------------------------------------------------------
    def deadline_at(self, override: str | None = None) -> float | None:
        """The deadline as a POSIX time (``override``: the teacher's extension), None without one."""
        text = override or self.deadline
        return _as_utc(text) if text else None

    def released(self, now: float | None = None) -> bool:
        """Are the true values released now (``now`` [s, POSIX], default the current time): has
        :attr:`release_at` come? From then on every student's page is as after the teacher's reveal.

        >>> ex = Exercise.new(hide=("M",), secret="00" * 32, release_at="2030-01-01T00:00+00:00")
        >>> ex.released(now=1893456000.0 - 1), ex.released(now=1893456000.0), ex.replace(release_at="").released()
        (False, True, False)
        """
        if not self.release_at:
            return False
        return (time.time() if now is None else now) >= _as_utc(self.release_at)

    def refusal(self, count: int, *, now: float | None = None, method: str | None = None, open_: bool = True,
                deadline: str | None = None, revealed: bool = False, source: str | None = None) -> str | None:
        """Why a student who has handed in ``count`` times may not hand in now (None: they may).

        Parameters
        ----------
        count : int
            The student's hand-ins so far.
        now : float, optional
            The time [s, POSIX]; default the current time.
        method : str, optional
            The route of the hand-in, a key of :data:`METHODS`; None: not checked.
        open_ : bool
            The teacher's switch: False closes hand-ins.
        deadline : str, optional
            The teacher's extension of the deadline (ISO-8601), replacing the exercise's.
        revealed : bool
            The teacher has shown every student their true values; that is final, whatever
            the deadline or the open switch say since. So is :attr:`release_at` once it has come.
        source : str, optional
            "file" for estimates from an uploaded file (refused unless :attr:`own_files`), else the
            student's own actuator's experiment.
        """
        now = time.time() if now is None else now
        if revealed:
            return "your teacher has revealed the true values: hand-ins are closed for good"
        if self.released(now):
            return f"the true values were released at {self.release_at}: hand-ins are closed for good"
        if source == "file" and not self.own_files:
            return ("this exercise takes estimates from your actuator's experiment (the simulated sensors), not from "
                    "a file: run the identification on the simulated sensors")
        if not open_:
            return "hand-ins are closed by your teacher"
        due = self.deadline_at(deadline)
        if due is not None and now > due:
            return f"the deadline ({deadline or self.deadline}) has passed; hand-ins are no longer accepted"
        if self.attempts and count >= self.attempts:
            return f"you have handed in {count} of {self.attempts} times allowed"
        if method is not None and method not in self.conditions.methods:
            return f"this exercise does not take hand-ins from the {METHODS.get(method, method).split(' (')[0]}"
        return None

    def shows_verdicts(self, *, now: float | None = None, deadline: str | None = None,
                       revealed: bool = False) -> bool:
        """Are the verdicts shown to the student now (the feedback rule, the deadline, a reveal)?

        Parameters
        ----------
        now : float, optional
            The time [s, POSIX]; default the current time.
        deadline : str, optional
            The teacher's extension of the deadline (ISO-8601), replacing the exercise's.
        revealed : bool
            The teacher has revealed the true values: verdicts are shown whatever the rule (so
            are they once :attr:`release_at` has come).
        """
        if revealed or self.feedback == "verdict" or self.released(now):
            return True
        if self.feedback == "none":
            return False
        due = self.deadline_at(deadline)
        return due is not None and (time.time() if now is None else now) > due

    def score(self, verdicts_per_handin: list[Mapping[str, bool]]) -> float:
        """The score by the exercise's rule (:data:`SCORE_RULES`) from each hand-in's fraction within
        tolerance: the last's, the mean, the best less :attr:`attempt_penalty` per hand-in before it (at
        least 0), or the best.

        ``verdicts_per_handin`` holds each hand-in's verdicts (:meth:`verdicts`), oldest first;
        none scores 0.

        >>> ex = Exercise.new(hide=("M",), score_rule="best-penalty", attempt_penalty=0.25)
        >>> ex.score([{"M": False}, {"M": False}, {"M": True}])            # the third: 1 - 2 x 0.25
        0.5
        >>> ex.replace(score_rule="mean").score([{"M": False}, {"M": True}])
        0.5
        """
        scores = [sum(bool(v) for v in h.values()) / max(len(h), 1) for h in verdicts_per_handin]
        if not scores:
            return 0.0
        if self.score_rule == "last":
            return scores[-1]
        if self.score_rule == "mean":
            return sum(scores) / len(scores)
        if self.score_rule == "best-penalty":
            return max(max(s - self.attempt_penalty * k, 0.0) for k, s in enumerate(scores))
        return max(scores)

    def score_text(self) -> str:
        """The rule in words, for the students and the teacher ("the last hand-in counts")."""
        return SCORE_TEXT[self.score_rule].format(penalty=f"{100 * self.attempt_penalty:g} points")


def _derive_code(secret: str, nonce: str) -> str:
    digest = hmac.new(bytes.fromhex(secret), f"join\0{nonce}".encode(), hashlib.sha256).digest()
    n = int.from_bytes(digest, "big")
    out = []
    for _ in range(_CODE_LENGTH):
        n, r = divmod(n, len(_CODE_ALPHABET))
        out.append(_CODE_ALPHABET[r])
    return "".join(out)
