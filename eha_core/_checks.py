"""Argument checks shared by the core: one message format everywhere,
"NAME = VALUE is not allowed: WHAT IS ALLOWED"."""

from __future__ import annotations

import math

__all__ = ["positive_number", "positive_integer"]


def positive_number(name: str, value, allowed: str = "must be a finite number > 0") -> float:
    """``value`` as a float if it is finite and > 0, else ValueError naming ``name``."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} is not allowed: {allowed}") from None
    if not math.isfinite(out) or out <= 0:
        raise ValueError(f"{name} = {value!r} is not allowed: {allowed}")
    return out


def positive_integer(name: str, value, allowed: str = "must be a whole number > 0") -> int:
    """``value`` as an int if it is a whole number > 0 (5.0 is accepted), else ValueError."""
    if isinstance(value, bool):
        raise ValueError(f"{name} = {value!r} is not allowed: {allowed}")
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} is not allowed: {allowed}") from None
    if not math.isfinite(out) or out <= 0 or out != int(out):
        raise ValueError(f"{name} = {value!r} is not allowed: {allowed}")
    return int(out)
