"""Continuous-time transfer-function estimation from sampled data (like MATLAB ``tfest``).

Model (docs/model.md, section 4)::

    G(s) = (b_0 s^nz + ... + b_nz) / (s^np + a_1 s^(np-1) + ... + a_np),  nz < np

estimated from one input ``u`` and one output ``y`` sampled at ``ts``, the input
being held constant between samples (zero-order hold, MATLAB's default).

Two stages, as MATLAB does it:

1. **SRIVC** (simplified refined instrumental variable method for
   continuous-time models; Young & Jakeman 1980, Garnier & Young's CONTSID
   toolbox). The model equation ``A(s) y = B(s) u`` is prefiltered by
   ``1/A_hat(s)``, which turns the unknown time derivatives into the states of
   a stable filter: ``y_f^(k) = s^k / A_hat(s) y``, ``k = 0..np``. The filtered
   equation ``y_f^(np) = -a_1 y_f^(np-1) - ... + b_0 u_f^(nz) + ...`` is linear in
   the coefficients and is solved with instruments built from the noise-free
   output of the auxiliary model ``x_hat = B_hat/A_hat u``; ``A_hat`` is updated
   and the whole repeated until the coefficients stop changing.

   - ``u`` is filtered *exactly* (ZOH discretisation of the filter);
   - ``y`` and ``x_hat`` are not piecewise constant: they are filtered with the
     first-order-hold (triangle-hold) discretisation, i.e. assuming linear
     interpolation between samples. At the fixed point (``A_hat = A``) the
     filter cancels ``A``, so noiseless data give the exact model whatever the
     interpolation; with noise the approximation costs a little accuracy,
     which stage 2 recovers.
   - An unstable ``A_hat`` (possible during the iterations) is stabilised for
     the filter by reflecting its right-half-plane poles into the left half.
   - With ``initial_condition="estimate"``, ``A(s) y = B(s) u + C(s)`` with an
     unknown initial-condition polynomial ``C`` (degree < np): its filtered
     form adds ``np`` exactly known regressors, the impulse responses of
     ``s^k / A_hat(s)``, which are their own instruments.
   - With ``input_offset="estimate"`` the model is ``y = G(s) (u + c)`` with a
     constant input offset ``c``: ``A(s) y = B(s) u + b_nz c 1(t)`` (the
     derivatives of a constant vanish; the impulses at ``t = 0`` fall into the
     initial-condition regressors, or are kept through ``B_hat`` when the
     initial state is zero). One more regressor, ``1/A_hat(s)`` applied to a
     unit step, exact (a step is piecewise constant) and its own instrument.
   - The IV equations are solved through a QR factorisation of the
     instruments, which avoids squaring the conditioning.
   - Start: the user's ``init`` model, or a least-squares state-variable-filter
     (LSSVF) estimate with the filter ``(s + lambda)^np``; without
     ``lambda_svf`` four cut-offs, log-spaced from ``pi / (2 ts)`` down to
     ``max(4 * 2 pi / (N ts), pi / (200 ts))``, are tried and the iterate with
     the smallest simulation error kept.

2. **Output-error refinement**: minimise ``||y - y_hat(theta)||^2`` where
   ``y_hat`` is the exact ZOH simulation of the continuous-time model
   (the machinery of :func:`eha_core.identify.validate.simulate_tf`, in
   :mod:`eha_core.identify._ctmodels`: matrix exponential of the augmented
   state matrix, then ``scipy.signal.lfilter``),
   with :func:`scipy.optimize.least_squares` (trust-region reflective,
   ``x_scale='jac'``). Coefficients such as 1, 430.1, 1.721e4, 2437 are
   optimised relative to their starting values (so every parameter is O(1));
   near-zero coefficients (an integrator's ``a_np``) get a floor scale from the
   model's frequency scale ``w0 = max_i |a_i|^(1/i)``. With
   ``initial_condition="estimate"`` the initial state joins the parameters; it
   enters the response linearly, so it is eliminated by linear least squares
   inside every residual evaluation (variable projection): same minimiser,
   better conditioning. An input offset ``c`` enters linearly too (its
   response is ``c`` times the step response) and is eliminated the same
   way, jointly with the initial state.

3. **Input delay** (``input_delay``, MATLAB's ``IODelay``): the model is
   ``y = G(s) e^(-s tau) (u + c)``, ``tau`` in seconds, not necessarily a
   multiple of ``ts``. The output-error simulation is exact for a held input
   delayed by ``tau = (d + f) ts`` (two input vectors, see
   :func:`eha_core.identify._ctmodels.discretise`), and SRIVC filters the
   delayed input exactly in the same way (the state-variable filter
   discretised for it), so a fixed delay changes neither stage's
   consistency. With ``input_delay="estimate"``:

   - the whole-sample part is searched first, as MATLAB's ``delayest``
     does: an ARX model (``np`` poles, ``np + 1`` input lags, a constant when
     the offset is estimated) is fitted by least squares for every delay
     ``0..max_delay`` on the same samples, and its loss gives the best whole
     delay ``d``;
   - SRIVC runs at ``d - 1``, ``d``, ``d + 1`` and the range is extended a
     sample at a time while the lowest output-error cost lies at one of its
     ends (ARX is biased by output noise and can be off by more than a
     sample). Only models that are not markedly unstable are ranked: a delay
     that is too long cannot be made up and SRIVC ends in unstable models
     there, so while there are none the search moves to shorter delays. At
     each delay SRIVC starts from the best model so far (few iterations),
     and from the default starts too while no stable model has been found;
   - the output-error stage then refines ``tau`` with the coefficients: it
     joins the parameter vector (bounded to ``[0, max_delay]``), since the
     exact simulation is smooth in ``tau``; its standard error
     (``input_delay_std``) and the coefficients' covariance come from the
     joint Jacobian.

Several SRIVC starts can converge to different models (the output-error
criterion may have several minima); the best ``n_refine`` distinct ones are
refined. The better of the two stages, by cost, is returned, and ``method``
says which. The reported ``initial_state`` and ``input_offset`` are the least-squares
ones for the returned coefficients. Only numpy and scipy are imported at
module import; ``TFEstimate.tf`` imports python-control lazily.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

from .._checks import not_allowed, positive_integer, positive_number
from ..cancel import CancelToken, check
from ._ctmodels import (
    FrequencyResponseData,
    as_pair,
    as_tf,
    as_ts,
    check_delay,
    delayed,
    discretise,
    expm_balanced,
    fit_linear_terms,
    fit_percent,
    frequency_response,
    linear_columns,
    readonly,
    simulate_tf,
    split_delay,
    state_numerators,
    zoh_matrices,
)

__all__ = ["TFEstimate", "oe_fit", "tfest"]

_INITIAL_CONDITIONS = ("zero", "estimate")
_INPUT_OFFSETS = ("zero", "estimate")
#: Default upper bound of an estimated input delay, as a fraction of the record's duration.
MAX_DELAY_FRACTION = 0.1


# ---------------------------------------------------------------------------
# result
# ---------------------------------------------------------------------------
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
                "input_delay_std": None if self.input_delay_std is None else float(self.input_delay_std)}

    def simulate(self, u, ts=None, initial_state=None, input_offset=None) -> np.ndarray:
        """Exact ZOH response to ``u`` sampled at ``ts`` (default: ``self.ts``), delayed by ``input_delay``.

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
                           input_delay=self.input_delay)

    def frequency_response(self, w) -> FrequencyResponseData:
        """Bode data of the estimate at ``w`` rad/s, ``G(j w) e^(-j w input_delay)``.

        The phase includes the delay's ``-w input_delay``.
        """
        return frequency_response(self.num, self.den, w, input_delay=self.input_delay)


# ---------------------------------------------------------------------------
# argument checking
# ---------------------------------------------------------------------------
def _check_orders(n_poles, n_zeros) -> tuple[int, int]:
    if isinstance(n_poles, bool) or not isinstance(n_poles, (int, np.integer)) or n_poles < 1:
        raise not_allowed("n_poles", n_poles, "must be a whole number >= 1")
    if isinstance(n_zeros, bool) or not isinstance(n_zeros, (int, np.integer)) or not (
        0 <= n_zeros <= n_poles - 1
    ):
        raise not_allowed("n_zeros", n_zeros, f"must be a whole number in [0, n_poles - 1] = [0, {n_poles - 1}] "
                                              "(the model must be strictly proper)")
    return int(n_poles), int(n_zeros)


def _check_data(u, y, ts, n_params: int, n_initial: int, n_offset: int = 0):
    u_arr, y_arr = as_pair(u, y, ("u", "y"))
    needed = n_params + n_initial + n_offset + 2
    if u_arr.size < needed:
        offset = f", {n_offset} input offset" if n_offset else ""
        raise not_allowed("u", u_arr, f"it has {u_arr.size} samples; this model needs at least {needed} "
                                             f"({n_params} coefficients, {n_initial} initial states{offset}, 2 spare)")
    return u_arr, y_arr, as_ts(ts)


def _check_initial_condition(initial_condition) -> bool:
    if not isinstance(initial_condition, str) or initial_condition not in _INITIAL_CONDITIONS:
        raise not_allowed("initial_condition", initial_condition, "use zero or estimate")
    return initial_condition == "estimate"


def _check_input_offset(input_offset) -> bool:
    if not isinstance(input_offset, str) or input_offset not in _INPUT_OFFSETS:
        raise not_allowed("input_offset", input_offset, "use zero or estimate")
    return input_offset == "estimate"


def _checked_problem(u, y, ts, n_poles, n_zeros, initial_condition, input_offset, tol, max_nfev):
    """The arguments :func:`tfest` and :func:`oe_fit` share, checked: ``(n, m, u, y, ts,
    estimate_initial_state, estimate_offset, tol, max_nfev)``."""
    n, m = _check_orders(n_poles, n_zeros)
    estimate_initial_state = _check_initial_condition(initial_condition)
    estimate_offset = _check_input_offset(input_offset)
    u_arr, y_arr, ts_f = _check_data(u, y, ts, n + m + 1, n if estimate_initial_state else 0, int(estimate_offset))
    tol = positive_number("tol", tol)
    max_nfev = 100 * (n + m + 1) if max_nfev is None else positive_integer("max_nfev", max_nfev)
    return n, m, u_arr, y_arr, ts_f, estimate_initial_state, estimate_offset, tol, max_nfev


def _check_delay_option(input_delay, max_delay, n_samples: int, ts: float):
    """``(estimate, fixed_delay_s, max_delay_s)`` from ``input_delay`` and ``max_delay``.

    A delay (fixed or searched) is limited to half the record: beyond that
    the delayed input leaves too little of the output to fit.
    """
    half = 0.5 * n_samples * ts
    limit = f"at most half the record, N ts / 2 = {half:.6g} s"
    if isinstance(input_delay, str):
        if input_delay != "estimate":
            raise not_allowed("input_delay", input_delay, "use a delay >= 0 s or estimate")
        if max_delay is None:
            max_delay_s = MAX_DELAY_FRACTION * n_samples * ts
        else:
            max_delay_s = positive_number("max_delay", max_delay, f"must be a delay > 0 s, {limit}")
            if max_delay_s > half:
                raise not_allowed("max_delay", max_delay, f"must be {limit}")
        return True, 0.0, max_delay_s
    tau = check_delay(input_delay)
    if tau > half:
        raise not_allowed("input_delay", input_delay, f"must be {limit}")
    if max_delay is not None:
        raise not_allowed("max_delay", max_delay, "bounds an estimated delay: give it with input_delay = estimate")
    return False, tau, None


def _model_coefficients(model, n: int, m: int, name: str) -> np.ndarray:
    """``theta = [a_1..a_n, b_0..b_m]`` from ``(num, den)`` or an object with them."""
    if hasattr(model, "num") and hasattr(model, "den"):
        num, den = model.num, model.den
        if isinstance(num, list):  # control.TransferFunction: nested lists
            num, den = num[0][0], den[0][0]
        names = (f"{name}.num", f"{name}.den")
    else:
        try:
            num, den = model
        except (TypeError, ValueError):
            raise not_allowed(name, model, "must be a (num, den) pair or a transfer function") from None
        names = (f"{name}[0]", f"{name}[1]")
    num_n, den_n = as_tf(num, den, names)
    if den_n.size - 1 != n or num_n.size - 1 > m:
        # shown as [num, den], whatever held them (a pair, a transfer function)
        given = [np.atleast_1d(np.asarray(num, dtype=float)), np.atleast_1d(np.asarray(den, dtype=float))]
        raise not_allowed(name, given, f"must have {n} poles and at most {m} zeros (n_poles = {n}, "
                                       f"n_zeros = {m}); it has {den_n.size - 1} poles and "
                                       f"{num_n.size - 1} zeros")
    b = np.zeros(m + 1)
    b[m + 1 - num_n.size:] = num_n
    return np.concatenate([den_n[1:], b])


def _split(theta: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` from ``theta = [a_1..a_n, b_0..b_m]``."""
    return theta[n:].copy(), np.concatenate([[1.0], theta[:n]])


# ---------------------------------------------------------------------------
# output-error criterion (shared by SRIVC's bookkeeping and the OE stage)
# ---------------------------------------------------------------------------
class _OutputError:
    """Residual ``y - y_hat(theta)`` of the exact ZOH simulation.

    The terms that enter ``y_hat`` linearly, the response ``c G(s) 1(t)`` to a
    constant input offset (with ``estimate_offset``) and the free response to
    the initial state (with ``estimate_initial_state``), are eliminated by linear least
    squares in every evaluation (variable projection). Their coefficients,
    ``[c, initial_state...]`` in that order, are the ``linear`` vector.

    The model's input delay is ``input_delay`` (seconds), or, with
    ``max_delay`` given, the last entry of ``theta`` (estimated, in
    ``[0, max_delay]``): ``theta = [a_1..a_n, b_0..b_m, tau]``.
    """

    def __init__(self, u: np.ndarray, y: np.ndarray, ts: float, n: int, estimate_initial_state: bool,
                 estimate_offset: bool = False, cancel: CancelToken | None = None, *,
                 input_delay: float = 0.0, max_delay: float | None = None):
        self.u, self.y, self.ts, self.n = u, y, ts, n
        self.estimate_initial_state = estimate_initial_state
        self.estimate_offset = estimate_offset
        self.input_delay = input_delay
        self.max_delay = max_delay
        self.nfev = 0
        # checked at every evaluation (each residual of the output-error stage,
        # each Jacobian column of the covariance) and by every SRIVC iteration:
        # a cancelled computation stops within one simulation of the model
        self.cancel = cancel

    @property
    def n_linear(self) -> int:
        return int(self.estimate_offset) + (self.n if self.estimate_initial_state else 0)

    @property
    def estimate_delay(self) -> bool:
        return self.max_delay is not None

    def split_delay(self, theta: np.ndarray) -> tuple[np.ndarray, float]:
        """``(coefficients, delay in s)`` of a parameter vector."""
        if self.estimate_delay:
            return theta[:-1], float(theta[-1])
        return theta, self.input_delay

    def model(self, theta: np.ndarray):
        """The exact ZOH discretisation at ``theta`` (with its delay)."""
        coefficients, tau = self.split_delay(theta)
        num, den = _split(coefficients, self.n)
        return discretise(num, den, self.ts, tau)

    def scale(self, theta: np.ndarray, n: int, m: int) -> np.ndarray:
        """:func:`_parameter_scale`, and ``ts`` for an estimated delay (so it is counted in samples)."""
        coefficients, _ = self.split_delay(theta)
        scale = _parameter_scale(coefficients, n, m)
        return np.r_[scale, self.ts] if self.estimate_delay else scale

    def split_linear(self, linear):
        """``(initial_state, offset)`` from the ``linear`` coefficients (None when not estimated)."""
        if linear is None:
            return None, None
        offset = float(linear[0]) if self.estimate_offset else None
        initial_state = linear[int(self.estimate_offset):] if self.estimate_initial_state else None
        return initial_state, offset

    def columns(self, theta: np.ndarray) -> np.ndarray:
        """The responses of the linear terms at ``theta``, shape ``(N, n_linear)``."""
        return linear_columns(self.model(theta), self.u.size,
                               offset=self.estimate_offset, initial_state=self.estimate_initial_state)

    def evaluate(self, theta: np.ndarray, linear: np.ndarray | None = None):
        """``(residual, linear)``; residual is None if the simulation is not finite.

        With ``linear`` given, those coefficients are used instead of the
        least-squares ones (for the Jacobian at fixed linear terms).
        """
        check(self.cancel)
        self.nfev += 1
        if not np.all(np.isfinite(theta)):
            return None, None
        if self.estimate_delay and not 0.0 <= theta[-1] <= self.max_delay:
            return None, None  # a finite-difference step out of the bounds
        try:
            with np.errstate(all="ignore"):
                model = self.model(theta)
                residual = self.y - model.forced(self.u)
                coef = None
                if self.n_linear and np.all(np.isfinite(residual)):
                    columns = linear_columns(model, self.u.size, offset=self.estimate_offset,
                                              initial_state=self.estimate_initial_state)
                    if not np.all(np.isfinite(columns)):
                        return None, None
                    coef = fit_linear_terms(columns, residual) if linear is None else linear
                    residual = residual - columns @ coef
        except (np.linalg.LinAlgError, ValueError):  # e.g. eigenvalues of an overflowed matrix
            return None, None
        with np.errstate(over="ignore", invalid="ignore"):
            finite = np.isfinite(residual @ residual)  # also catches overflow of the sum
        if not finite:
            return None, None
        return residual, coef

    def cost(self, theta: np.ndarray) -> float:
        residual, _ = self.evaluate(theta)
        return np.inf if residual is None else 0.5 * float(residual @ residual)


# ---------------------------------------------------------------------------
# stage 1: SRIVC
# ---------------------------------------------------------------------------
def _stabilise(den: np.ndarray) -> np.ndarray:
    """Reflect right-half-plane roots of a monic polynomial into the left half."""
    roots = np.roots(den)
    if np.all(roots.real < 0):
        return den
    roots = np.where(roots.real > 0, -roots.real + 1j * roots.imag, roots)
    return np.real(np.poly(roots))


class _StateVariableFilter:
    """``s^k / A_f(s)``, ``k = 0..n``, discretised for ZOH and FOH inputs.

    ``1/A_f`` is realised in controllable canonical form with states
    ``[w, w', ..., w^(n-1)]``; then ``w^(n) = input - a_1 w^(n-1) - ... - a_n w``.
    One exponential of the block matrix ``[[A ts, B ts, 0], [0, 0, 1], [0, 0, 0]]``
    gives the ZOH input matrix ``G1`` and the ramp matrix ``G2`` of the FOH
    (triangle-hold) discretisation, as in ``scipy.signal.cont2discrete``.

    With ``input_delay = (d + f) ts`` the ZOH signals (the inputs) are
    filtered as ``s^k / A_f e^(-s input_delay)``, exactly: shifted by ``d``
    samples, and with a fraction ``f`` split between ``u[k-d]`` and
    ``u[k-d-1]`` by the input vectors ``Gamma0`` and ``Gamma1 = G1 - Gamma0``
    of :func:`eha_core.identify._ctmodels.discretise`. The FOH signals (the
    output, the auxiliary model's output) are not delayed.
    """

    def __init__(self, den_f: np.ndarray, ts: float, input_delay: float = 0.0):
        n = den_f.size - 1
        self.den_f = den_f
        a_mat = np.eye(n, k=1)
        a_mat[-1, :] = -den_f[:0:-1]
        block = np.zeros((n + 2, n + 2))
        block[:n, :n] = a_mat * ts
        block[n - 1, n] = ts
        block[n, n + 1] = 1.0
        e = expm_balanced(block)
        ad, g1, g2 = e[:n, :n], e[:n, n], e[:n, n + 1]
        self.den_z = np.real(np.poly(np.linalg.eigvals(ad)))
        ident = np.eye(n)
        self.num_zoh = state_numerators(ad, g1, self.den_z, ident, np.zeros(n))
        self.delay_samples, self.delay_fraction = (0, 0.0) if input_delay == 0.0 else split_delay(input_delay, ts)
        if self.delay_fraction:
            _, gamma0 = zoh_matrices(a_mat, ident[:, -1], (1.0 - self.delay_fraction) * ts)
            num_delayed = np.zeros((n, n + 2))
            num_delayed[:, :n + 1] = state_numerators(ad, gamma0, self.den_z, ident, np.zeros(n))
            num_delayed[:, 1:] += state_numerators(ad, g1 - gamma0, self.den_z, ident, np.zeros(n))
            self.num_zoh = num_delayed
        self.num_foh = state_numerators(ad, g1 - g2 + ad @ g2, self.den_z, ident, g2)
        # exact samples of the impulse responses of s^k / A_f, k < n: the
        # states' free response from x(0) = e_n (the input vector)
        self.num_impulse = state_numerators(ad, ad[:, -1], self.den_z, ident, ident[:, -1])

    def impulse_responses(self, n_samples: int) -> np.ndarray:
        """Sampled impulse responses of ``s^k / A_f``, ``k = 0..n-1``, shape ``(N, n)``.

        A system's initial conditions add ``C(s) / A(s)`` (``deg C < n``) to its
        output; after the prefilter they add a combination of these signals,
        which therefore serve as the initial-condition regressors.
        """
        impulse = np.zeros(n_samples)
        impulse[0] = 1.0
        return np.column_stack([scipy.signal.lfilter(num, self.den_z, impulse)
                                for num in self.num_impulse])

    def apply(self, signals: np.ndarray, hold: str) -> np.ndarray:
        """Filtered derivatives, shape ``(N, n_signals, n + 1)``: ``[..., k] = s^k/A_f x``.

        ZOH signals are delayed by the filter's ``input_delay``.
        """
        nums = self.num_zoh if hold == "zoh" else self.num_foh
        n = nums.shape[0]
        if hold == "zoh" and self.delay_samples:
            signals = delayed(signals, self.delay_samples)
        out = np.empty(signals.shape + (n + 1,))
        for k in range(n):
            out[..., k] = scipy.signal.lfilter(nums[k], self.den_z, signals, axis=0)
        # the top derivative's input term is the (delayed) input at the sample
        # instant: u(k ts - tau) = u[k-d-1] when the delay has a fraction
        top = delayed(signals, 1) if hold == "zoh" and self.delay_fraction else signals
        out[..., n] = top - out[..., :n] @ self.den_f[:0:-1]
        return out


def _iv_solve(phi: np.ndarray, zeta: np.ndarray, target: np.ndarray):
    """Instrumental-variable solution ``(Z^T Phi)^-1 Z^T t`` with column scaling.

    Solved as ``(Q^T Phi)^-1 Q^T t`` with ``Z = Q R`` (the same solution, as
    ``R`` is invertible): forming ``Z^T Phi`` would square the conditioning,
    which matters when regressors are nearly collinear (an input offset's
    step regressor against the filtered output of a slow system).
    """
    scale = np.linalg.norm(phi, axis=0)
    scale[scale == 0] = 1.0
    q, _ = np.linalg.qr(zeta / scale)
    gram = q.T @ (phi / scale)
    rhs = q.T @ target
    theta_scaled = np.linalg.solve(gram, rhs)
    return theta_scaled / scale, scale


def _regressors(yf: np.ndarray, uf: np.ndarray, n: int, m: int) -> np.ndarray:
    """``[-y_f^(n-1), ..., -y_f, u_f^(m), ..., u_f]`` (matches ``theta``)."""
    return np.hstack([-yf[:, n - 1::-1], uf[:, m::-1]])


def _offset_regressor(sf: np.ndarray, num: np.ndarray | None, m: int, ic: bool) -> np.ndarray:
    """Filtered regressor of ``d = b_nz c`` (``c`` a constant input offset).

    ``sf[:, k] = s^k / A_f`` applied to a unit step (ZOH-exact). For ``t > 0``
    ``B(s) (c 1(t)) = b_nz c 1(t)`` plus impulses at ``t = 0``, which are
    ``c sum_{j>=1} b_j s^(j-1) delta`` (``b_j`` the coefficient of ``s^j``).
    With estimated initial conditions those impulses lie in the span of the
    initial-condition regressors, so the regressor is ``1/A_f`` applied to the
    step. With a zero initial state they are kept, with the current numerator
    ``B_hat``: ``(B_hat / b_nz_hat) / A_f`` applied to the step (exact at the
    fixed point ``B_hat = B``); that needs ``b_nz_hat`` clear of zero.
    """
    if ic or m == 0 or num is None:
        return sf[:, 0]
    b_nz = num[-1]
    if not abs(b_nz) > 1e-8 * np.max(np.abs(num)):
        return sf[:, 0]
    return (sf[:, m::-1] @ num) / b_nz


def _srivc(u, y, ts, n, m, start, max_iter, tol, criterion):
    """SRIVC iterations from ``start`` = ("lambda", value) or ("model", theta).

    With ``criterion.estimate_initial_state`` the ``n`` initial-condition regressors of
    :meth:`_StateVariableFilter.impulse_responses` join the regression (they
    are noise-free, so they are their own instruments) and the auxiliary model
    includes the estimated initial-condition response.

    With ``criterion.estimate_offset`` the model is ``A(s) y = B(s) (u + c)``:
    for a constant ``c`` the derivatives vanish, leaving ``b_nz c`` times a
    step, which is linear in ``d = b_nz c``. Its filtered regressor (see
    :func:`_offset_regressor`) is exact (a step is piecewise constant, so the
    ZOH discretisation of the filter is exact) and noise-free, so it is its own
    instrument; the auxiliary model includes ``d`` times it. ``c = d / b_nz``
    itself is not needed here: the output-error criterion that ranks the
    iterates eliminates it by least squares.

    With ``criterion.input_delay`` (fixed) the inputs are filtered delayed
    (:class:`_StateVariableFilter`). The offset's regressor is then the
    delayed step through ``B_hat`` (:func:`_offset_regressor` without initial
    conditions): the impulses of ``B(s)`` applied to the delayed step come at
    ``t = tau``, outside the span of the initial-condition regressors.

    Returns ``(best_theta, best_cost, iterations, converged)``; the best
    iterate by output-error cost is kept (SRIVC may oscillate on poor data).
    """
    check(criterion.cancel)
    kind, value = start
    n_theta = n + m + 1
    tau = criterion.input_delay
    ic = criterion.estimate_initial_state
    oc = criterion.estimate_offset
    n_extra = int(oc) + (n if ic else 0)
    # u, plus a unit step when the offset is estimated: both piecewise constant
    inputs = np.column_stack([u, np.ones_like(u)]) if oc else u[:, None]

    def extra_regressors(svf, uf_all, num):
        cols = []
        if oc:
            cols.append(_offset_regressor(uf_all[:, 1], num, m, ic and tau == 0.0)[:, None])
        if ic:
            cols.append(svf.impulse_responses(u.size))
        return np.hstack(cols) if cols else np.zeros((u.size, 0))

    if kind == "lambda":
        # LSSVF: least squares with the fixed filter (s + lambda)^n.
        den_f = np.real(np.poly(np.full(n, -value)))
        svf = _StateVariableFilter(den_f, ts, tau)
        uf_all = svf.apply(inputs, "zoh")
        yf = svf.apply(y, "foh")
        phi = np.hstack([_regressors(yf, uf_all[:, 0], n, m),
                         extra_regressors(svf, uf_all, None)])
        theta, _ = _iv_solve(phi, phi, yf[:, n])
        theta = theta[:n_theta]
    else:
        theta = value.copy()
    # coefficients of the extra regressors ([d, C(s)...]) in the auxiliary model
    extra_coeffs = np.zeros(n_extra)
    best_theta, best_cost = theta, criterion.cost(theta)
    converged = False
    iterations = 0  # the count is returned, so it is kept outside the loop
    for _ in range(max_iter):
        iterations += 1
        # an iteration filters the data several times: as costly as a few
        # simulations of the model, so a cancel is looked at before each
        check(criterion.cancel)
        num, den = _split(theta, n)
        den_f = _stabilise(den)
        svf = _StateVariableFilter(den_f, ts, tau)
        uf_all = svf.apply(inputs, "zoh")
        uf = uf_all[:, 0]
        extra = extra_regressors(svf, uf_all, num)
        # auxiliary model B/A_f u (+ offset and initial-condition responses),
        # exact under ZOH
        x_hat = uf[:, m::-1] @ num + extra @ extra_coeffs
        yxf = svf.apply(np.column_stack([y, x_hat]), "foh")
        phi = np.hstack([_regressors(yxf[:, 0], uf, n, m), extra])
        zeta = np.hstack([_regressors(yxf[:, 1], uf, n, m), extra])
        theta_new, scale = _iv_solve(phi, zeta, yxf[:, 0, n])
        if not np.all(np.isfinite(theta_new)):
            break
        # The extra coefficients are d = b_nz c and those of C(s) in
        # A(s) y = B(s) u + d 1(t) + C(s) (initial conditions). The auxiliary
        # model's responses to them are formed with the filter's A_f, which
        # equals A at convergence.
        extra_coeffs = theta_new[n_theta:]
        theta_new, scale = theta_new[:n_theta], scale[:n_theta]
        change = np.linalg.norm((theta_new - theta) * scale) / max(
            np.linalg.norm(theta_new * scale), np.finfo(float).tiny
        )
        theta = theta_new
        cost = criterion.cost(theta)
        if cost < best_cost:
            best_theta, best_cost = theta, cost
        if change < tol:
            converged = True
            break
    return best_theta, best_cost, iterations, converged


def _default_lambdas(n_samples: int, ts: float) -> np.ndarray:
    """Filter cut-offs spread log-uniformly between the record and Nyquist."""
    w_low = 2.0 * np.pi / (n_samples * ts)
    w_nyq = np.pi / ts
    return np.geomspace(w_nyq / 2.0, max(4.0 * w_low, w_nyq / 200.0), 4)


# ---------------------------------------------------------------------------
# stage 2: output error
# ---------------------------------------------------------------------------
def _parameter_scale(theta: np.ndarray, n: int, m: int) -> np.ndarray:
    """Scale so that ``theta / scale`` is O(1); floors for near-zero entries."""
    a, b = theta[:n], theta[n:]
    powers = np.arange(1, n + 1)
    w0 = np.max(np.abs(a) ** (1.0 / powers))
    if not np.isfinite(w0) or w0 <= 0:
        w0 = 1.0
    floor_a = 1e-6 * w0**powers
    j = np.arange(m + 1)
    b_ref = np.abs(b) * w0 ** (-j)
    floor_b = 1e-6 * np.max(b_ref) * w0**j if np.max(b_ref) > 0 else np.ones(m + 1)
    scale = np.maximum(np.abs(theta), np.concatenate([floor_a, floor_b]))
    scale[~np.isfinite(scale) | (scale == 0)] = 1.0
    return scale


def _covariance(criterion: _OutputError, theta: np.ndarray, scale: np.ndarray,
                residual: np.ndarray, linear: np.ndarray | None):
    """Gauss-Newton covariances of the coefficients and of the linear terms.

    ``J`` is the central-difference Jacobian of ``y_hat`` with respect to the
    scaled coefficients at fixed linear terms ``linear`` (input offset,
    initial state), ``L`` the linear terms' columns. The coefficients'
    covariance is ``sigma^2 (J^T P J)^-1`` with ``P`` the projector orthogonal
    to ``L`` (the coefficient block of the joint covariance), and the linear
    terms' is ``sigma^2 (L^+ L^+T + L^+ J (J^T P J)^-1 J^T L^+T)``.

    Returns ``(covariance, variance, linear_covariance)``.
    """
    p = theta / scale
    n_lin = 0 if linear is None else linear.size
    nan = np.full((p.size, p.size), np.nan), np.nan, np.full((n_lin, n_lin), np.nan)
    jac = np.empty((residual.size, p.size))
    for i in range(p.size):
        h = 1e-6 * max(1.0, abs(p[i]))
        step = np.zeros_like(p)
        step[i] = h
        r_plus, _ = criterion.evaluate((p + step) * scale, linear)
        r_minus, _ = criterion.evaluate((p - step) * scale, linear)
        if criterion.estimate_delay and i == p.size - 1 and (r_plus is None) != (r_minus is None):
            # an estimated delay at a bound of its search (0, say): one-sided
            # difference, ``residual`` being the residual at ``theta`` itself
            r_plus, r_minus, h = (residual, r_minus, h / 2.0) if r_plus is None else (r_plus, residual, h / 2.0)
        if r_plus is None or r_minus is None:
            return nan
        # residual = y - y_hat, so d(y_hat)/dp = -d(residual)/dp
        jac[:, i] = -(r_plus - r_minus) / (2.0 * h)
    dof = residual.size - p.size - n_lin
    variance = float(residual @ residual) / dof
    jac_projected = jac
    if n_lin:
        columns = criterion.columns(theta)
        norms = np.linalg.norm(columns, axis=0)
        norms[norms == 0] = 1.0
        u_l, s_l, vt_l = np.linalg.svd(columns / norms, full_matrices=False)
        keep_l = s_l > s_l[0] * max(columns.shape) * np.finfo(float).eps
        jac_projected = jac - u_l[:, keep_l] @ (u_l[:, keep_l].T @ jac)
    _, sing, vt = np.linalg.svd(jac_projected, full_matrices=False)
    keep = sing > sing[0] * 1e-13 if sing[0] > 0 else np.zeros_like(sing, dtype=bool)
    inv = (vt[keep].T / sing[keep] ** 2) @ vt[keep]
    if not np.all(keep):
        inv = np.full_like(inv, np.nan)
    cov_lin = np.zeros((0, 0))
    if n_lin:
        # L^+ of the unnormalised columns; NaN if the linear terms are not
        # all identifiable (e.g. an offset with a zero at s = 0)
        pinv_cols = ((vt_l[keep_l].T / s_l[keep_l]) @ u_l[:, keep_l].T) / norms[:, None]
        if not np.all(keep_l):
            pinv_cols = np.full_like(pinv_cols, np.nan)
        pj = pinv_cols @ jac
        cov_lin = variance * (pinv_cols @ pinv_cols.T + pj @ inv @ pj.T)
    cov_p = variance * inv
    return cov_p * scale[:, None] * scale[None, :], variance, cov_lin


def _oe_refine(criterion: _OutputError, theta0: np.ndarray, n: int, m: int,
               max_nfev: int, tol: float):
    """``least_squares`` on the exact ZOH output error, from ``theta0``.

    An estimated delay (the last parameter) is bounded to
    ``[0, criterion.max_delay]``; the coefficients are free.
    """
    scale = criterion.scale(theta0, n, m)
    bounds = (-np.inf, np.inf)
    if criterion.estimate_delay:
        lower = np.full(theta0.size, -np.inf)
        upper = np.full(theta0.size, np.inf)
        lower[-1], upper[-1] = 0.0, criterion.max_delay / scale[-1]
        bounds = (lower, upper)

    def residual(p):
        r, _ = criterion.evaluate(p * scale)
        return np.full(criterion.y.size, np.inf) if r is None else r

    try:
        # a trial step to an unstable model can overflow scipy's reduction ratio
        with np.errstate(over="ignore"):
            res = scipy.optimize.least_squares(
                residual, theta0 / scale, method="trf", x_scale="jac", jac="2-point",
                xtol=tol, ftol=tol, gtol=tol, max_nfev=max_nfev, bounds=bounds,
            )
    except ValueError as exc:  # e.g. non-finite residuals at the start point
        return theta0, np.inf, False, f"output-error refinement not possible: {exc}"
    return res.x * scale, float(res.cost), bool(res.success), res.message


def _nan_estimate(n, m, ts, n_samples, estimate_initial_state, estimate_offset, message, nit, nfev,
                  input_delay=0.0):
    """A failed estimate; ``input_delay`` is the fixed delay, or None when it was to be estimated."""
    p = n + m + 1
    return TFEstimate(
        num=readonly(np.full(m + 1, np.nan)), den=readonly(np.r_[1.0, np.full(n, np.nan)]),
        ts=ts, n_poles=n, n_zeros=m, fit_percent=np.nan, cost=np.nan, mse=np.nan,
        noise_variance=np.nan, initial_condition="estimate" if estimate_initial_state else "zero",
        initial_state=None, input_offset=np.nan if estimate_offset else None,
        input_offset_std=np.nan if estimate_offset else None, success=False,
        message=message, method="none", nit_srivc=nit, nfev_oe=nfev,
        param_std=readonly(np.full(p, np.nan)), covariance=readonly(np.full((p, p), np.nan)),
        srivc_num=None, srivc_den=None, srivc_cost=np.nan, n_samples=n_samples,
        input_delay=np.nan if input_delay is None else float(input_delay),
        input_delay_std=np.nan if input_delay is None else None,
    )


def _estimate_result(criterion, theta, n, m, ts, success, message, method, nit, srivc_theta,
                     srivc_cost) -> TFEstimate:
    """Assemble the result: fit, covariance, initial_state and input offset at the final estimate."""
    nfev = criterion.nfev
    residual, linear = criterion.evaluate(theta)
    if residual is None:
        return _nan_estimate(n, m, ts, criterion.y.size, criterion.estimate_initial_state,
                             criterion.estimate_offset,
                             message + "; the final model cannot be simulated", nit, nfev,
                             None if criterion.estimate_delay else criterion.input_delay)
    covariance, variance, cov_linear = _covariance(
        criterion, theta, criterion.scale(theta, n, m), residual, linear)
    theta, tau = criterion.split_delay(theta)
    tau_std = None
    if criterion.estimate_delay:
        # the coefficients' block of the joint covariance keeps the delay's
        # uncertainty in it (a marginal, not a conditional, covariance)
        tau_std = float(np.sqrt(abs(covariance[-1, -1])))
        covariance = covariance[:-1, :-1]
        message += f"; input delay estimated: {tau:.6g} s ({tau / ts:.4g} samples)"
    if srivc_theta is not None:
        srivc_theta, _ = criterion.split_delay(srivc_theta)
    initial_state, offset = criterion.split_linear(linear)
    offset_std = None
    if criterion.estimate_offset:
        offset_std = float(np.sqrt(abs(cov_linear[0, 0])))
        message += f"; input offset estimated: {offset:.6g} (input units)"
    num, den = _split(theta, n)
    poles = np.roots(den)
    if np.any(poles.real > 1e-9 * max(1.0, np.max(np.abs(poles)))):
        message += (f"; note: the estimate is unstable (largest pole real part "
                    f"{np.max(poles.real):.4g} rad/s)")
    y_hat = criterion.y - residual
    sse = float(residual @ residual)
    srivc_num = srivc_den = None
    if srivc_theta is not None:
        srivc_num, srivc_den = _split(srivc_theta, n)
    return TFEstimate(
        num=readonly(num), den=readonly(den), ts=ts, n_poles=n, n_zeros=m,
        fit_percent=fit_percent(criterion.y, y_hat), cost=0.5 * sse,
        mse=sse / residual.size, noise_variance=variance,
        initial_condition="estimate" if criterion.estimate_initial_state else "zero",
        initial_state=None if initial_state is None else readonly(initial_state), input_offset=offset,
        input_offset_std=offset_std, success=bool(success), message=message,
        method=method, nit_srivc=nit, nfev_oe=nfev,
        param_std=readonly(np.sqrt(np.abs(np.diag(covariance)))),
        covariance=readonly(covariance),
        srivc_num=None if srivc_num is None else readonly(srivc_num),
        srivc_den=None if srivc_den is None else readonly(srivc_den),
        srivc_cost=float(srivc_cost), n_samples=residual.size,
        input_delay=float(tau), input_delay_std=tau_std,
    )


# ---------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------
def tfest(u, y, ts, n_poles=3, n_zeros=0, *, initial_condition="zero", input_offset="zero",
          input_delay=0.0, max_delay=None, init=None, lambda_svf=None, refine=True, n_refine=2,
          max_iter=50, max_nfev=None, tol=1e-10, cancel: CancelToken | None = None) -> TFEstimate:
    """Estimate a continuous-time transfer function from sampled data (MATLAB ``tfest``).

    SRIVC (refined instrumental variables with state-variable filters) gives
    a consistent start; an output-error fit on the exact ZOH simulation
    refines it. See the module docstring for the algorithm.

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input (held constant between samples) and output samples.
    ts : float
        Sampling time in seconds.
    n_poles : int
        Number of poles ``np >= 1`` (default 3, as in the paper).
    n_zeros : int
        Number of zeros, ``0 <= nz <= np - 1`` (strictly proper model).
    initial_condition : {"zero", "estimate"}
        ``"zero"``: the system starts at rest. ``"estimate"``: the initial
        state is estimated together with the coefficients (reported in
        ``initial_state``) and used for ``fit_percent``.
    input_offset : {"zero", "estimate"}
        ``"estimate"``: the model is ``y = G(s) (u + c)`` with a constant input
        offset ``c`` (input units, from the first sample on), estimated in both
        stages and reported in ``input_offset`` (MATLAB's ``InputOffset``). A
        constant bias at a closed loop's plant input (e.g. a valve whose flow
        gains differ with the sign of the command) is such an offset on the
        reference. ``"zero"`` (default): no offset.
    input_delay : float or "estimate"
        Input delay ``tau`` in seconds (MATLAB's ``IODelay``): the model is
        ``y = G(s) e^(-s tau) (u + c)``, the input before the first sample
        taken as zero. A number ``>= 0`` (default 0, no delay), not
        necessarily a multiple of ``ts``, is fixed; ``"estimate"`` searches
        ``[0, max_delay]`` (whole samples first, then the fraction with the
        coefficients; see the module docstring). At most half the record.
        The result's ``input_delay`` (and ``input_delay_std`` when estimated)
        report it.
    max_delay : float, optional
        Upper bound (seconds) of an estimated delay; default a tenth of the
        record, ``0.1 N ts``. Only with ``input_delay="estimate"``.
    init : (num, den) or transfer function, optional
        A model to start SRIVC from (``n_poles`` poles, at most ``n_zeros``
        zeros), e.g. the linearised physics; tried besides the default starts.
    lambda_svf : float, optional
        Cut-off (rad/s) of the initial filter ``(s + lambda)^np``. Default: a
        few values between the record's lowest frequency and ``pi/ts/2`` are
        tried and the best kept.
    refine : bool
        Run the output-error stage (default True).
    n_refine : int
        How many of the best distinct SRIVC results the output-error stage
        refines (default 2); the lowest final cost is kept.
    max_iter : int
        Maximum SRIVC iterations per start.
    max_nfev : int, optional
        Maximum output-error residual evaluations (default ``100 * n_params``).
    tol : float
        Relative tolerance: SRIVC stops when the coefficients change by less;
        ``xtol``, ``ftol`` and ``gtol`` of ``least_squares``.
    cancel : eha_core.cancel.CancelToken, optional
        Checked before every SRIVC iteration and every simulation of a
        candidate model (each output-error residual), so a cancel lands within
        one of them; raises :class:`~eha_core.cancel.Cancelled` when set.

    Returns
    -------
    TFEstimate
        Estimate, fit, statistics, diagnostics. ``success`` is False (with a
        ``message``) when the estimation fails; no exception is raised then.

    Raises
    ------
    ValueError
        For invalid arguments (the message names the argument).
    eha_core.cancel.Cancelled
        When ``cancel`` was set.

    Examples
    --------
    >>> import numpy as np
    >>> ts = 0.01
    >>> u = np.sign(np.sin(2 * np.pi * 0.5 * ts * np.arange(800)))  # square wave
    >>> y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, ts)
    >>> est = tfest(u, y, ts, n_poles=2)
    >>> est.success, est.method
    (True, 'srivc+oe')
    >>> np.round(est.den, 6), np.round(est.num, 6)
    (array([ 1.,  6., 20.]), array([20.]))
    >>> round(est.fit_percent, 4)
    100.0

    The same system behind a delay of 3.4 samples, estimated:

    >>> y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, ts, input_delay=3.4 * ts)
    >>> est = tfest(u, y, ts, n_poles=2, input_delay="estimate")
    >>> round(est.input_delay / ts, 4), np.round(est.den, 4)
    (3.4, array([ 1.,  6., 20.]))
    """
    n, m, u_arr, y_arr, ts_f, estimate_initial_state, estimate_offset, tol, max_nfev = _checked_problem(
        u, y, ts, n_poles, n_zeros, initial_condition, input_offset, tol, max_nfev)
    estimate_delay, fixed_delay, max_delay_s = _check_delay_option(input_delay, max_delay, u_arr.size, ts_f)
    max_iter = positive_integer("max_iter", max_iter)
    if not isinstance(refine, (bool, np.bool_)):
        raise not_allowed("refine", refine, "must be True or False")
    n_refine = positive_integer("n_refine", n_refine)
    starts, start_names = [], []
    if init is not None:
        starts.append(("model", _model_coefficients(init, n, m, "init")))
        start_names.append("init")
    if lambda_svf is not None:
        lambdas = np.array([positive_number("lambda_svf", lambda_svf)])
    else:
        lambdas = _default_lambdas(u_arr.size, ts_f)
    starts += [("lambda", lam) for lam in lambdas]
    start_names += [f"lambda = {lam:.4g} rad/s" for lam in lambdas]
    if estimate_delay:
        criterion = _OutputError(u_arr, y_arr, ts_f, n, estimate_initial_state, estimate_offset, cancel,
                                 max_delay=max_delay_s)
        candidates, nit_total = _delay_candidates(criterion, m, starts, start_names, max_iter, tol)
    else:
        criterion = _OutputError(u_arr, y_arr, ts_f, n, estimate_initial_state, estimate_offset, cancel,
                                 input_delay=fixed_delay)
        candidates, nit_total = _srivc_candidates(criterion, m, starts, start_names, max_iter, tol)
    if not candidates:
        return _nan_estimate(
            n, m, ts_f, u_arr.size, estimate_initial_state, estimate_offset,
            "SRIVC failed from every start (singular instrument matrix or unstable "
            "simulation): is the input exciting enough?", nit_total, 0,
            None if estimate_delay else fixed_delay,
        )
    candidates.sort(key=lambda c: c[1])
    best = candidates[0]
    srivc_theta, srivc_cost, srivc_converged, start_name, srivc_nit = best
    srivc_msg = (f"SRIVC {'converged' if srivc_converged else 'did not converge'} in "
                 f"{srivc_nit} iterations from {start_name}")
    if not refine:
        criterion.nfev = 0
        return _estimate_result(criterion, srivc_theta, n, m, ts_f, srivc_converged,
                                srivc_msg + "; output-error refinement skipped", "srivc",
                                nit_total, srivc_theta, srivc_cost)
    # The output-error criterion can have several minima (e.g. a slow drift of a
    # nonlinear plant mimicked by a slow pole, versus the plant's resonance):
    # refine the best distinct SRIVC candidates and keep the lowest cost.
    criterion.nfev = 0
    refined = []
    for cand in _distinct(candidates, n_refine, n, m, criterion.scale):
        theta_oe, cost_oe, oe_success, oe_msg = _oe_refine(criterion, cand[0], n, m, max_nfev, tol)
        refined.append((cost_oe, theta_oe, oe_success, oe_msg, cand))
    refined = [r for r in refined if np.isfinite(r[0])]
    if refined:
        cost_oe, theta_oe, oe_success, oe_msg, cand = min(refined, key=lambda r: r[0])
        if cost_oe <= srivc_cost:
            if cand is not best:
                srivc_msg += f"; the output error was lowest from the SRIVC start {cand[3]}"
            return _estimate_result(criterion, theta_oe, n, m, ts_f, oe_success,
                                    f"{srivc_msg}; output error: {oe_msg}; kept the output-error estimate "
                                    f"(cost {cost_oe:.4g} <= SRIVC {srivc_cost:.4g})",
                                    "srivc+oe", nit_total, srivc_theta, srivc_cost)
        oe_msg_last = oe_msg
    else:
        cost_oe, oe_msg_last = float("nan"), "no finite output-error cost"
    return _estimate_result(criterion, srivc_theta, n, m, ts_f, srivc_converged,
                            f"{srivc_msg}; output error: {oe_msg_last}; kept the SRIVC estimate "
                            f"(cost {srivc_cost:.4g} < output error {cost_oe:.4g})",
                            "srivc", nit_total, srivc_theta, srivc_cost)


def _srivc_candidates(criterion: _OutputError, m: int, starts, start_names, max_iter: int, tol: float):
    """SRIVC from every start at the criterion's fixed delay: ``(candidates, iterations)``.

    A candidate is ``(theta, cost, converged, start name, iterations)``; starts
    that fail or end with an infinite cost give none.
    """
    u, y, ts, n = criterion.u, criterion.y, criterion.ts, criterion.n
    candidates = []
    nit_total = 0
    for name, start in zip(start_names, starts, strict=True):
        try:
            theta, cost, nit, converged = _srivc(u, y, ts, n, m, start, max_iter, tol, criterion)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            continue
        nit_total += nit
        if np.isfinite(cost):
            candidates.append((theta, cost, converged, name, nit))
    return candidates, nit_total


def _arx_delay_losses(u: np.ndarray, y: np.ndarray, n: int, d_max: int, offset: bool,
                      cancel: CancelToken | None = None) -> np.ndarray:
    """ARX loss for every whole-sample delay ``d = 0..d_max`` (MATLAB ``delayest``'s approach).

    ``y[k] + a_1 y[k-1] + ... + a_n y[k-n] = b_0 u[k-d-1] + ... + b_n u[k-d-1-n] (+ const)``:
    the exact ZOH model of ``G(s) e^(-s (d + f) ts)`` (strictly proper) has
    ``n + 1`` input lags from ``d + 1`` on. Every delay is fitted on the same
    samples (``k >= d_max + n + 1``), so the losses compare. The output lags
    (and the constant) are projected out once; each delay then costs one
    small least-squares problem. ``cancel`` is looked at every 64 delays.
    """
    n_b = n + 1
    k0 = max(n, d_max + n_b)
    n_rows = y.size - k0
    base = [-y[k0 - i:y.size - i] for i in range(1, n + 1)]
    if offset:
        base.append(np.ones(n_rows))
    q, _ = np.linalg.qr(np.column_stack(base))
    target = y[k0:] - q @ (q.T @ y[k0:])
    losses = np.empty(d_max + 1)
    for d in range(d_max + 1):
        if d % 64 == 0:
            check(cancel)
        lags = np.column_stack([u[k0 - d - 1 - j:u.size - d - 1 - j] for j in range(n_b)])
        lags -= q @ (q.T @ lags)
        coef, *_ = np.linalg.lstsq(lags, target, rcond=None)
        r = target - lags @ coef
        losses[d] = r @ r
    return losses


def _is_stable(theta: np.ndarray, n: int, rate: float) -> bool:
    """No pole of ``theta``'s denominator with a real part above ``rate`` (1/s).

    ``rate`` is about one over the record's length: a pole growing slower
    than that is indistinguishable from an integrator (which an estimate
    may put slightly to the right of zero).
    """
    poles = np.roots(np.r_[1.0, theta[:n]])
    return bool(np.all(poles.real <= rate))


def _delay_candidates(criterion: _OutputError, m: int, starts, start_names, max_iter: int, tol: float):
    """SRIVC candidates for an estimated delay, their ``theta`` ending with the delay (s).

    A local search over whole-sample delays on the SRIVC/output-error cost,
    started at the delay ``d`` of least ARX loss (:func:`_arx_delay_losses`):
    ``d - 1``, ``d``, ``d + 1`` are tried, then the range is extended by one
    sample on the side where the lowest cost lies, as long as it lies at an
    end. ARX is biased by output noise and can be off by more than a sample.
    A delay that is too long cannot be made up by the model (it would have to
    anticipate the input), and SRIVC then ends in unstable models whose
    costs say nothing about the direction to go; a delay that is too short
    is partly made up by slower poles, and the cost falls towards the true
    delay. So only models that are not markedly unstable (no pole growing
    faster than once over the record) are ranked, and while there are none
    the search moves to shorter delays.

    At each delay SRIVC starts from the best such model found so far (the
    dynamics barely change with a sample of delay, so few iterations are
    needed); while there is none, the default starts are tried too.
    """
    u, y, ts, n = criterion.u, criterion.y, criterion.ts, criterion.n
    d_max = int(np.floor(criterion.max_delay / ts + 1e-10))
    rate = 1.0 / (u.size * ts)
    d_arx = int(np.argmin(_arx_delay_losses(u, y, n, d_max, criterion.estimate_offset, criterion.cancel)))
    candidates, stable = [], []
    stable_cost = {}  # lowest cost of a stable model at each delay tried (inf: none)
    nit_total = 0

    def run(d: int) -> None:
        nonlocal nit_total
        best = min(stable or candidates, key=lambda c: c[1]) if candidates else None
        d_starts, d_names = [], []
        if best is not None:
            d_starts.append(("model", best[0][:-1]))
            d_names.append(f"the estimate at a delay of {round(best[0][-1] / ts)} samples")
        if not stable:
            d_starts += starts
            d_names += start_names
        fixed = _OutputError(u, y, ts, n, criterion.estimate_initial_state, criterion.estimate_offset,
                             criterion.cancel, input_delay=d * ts)
        found, nit = _srivc_candidates(fixed, m, d_starts, d_names, max_iter, tol)
        nit_total += nit
        found = [(np.r_[c[0], d * ts], c[1], c[2], f"{c[3]} (delay {d} samples)", c[4]) for c in found]
        candidates.extend(found)
        found_stable = [c for c in found if _is_stable(c[0], n, rate)]
        stable.extend(found_stable)
        stable_cost[d] = min((c[1] for c in found_stable), default=np.inf)

    for d in (d_arx, d_arx - 1, d_arx + 1):
        if 0 <= d <= d_max:
            run(d)
    while True:
        lo, hi = min(stable_cost), max(stable_cost)
        lowest = min(stable_cost, key=stable_cost.get)
        if not np.isfinite(stable_cost[lowest]):
            if lo == 0:
                break  # unstable at every delay down to 0: rank what there is by cost
            run(lo - 1)
        elif lowest == lo and lo > 0:
            run(lo - 1)
        elif lowest == hi and hi < d_max:
            run(hi + 1)
        else:
            break
    return candidates, nit_total


def _distinct(candidates, k: int, n: int, m: int, scale=_parameter_scale):
    """Up to ``k`` candidates (sorted by cost) whose coefficients differ by > 1 %.

    Relative to ``scale`` (default :func:`_parameter_scale`), whose floors keep
    a near-zero coefficient (an integrator's ``a_n``) from making two copies
    of the same model look distinct; with a delay in the parameters,
    :meth:`_OutputError.scale` counts it in samples, so candidates a sample
    apart are distinct.
    """
    chosen = []
    for cand in candidates:
        if all(np.max(np.abs(cand[0] - c[0]) / scale(c[0], n, m)) > 0.01
               for c in chosen):
            chosen.append(cand)
        if len(chosen) == k:
            break
    return chosen


def oe_fit(u, y, ts, num0, den0, *, initial_condition="zero", input_offset="zero",
           max_nfev=None, tol=1e-10, cancel: CancelToken | None = None) -> TFEstimate:
    """Plain output-error fit of a continuous-time transfer function from a start model.

    The same criterion, parameterisation and optimiser as the second stage of
    :func:`tfest` (so the two are comparable), without SRIVC. The orders are
    those of ``den0`` (poles) and ``num0`` (zeros, ``< n_poles``).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input (ZOH) and output samples.
    ts : float
        Sampling time in seconds.
    num0, den0 : array_like
        Start model, descending powers of s.
    initial_condition : {"zero", "estimate"}
    input_offset : {"zero", "estimate"}
        Estimate a constant input offset ``c`` (``y = G(s) (u + c)``), see
        :func:`tfest`.
    max_nfev : int, optional
        Maximum residual evaluations (default ``100 * n_params``).
    tol : float
        ``xtol``, ``ftol`` and ``gtol`` of ``least_squares``.
    cancel : eha_core.cancel.CancelToken, optional
        Checked at every simulation of the model (each output-error
        residual); raises :class:`~eha_core.cancel.Cancelled` when set.

    Returns
    -------
    TFEstimate
        With ``method == "oe"``, ``nit_srivc == 0`` and no SRIVC estimate.

    Examples
    --------
    >>> import numpy as np
    >>> ts = 0.05
    >>> u = np.sign(np.sin(0.7 * np.arange(400) * ts))
    >>> y = simulate_tf([3.0], [1.0, 1.5], u, ts)
    >>> est = oe_fit(u, y, ts, [1.0], [1.0, 1.0])
    >>> np.round(est.num, 6), np.round(est.den, 6), est.method
    (array([3.]), array([1. , 1.5]), 'oe')
    """
    num_n, den_n = as_tf(num0, den0, ("num0", "den0"))
    n = den_n.size - 1
    m = max(num_n.size - 1, 0)
    if n < 1:
        raise not_allowed("den0", np.asarray(den0, dtype=float),
                          "the start model needs at least 1 pole (den0 of degree >= 1)")
    if m > n - 1:
        raise not_allowed("num0", np.asarray(num0, dtype=float),
                          f"the start model must have fewer zeros than poles (strictly proper); "
                          f"num0 has {m} zeros and den0 {n} poles")
    n, m, u_arr, y_arr, ts_f, estimate_initial_state, estimate_offset, tol, max_nfev = _checked_problem(
        u, y, ts, n, m, initial_condition, input_offset, tol, max_nfev)
    theta0 = _model_coefficients((num_n, den_n), n, m, "num0/den0")
    criterion = _OutputError(u_arr, y_arr, ts_f, n, estimate_initial_state, estimate_offset, cancel)
    cost0 = criterion.cost(theta0)
    if not np.isfinite(cost0):
        return _nan_estimate(n, m, ts_f, u_arr.size, estimate_initial_state, estimate_offset,
                             "the start model cannot be simulated on this record", 0,
                             criterion.nfev)
    theta, cost, success, msg = _oe_refine(criterion, theta0, n, m, max_nfev, tol)
    if not np.isfinite(cost):
        theta = theta0
    return _estimate_result(criterion, theta, n, m, ts_f, success, f"output error: {msg}", "oe", 0,
                            None, np.nan)
