"""A transfer function estimated from a measured record (a student's own file), validated on its last part.

The record is t, u, y uniformly sampled (for the paper's closed loop: u = r, y = x).
Optionally the mean or a linear trend is removed from u and y first (a sensor's
offset or drift the model does not describe). The first part of the record
(``1 - validation_fraction``) estimates H(s) with :func:`~eha_core.identify.tfest.tfest`;
the rest validates it (MATLAB's ``compare`` semantics, its initial state
estimated); the whole record gives the data's frequency response and the
residual checks.

>>> import numpy as np
>>> from eha_core.identify.validate import simulate_tf
>>> t = np.arange(2000) * 0.01
>>> u = np.sign(np.sin(2 * np.pi * 0.37 * t)) + 0.5 * np.sin(2 * np.pi * 1.3 * t)
>>> y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, 0.01)
>>> rec = identify_record(t, u, y, n_poles=2)
>>> round(rec.estimate.fit_percent, 3), round(rec.validation.fit_percent, 3), np.round(rec.estimate.den, 3)
(100.0, 100.0, array([ 1.,  6., 20.]))
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._checks import not_allowed

__all__ = ["RecordIdentification", "identify_record", "DETRENDS"]

DETRENDS = ("none", "mean", "linear")


@dataclass(frozen=True, eq=False)
class RecordIdentification:
    """The estimate from the first part of the record, its validation on the rest, and the record's
    frequency response and residual checks (``u``, ``y`` as used: after detrending)."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    ts: float
    detrend: str
    n_estimation: int
    estimate: object            # TFEstimate
    validation: object | None   # CompareResult on the last part (None when the estimate failed)
    y_hat: np.ndarray | None    # the estimate's output over the estimation part
    data_response: object       # DataFrequencyResponse of the whole record
    residuals: object | None    # ResidualAnalysis of the estimation part
    bode: object | None = None  # BodeData: the estimate and the record's response (no theoretical curve)


def _detrended(x: np.ndarray, how: str) -> np.ndarray:
    if how == "mean":
        return x - x.mean()
    if how == "linear":
        k = np.arange(x.size)
        return x - np.polyval(np.polyfit(k, x, 1), k)
    return x


def identify_record(t, u, y, *, n_poles: int = 3, n_zeros: int = 0, initial_condition: str = "estimate",
                    input_offset: str = "estimate", detrend: str = "none", validation_fraction: float = 1 / 3,
                    cancel=None) -> RecordIdentification:
    """Estimate H(s) = Y(s)/U(s) from a record and validate it on the record's last part."""
    from ..data import sample_time
    from .spectral import data_frequency_response
    from .tfest import tfest
    from .validate import compare, residual_analysis

    t, u, y = (np.asarray(a, dtype=float) for a in (t, u, y))
    if detrend not in DETRENDS:
        raise not_allowed("detrend", detrend, f"use one of {', '.join(DETRENDS)}")
    if not 0 <= validation_fraction < 0.9:
        raise not_allowed("validation_fraction", validation_fraction, "must lie in [0, 0.9)")
    ts = sample_time(t, name="record", path="record")
    u, y = _detrended(u, detrend), _detrended(y, detrend)
    n_est = int(round(t.size * (1 - validation_fraction)))
    est = tfest(u[:n_est], y[:n_est], ts, n_poles, n_zeros, initial_condition=initial_condition,
                input_offset=input_offset, cancel=cancel)
    validation = y_hat = residuals = None
    if est.success and np.all(np.isfinite(est.den)):
        y_hat = est.simulate(u[:n_est], initial_state=est.initial_state, input_offset=est.input_offset)
        residuals = residual_analysis(y[:n_est] - y_hat, u[:n_est])
        if t.size - n_est >= 2 * (n_poles + n_zeros + 2):
            validation = compare(est.num, est.den, u[n_est:], y[n_est:], ts, initial_condition="estimate",
                                 input_offset=input_offset)
    from ..experiments import bode_data

    response = data_frequency_response(u, y, ts)
    bode = bode_data(est, None, response, ts) if y_hat is not None else None
    return RecordIdentification(t=t, u=u, y=y, ts=ts, detrend=detrend, n_estimation=n_est, estimate=est,
                                validation=validation, y_hat=y_hat, data_response=response,
                                residuals=residuals, bode=bode)
