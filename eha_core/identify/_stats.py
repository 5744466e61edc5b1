"""Statistical constants shared by the estimators (no scipy.stats import for one number)."""

from __future__ import annotations

__all__ = ["Z95"]

#: The two-sided 95 % quantile of the standard normal distribution,
#: ``scipy.stats.norm.ppf(0.975)``: a 95 % interval is ``estimate +- Z95 * std``.
Z95 = 1.959963984540054
