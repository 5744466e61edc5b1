"""A class exercise: every student identifies an actuator of their own, with some parameters hidden.

The teacher's exercise file holds a secret and the rules: which parameters are
hidden, how far each student's actuator varies around the paper's values, and
the tolerance for a correct answer. A student's actuator is derived from the
secret and the student's id (HMAC-SHA256): the same id always gets the same
actuator, different ids different ones, and only the holder of the secret can
compute any of them. The file is read only by the server and the teacher's
command line; a verdict says within tolerance or not, never the true value.

Examples
--------
>>> ex = Exercise.new(hide=("M", "B"), vary=0.25, tolerance=0.05, title="Lab 3", secret="00" * 32)
>>> p = ex.student_params("ada")
>>> p == ex.student_params(" Ada ")            # ids are compared without case and spaces
True
>>> 0.75 * 4000 <= p.M <= 1.25 * 4000 and p.Af == 3000.0
True
>>> ex.verdicts("ada", {"M": p.M * 1.04, "B": p.B * 0.5})
{'M': True, 'B': False}
>>> "00" * 16 in repr(ex)                      # the secret is not in its repr
False
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import json
import math
import secrets
import time
from dataclasses import dataclass
from pathlib import Path

from ._checks import not_allowed
from .params import ActuatorParams

__all__ = ["Exercise", "HIDEABLE", "normalize_id", "MAX_VARY", "MAX_ID_LENGTH"]

#: The parameters an exercise may hide: the ones the least squares estimate (eqs. 15-18).
HIDEABLE = ("M", "B", "Af", "beta_e")
#: How far a student's actuator may vary around the paper's values (a fraction).
MAX_VARY = 0.5
MAX_ID_LENGTH = 64
_FORMAT = "eha-exercise/1"


def normalize_id(student_id: str) -> str:
    """The id as compared and stored: trimmed, inner spaces collapsed, lower case.

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


@dataclass(frozen=True)
class Exercise:
    """The rules of an exercise and its secret (``secret``: 64 hex digits; never shown to students)."""

    hide: tuple[str, ...]
    vary: float
    tolerance: float
    title: str
    secret: str = dataclasses.field(repr=False)       # never in a log line or a traceback
    created: str = ""

    def __post_init__(self):
        if not self.hide:
            raise not_allowed("hide", "", f"name at least one of {', '.join(HIDEABLE)}")
        for name in self.hide:
            if name not in HIDEABLE:
                raise not_allowed("hide", ",".join(self.hide), f"{name} cannot be hidden; use {', '.join(HIDEABLE)} "
                                  "(the parameters the least squares estimate)")
        if len(set(self.hide)) != len(self.hide):
            raise not_allowed("hide", ",".join(self.hide), "name each parameter once")
        if not (math.isfinite(self.vary) and 0 <= self.vary <= MAX_VARY):
            raise not_allowed("vary", f"{100 * self.vary:g} %", f"must lie in [0, {100 * MAX_VARY:g}] %")
        if not (math.isfinite(self.tolerance) and 0 < self.tolerance < 1):
            raise not_allowed("tolerance", f"{100 * self.tolerance:g} %", "must lie in (0, 100) %")
        try:
            ok = len(bytes.fromhex(self.secret)) >= 16
        except ValueError:
            ok = False
        if not ok:
            raise not_allowed("secret", "(the file's secret)", "must be at least 32 hex digits: "
                              "make a new exercise file with `eha exercise new`")

    # -- making, reading, writing --------------------------------------------------------
    @classmethod
    def new(cls, hide, vary: float = 0.25, tolerance: float = 0.05, title: str = "EHA identification exercise",
            secret: str | None = None) -> Exercise:
        """A new exercise with a fresh random secret (``secrets.token_hex``)."""
        return cls(hide=tuple(hide), vary=float(vary), tolerance=float(tolerance), title=str(title),
                   secret=secret or secrets.token_hex(32), created=time.strftime("%Y-%m-%dT%H:%M:%S"))

    def to_json(self) -> str:
        return json.dumps({"format": _FORMAT, **dataclasses.asdict(self)}, indent=1)

    @classmethod
    def from_json(cls, text: str, name: str = "exercise file") -> Exercise:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise not_allowed(name, "(not JSON)", f"line {exc.lineno}: {exc.msg}") from None
        if not isinstance(data, dict) or data.get("format") != _FORMAT:
            raise not_allowed(name, "(no exercise)", f"not an exercise file (format {_FORMAT!r} expected); "
                              "make one with `eha exercise new`")
        try:
            return cls(hide=tuple(data["hide"]), vary=float(data["vary"]), tolerance=float(data["tolerance"]),
                       title=str(data.get("title", "")), secret=str(data["secret"]),
                       created=str(data.get("created", "")))
        except (KeyError, TypeError) as exc:
            raise not_allowed(name, "(incomplete)", f"missing or wrong field {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Exercise:
        path = Path(path)
        return cls.from_json(path.read_text(encoding="utf-8"), name=str(path))

    def save(self, path: str | Path) -> None:
        path = Path(path)
        path.write_text(self.to_json(), encoding="utf-8")
        path.chmod(0o600)                   # the teacher's: the secret is not for the class

    # -- a student's actuator --------------------------------------------------------------
    def _factor(self, student: str, name: str) -> float:
        digest = hmac.new(bytes.fromhex(self.secret), f"{student}\0{name}".encode(), hashlib.sha256).digest()
        unit = int.from_bytes(digest[:8], "big") / 2.0**64          # uniform in [0, 1)
        return 1.0 + self.vary * (2.0 * unit - 1.0)

    def student_params(self, student_id: str, base: ActuatorParams | None = None) -> ActuatorParams:
        """The student's actuator: each hidden parameter of ``base`` (the paper's) times a
        factor in [1 - vary, 1 + vary] drawn from the secret and the id."""
        base = base if base is not None else ActuatorParams()
        student = normalize_id(student_id)
        return base.replace(**{n: getattr(base, n) * self._factor(student, n) for n in self.hide})

    def verdicts(self, student_id: str, estimates: dict) -> dict[str, bool]:
        """Per hidden parameter: is the estimate within ``tolerance`` (relative) of the truth?
        A missing or non-finite estimate is not."""
        truth = self.student_params(student_id)
        out = {}
        for n in self.hide:
            v = estimates.get(n)
            ok = v is not None and math.isfinite(float(v))
            out[n] = bool(ok and abs(float(v) / getattr(truth, n) - 1.0) <= self.tolerance)
        return out
