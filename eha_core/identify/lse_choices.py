"""The least squares' choices of estimator and intervals, and their check.

``estimator``: ``ls``, the paper's filtered least squares (eq. 18), or
``iv``, instrumental variables whose instruments come from a noise-free
simulation of the model (:func:`eha_core.identify.lse.identify_lse` tells
why). ``intervals``: ``newey-west`` (Newey-West standard errors, normal
quantile) or ``ewc`` (equal-weighted cosines, Student's t quantile); each
estimator has its default (:data:`DEFAULT_INTERVALS`). This module is light
(no scipy), so that the command line and a study refuse a typo before the
estimator is loaded.

>>> checked_choices("iv")
('iv', 'ewc')
>>> checked_choices("ls", "ewc")
('ls', 'ewc')
>>> checked_choices("ols", name="--estimator")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
eha_core._checks.FieldError: --estimator = ols is not allowed: use ls (the paper's least squares) or iv ...
"""

from __future__ import annotations

from .._checks import not_allowed

__all__ = ["ESTIMATORS", "INTERVALS", "DEFAULT_INTERVALS", "checked_choices"]

#: The estimators: the paper's least squares (eq. 18), or instrumental variables.
ESTIMATORS = ("ls", "iv")
#: How standard errors and intervals are computed: Newey-West with the normal
#: quantile, or equal-weighted cosines with Student's t quantile.
INTERVALS = ("newey-west", "ewc")
#: The intervals each estimator takes unless told: the paper's estimator keeps
#: the Newey-West errors it always had; the IV takes the intervals that were
#: measured honest for it (benchmarks/bench_lse_coverage.py).
DEFAULT_INTERVALS = {"ls": "newey-west", "iv": "ewc"}


def checked_choices(estimator, intervals=None, *, name: str = "estimator",
                    intervals_name: str = "intervals") -> tuple[str, str]:
    """``(estimator, intervals)`` checked, ``intervals`` the estimator's default when None.

    Parameters
    ----------
    estimator : str
        One of :data:`ESTIMATORS`.
    intervals : str, optional
        One of :data:`INTERVALS`; default the estimator's (:data:`DEFAULT_INTERVALS`).
    name, intervals_name : str
        What the refusals call the two (an argument, or an option such as ``--estimator``).
    """
    if not isinstance(estimator, str) or estimator not in ESTIMATORS:
        raise not_allowed(name, estimator, "use ls (the paper's least squares) or iv (instrumental variables)")
    if intervals is None:
        return estimator, DEFAULT_INTERVALS[estimator]
    if not isinstance(intervals, str) or intervals not in INTERVALS:
        raise not_allowed(intervals_name, intervals, "use newey-west or ewc (equal-weighted cosines)")
    return estimator, intervals
