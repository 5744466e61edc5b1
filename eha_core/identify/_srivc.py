"""Stage 1 of :func:`eha_core.identify.tfest.tfest`: SRIVC iterations from several starts.

SRIVC, the simplified refined instrumental variable method for
continuous-time models (Young & Jakeman 1980, Garnier & Young's CONTSID
toolbox). The model equation ``A(s) y = B(s) u`` is prefiltered by
``1/A_hat(s)``, which turns the unknown time derivatives into the states of
a stable filter: ``y_f^(k) = s^k / A_hat(s) y``, ``k = 0..np``. The filtered
equation ``y_f^(np) = -a_1 y_f^(np-1) - ... + b_0 u_f^(nz) + ...`` is linear in
the coefficients and is solved with instruments built from the noise-free
output of the auxiliary model ``x_hat = B_hat/A_hat u``; ``A_hat`` is updated
and the whole repeated until the coefficients stop changing.

- ``u`` is filtered *exactly*: the filter discretised for the input's
  intersample behaviour, held between samples (ZOH, ``intersample="zoh"``)
  or linear between them (``"foh"``, :func:`eha_core.identify._ctmodels.foh_numerators`);
- ``y`` and ``x_hat`` are not piecewise constant: they are filtered with the
  first-order-hold (triangle-hold) discretisation, i.e. assuming linear
  interpolation between samples. At the fixed point (``A_hat = A``) the
  filter cancels ``A``, so noiseless data give the exact model whatever the
  interpolation; with noise the approximation costs a little accuracy,
  which the output-error stage (:mod:`eha_core.identify._oe_refine`) recovers.
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
- With a fixed input delay ``tau`` the state-variable filter is discretised
  for the delayed held input, exactly, so the delay does not cost SRIVC its
  consistency.
- The IV equations are solved through a QR factorisation of the
  instruments, which avoids squaring the conditioning.
- Start: the user's ``init`` model, or a least-squares state-variable-filter
  (LSSVF) estimate with the filter ``(s + lambda)^np``; without
  ``lambda_svf`` four cut-offs, log-spaced from ``pi / (2 ts)`` down to
  ``max(4 * 2 pi / (N ts), pi / (200 ts))`` (:func:`default_lambdas`), are
  tried. Every iterate is ranked by the output-error cost of
  :class:`eha_core.identify._oe_criterion.OutputError` and the best kept.

Private as a module: its names are used by :mod:`eha_core.identify.tfest`
and :mod:`eha_core.identify._delay_search`. Only numpy and scipy are
imported here.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from ..cancel import check
from ._ctmodels import delayed, expm_balanced, foh_numerators, split_delay, state_numerators, zoh_matrices
from ._oe_criterion import OutputError, split_theta

__all__ = [
    "StateVariableFilter",
    "default_lambdas",
    "iv_solve",
    "offset_regressor",
    "regressors",
    "srivc",
    "srivc_candidates",
    "stabilise",
]


def stabilise(den: np.ndarray) -> np.ndarray:
    """Reflect right-half-plane roots of a monic polynomial into the left half."""
    roots = np.roots(den)
    if np.all(roots.real < 0):
        return den
    roots = np.where(roots.real > 0, -roots.real + 1j * roots.imag, roots)
    return np.real(np.poly(roots))


class StateVariableFilter:
    """``s^k / A_f(s)``, ``k = 0..n``, discretised for ZOH and FOH inputs.

    ``apply(signals, "zoh")`` filters held signals (the input, an offset's
    step) exactly, delayed by ``input_delay``; ``apply(signals, "foh")``
    filters the output and the auxiliary model's output as linear between
    samples, undelayed. With ``intersample="foh"`` the input is linear
    between samples: :meth:`apply_inputs` filters it exactly for that,
    delayed (``"input"``), and the offset's step still as held.

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

    def __init__(self, den_f: np.ndarray, ts: float, input_delay: float = 0.0, intersample: str = "zoh"):
        n = den_f.size - 1
        self.den_f = den_f
        self.intersample = intersample
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
        if intersample == "foh":
            # the input linear between samples, delayed, from rest (foh_numerators)
            self.num_input, self.start_input = foh_numerators(a_mat, ident[:, -1], ident, np.zeros(n), ts,
                                                              self.delay_fraction, ad, g1, g2, self.den_z)
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

    def apply_inputs(self, u: np.ndarray, offset: bool) -> np.ndarray:
        """The input (and a unit step for an offset) filtered, shape ``(N, 1 or 2, n + 1)``."""
        if self.intersample == "zoh":
            # u, plus a unit step when the offset is estimated: both piecewise constant
            inputs = np.column_stack([u, np.ones_like(u)]) if offset else u[:, None]
            return self.apply(inputs, "zoh")
        filtered = [self.apply(u[:, None], "input")]
        if offset:  # a step is held between samples whatever the input is
            filtered.append(self.apply(np.ones((u.size, 1)), "zoh"))
        return np.concatenate(filtered, axis=1)

    def apply(self, signals: np.ndarray, hold: str) -> np.ndarray:
        """Filtered derivatives, shape ``(N, n_signals, n + 1)``: ``[..., k] = s^k/A_f x``.

        ``hold``: ``"zoh"`` (held signals) and ``"input"`` (an input linear
        between samples, with ``intersample="foh"``) are delayed by the
        filter's ``input_delay``; ``"foh"`` (the outputs) is not.
        """
        if hold == "input":
            return self._apply_linear_input(signals)
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


    def _apply_linear_input(self, signals: np.ndarray) -> np.ndarray:
        """:meth:`apply` for an input linear between samples, exact, delayed by ``(d + f) ts``.

        The ramp up to the first sample that the filter implies before the
        start is taken off (:func:`eha_core.identify._ctmodels.foh_numerators`).
        """
        n = self.num_input.shape[0]
        d, f = self.delay_samples, self.delay_fraction
        shifted = delayed(signals, d)
        impulse = np.zeros(signals.shape[0])
        impulse[0] = 1.0
        out = np.empty(signals.shape + (n + 1,))
        for k in range(n):
            start = delayed(scipy.signal.lfilter(self.start_input[k], self.den_z, impulse), d)
            out[..., k] = (scipy.signal.lfilter(self.num_input[k], self.den_z, shifted, axis=0)
                           - np.multiply.outer(start, signals[0]))
        # the top derivative's input term: the delayed input at the sample
        # instant, f u[k-d-1] + (1 - f) u[k-d], zero before tau
        top = shifted
        if f:
            top = f * delayed(signals, d + 1) + (1.0 - f) * shifted
            if d < signals.shape[0]:
                top[d] -= (1.0 - f) * signals[0]
        out[..., n] = top - out[..., :n] @ self.den_f[:0:-1]
        return out


def iv_solve(phi: np.ndarray, zeta: np.ndarray, target: np.ndarray):
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


def regressors(yf: np.ndarray, uf: np.ndarray, n: int, m: int) -> np.ndarray:
    """``[-y_f^(n-1), ..., -y_f, u_f^(m), ..., u_f]`` (matches ``theta``)."""
    return np.hstack([-yf[:, n - 1::-1], uf[:, m::-1]])


def offset_regressor(sf: np.ndarray, num: np.ndarray | None, m: int, ic: bool) -> np.ndarray:
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


def srivc(u, y, ts, n, m, start, max_iter, tol, criterion):
    """SRIVC iterations from ``start`` = ("lambda", value) or ("model", theta).

    With ``criterion.estimate_initial_state`` the ``n`` initial-condition regressors of
    :meth:`StateVariableFilter.impulse_responses` join the regression (they
    are noise-free, so they are their own instruments) and the auxiliary model
    includes the estimated initial-condition response.

    With ``criterion.estimate_offset`` the model is ``A(s) y = B(s) (u + c)``:
    for a constant ``c`` the derivatives vanish, leaving ``b_nz c`` times a
    step, which is linear in ``d = b_nz c``. Its filtered regressor (see
    :func:`offset_regressor`) is exact (a step is piecewise constant, so the
    ZOH discretisation of the filter is exact) and noise-free, so it is its own
    instrument; the auxiliary model includes ``d`` times it. ``c = d / b_nz``
    itself is not needed here: the output-error criterion that ranks the
    iterates eliminates it by least squares.

    With ``criterion.input_delay`` (fixed) the inputs are filtered delayed
    (:class:`StateVariableFilter`), held or linear between samples as
    ``criterion.intersample`` says (the offset's step is held either way). The offset's regressor is then the
    delayed step through ``B_hat`` (:func:`offset_regressor` without initial
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
    intersample = criterion.intersample

    def extra_regressors(svf, uf_all, num):
        cols = []
        if oc:
            cols.append(offset_regressor(uf_all[:, 1], num, m, ic and tau == 0.0)[:, None])
        if ic:
            cols.append(svf.impulse_responses(u.size))
        return np.hstack(cols) if cols else np.zeros((u.size, 0))

    if kind == "lambda":
        # LSSVF: least squares with the fixed filter (s + lambda)^n.
        den_f = np.real(np.poly(np.full(n, -value)))
        svf = StateVariableFilter(den_f, ts, tau, intersample)
        uf_all = svf.apply_inputs(u, oc)
        yf = svf.apply(y, "foh")
        phi = np.hstack([regressors(yf, uf_all[:, 0], n, m),
                         extra_regressors(svf, uf_all, None)])
        theta, _ = iv_solve(phi, phi, yf[:, n])
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
        num, den = split_theta(theta, n)
        den_f = stabilise(den)
        svf = StateVariableFilter(den_f, ts, tau, intersample)
        uf_all = svf.apply_inputs(u, oc)
        uf = uf_all[:, 0]
        extra = extra_regressors(svf, uf_all, num)
        # auxiliary model B/A_f u (+ offset and initial-condition responses),
        # exact for the input's intersample behaviour
        x_hat = uf[:, m::-1] @ num + extra @ extra_coeffs
        yxf = svf.apply(np.column_stack([y, x_hat]), "foh")
        phi = np.hstack([regressors(yxf[:, 0], uf, n, m), extra])
        zeta = np.hstack([regressors(yxf[:, 1], uf, n, m), extra])
        theta_new, scale = iv_solve(phi, zeta, yxf[:, 0, n])
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


def default_lambdas(n_samples: int, ts: float) -> np.ndarray:
    """Filter cut-offs spread log-uniformly between the record and Nyquist."""
    w_low = 2.0 * np.pi / (n_samples * ts)
    w_nyq = np.pi / ts
    return np.geomspace(w_nyq / 2.0, max(4.0 * w_low, w_nyq / 200.0), 4)


#: Two converged starts whose costs agree this closely (relative) found the same minimum.
AGREE_COST = 1e-6


def srivc_candidates(criterion: OutputError, m: int, starts, start_names, max_iter: int, tol: float, *,
                     until_agreed: int | None = None):
    """SRIVC from every start at the criterion's fixed delay: ``(candidates, iterations)``.

    A candidate is ``(theta, cost, converged, start name, iterations)``; starts
    that fail or end with an infinite cost give none. ``until_agreed``: stop once
    that many converged starts reached the lowest cost so far (within
    :data:`AGREE_COST`): the starts left would only find the same minimum again
    (on the actuator's records all five default starts end within 5e-7 of each
    other's cost, from 13-20 iterations each); None tries every start.
    """
    u, y, ts, n = criterion.u, criterion.y, criterion.ts, criterion.n
    candidates = []
    nit_total = 0
    for name, start in zip(start_names, starts, strict=True):
        try:
            theta, cost, nit, converged = srivc(u, y, ts, n, m, start, max_iter, tol, criterion)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            continue
        nit_total += nit
        if np.isfinite(cost):
            candidates.append((theta, cost, converged, name, nit))
        if until_agreed is not None and _agreed(candidates) >= until_agreed:
            break
    return candidates, nit_total


def _agreed(candidates) -> int:
    """How many converged candidates end at the lowest cost of them all (within :data:`AGREE_COST`)."""
    costs = [c[1] for c in candidates if c[2]]
    if not costs:
        return 0
    best = min(costs)
    return sum(1 for c in costs if c - best <= AGREE_COST * max(abs(best), 1e-300))
