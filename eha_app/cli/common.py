"""What every subcommand of ``eha`` shares: one-line errors, parameters, outputs.

Every bad input ends with one line on stderr naming the option, the value as
typed and what is allowed (``--n = 1e12 is not allowed: ...``), and exit code
2; a notice (a warning of the core) is one plain line on stderr too. Checks run
before anything heavy is imported or computed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
from pathlib import Path

from eha_core.errors import FieldError
from eha_core.params import PARAM_NAMES

__all__ = ["EXIT_USAGE", "UsageError", "Parser", "PARAM_HELP", "parse_params", "check_output_file",
           "check_input_file", "check_range", "json_text", "tf_text", "terminal_text", "refused", "refused_file",
           "as_option"]

EXIT_USAGE = 2


class UsageError(Exception):
    """Bad input on the command line (exit code 2, one line on stderr).

    ``UsageError(FieldError(...))`` carries the refusal as data (``error``: the
    option, the value, what is allowed), its line being the refusal's sentence;
    ``UsageError(text)`` is argparse's own complaint, which is no refusal of a
    value (``error`` is None). :func:`refused` builds the first kind.

    >>> str(refused("--np", 9, "use 1 to 8 poles"))
    '--np = 9 is not allowed: use 1 to 8 poles'
    >>> refused("--np", 9, "use 1 to 8 poles").error.field
    '--np'
    """

    def __init__(self, problem: str | FieldError):
        self.error = problem if isinstance(problem, FieldError) else None
        super().__init__(str(problem))


def refused(option: str, value, what: str, *, value_text: str | None = None, context: str = "") -> UsageError:
    """The UsageError of a refused option value: ``OPTION = VALUE is not allowed: WHAT``
    (see :class:`eha_core.errors.FieldError` for ``value_text`` and ``context``)."""
    return UsageError(FieldError(option, value, what, value_text=value_text, context=context))


def refused_file(option: str, path, what: str) -> UsageError:
    """:func:`refused` for a file name, written quoted as a shell would need it (``--out = 'a b.csv'``)."""
    return refused(option, path, what, value_text=repr(path))


def as_option(error: FieldError, options: dict[str, str]) -> UsageError:
    """A core refusal as the command line's: the core's name of the field replaced by the option that set it.

    ``options`` maps the core's names to options (``{"input_delay": "--delay"}``); a field not
    among them keeps its name.
    """
    return UsageError(error.renamed(options.get(error.field, error.field)))


class Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line (no usage dump) and exit code 2."""

    def error(self, message):
        raise UsageError(f"{message} ({self.prog} --help tells more)")


PARAM_HELP = ("set a parameter or initial condition (SI units), repeatable; NAME is one of "
              + ", ".join(PARAM_NAMES) + ". p2_0=balance restores the force balance.")


def parse_params(items):
    """``--param NAME=VALUE`` assignments as an :class:`~eha_core.params.ActuatorParams`."""
    from eha_core.params import parse_param_assignments

    return parse_param_assignments(items)


def terminal_text(text) -> str:
    r"""``text`` safe to print on the teacher's terminal: control characters (an ANSI escape, a
    bell, a right-to-left override) are shown as escapes instead of acting.

    >>> print(terminal_text("ada\x1b[2J\u202e"))
    ada\x1b[2J\u202e
    """
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape").decode("ascii") for ch in str(text))


def check_range(option: str, value, lo, hi, unit: str = "") -> None:
    """UsageError unless ``lo <= value <= hi`` (a size argument's limit)."""
    if not lo <= value <= hi:
        what = f"{lo:g}-{hi:g}" if isinstance(lo, float) or isinstance(hi, float) else f"{lo} to {hi}"
        raise refused(option, value, f"use {what}{' ' + unit if unit else ''}", value_text=str(value))


def check_output_file(option: str, path: str | None) -> None:
    """Before computing anything: can ``path`` be written?"""
    if path is None:
        return
    p = Path(path)
    if p.is_dir():
        raise refused_file(option, path, "it is a folder; give a file name")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise refused_file(option, path, f"the folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise refused_file(option, path, "it cannot be written (permission denied)")


def check_input_file(option: str, path: str | None) -> None:
    """Before anything heavy: does ``path`` exist and can it be read?"""
    if path is None:
        return
    p = Path(path)
    if not p.exists():
        raise refused_file(option, path, "no such file")
    if p.is_dir() or not os.access(p, os.R_OK):
        raise refused_file(option, path, "it is not a readable file")


def json_text(data) -> str:
    """JSON of results holding numpy values; a NaN or an infinity (a value not given) is ``null``.

    >>> " ".join(json_text({"ci95": [float("nan"), 1.5]}).split())
    '{ "ci95": [ null, 1.5 ] }'
    """
    from eha_app.render.formatting import json_default, json_safe

    return json.dumps(json_safe(data), indent=2, default=json_default, allow_nan=False)


def _poly_text(coeffs) -> str:
    n = len(coeffs) - 1
    text = ""
    for i, c in enumerate(coeffs):
        p = n - i
        power = "" if p == 0 else (" s" if p == 1 else f" s^{p}")
        mag = f"{abs(c):.4g}"
        term = power.strip() if mag == "1" and p else mag + power
        if not text:
            text = ("-" if c < 0 else "") + term
        else:
            text += (" - " if c < 0 else " + ") + term
    return text


def tf_text(num, den, name: str) -> str:
    """``name = (num) / (den)`` in plain text."""
    return f"{name} = ({_poly_text(num)}) / ({_poly_text(den)})"


_NOISE_UNITS = {"x": {"m": 1.0, "mm": 1e-3, "um": 1e-6}, "v": {"m/s": 1.0, "mm/s": 1e-3},
                "p": {"pa": 1.0, "kpa": 1e3, "mpa": 1e6, "bar": 1e5}}


def parse_noise(text: str, option: str = "--noise") -> dict:
    """``x=0.01mm,v=1mm/s,p=0.05MPa`` -> σ per signal in SI (p: both pressures)."""
    if text.strip().lower() in ("none", "0", ""):
        return {}
    out = {}
    for part in text.split(","):
        name, _, value = part.partition("=")
        name, value = name.strip().lower(), value.strip().replace(" ", "")
        signals = ("p1", "p2") if name == "p" else (name,)
        kind = "p" if name in ("p", "p1", "p2") else name
        if kind not in _NOISE_UNITS:
            raise refused(option, text, f"{name or '(blank)'} is not a signal; use x, v, p (or p1, p2)")
        m = re.fullmatch(r"([-+0-9.eE]*?)([a-zA-Z/]*)", value)
        number, unit = (m.group(1), m.group(2).lower()) if m else (value, "")
        scale = _NOISE_UNITS[kind].get(unit) if unit else next(iter(_NOISE_UNITS[kind].values()))
        try:
            sigma = float(number) * scale
        except (TypeError, ValueError):
            raise refused(option, text, f"σ of {name} as a number with a unit of "
                                           f"{', '.join(_NOISE_UNITS[kind])}, e.g. x=0.01mm") from None
        for sig in signals:
            out[sig] = sigma
    return out
