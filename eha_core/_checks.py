"""Argument checks shared by the core, and the one form of their messages.

Every refusal, in the core, the command line and the app, reads
``NAME = VALUE is not allowed: WHAT`` (:func:`not_allowed`): NAME is what the
user called it (a field, an option, an argument), VALUE is written as typed
(text without quotes, numbers with six significant digits), WHAT says what is
allowed, or what is wrong and what to do.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["not_allowed", "shown", "positive_number", "positive_integer"]


def shown(value) -> str:
    """A value as a message shows it: as typed."""
    if isinstance(value, str):
        return value.strip() or "(empty)"
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, np.ndarray):
        # a short array as the list of its numbers, as it would have been typed
        return f"an array of shape {value.shape}" if value.size > 8 else shown(value.tolist())
    if isinstance(value, (list, tuple)) and len(value) <= 8:
        return "[" + ", ".join(shown(v) for v in value) + "]"
    return type(value).__name__ if len(repr(value)) > 80 else repr(value)


def not_allowed(name: str, value, what: str) -> ValueError:
    """The ValueError of a refused value (raise it)."""
    return ValueError(f"{name} = {shown(value)} is not allowed: {what}")


def positive_number(name: str, value, allowed: str = "must be a finite number > 0") -> float:
    """``value`` as a float if it is finite and > 0, else ValueError naming ``name``."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise not_allowed(name, value, allowed) from None
    if not math.isfinite(out) or out <= 0:
        raise not_allowed(name, value, allowed)
    return out


def positive_integer(name: str, value, allowed: str = "must be a whole number > 0") -> int:
    """``value`` as an int if it is a whole number > 0 (5.0 is accepted), else ValueError."""
    if isinstance(value, bool):
        raise not_allowed(name, value, allowed)
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise not_allowed(name, value, allowed) from None
    if not math.isfinite(out) or out <= 0 or out != int(out):
        raise not_allowed(name, value, allowed)
    return int(out)
