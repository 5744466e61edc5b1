"""A transfer function estimated from a measured record (a student's own file), validated on its last part.

The record is t, u, y uniformly sampled (for the paper's closed loop: u = r, y = x).
:func:`prepare_record` does the preprocessing a student chooses, and keeps what
it removed so that it can be drawn: a time range of the record, then the mean
or a linear trend removed from u and y (a sensor's offset or drift the model
does not describe). The first part of the prepared record
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

__all__ = ["PreparedRecord", "RecordIdentification", "identify_record", "prepare_record", "DETRENDS",
           "MIN_RECORD_SAMPLES"]

DETRENDS = ("none", "mean", "linear")
#: Fewest samples in the part of a record that is used.
MIN_RECORD_SAMPLES = 30


@dataclass(frozen=True, eq=False)
class PreparedRecord:
    """A record as the estimation uses it, and what the preprocessing took away.

    ``t``, ``u``, ``y``: the chosen time range with the trend removed;
    ``u_removed``, ``y_removed``: the removed trend on that range (zero for
    ``detrend="none"``), so that ``u + u_removed`` is the file's u there;
    ``n_estimation``: the first samples estimate, the rest validate.
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    u_removed: np.ndarray
    y_removed: np.ndarray
    ts: float
    detrend: str
    t_from: float
    t_to: float
    n_estimation: int

    @property
    def t_split(self) -> float:
        """Time of the first validation sample (the end of the record when nothing validates)."""
        return float(self.t[self.n_estimation]) if self.n_estimation < self.t.size else float(self.t[-1])


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
    prepared: PreparedRecord | None = None

    def to_pandas(self):
        """The estimate's coefficients as a :class:`pandas.DataFrame`
        (:meth:`TFEstimate.to_pandas <eha_core.identify.tfresult.TFEstimate.to_pandas>`)."""
        return self.estimate.to_pandas()

    def __repr__(self) -> str:
        from .._display import block, with_error
        from .assessment import assess_residuals

        e = self.estimate
        n_validation = self.t.size - self.n_estimation
        head = (f"RecordIdentification: {e.n_poles} poles, {e.n_zeros} zeros from the first {self.n_estimation} "
                f"samples, validated on the last {n_validation} (detrend {self.detrend})")
        std = e.param_std if e.param_std is not None else [float("nan")] * (len(e.den) - 1 + len(e.num))
        items = [with_error(n, v, s) for n, v, s in zip(e.coefficient_names(), [*e.den[1:], *e.num], std,
                                                          strict=True)]
        fits = f"fit {e.fit_percent:.2f} % (estimation)"
        if self.validation is not None:
            fits += f", {self.validation.fit_percent:.2f} % (validation)"
        if self.residuals is not None:
            checks = assess_residuals(self.residuals)
            fits += (f"; residuals white: {'yes' if checks.whiteness.passed else 'no'}, independent of u: "
                     f"{'yes' if checks.independence.passed else 'no'}")
        notes = [f"G(s) = {e.formula()}, ± 1 standard error; {fits}", ".estimate, .validation; .to_pandas()"]
        return block(head, e.success, e.message, items, notes)


def _trend(x: np.ndarray, how: str) -> np.ndarray:
    """The part of ``x`` that ``detrend = how`` removes."""
    if how == "mean":
        return np.full_like(x, x.mean())
    if how == "linear":
        k = np.arange(x.size)
        return np.polyval(np.polyfit(k, x, 1), k)
    return np.zeros_like(x)


def _time(value, name: str, t: np.ndarray) -> float | None:
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    try:
        v = float(str(value).replace(",", ".")) if isinstance(value, str) else float(value)
    except (TypeError, ValueError):
        raise not_allowed(name, value, "enter a time in s, or leave it blank") from None
    if not (np.isfinite(v) and t[0] <= v <= t[-1]):
        raise not_allowed(name, value, f"your record runs from {t[0]:g} to {t[-1]:g} s")
    return v


def prepare_record(t, u, y, *, detrend: str = "none", t_from=None, t_to=None,
                   validation_fraction: float = 1 / 3) -> PreparedRecord:
    """Cut the record to [t_from, t_to] (s; None or blank: its start or end) and remove its trend.

    Raises ValueError naming ``from t`` / ``to t`` (as the app's fields are
    called) when a time is not a number, lies outside the record, or leaves
    fewer than :data:`MIN_RECORD_SAMPLES` samples.

    Parameters
    ----------
    t : array_like
        Sample times [s], uniformly spaced.
    u, y : array_like
        Input and output samples, one per time (for the paper's closed loop: r and x [m]).
    detrend : {'none', 'mean', 'linear'}
        What is removed from u and y over the chosen range: nothing, the mean or a straight line.
    t_from, t_to : float or str, optional
        The range kept [s] (a comma as decimal mark is accepted); None or blank: the record's
        start or end.
    validation_fraction : float
        The share of the prepared record, at its end, kept to validate, in [0, 0.9).
    """
    from ..data import sample_time

    t, u, y = (np.asarray(a, dtype=float) for a in (t, u, y))
    if detrend not in DETRENDS:
        raise not_allowed("detrend", detrend, f"use one of {', '.join(DETRENDS)}")
    if not 0 <= validation_fraction < 0.9:
        raise not_allowed("validation_fraction", validation_fraction, "must lie in [0, 0.9)")
    lo, hi = _time(t_from, "from t", t), _time(t_to, "to t", t)
    keep = (t >= (t[0] if lo is None else lo)) & (t <= (t[-1] if hi is None else hi))
    n = int(np.count_nonzero(keep))
    if n < MIN_RECORD_SAMPLES:
        name, value = ("to t", t_to) if hi is not None else ("from t", t_from)
        raise not_allowed(name, value, f"the range [{t[0] if lo is None else lo:g}, {t[-1] if hi is None else hi:g}] "
                                       f"s holds {n} samples; need at least {MIN_RECORD_SAMPLES}")
    t, u, y = t[keep], u[keep], y[keep]
    ts = sample_time(t, name="record", path="record")
    u_removed, y_removed = _trend(u, detrend), _trend(y, detrend)
    return PreparedRecord(t=t, u=u - u_removed, y=y - y_removed, u_removed=u_removed, y_removed=y_removed, ts=ts,
                          detrend=detrend, t_from=float(t[0]), t_to=float(t[-1]),
                          n_estimation=int(round(t.size * (1 - validation_fraction))))


def identify_record(t, u, y, *, n_poles: int = 3, n_zeros: int = 0, initial_condition: str = "estimate",
                    input_offset: str = "estimate", detrend: str = "none", t_from=None, t_to=None,
                    validation_fraction: float = 1 / 3, input_delay=0.0, cancel=None) -> RecordIdentification:
    """Estimate H(s) = Y(s)/U(s) from a record and validate it on the record's last part.

    The record is first prepared by :func:`prepare_record` (time range, trend).

    Parameters
    ----------
    t : array_like
        Sample times [s], uniformly spaced.
    u, y : array_like
        Input and output samples, one per time (for the paper's closed loop: r and x [m]).
    detrend : {'none', 'mean', 'linear'}
        What is removed from u and y over the chosen range: nothing, the mean or a straight line.
    t_from, t_to : float or str, optional
        The range kept [s] (a comma as decimal mark is accepted); None or blank: the record's
        start or end.
    validation_fraction : float
        The share of the prepared record, at its end, kept to validate, in [0, 0.9).
    n_poles, n_zeros : int
        The model's orders, as for :func:`~eha_core.identify.tfest.tfest`.
    initial_condition, input_offset : {'estimate', 'zero'}
        Estimate the initial state and a constant input offset with the model, or not
        (:func:`~eha_core.identify.tfest.tfest`); the validation estimates its own initial state.
    input_delay : float or 'estimate'
        The model's dead time [s], or ``"estimate"`` (see :func:`~eha_core.identify.tfest.tfest`);
        a measured actuator often has one.
    cancel : eha_core.cancel.CancelToken, optional
        Reaches the estimator.
    """
    from .spectral import data_frequency_response
    from .tfest import tfest
    from .validate import compare, residual_analysis

    prepared = prepare_record(t, u, y, detrend=detrend, t_from=t_from, t_to=t_to,
                              validation_fraction=validation_fraction)
    t, u, y, ts, n_est = prepared.t, prepared.u, prepared.y, prepared.ts, prepared.n_estimation
    est = tfest(u[:n_est], y[:n_est], ts, n_poles, n_zeros, initial_condition=initial_condition,
                input_offset=input_offset, input_delay=input_delay, cancel=cancel)
    validation = y_hat = residuals = None
    if est.success and np.all(np.isfinite(est.den)):
        y_hat = est.simulate(u[:n_est], initial_state=est.initial_state, input_offset=est.input_offset)
        residuals = residual_analysis(y[:n_est] - y_hat, u[:n_est])
        if t.size - n_est >= 2 * (n_poles + n_zeros + 2):
            validation = compare(est.num, est.den, u[n_est:], y[n_est:], ts, initial_condition="estimate",
                                 input_offset=input_offset, input_delay=est.input_delay)
    from ..experiments import bode_data

    response = data_frequency_response(u, y, ts)
    bode = bode_data(est, None, response, ts) if y_hat is not None else None
    return RecordIdentification(t=t, u=u, y=y, ts=ts, detrend=detrend, n_estimation=n_est, estimate=est,
                                validation=validation, y_hat=y_hat, data_response=response,
                                residuals=residuals, bode=bode, prepared=prepared)
