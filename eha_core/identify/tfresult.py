"""The result of a continuous-time transfer-function estimate: :class:`TFEstimate`.

Returned by :func:`eha_core.identify.tfest.tfest` and
:func:`eha_core.identify.tfest.oe_fit` (and re-exported there). Like
:class:`scipy.optimize.OptimizeResult` it carries the estimate, the fit, the
statistics and how the estimator got there, so a failure is data. Its
:meth:`~TFEstimate.simulate` and :meth:`~TFEstimate.frequency_response` use
the exact machinery of :mod:`eha_core.identify._ctmodels`, with the
estimated input delay and the input's intersample behaviour. Only numpy is imported at module import;
:attr:`TFEstimate.tf` imports python-control lazily.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._checks import not_allowed
from ._ctmodels import FrequencyResponseData, frequency_response, simulate_tf

__all__ = ["TFEstimate"]


@dataclass(frozen=True, eq=False)
class TFEstimate:
    """An estimated continuous-time transfer function and how it was obtained.

    Like :class:`scipy.optimize.OptimizeResult`, a failed estimation is data:
    ``success`` is False and ``message`` says why (coefficients may be NaN).

    Attributes
    ----------
    num, den : numpy.ndarray
        Coefficients in descending powers of s; ``den[0] == 1``.
    ts : float
        Sampling time of the estimation data, in seconds.
    n_poles, n_zeros : int
        Model orders.
    fit_percent : float
        MATLAB ``compare`` fit on the estimation data, with the same
        initial-condition handling as the estimation.
    cost : float
        ``0.5 * sum((y - y_hat)^2)`` (scipy's convention).
    mse : float
        ``sum((y - y_hat)^2) / N`` (MATLAB's ``Report.Fit.MSE``).
    noise_variance : float
        ``sum((y - y_hat)^2) / (N - n_params - n_initial)``.
    initial_condition : str
        ``"zero"`` or ``"estimate"`` (the option it was run with).
    initial_state : numpy.ndarray or None
        Estimated initial state (observability canonical form, see
        :mod:`eha_core.identify.validate`; ``[y, y', y'']`` at t = 0 for an
        all-pole model), or None for zero.
    input_offset : float or None
        Estimated constant input offset ``c``, in input units: the model is
        ``y = G(s) (u + c)``. None when the offset was not estimated (zero).
    input_offset_std : float or None
        Standard error of ``input_offset`` (None when not estimated).
    success : bool
    message : str
    method : str
        ``"srivc+oe"``, ``"srivc"`` or ``"oe"``: the stage whose estimate is kept.
    nit_srivc : int
        SRIVC iterations (all starts; 0 for :func:`oe_fit`).
    nfev_oe : int
        Output-error residual evaluations (including finite differences).
    param_std : numpy.ndarray
        Standard errors of ``[den[1:], num]`` (same order as ``covariance``).
    covariance : numpy.ndarray
        ``noise_variance * (J^T J)^-1`` of the transfer-function coefficients,
        from the output-error Jacobian ``J`` with the linear terms (initial
        state, input offset) projected out.
    srivc_num, srivc_den : numpy.ndarray or None
        Stage-1 (SRIVC) estimate.
    srivc_cost : float
        Cost of the SRIVC estimate (NaN if not run).
    n_samples : int
    input_delay : float
        Input delay ``tau`` in seconds (0.0 when none): the model is
        ``y = G(s) e^(-s tau) (u + c)``. Fixed (the option's value) or
        estimated; ``fit_percent``, ``cost`` and ``covariance`` are computed
        with it in place.
    input_delay_std : float or None
        Standard error of an estimated ``input_delay`` (seconds); None when
        the delay was fixed.
    intersample : str
        ``"zoh"`` (the input held between samples) or ``"foh"`` (linear
        between them): the option the estimate was made with, and
        :meth:`simulate`'s default.
    optimizer_success : bool or None
        The kept stage's own stop: SRIVC converged, or ``least_squares``
        reported success (None when not recorded). ``success`` is this and
        the estimator's checks of the answer: with an estimated delay, a
        ``noise_variance`` not markedly above ``noise_floor``
        (:func:`~eha_core.identify._delay_search.above_floor`).
    noise_floor : float or None
        With an estimated delay, the residual variance of a long linear
        model of the record that fits any delay within its lags
        (:func:`~eha_core.identify._delay_search.noise_floor`): a
        ``noise_variance`` far above it says the delay search ended in a
        local minimum (or the model lacks poles or zeros). None otherwise.
    """

    num: np.ndarray
    den: np.ndarray
    ts: float
    n_poles: int
    n_zeros: int
    fit_percent: float
    cost: float
    mse: float
    noise_variance: float
    initial_condition: str
    initial_state: np.ndarray | None
    input_offset: float | None
    input_offset_std: float | None
    success: bool
    message: str
    method: str
    nit_srivc: int
    nfev_oe: int
    param_std: np.ndarray
    covariance: np.ndarray
    srivc_num: np.ndarray | None
    srivc_den: np.ndarray | None
    srivc_cost: float
    n_samples: int
    input_delay: float = 0.0
    input_delay_std: float | None = None
    intersample: str = "zoh"
    optimizer_success: bool | None = None
    noise_floor: float | None = None

    @property
    def tf(self):
        """The estimate ``G(s)`` as a ``control.TransferFunction`` (imports python-control).

        python-control's ``TransferFunction`` does not carry the delay: with
        an ``input_delay`` the model is this times ``e^(-s input_delay)``, and
        the delay is *not* included here (no Pade approximation is substituted
        behind your back; :func:`control.pade` makes one if you want it).
        :meth:`simulate` and :meth:`frequency_response` do include it.
        """
        import control  # lazy: importing python-control costs about 1.4 s

        return control.TransferFunction(list(self.num), list(self.den))

    def poles(self) -> np.ndarray:
        """Roots of ``den`` (rad/s)."""
        return np.roots(self.den)

    def zeros(self) -> np.ndarray:
        """Roots of ``num`` (rad/s)."""
        return np.roots(self.num) if self.num.size > 1 else np.zeros(0)

    def to_dict(self) -> dict:
        """The estimate as plain numbers (JSON-ready)."""
        return {"num": [float(c) for c in self.num], "den": [float(c) for c in self.den],
                "fit_percent": float(self.fit_percent), "initial_condition": self.initial_condition,
                "input_offset": None if self.input_offset is None else float(self.input_offset),
                "param_std": None if self.param_std is None else [float(v) for v in self.param_std],
                "success": bool(self.success), "message": self.message, "method": self.method,
                "n_poles": int(self.n_poles), "n_zeros": int(self.n_zeros),
                "input_delay": float(self.input_delay),
                "input_delay_std": None if self.input_delay_std is None else float(self.input_delay_std),
                "intersample": self.intersample,
                "optimizer_success": None if self.optimizer_success is None else bool(self.optimizer_success),
                "noise_floor": None if self.noise_floor is None else float(self.noise_floor)}

    def coefficient_names(self) -> tuple[str, ...]:
        """Names of ``[den[1:], num]`` (the order of ``param_std``): ``a1 .. an`` of the denominator
        ``s^n + a1 s^(n-1) + ... + an``, then ``bm .. b0`` of the numerator ``bm s^m + ... + b0``."""
        n, m = len(self.den) - 1, len(self.num) - 1
        return tuple(f"a{k}" for k in range(1, n + 1)) + tuple(f"b{j}" for j in range(m, -1, -1))

    def formula(self) -> str:
        """The model in the names of its coefficients (:meth:`coefficient_names`), as text:
        ``b0 / (s^3 + a1 s^2 + a2 s + a3)``."""

        def term(coefficient: str, power: int) -> str:
            s_power = "" if power == 0 else " s" if power == 1 else f" s^{power}"
            return f"{coefficient}{s_power}".strip()

        n, m = len(self.den) - 1, len(self.num) - 1
        names = self.coefficient_names()
        den = " + ".join(term(c, n - k) for k, c in enumerate(("",) + names[:n]))
        num = " + ".join(term(c, m - j) for j, c in enumerate(names[n:]))
        return f"({num}) / ({den})" if m > 0 else f"{num} / ({den})"

    def _units(self) -> dict[str, tuple[str, str, float]]:
        """Each coefficient's unit, and the input offset's (the input's, ``u``)."""
        def per_s(k: int) -> str:
            return "" if k == 0 else "/s" if k == 1 else f"/s^{k}"

        n = len(self.den) - 1
        units = {"input_offset": ("u", "u", 1.0)}
        for name in self.coefficient_names():
            # a_k multiplies s^(n-k) of the monic denominator: 1/s^k; b_j multiplies s^j: the gain y/u over s^(n-j)
            k = int(name[1:])
            unit = f"1{per_s(k)}" if name[0] == "a" else f"(y/u){per_s(n - k)}"
            units[name] = (unit, unit, 1.0)
        return units

    def to_pandas(self):
        """The coefficients (:meth:`coefficient_names`), and the input offset and delay when estimated, as a
        :class:`pandas.DataFrame` indexed by name: ``value``, ``std_error``, ``ci95_low``, ``ci95_high``
        (value +- 1.96 standard errors), ``unit`` (y/u: the output's unit over the input's),
        ``display_unit``, ``display_scale``."""
        from .._display import estimates_frame
        from ._stats import Z95

        values = [*self.den[1:], *self.num]
        std = np.full(len(values), np.nan) if self.param_std is None else np.asarray(self.param_std, dtype=float)
        rows = [(n, v, s) for n, v, s in zip(self.coefficient_names(), values, std, strict=True)]
        if self.input_offset is not None:
            rows.append(("input_offset", self.input_offset, np.nan if self.input_offset_std is None
                         else self.input_offset_std))
        if self.input_delay_std is not None:
            rows.append(("input_delay", self.input_delay, self.input_delay_std))
        return estimates_frame(((n, v, s, v - Z95 * s, v + Z95 * s) for n, v, s in rows), index_name="coefficient",
                               units=self._units())

    def plot(self, w=None):
        """Draw the Bode diagram with matplotlib (:func:`eha_core.plotting.plot_bode`); returns the Figure.

        Parameters
        ----------
        w : array_like, optional
            Frequencies [rad/s]; default 400 from 0.01 rad/s to the Nyquist frequency.
        """
        from ..plotting import plot_bode

        return plot_bode(self, w)

    def __repr__(self) -> str:
        from .._display import block, with_error

        head = (f"TFEstimate: {self.n_poles} poles, {self.n_zeros} zeros ({self.method}), fit "
                f"{self.fit_percent:.2f} % on {self.n_samples} samples")
        std = [math.nan] * (len(self.den) - 1 + len(self.num)) if self.param_std is None else self.param_std
        items = [with_error(n, v, s) for n, v, s in zip(self.coefficient_names(), [*self.den[1:], *self.num], std,
                                                          strict=True)]
        if self.input_offset is not None:
            items.append(with_error("input_offset", self.input_offset, self.input_offset_std) + " (input units)")
        if self.input_delay or self.input_delay_std is not None:
            items.append(with_error("input_delay", self.input_delay, self.input_delay_std))
        notes = [f"G(s) = {self.formula()}; ± 1 standard error; .to_pandas(), .tf (python-control), .plot(): Bode"]
        return block(head, self.success, self.message, items, notes)

    def simulate(self, u, ts=None, initial_state=None, input_offset=None, intersample=None) -> np.ndarray:
        """Exact response to ``u`` sampled at ``ts`` (default: ``self.ts``), delayed by ``input_delay``.

        The input held (``"zoh"``) or linear (``"foh"``) between samples as
        ``intersample`` says (default: the estimate's, ``self.intersample``).
        ``initial_state`` is an initial state (e.g. ``self.initial_state``); default zero.
        ``input_offset`` is a constant added to ``u`` (input units, e.g.
        ``self.input_offset``); default none. The offset estimated on one
        record usually does not carry over to a new data set, which needs its
        own: see :func:`eha_core.identify.validate.compare`.
        """
        if input_offset is not None:
            try:
                offset = float(input_offset)
            except (TypeError, ValueError):
                offset = np.nan
            if not np.isfinite(offset):
                raise not_allowed("input_offset", input_offset, "must be None or a finite number (input units)")
            u = np.asarray(u, dtype=float) + offset
        return simulate_tf(self.num, self.den, u, self.ts if ts is None else ts, initial_state=initial_state,
                           input_delay=self.input_delay,
                           intersample=self.intersample if intersample is None else intersample)

    def frequency_response(self, w) -> FrequencyResponseData:
        """Bode data of the estimate at ``w`` rad/s, ``G(j w) e^(-j w input_delay)``.

        The phase includes the delay's ``-w input_delay``.
        """
        return frequency_response(self.num, self.den, w, input_delay=self.input_delay)
