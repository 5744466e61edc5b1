"""How the core's results read at a Python prompt: short reprs, values in the units a user reads, tables.

Shared by the result types of :mod:`eha_core.simulate`, :mod:`eha_core.identify`, :mod:`eha_core.study`
and :mod:`eha_core.experiments` (their ``__repr__`` and ``to_pandas``), as python-control's response
objects share theirs. A repr is a few lines: the kind of result and its route, its verdict (a failed
result says ``FAILED`` and why on its first lines, so that it never reads as a success), then the
estimates, each with one standard error, in the display units of
:data:`eha_core.param_table.FIELD_INFO`. numpy and the parameter table are imported here; pandas inside
:func:`estimates_frame`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from .param_table import FIELD_INFO

__all__ = ["unit_of", "in_units", "with_error", "span", "polynomial", "block", "unit_columns", "short",
           "estimates_frame", "SIGNAL_DISPLAY", "TF_UNITS"]

#: How a plot or a repr shows each signal: (SI unit, display unit, display scale), value_display = value_SI / scale.
SIGNAL_DISPLAY = {"t": ("s", "s", 1.0), "x": ("m", "mm", 1e-3), "r": ("m", "mm", 1e-3), "v": ("m/s", "mm/s", 1e-3),
                  "p1": ("Pa", "MPa", 1e6), "p2": ("Pa", "MPa", 1e6), "u": ("V", "V", 1.0), "d": ("N", "kN", 1e3)}
#: Quantities the estimators report that are not fields of ActuatorParams.
_OTHER_UNITS = {
    "d_sin": ("N", "N", 1.0), "d_cos": ("N", "N", 1.0),          # the harmonic disturbance (lse.py)
    "damping": ("N s/m", "N s/m", 1.0),                          # B + 2 k_f Af / pi (backout.py, eq. 27)
    "beta_e_from_gain": ("Pa", "GPa", 1e9), "beta_e_from_stiffness": ("Pa", "GPa", 1e9),
    "input_delay": ("s", "ms", 1e-3),
}
#: The closed loop H(s) = b0 / (s^3 + a1 s^2 + a2 s + a3) from r [m] to x [m] (eq. 24): its coefficients' units.
TF_UNITS = {"a1": ("1/s", "1/s", 1.0), "a2": ("1/s^2", "1/s^2", 1.0), "a3": ("1/s^3", "1/s^3", 1.0),
            "b0": ("1/s^3", "1/s^3", 1.0)}
#: Longest message a repr quotes (the whole one is the result's ``message``).
_MESSAGE_CHARS = 240
#: Width of a repr's lines of estimates.
_LINE_CHARS = 100


def unit_of(name: str) -> tuple[str, str, float]:
    """``(SI unit, display unit, display scale)`` of a parameter or signal ``name``; unknown: ``("", "", 1.0)``."""
    if name in FIELD_INFO:
        info = FIELD_INFO[name]
        return info.unit, info.display_unit, info.display_scale
    return _OTHER_UNITS.get(name) or SIGNAL_DISPLAY.get(name) or ("", "", 1.0)


def _joined(number: str, unit: str) -> str:
    # a unit that is a power of ten times a unit (Kq's "1e-8 m³/(s V √Pa)") reads as a product
    if not unit:
        return number
    return f"{number} × {unit}" if unit[:2] == "1e" else f"{number} {unit}"


def in_units(name: str, value: float, digits: int = 4) -> str:
    """``value`` (SI) of ``name`` in its display unit, to ``digits`` significant digits: ``0.9 GPa``."""
    _, unit, scale = unit_of(name)
    return _joined(f"{value / scale:.{digits}g}", unit)


def span(name: str, values) -> str:
    """The range of the finite ``values`` (SI) of signal ``name`` in its display unit: ``x -0.1 to 35.3 mm``."""
    values = np.asarray(values, dtype=float)
    finite = values[np.isfinite(values)]
    if not finite.size:
        return f"{name} not finite"
    lo, hi = float(finite.min()), float(finite.max())
    _, unit, scale = unit_of(name)
    return f"{name} {_joined(f'{lo / scale:.3g} to {hi / scale:.3g}', unit)}"


def polynomial(coefficients: Sequence[float]) -> str:
    """Coefficients in descending powers of s as text, four significant digits: ``s^3 + 9.459 s^2 - 51.9``."""
    n = len(coefficients) - 1
    text = ""
    for k, c in enumerate(coefficients):
        power = n - k
        if c == 0 and n > 0:
            continue
        s_power = "" if power == 0 else " s" if power == 1 else f" s^{power}"
        magnitude = "" if abs(c) == 1 and power > 0 else f"{abs(c):.4g}"
        term = f"{magnitude}{s_power}".strip()
        if text:
            text += f" {'-' if c < 0 else '+'} {term}"
        else:
            text = f"-{term}" if c < 0 else term
    return text or "0"


def _pm(value: float, std: float) -> str:
    """``value ± std`` rounded at the standard error's second significant digit."""
    decimals = 1 - math.floor(math.log10(std))
    if decimals > 8:                       # an error far below the value's size: keep it readable
        return f"{value:.8g} ± {std:.2g}"
    if decimals > 0:
        return f"{value:.{decimals}f} ± {std:.{decimals}f}"
    step = 10.0 ** -decimals
    return f"{round(value / step) * step:.0f} ± {round(std / step) * step:.0f}"


def with_error(name: str, value: float, std: float | None) -> str:
    """``name = value ± std unit`` in the display unit (``±`` one standard error); without a finite error,
    the value alone and ``(no s.e.)``."""
    _, unit, scale = unit_of(name)
    if not math.isfinite(value):
        return f"{name} = {value}"
    if std is None or not math.isfinite(std) or std <= 0:
        return f"{name} = {_joined(f'{value / scale:.6g}', unit)} (no s.e.)"
    return f"{name} = {_joined(_pm(value / scale, std / scale), unit)}"


def short(text: str, limit: int = _MESSAGE_CHARS) -> str:
    """``text`` on one line, cut to ``limit`` characters with an ellipsis."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit - 1].rstrip() + "…"


def _wrapped(items: Sequence[str], width: int = _LINE_CHARS) -> list[str]:
    lines: list[str] = []
    for item in items:
        if lines and len(lines[-1]) + 2 + len(item) <= width:
            lines[-1] += "; " + item
        else:
            lines.append(item)
    return lines


def block(head: str, success: bool, message: str, items: Iterable[str] = (), notes: Iterable[str] = (), *,
          passed: str = "success") -> str:
    """A repr: ``head: passed`` on the first line, or for a failure ``head: FAILED`` and the ``message``
    (cut short) on the next; then the ``items`` (estimates) packed into lines of about 100 characters, then
    each of ``notes``, indented."""
    lines = [f"{head}: {passed}"] if success else [f"{head}: FAILED", "  " + short(message)]
    lines += ["  " + line for line in _wrapped(list(items))]
    lines += ["  " + note for note in notes if note]
    return "\n".join(lines)


def unit_columns(names: Iterable[str], units: dict[str, tuple[str, str, float]] | None = None) -> dict[str, list]:
    """The columns ``unit``, ``display_unit``, ``display_scale`` of a table whose rows are ``names``: from
    ``units`` (name -> the three) where it names the row, else :func:`unit_of`."""
    found = [(units or {}).get(n) or unit_of(n) for n in names]
    return {"unit": [u[0] for u in found], "display_unit": [u[1] for u in found],
            "display_scale": [float(u[2]) for u in found]}


def estimates_frame(rows: Iterable[tuple[str, float, float, float, float]], *, index_name: str = "parameter",
                    extra: dict[str, Sequence] | None = None, units: dict[str, tuple[str, str, float]] | None = None):
    """A :class:`pandas.DataFrame` of estimates, one row per ``(name, value, std_error, ci95_low, ci95_high)``
    (SI), with the SI unit, the display unit and its scale (value_display = value / display_scale): from
    ``units`` (name -> the three) where it names the row, else :func:`unit_of`; and the columns of ``extra``
    (name -> one value per row) after them."""
    import pandas as pd

    rows = list(rows)
    data = {"value": [float(r[1]) for r in rows], "std_error": [float(r[2]) for r in rows],
            "ci95_low": [float(r[3]) for r in rows], "ci95_high": [float(r[4]) for r in rows]}
    data.update(unit_columns([r[0] for r in rows], units))
    for column, values in (extra or {}).items():
        data[column] = list(values)
    return pd.DataFrame(data, index=pd.Index([r[0] for r in rows], name=index_name))
