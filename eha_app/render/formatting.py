"""Numbers and transfer functions written for people (HTML, no JavaScript math)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["num_html", "pct_text", "poly_html", "tf_html", "poles_html", "table_html", "json_default",
           "json_safe", "pct_short", "estimate_texts", "display_unit"]


def num_html(x: float, digits: int = 4) -> str:
    """4 significant digits, powers of ten as 1.721·10⁴."""
    if x == 0:
        return "0"                      # -0.0 too: a sign on nothing only puzzles
    if not math.isfinite(x):
        return f"{x:g}"
    # the exponent from Python's own rounding: x / 10**exp underflows for subnormal x (10**-324 == 0)
    mant, exp = f"{x:.{digits - 1}e}".split("e")
    exp = int(exp)
    if -3 <= exp < digits:
        return f"{x:.{digits}g}"
    return mant.rstrip("0").rstrip(".") + f"·10<sup>{exp}</sup>"


def display_unit(name: str, si_unit: str = "") -> tuple[str, float]:
    """The unit a quantity is written in wherever the app shows it, and its factor from SI: tab 1's
    (βe in GPa, everything else as typed there); ``si_unit`` for a quantity tab 1 does not have.

    >>> display_unit("beta_e"), display_unit("M"), display_unit("d0", "N")
    (('GPa', 1000000000.0), ('kg', 1.0), ('N', 1.0))
    """
    from eha_core.param_table import FIELD_INFO

    info = FIELD_INFO.get(name)
    return (info.display_unit, float(info.display_scale)) if info is not None else (si_unit, 1.0)


def estimate_texts(value: float, lo: float, hi: float, scale: float = 1.0) -> tuple[str, str]:
    """An estimate and its 95 % interval written one way (divided by ``scale``, the display unit's
    factor): the digits follow the interval (its half-width to two significant digits, so that an
    estimate never shows fewer digits than its interval, nor more than the data give), and the
    estimate and both ends share one power of ten. An interval that collapsed (no noise) or is not
    finite leaves the estimate its usual five digits.

    >>> estimate_texts(1499.93, 1401.2, 1598.7)
    ('1500', '[1401, 1599]')
    >>> estimate_texts(-7.8868e-4, -0.0019016, 3.2499e-4)
    ('-0.8·10<sup>-3</sup>', '[-1.9, 0.3]·10<sup>-3</sup>')
    >>> estimate_texts(1.0976e9, 1.0946e9, 1.1006e9, scale=1e9)
    ('1.0976', '[1.0946, 1.1006]')
    >>> estimate_texts(4000.0, 4000.0, 4000.0)
    ('4000', '[4000, 4000]')
    """
    v, a, b = value / scale, lo / scale, hi / scale
    half = 0.5 * (b - a)
    top = max(abs(v), abs(a), abs(b))
    if not (math.isfinite(v) and math.isfinite(a) and math.isfinite(b)) or top == 0 or not half > 1e-9 * top:
        return num_html(v, 5), f"[{num_html(a, 5)}, {num_html(b, 5)}]"
    exp = math.floor(math.log10(top))
    power = exp if (exp >= 5 or exp <= -3) else 0
    f = 10.0 ** power
    decimals = min(max(0, 1 - math.floor(math.log10(half / f))), 8)

    def text(x: float) -> str:
        out = f"{x / f:.{decimals}f}"
        return "0" if float(out) == 0 else out          # -0.0 too: a sign on nothing only puzzles

    times = f"·10<sup>{power}</sup>" if power else ""
    return text(v) + times, f"[{text(a)}, {text(b)}]" + times


def pct_text(fraction: float, digits: int = 2) -> str:
    """A relative difference as a signed percentage; one that rounds to zero is "+0.00 %", never "−0.00 %".

    >>> pct_text(-0.000001, 3), pct_text(0.1234), pct_text(-0.5, 0)
    ('+0.000 %', '+12.34 %', '-50 %')
    """
    text = f"{100 * fraction:+.{digits}f}"
    if float(text) == 0:
        text = "+" + text[1:]
    return text + " %"


def pct_short(fraction: float) -> str:
    """A small relative change as a signed percentage with the digits it needs: one decimal from 0.1 %,
    one significant digit below (a change of 0.003 % is not "+0.0 %").

    >>> pct_short(0.0412), pct_short(-0.02), pct_short(-3.1e-5), pct_short(0.0)
    ('+4.1 %', '-2.0 %', '-0.003 %', '+0 %')
    """
    p = 100 * fraction
    if p == 0:
        return "+0 %"
    return (f"{p:+.1f}" if abs(p) >= 0.095 else f"{p:+.1g}") + " %"


def poly_html(coeffs, var: str = "s") -> str:
    """c0 s^n + ... + cn, dropping zero terms; unit leading coefficient shown as s^n."""
    coeffs = list(np.atleast_1d(coeffs))
    n = len(coeffs) - 1
    terms = []
    for i, c in enumerate(coeffs):
        p = n - i
        if c == 0 and len(coeffs) > 1:
            continue
        power = "" if p == 0 else (var if p == 1 else f"{var}<sup>{p}</sup>")
        mag = abs(c)
        coef = "" if (mag == 1 and p > 0) else num_html(mag)
        sign = "−" if c < 0 else "+"
        body = f"{coef}&#8239;{power}" if coef and power else (coef or power)
        terms.append((sign, body))
    if not terms:
        return "0"
    first_sign, first = terms[0]
    text = ("−" if first_sign == "−" else "") + first
    for sign, body in terms[1:]:
        text += f" {sign} {body}"
    return text


def tf_html(name: str, num, den, note: str = "") -> str:
    """A transfer function as an HTML fraction."""
    return (f'<div class="eha-tf"><span class="eha-tf-name">{name} =</span>'
            f'<span class="eha-frac"><span class="eha-num">{poly_html(num)}</span>'
            f'<span class="eha-den">{poly_html(den)}</span></span>'
            + (f'<span class="eha-tf-note">{note}</span>' if note else "") + "</div>")


def poles_html(poles) -> str:
    parts = []
    for p in sorted(np.atleast_1d(poles), key=lambda z: (-z.real, z.imag)):
        if abs(p.imag) < 1e-9 * max(1.0, abs(p)):
            parts.append(num_html(p.real))
        elif p.imag > 0:
            parts.append(f"{num_html(p.real)} ± {num_html(p.imag)}j")
    return ", ".join(parts)


def table_html(header, rows, cls: str = "eha-table") -> str:
    h = "".join(f"<th>{c}</th>" for c in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f'<table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>'


def json_default(obj):
    """``json.dumps(default=...)`` for results holding numpy values."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def json_safe(obj):
    """``obj`` with every number JSON can hold as it is and every NaN or infinity as None (JSON's
    ``null``: ``json.dumps`` would write ``NaN``, which is no JSON and which strict readers refuse);
    numpy values as Python's.

    >>> json_safe({"ci95": (float("nan"), 2.0), "n": np.int64(3), "r": np.array([1.0, np.inf])})
    {'ci95': [None, 2.0], 'n': 3, 'r': [1.0, None]}
    """
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
