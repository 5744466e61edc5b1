"""Argument checks shared by the core, and the one form of their messages.

Every refusal, in the core, the command line and the app, reads
``NAME = VALUE is not allowed: WHAT`` (:func:`not_allowed`): NAME is what the
user called it (a field, an option, an argument), VALUE is written as typed
(text without quotes, numbers with six significant digits), WHAT says what is
allowed, or what is wrong and what to do.

A refusal is a value, :class:`FieldError` (``field``, ``value``, ``what``):
the sentence is rendered from it (:meth:`FieldError.render` writes it with
the label and unit a form shows), and code that needs to know more reads its
attributes, never the text. This module is the one place that writes the
sentence.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["FieldError", "ComputationError", "not_allowed", "shown", "positive_number", "positive_integer",
           "whole_number"]


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


class FieldError(ValueError):
    """A refused value, as data: which field, which value, and what is allowed.

    ``str(error)`` is the project's one sentence, ``FIELD = VALUE is not
    allowed: WHAT``; :meth:`render` writes the same sentence with the label and
    unit a user interface shows. A ValueError, so ``except ValueError`` still
    catches every refusal.

    Parameters
    ----------
    field : str
        What the user called it: a field, an option (``--np``), an argument.
    value : object
        The refused value.
    what : str
        What is allowed, or what is wrong and what to do.
    value_text : str, optional
        How the message writes the value; default :func:`shown` (as typed).
        A file name, say, is written quoted.
    context : str, optional
        A condition of the refusal, written after "is not allowed"
        (``"with --model linear"``); default none.

    Examples
    --------
    >>> error = FieldError("beta_e", 1.1e9, "must be at most 1e+10 Pa")
    >>> str(error)
    'beta_e = 1.1e+09 is not allowed: must be at most 1e+10 Pa'
    >>> error.field, error.value, error.what
    ('beta_e', 1100000000.0, 'must be at most 1e+10 Pa')
    >>> error.render("βe", "GPa", value_text="1.1")
    'βe = 1.1 GPa is not allowed: must be at most 1e+10 Pa'
    >>> str(FieldError("--branch", "nonlinear", "the branch chooses ...", context="with --model linear"))
    '--branch = nonlinear is not allowed with --model linear: the branch chooses ...'
    """

    def __init__(self, field: str, value, what: str, *, value_text: str | None = None, context: str = ""):
        self.field = field
        self.value = value
        self.what = what
        self.value_text = shown(value) if value_text is None else value_text
        self.context = context
        super().__init__(self.render())

    def render(self, label: str | None = None, unit: str = "", value_text: str | None = None) -> str:
        """The sentence with ``label`` for the field and the value written ``value_text`` followed by ``unit``.

        Each defaults to the error's own (``field``, no unit, ``value_text``).
        """
        text = self.value_text if value_text is None else value_text
        if unit:
            text = f"{text} {unit}"
        condition = f" {self.context}" if self.context else ""
        return f"{self.field if label is None else label} = {text} is not allowed{condition}: {self.what}"

    def renamed(self, field: str) -> FieldError:
        """The same refusal of a field called ``field`` (the command line's option for a core argument)."""
        return FieldError(field, self.value, self.what, value_text=self.value_text, context=self.context)

    def __reduce__(self):
        # the subclasses' constructors differ: rebuild from the attributes, so that an
        # error crosses a process boundary (pickle) as the same value
        return _rebuilt, (type(self), self.args), self.__dict__


class ComputationError(RuntimeError):
    """A computation these inputs do not allow, found only by doing it: a simulation whose state
    stops being finite, say. An outcome to show the user, like a refusal, not a fault of the code.

    >>> str(ComputationError("the simulation failed: the state stopped being finite at t = 0 s"))
    'the simulation failed: the state stopped being finite at t = 0 s'
    """


def _rebuilt(cls, args):
    error = cls.__new__(cls, *args)
    error.args = args
    return error


def not_allowed(name: str, value, what: str, *, value_text: str | None = None, context: str = "") -> FieldError:
    """The :class:`FieldError` of a refused value (raise it): ``NAME = VALUE is not allowed: WHAT``.

    Parameters
    ----------
    name : str
        What the user called it: a field, an option (``--np``), an argument.
    value : object
        The refused value.
    what : str
        What is allowed, or what is wrong and what to do.
    value_text : str, optional
        How the message writes the value; default :func:`shown` (as typed).
    context : str, optional
        A condition of the refusal, written after "is not allowed" (``"with --model linear"``).

    Examples
    --------
    >>> str(not_allowed("kp", -1.0, "must be a finite gain > 0"))
    'kp = -1 is not allowed: must be a finite gain > 0'
    """
    return FieldError(name, value, what, value_text=value_text, context=context)


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
    return whole_number(name, value, 1, allowed)


def whole_number(name: str, value, minimum: int, allowed: str | None = None) -> int:
    """``value`` as an int if it is a whole number >= ``minimum`` (5.0 and numpy integers are accepted),
    else ValueError naming ``name``; ``allowed`` says what is allowed (default "must be a whole number >=
    MINIMUM")."""
    allowed = allowed or f"must be a whole number >= {minimum}"
    if isinstance(value, bool):
        raise not_allowed(name, value, allowed)
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise not_allowed(name, value, allowed) from None
    if not math.isfinite(out) or out < minimum or out != int(out):
        raise not_allowed(name, value, allowed)
    return int(out)
