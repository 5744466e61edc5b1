"""Continuous-time transfer-function estimation from sampled data (like MATLAB ``tfest``).

Model (docs/model.md, section 4)::

    G(s) = (b_0 s^nz + ... + b_nz) / (s^np + a_1 s^(np-1) + ... + a_np),  nz < np

estimated from one input ``u`` and one output ``y`` sampled at ``ts``, the input
being held constant between samples (zero-order hold, MATLAB's default) or,
with ``intersample="foh"`` (MATLAB's ``InterSample``), linear between samples
(first-order hold: a smooth input sampled). Every simulation of the model,
in both stages, is exact for the one assumed (see item 4).

Two stages, as MATLAB does it, each in a module of its own:

1. **SRIVC** (:mod:`eha_core.identify._srivc`): the simplified refined
   instrumental variable method for continuous-time models (Young & Jakeman
   1980, Garnier & Young's CONTSID toolbox), with state-variable filters
   discretised exactly for the held input, from several starts (the user's
   ``init`` model, least-squares state-variable-filter estimates at a few
   cut-offs), optionally with an initial-condition polynomial and an input
   offset among the regressors.

2. **Output-error refinement** (:mod:`eha_core.identify._oe_refine`):
   minimise ``||y - y_hat(theta)||^2`` where ``y_hat`` is the exact
   simulation of the continuous-time model for the sampled input, with
   :func:`scipy.optimize.least_squares`; the initial state and the input
   offset, which enter the response linearly, are eliminated inside every
   evaluation (variable projection). The criterion, shared by both stages,
   is :class:`eha_core.identify._oe_criterion.OutputError`.

3. **Input delay** (``input_delay``, MATLAB's ``IODelay``): the model is
   ``y = G(s) e^(-s tau) (u + c)``, ``tau`` in seconds, not necessarily a
   multiple of ``ts``. The output-error simulation is exact for a held input
   delayed by ``tau = (d + f) ts`` (two input vectors, see
   :func:`eha_core.identify._ctmodels.discretise`), and SRIVC filters the
   delayed input exactly in the same way (the state-variable filter
   discretised for it), so a fixed delay changes neither stage's
   consistency. With ``input_delay="estimate"`` the whole-sample part is
   searched first (ARX losses as MATLAB's ``delayest``, then SRIVC around
   the best and, a few iterations per delay, over the whole range, from the
   default starts too at a few delays, since the cost can have several
   local minima over the delay; :mod:`eha_core.identify._delay_search`),
   and the output-error stage refines ``tau`` with the coefficients from
   the best models of the lowest few local minima: it joins the parameter
   vector (bounded to ``[0, max_delay]``); its standard error
   (``input_delay_std``) and the coefficients' covariance come from the
   joint Jacobian. The answer is checked: a noise variance markedly above
   that of a long linear model of the record (``noise_floor``, which fits
   any delay) sends the search round again with the default starts at every
   delay, and an answer still above it has ``success`` False, the message
   saying what to try (``optimizer_success`` keeps the optimiser's flag).

4. **Intersample behaviour** (``intersample``, MATLAB's ``InterSample``):
   the input held between samples (``"zoh"``) or linear between them
   (``"foh"``). A smooth input sampled is nearer the second; taking it as
   held shifts it by about half a sample and biases the coefficients (in
   the tests, ``b_0`` of ``10 / (s + 10)`` sampled at 0.04 s, white samples
   linear between them, comes out 17 % low, its 95 % interval never
   covering it; ``"foh"`` makes it unbiased, covered 39 times in 40). The
   assumption lives in the exact discretisation
   (:func:`eha_core.identify._ctmodels.discretise`, which the output-error
   criterion simulates with, the fraction of an input delay included), in
   SRIVC's filtering of the input (:class:`eha_core.identify._srivc.StateVariableFilter`)
   and in the lags of the delay search's ARX models; an input offset's step
   is held either way. ``"foh"`` takes the system at rest before the first
   sample, the input jumping to ``u[0]`` (and, delayed, at ``tau``), then
   linear from sample to sample.

Several SRIVC starts can converge to different models (the output-error
criterion may have several minima); the best ``n_refine`` distinct ones are
refined. The better of the two stages, by cost, is returned, and ``method``
says which. The reported ``initial_state`` and ``input_offset`` are the least-squares
ones for the returned coefficients; the result is a
:class:`~eha_core.identify.tfresult.TFEstimate` (re-exported here). This
module checks the arguments and runs the stages. Only numpy and scipy are
imported at module import; ``TFEstimate.tf`` imports python-control lazily.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._checks import not_allowed, positive_integer, positive_number
from ..cancel import CancelToken
from ._ctmodels import as_pair, as_tf, as_ts, check_delay, check_intersample
from ._ctmodels import fit_percent as fit_percent  # re-exported: the same fit as validate.compare's
from ._ctmodels import simulate_tf as simulate_tf  # re-exported: callers and the examples import it from here
from ._delay_search import above_floor, delay_candidates, noise_floor
from ._oe_criterion import OutputError, parameter_scale
from ._oe_refine import estimate_result, failed_estimate, oe_refine
from ._srivc import default_lambdas, srivc_candidates
from .tfresult import TFEstimate

__all__ = ["TFEstimate", "oe_fit", "tfest"]

_INITIAL_CONDITIONS = ("zero", "estimate")
_INPUT_OFFSETS = ("zero", "estimate")
#: Default upper bound of an estimated input delay, as a fraction of the record's duration.
MAX_DELAY_FRACTION = 0.1


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



# ---------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------
def tfest(u, y, ts, n_poles=3, n_zeros=0, *, initial_condition="zero", input_offset="zero",
          input_delay=0.0, max_delay=None, intersample="zoh", init=None, lambda_svf=None, refine=True,
          n_refine=2, max_iter=50, max_nfev=None, tol=1e-10, cancel: CancelToken | None = None) -> TFEstimate:
    """Estimate a continuous-time transfer function from sampled data (MATLAB ``tfest``).

    SRIVC (refined instrumental variables with state-variable filters) gives
    a consistent start; an output-error fit on the exact simulation (the
    input held or linear between samples, ``intersample``) refines it. See
    the module docstring for the algorithm.

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input (held constant or linear between samples, see ``intersample``)
        and output samples.
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
        ``[0, max_delay]`` (whole samples first, over the whole range, then
        the fraction with the coefficients from the lowest few local minima
        of the cost; see the module docstring). At most half the record.
        The result's ``input_delay`` (and ``input_delay_std`` when estimated)
        report it.
    max_delay : float, optional
        Upper bound (seconds) of an estimated delay; default a tenth of the
        record, ``0.1 N ts``. Only with ``input_delay="estimate"``.
    intersample : {"zoh", "foh"}
        The input between samples (MATLAB's ``InterSample``): ``"zoh"``
        (default) held from one sample to the next, as a digital
        controller's output; ``"foh"`` linear from one sample to the next, as
        a smooth signal sampled, the system at rest before the first sample.
        The estimate's :meth:`~TFEstimate.simulate` uses it too.
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
        refines (default 2); the lowest final cost is kept. With an estimated
        delay the best model at each of the lowest local minima of the cost
        over the whole-sample delays is refined too (up to three, those
        within twice the lowest cost). The SRIVC estimate of least cost is
        kept instead when no refinement ends below it.
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
        ``message``) when the estimation fails, or when an estimated delay's
        answer fits markedly worse than a long linear model of the record
        (the search may have ended in a local minimum; ``optimizer_success``
        is the optimiser's own flag); no exception is raised then.

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
    intersample = check_intersample(intersample)
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
        lambdas = default_lambdas(u_arr.size, ts_f)
    starts += [("lambda", lam) for lam in lambdas]
    start_names += [f"lambda = {lam:.4g} rad/s" for lam in lambdas]
    if estimate_delay:
        criterion = OutputError(u_arr, y_arr, ts_f, n, estimate_initial_state, estimate_offset, cancel,
                                 max_delay=max_delay_s, intersample=intersample)
        candidates, nit_total, basins = delay_candidates(criterion, m, starts, start_names, max_iter, tol)
    else:
        basins = []
        criterion = OutputError(u_arr, y_arr, ts_f, n, estimate_initial_state, estimate_offset, cancel,
                                 input_delay=fixed_delay, intersample=intersample)
        # two starts at one minimum: the others would find it again (the refinement polishes it)
        candidates, nit_total = srivc_candidates(criterion, m, starts, start_names, max_iter, tol, until_agreed=2)
    if not candidates:
        return failed_estimate(
            n, m, ts_f, u_arr.size, estimate_initial_state, estimate_offset,
            "SRIVC failed from every start (singular instrument matrix or unstable "
            "simulation): is the input exciting enough?", nit_total, 0,
            None if estimate_delay else fixed_delay, intersample,
        )
    criterion.nfev = 0
    result = _estimate_from(criterion, candidates, basins, n, m, ts_f, refine, n_refine, max_nfev, tol, nit_total)
    result = replace(result, optimizer_success=result.success)
    if not estimate_delay:
        return result
    floor, lags = noise_floor(u_arr, y_arr, n, int(np.floor(max_delay_s / ts_f + 1e-10)), estimate_offset)
    if above_floor(result.noise_variance, floor, y_arr):
        # the answer may be a local minimum: search again with the default starts at every delay swept
        wider, nit_wider, wider_basins = delay_candidates(criterion, m, starts, start_names, max_iter, tol,
                                                          everywhere=True)
        nit_total += nit_wider
        again = _estimate_from(criterion, wider, wider_basins, n, m, ts_f, refine, n_refine, max_nfev, tol,
                               nit_total) if wider else result
        if again.cost < result.cost:
            result = replace(again, optimizer_success=again.success,
                             message=again.message + "; found by a second search with the default starts at "
                                                     "every delay, the first one's variance being above the floor")
        else:
            result = replace(result, nit_srivc=nit_total, nfev_oe=criterion.nfev)
    return _checked_against_floor(result, floor, lags, ts_f, y_arr)


def _estimate_from(criterion, candidates, basins, n, m, ts_f, refine, n_refine, max_nfev, tol, nit_total):
    """The estimate from SRIVC's candidates: the best few (and the delay search's ``basins``) refined.

    Several SRIVC starts can converge to different models (the output-error
    criterion may have several minima, e.g. a slow drift of a nonlinear
    plant mimicked by a slow pole, versus the plant's resonance): the best
    ``n_refine`` distinct candidates are refined, and the lowest cost kept.
    ``success`` is the kept stage's own flag.
    """
    candidates = sorted(candidates, key=lambda c: c[1])
    best = candidates[0]
    srivc_theta, srivc_cost, srivc_converged, start_name, srivc_nit = best
    srivc_msg = (f"SRIVC {'converged' if srivc_converged else 'did not converge'} in "
                 f"{srivc_nit} iterations from {start_name}")
    if not refine:
        return estimate_result(criterion, srivc_theta, n, m, ts_f, srivc_converged,
                                srivc_msg + "; output-error refinement skipped", "srivc",
                                nit_total, srivc_theta, srivc_cost)
    refined = []
    to_refine = _distinct(candidates, n_refine, n, m, criterion.scale)
    # an estimated delay: the best model at each of the lowest local minima of
    # the cost over the delay too (the cost may be lower in another one)
    to_refine += [b for b in basins if all(b is not c for c in to_refine)]
    for cand in to_refine:
        theta_oe, cost_oe, oe_success, oe_msg = oe_refine(criterion, cand[0], n, m, max_nfev, tol)
        refined.append((cost_oe, theta_oe, oe_success, oe_msg, cand))
    refined = [r for r in refined if np.isfinite(r[0])]
    if refined:
        cost_oe, theta_oe, oe_success, oe_msg, cand = min(refined, key=lambda r: r[0])
        if cost_oe <= srivc_cost:
            if cand is not best:
                srivc_msg += f"; the output error was lowest from the SRIVC start {cand[3]}"
            return estimate_result(criterion, theta_oe, n, m, ts_f, oe_success,
                                    f"{srivc_msg}; output error: {oe_msg}; kept the output-error estimate "
                                    f"(cost {cost_oe:.4g} <= SRIVC {srivc_cost:.4g})",
                                    "srivc+oe", nit_total, srivc_theta, srivc_cost)
        oe_msg_last = oe_msg
    else:
        cost_oe, oe_msg_last = float("nan"), "no finite output-error cost"
    return estimate_result(criterion, srivc_theta, n, m, ts_f, srivc_converged,
                            f"{srivc_msg}; output error: {oe_msg_last}; kept the SRIVC estimate "
                            f"(cost {srivc_cost:.4g} < output error {cost_oe:.4g})",
                            "srivc", nit_total, srivc_theta, srivc_cost)


def _checked_against_floor(result: TFEstimate, floor: float, lags: int, ts: float, y: np.ndarray) -> TFEstimate:
    """``result`` with its ``noise_floor``, and not a success when its noise variance is far above it.

    An estimated delay's result is compared with :func:`~eha_core.identify._delay_search.noise_floor`,
    the residual variance of a long linear model of the record that fits any
    delay within its lags: a noise variance well above it
    (:func:`~eha_core.identify._delay_search.above_floor`) says the delay
    search (even the second, wider one) ended in a local minimum, or the
    model lacks poles or zeros.
    """
    result = replace(result, noise_floor=floor)
    if not above_floor(result.noise_variance, floor, y):
        return result
    ratio = result.noise_variance / floor
    return replace(result, success=False, message=(
        f"{result.message}; the optimum may be local: the residual variance {result.noise_variance:.4g} is "
        f"{ratio:.3g} times that of a long linear model of the record ({lags} input lags, any delay up to "
        f"{lags * ts:.4g} s: "
        f"{floor:.4g}), so the delay search may have ended in a local minimum (here {result.input_delay:.4g} s) "
        f"or the model needs more poles or zeros; try a longer record or a richer input, a max_delay that "
        f"bounds the delay you expect, the delay fixed (input_delay in s) if you know it, or more poles or zeros"))


def _distinct(candidates, k: int, n: int, m: int, scale=parameter_scale):
    """Up to ``k`` candidates (sorted by cost) whose coefficients differ by > 1 %.

    Relative to ``scale`` (default :func:`parameter_scale`), whose floors keep
    a near-zero coefficient (an integrator's ``a_n``) from making two copies
    of the same model look distinct; with a delay in the parameters,
    :meth:`OutputError.scale` counts it in samples, so candidates a sample
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


def oe_fit(u, y, ts, num0, den0, *, initial_condition="zero", input_offset="zero", intersample="zoh",
           max_nfev=None, tol=1e-10, cancel: CancelToken | None = None) -> TFEstimate:
    """Plain output-error fit of a continuous-time transfer function from a start model.

    The same criterion, parameterisation and optimiser as the second stage of
    :func:`tfest` (so the two are comparable), without SRIVC. The orders are
    those of ``den0`` (poles) and ``num0`` (zeros, ``< n_poles``).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input (held or linear between samples, ``intersample``) and output samples.
    ts : float
        Sampling time in seconds.
    num0, den0 : array_like
        Start model, descending powers of s.
    initial_condition : {"zero", "estimate"}
        Start at rest, or estimate the initial state with the coefficients, see :func:`tfest`.
    input_offset : {"zero", "estimate"}
        Estimate a constant input offset ``c`` (``y = G(s) (u + c)``), see
        :func:`tfest`.
    intersample : {"zoh", "foh"}
        The input held (default) or linear between samples, see :func:`tfest`.
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
    intersample = check_intersample(intersample)
    theta0 = _model_coefficients((num_n, den_n), n, m, "num0/den0")
    criterion = OutputError(u_arr, y_arr, ts_f, n, estimate_initial_state, estimate_offset, cancel,
                            intersample=intersample)
    cost0 = criterion.cost(theta0)
    if not np.isfinite(cost0):
        return failed_estimate(n, m, ts_f, u_arr.size, estimate_initial_state, estimate_offset,
                             "the start model cannot be simulated on this record", 0,
                             criterion.nfev, intersample=intersample)
    theta, cost, success, msg = oe_refine(criterion, theta0, n, m, max_nfev, tol)
    if not np.isfinite(cost):
        theta = theta0
    return estimate_result(criterion, theta, n, m, ts_f, success, f"output error: {msg}", "oe", 0,
                            None, np.nan)
