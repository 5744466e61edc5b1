"""What every subcommand of ``eha`` shares: one-line errors, parameters, outputs.

Every bad input ends with one line on stderr naming the option, the value as
typed and what is allowed (``--n = 1e12 is not allowed: ...``), and exit code
2; a notice (a warning of the core) is one plain line on stderr too. Checks run
before anything heavy is imported or computed.

A refusal of the core names the core's field (``tau_f``): a subcommand declares
which option sets each (``fields``, a default of its parser) and which options
a computation that fails may follow from (``inputs``), so that the line names
what the user typed (:func:`as_typed`, :func:`computation_refused`).
"""

from __future__ import annotations

import argparse
import contextlib
import decimal
import json
import math
import os
import re
import signal
import threading
from pathlib import Path

from eha_core.errors import FieldError
from eha_core.params import PARAM_NAMES

__all__ = ["EXIT_USAGE", "EXIT_INTERRUPTED", "UsageError", "Parser", "PARAM_HELP", "NOISE_GRAMMAR", "parse_params",
           "parse_noise", "check_output_file", "check_input_file", "check_range", "json_text", "tf_text",
           "table_text", "terminal_text", "refused", "refused_file", "as_option", "as_typed", "typed_options",
           "computation_refused", "interrupt_cancels", "APP_LIBRARIES", "require_app"]

#: What the web app and its reports need beyond the core (the ``app`` extra of pyproject.toml).
APP_LIBRARIES = ("panel", "bokeh", "threadpoolctl")


def require_app(what: str) -> None:
    """Refuse ``what`` (a command that serves or draws the web app's figures) in one line when the app's
    libraries are not installed: the core installs without them (``pip install eha``), the app with
    ``pip install "eha[app]"``."""
    import importlib.util

    missing = [m for m in APP_LIBRARIES if importlib.util.find_spec(m) is None]
    if missing:
        raise UsageError(f"{what} needs the web app, which is not installed ({', '.join(missing)} missing): "
                         "pip install \"eha[app]\"")

EXIT_USAGE = 2
#: The shell's code of a command ended by Ctrl-C (128 + SIGINT).
EXIT_INTERRUPTED = 130


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


#: What a number option takes, said when a value is not one.
_TYPE_WANTED = {int: "use a whole number", float: "use a number"}


class Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line (no usage dump) and exit code 2.

    A value a number option cannot read is refused like any other
    (``--port = abc is not allowed: use a whole number``), and a value that
    starts with a minus sign is a value, not an option (``--snr-db -1e9``,
    ``--vary -5%``), so that the check of the value says what is allowed.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # argparse 3.11 takes only -5 and -.5 for numbers and reads -1e9 or -5% as an unknown option
        # ("expected one argument"); this is 3.13's own pattern, which takes a minus and a digit
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def add_argument(self, *args, **kwargs):
        wanted = _TYPE_WANTED.get(kwargs.get("type"))
        if wanted is not None:
            option = next((a for a in args if a.startswith("--")), args[0] if args else kwargs.get("dest"))
            kwargs["type"] = _number(kwargs["type"], option, wanted)
        return super().add_argument(*args, **kwargs)

    def error(self, message):
        raise UsageError(f"{message} ({self.prog} --help tells more)")


def _number(convert, option: str, wanted: str):
    """``convert`` (int or float) for the values of ``option``: a word that is no number is refused as a
    value of the option (a UsageError, which argparse passes on), not as argparse's "invalid int value"."""
    def read(text: str):
        try:
            return convert(text)
        except ValueError:
            raise refused(option, text, wanted, value_text=text.strip() or "(empty)") from None
    read.__name__ = convert.__name__
    return read


def typed_options(argv) -> dict[str, str]:
    """The options of the command line ``argv`` with their values as typed (the last, for a repeated
    one; ``--param`` by the parameter's name, ``--param M``).

    Only for the messages: a value is the words after the option up to the next option (``--band 0.6
    0.2``), or what follows ``=``.

    >>> typed_options(["idinput", "--band", "0.6", "0.2", "--kp=1e308", "--param", "M=1", "--json", "--seed", "3"])
    {'--band': '0.6 0.2', '--kp': '1e308', '--param M': '1', '--seed': '3'}
    """
    out: dict[str, str] = {}
    words = list(argv)
    for k, word in enumerate(words):
        if not word.startswith("--"):
            continue
        option, eq, value = word.partition("=")
        if not eq:
            following = []
            for later in words[k + 1:]:
                if later.startswith("--"):
                    break
                following.append(later)
            if not following:
                continue                        # a flag
            value = following[0] if option == "--param" else " ".join(following)
        if option == "--param":
            name, _, value = value.partition("=")
            option = f"--param {name.strip()}"
        out[option] = value.strip()
    return out


def as_typed(error: FieldError, fields: dict[str, str], typed: dict[str, str]) -> FieldError:
    """A core refusal named as the user typed it: the core's field replaced by the option ``fields``
    gives for it, and the value written as the option was typed (``typed``, :func:`typed_options`).

    A field not in ``fields`` is left as it is (it is an option already, or a parameter's name).

    >>> str(as_typed(FieldError("tau_f", 1e6, "use at most 0.99 s"), {"tau_f": "--tau-f"}, {"--tau-f": "1e6"}))
    '--tau-f = 1e6 is not allowed: use at most 0.99 s'
    """
    option = fields.get(error.field)
    if option is None:
        return error
    text = typed.get(option)
    return FieldError(option, error.value, error.what, value_text=error.value_text if text is None else text,
                      context=error.context)


def computation_refused(error: Exception, inputs, typed: dict[str, str]) -> UsageError:
    """A computation that failed (a :class:`~eha_core.errors.ComputationError`, or a number that overflowed)
    as the refusal of what the user typed: the first of ``inputs`` (options, the likeliest cause first)
    the user typed, with the others typed as its condition.

    >>> str(computation_refused(RuntimeError("the simulation failed"), ("--kp", "--param"),
    ...                         {"--kp": "1e308", "--seed": "2"}))
    '--kp = 1e308 is not allowed: the simulation failed'
    >>> str(computation_refused(RuntimeError("the simulation failed"), ("--kp", "--param"),
    ...                         {"--param M": "1e-3", "--kp": "9"}))
    '--kp = 9 is not allowed with --param M=1e-3: the simulation failed'
    """
    what = " ".join(str(error).split()) or type(error).__name__
    given = [(option, text) for wanted in inputs for option, text in typed.items()
             if option == wanted or option.startswith(f"{wanted} ")]
    if not given:
        # nothing the user typed feeds this computation: the line says what failed
        return UsageError(what)
    (option, text), others = given[0], given[1:]
    context = "with " + ", ".join(f"--param {o[8:]}={t}" if o.startswith("--param ") else f"{o} {t}"
                                  for o, t in others) if others else ""
    return refused(option, text, what, value_text=text, context=context)


PARAM_HELP = ("set a parameter or initial condition (SI units), repeatable; NAME is one of "
              + ", ".join(PARAM_NAMES) + ". p2_0=balance restores the force balance.")


@contextlib.contextmanager
def interrupt_cancels(token):
    """Within this block Ctrl-C also cancels ``token`` (a :class:`~eha_core.cancel.CancelToken`) before it
    interrupts: the worker threads stop at their next check instead of finishing the seeds they run, and
    the command ends at once (with one line, :func:`eha_app.cli.main`).

    Only in the main thread, and only where Ctrl-C interrupts (a shell that ignores it for a job in the
    background keeps ignoring it).
    """
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return

    def interrupted(signum, frame):
        token.cancel("interrupted")
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def parse_params(items):
    """``--param NAME=VALUE`` assignments as an :class:`~eha_core.params.ActuatorParams`.

    A refusal names the assignment as typed (``--param M = -1 is not allowed: ...``); a rule that ties
    fields together may name one the user did not type (the rod of a bore typed too small), and then
    says which assignments it follows from.

    >>> parse_params(["M=-1"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    eha_app.cli.common.UsageError: --param M = -1 is not allowed: must be ...
    """
    from eha_core.params import ParameterError, parse_param_assignments

    try:
        return parse_param_assignments(items)
    except ParameterError as exc:
        raise _param_refusal(exc, items) from None


def _param_refusal(error: FieldError, items) -> UsageError:
    if error.field.startswith("--"):
        return UsageError(error)
    typed = {}
    for item in items or ():
        name, _, text = item.partition("=")
        typed[name.strip()] = text.strip()
    if error.field == "" and "" in typed:
        return refused("--param", f"={typed['']}", "expected NAME=VALUE, e.g. M=4000")
    if error.field in typed:
        return refused(f"--param {error.field}", typed[error.field], error.what,
                       value_text=typed[error.field] or "(empty)", context=error.context)
    given = ", ".join(f"--param {n}={t}" for n, t in typed.items())
    return UsageError(FieldError(error.field, error.value, error.what, value_text=error.value_text,
                                 context=f"with {given}" if given else error.context))


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


def table_text(header, rows, align: str = "") -> list[str]:
    r"""Lines of a table whose columns are always apart: each as wide as its widest cell, two spaces
    between them; ``align`` says per column ``l`` (flush left) or ``r`` (flush right, numbers), by
    default the first column left and the others right.

    >>> print("\n".join(table_text(["name", "value", "error", "note"], [["a1", "0.1109", "-3791.854", "!"]],
    ...                             align="lrrl")))
    name   value      error  note
    a1    0.1109  -3791.854  !
    """
    cells = [[str(c) for c in header], *([str(c) for c in row] for row in rows)]
    align = align or "l" + "r" * (len(header) - 1)
    widths = [max(len(line[k]) for line in cells) for k in range(len(header))]
    return ["  ".join(c.ljust(w) if a == "l" else c.rjust(w) for c, w, a in zip(line, widths, align, strict=True))
            .rstrip() for line in cells]


#: The units ``--noise`` takes per kind of signal, as powers of ten of SI (the first is SI, a plain number's).
_NOISE_UNITS = {"x": {"m": 0, "mm": -3, "um": -6}, "v": {"m/s": 0, "mm/s": -3},
                "p": {"Pa": 0, "kPa": 3, "MPa": 6, "bar": 5}}
_NOISE_SIGNALS = ("x", "v", "p1", "p2")
_NOISE_EXAMPLE = {"x": "x=0.01mm", "v": "v=1mm/s", "p1": "p1=0.05MPa", "p2": "p2=0.05MPa"}

#: The one grammar of ``--noise``, which every subcommand's help gives.
NOISE_GRAMMAR = ("σ of the white noise per signal as SIGNAL=SIGMA[UNIT], joined by commas: x (m, mm, um), v (m/s, "
                 "mm/s), p1, p2, or p for both pressures (Pa, kPa, MPa, bar); without a unit SI; none: no noise")


def parse_noise(text: str, option: str = "--noise", *, signals=_NOISE_SIGNALS, bare: str | None = None) -> dict:
    """``--noise`` as σ per signal in SI: ``x=0.01mm,v=1mm/s,p=0.05MPa`` (p: both pressures), or ``none``.

    ``signals`` are those the command records (another is refused); ``bare`` is the signal a plain
    number stands for (``1e-4``: σ of x in m), if any. A σ is a finite number >= 0.

    >>> parse_noise("x=0.01mm,p=0.05MPa")
    {'x': 1e-05, 'p1': 50000.0, 'p2': 50000.0}
    >>> parse_noise("x=-1mm")
    Traceback (most recent call last):
    ...
    eha_app.cli.common.UsageError: --noise = x=-1mm is not allowed: σ of x must be a finite number >= 0; e.g. x=0.01mm
    """
    value_text = str(text).strip()
    if value_text.lower() in ("none", "0", ""):
        return {}
    usage = (f"give SIGNAL=SIGMA[UNIT] with SIGNAL one of {', '.join(signals)}, e.g. "
             + ",".join(_NOISE_EXAMPLE[s] for s in signals[:2]))
    out = {}
    for part in value_text.split(","):
        name, eq, value = part.partition("=")
        if not eq:
            if bare is None:
                raise refused(option, text, usage, value_text=value_text)
            name, value = bare, part
        name, value = name.strip().lower(), value.strip().replace(" ", "")
        names = ("p1", "p2") if name == "p" else (name,)
        if not name or not set(names) <= set(signals):
            pressures = " (p: both pressures)" if {"p1", "p2"} <= set(signals) else ""
            raise refused(option, text, f"{name or '(blank)'} is not a signal; use {', '.join(signals)}{pressures}",
                          value_text=value_text)
        units = _NOISE_UNITS["p" if name in ("p", "p1", "p2") else name]
        m = re.fullmatch(r"([-+0-9.eE]*?)([a-zA-Z/]*)", value)
        number, unit = (m.group(1), m.group(2).lower()) if m else (value, "")
        power = next((k for u, k in units.items() if u.lower() == unit), None) if unit else 0
        try:
            # in decimal: 0.1mm is 1e-4 m exactly as typed (0.1 * 1e-3 is 1.0000000000000002e-04)
            sigma = float(decimal.Decimal(number).scaleb(power))
        except (TypeError, ValueError, decimal.DecimalException):
            raise refused(option, text, f"σ of {name} as a number with a unit of {', '.join(units)}, e.g. "
                                        f"{_NOISE_EXAMPLE[names[0]]}", value_text=value_text) from None
        if not (math.isfinite(sigma) and sigma >= 0):
            raise refused(option, text, f"σ of {name} must be a finite number >= 0; e.g. {_NOISE_EXAMPLE[names[0]]}",
                          value_text=value_text)
        for sig in names:
            out[sig] = sigma
    return out


def add_store_option(parser) -> None:
    """``--store URL``: where the lab's state is (the SQLite file beside the exercise by default; a
    PostgreSQL database shared by several servers). ``EHA_STORE`` gives it too (a URL with a password
    on the command line is visible to every user of the machine in ``ps``)."""
    parser.add_argument("--store", default=os.environ.get("EHA_STORE") or None, metavar="URL",
                        help="the lab's database: postgresql://USER@HOST:PORT/DATABASE (the password from "
                             "~/.pgpass or PGPASSWORD), or sqlite:///PATH (sqlite:////PATH: absolute); default: "
                             "the SQLite file beside the exercise (EHA_STORE sets it too)")


def open_store(exercise_path, store: str | None = None, option: str = "--store", exercise_option: str = "exercise"):
    """The exercise's lab state, checked (made or brought to this version's schema): a database that
    cannot be used is one line naming it (a URL without its password) and exit code 2, under ``option``
    (a database URL) or ``exercise_option`` (the SQLite file beside the exercise)."""
    from eha_app.runtime.handins import HandIns, StoreError

    try:
        return HandIns(exercise_path, store=store).check()
    except StoreError as exc:
        if store:
            raise UsageError(f"{option}: {exc}") from None
        raise refused_file(exercise_option, str(exercise_path), f"{exc}") from None
