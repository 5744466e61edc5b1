"""Refusals as values: the error every check of the core raises, for the app and the command line.

A refused value is a :class:`FieldError` (``field``, ``value``, ``what``), a
ValueError whose message is rendered from those: ``FIELD = VALUE is not
allowed: WHAT``. The core's own kinds are subclasses:
:class:`eha_core.params.ParameterError` (a physical parameter),
:class:`eha_core.data.DataError` (a data file; ``missing_columns`` says which
needed columns it lacks) and :class:`eha_core.signals.SignalSpecError` (a
signal written as text). A user interface writes the sentence with its own
label and unit (:meth:`FieldError.render`), and never reads the text back.
A computation the inputs do not allow, found only by doing it (a simulation
that diverges), raises :class:`ComputationError`: an outcome to show, not a
fault of the code.

>>> from eha_core.errors import FieldError
>>> from eha_core.params import ActuatorParams
>>> try:
...     ActuatorParams(beta_e=-1.0)
... except FieldError as error:
...     print(error.field, error.value)
...     print(error.render("βe", "GPa", value_text=f"{error.value / 1e9:g}"))
beta_e -1.0
βe = -1e-09 GPa is not allowed: must be > 0 Pa (effective bulk modulus of the oil)
"""

from __future__ import annotations

from ._checks import ComputationError, FieldError, not_allowed

__all__ = ["FieldError", "ComputationError", "not_allowed"]
