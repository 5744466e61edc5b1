"""Continuous-time transfer functions on sampled data: the machinery shared by
:mod:`eha_core.identify.validate` and :mod:`eha_core.identify.tfest`.

Private as a module (like scipy.signal's ``_lti_conversion``): its names are
used by those two modules, and the public ones are re-exported by
:mod:`eha_core.identify.validate`. It holds

* argument handling: samples (:func:`as_samples`, :func:`as_pair`), the
  sample time (:func:`as_ts`), a transfer function normalised to a monic
  denominator (:func:`as_tf`); every refusal reads ``NAME = VALUE is not allowed: WHAT``
  (:func:`eha_core._checks.not_allowed`);
* the observability canonical form of ``num(s) / den(s)`` from its Markov
  parameters (:func:`markov_parameters`, :func:`observability_form`; Kailath,
  *Linear Systems*, Prentice-Hall 1980, ch. 2); the state convention it
  fixes for initial states is described in :mod:`eha_core.identify.validate`;
* the exact zero-order-hold (ZOH) discretisation: the exponential of the
  augmented matrix ``[[A ts, B ts], [0, 0]]`` gives ``(Ad, Bd)`` at once
  (Van Loan, "Computing integrals involving the matrix exponential", IEEE
  Trans. Automat. Control 23, 1978; the method of
  ``scipy.signal.cont2discrete(method='zoh')``), computed by
  :func:`expm_balanced`: diagonal balancing (Parlett & Reinsch 1969, LAPACK's
  ``gebal``) and the scaling-and-squaring [13/13] Pade approximant (Higham,
  SIAM J. Matrix Anal. Appl. 26, 2005, the algorithm of
  ``scipy.linalg.expm``); then the discrete transfer function
  ``num_z / den_z`` (:func:`state_numerators`, :class:`DiscreteModel`,
  :func:`discretise`) and the exact ZOH simulation :func:`simulate_tf`;
* an input delay ``tau = (d + f) ts`` (``d`` whole samples, ``0 <= f < 1``,
  :func:`split_delay`), which need not be a multiple of ``ts``: a held
  input delayed by a fraction of a sample switches inside a sample
  interval, so the discretisation has two input vectors,
  ``Gamma0 = int_0^((1-f) ts) e^(A s) ds B`` applied to ``u[k-d]`` and
  ``Gamma1 = e^(A (1-f) ts) int_0^(f ts) e^(A s) ds B`` applied to
  ``u[k-d-1]`` (Franklin, Powell & Workman, *Digital Control of Dynamic
  Systems*, 3rd ed., 1998, sec. 4.3.4); exact, like the delay-free case;
* the exact first-order-hold (FOH) discretisation, for an input linear
  between samples (MATLAB's ``InterSample = 'foh'``; ``intersample="foh"``
  of :func:`discretise` and :func:`simulate_tf`): the exponential of
  ``[[A ts, B ts, 0], [0, 0, 1], [0, 0, 0]]`` gives the held and the ramp
  input matrices (:func:`foh_matrices`, as
  ``scipy.signal.cont2discrete(method='foh')``), the delayed input's knot
  inside the interval splits it in two (:func:`foh_numerators`), and the
  ramp up to the first sample that the discrete filter implies is taken
  off, so the system starts at rest;
* the terms that enter the simulated output linearly, the response to a
  constant input offset and the free response to the initial state
  (:func:`linear_columns`), and their least-squares fit
  (:func:`fit_linear_terms`), which the output-error criterion of
  :mod:`eha_core.identify.tfest` (:mod:`eha_core.identify._oe_criterion`) uses to eliminate them (variable projection:
  Golub & Pereyra, SIAM J. Numer. Anal. 10, 1973);
* MATLAB ``compare``'s fit (:func:`fit_percent`) and the frequency response
  ``G(j w) e^(-j w tau)`` (:func:`frequency_response`, :class:`FrequencyResponseData`).

Only numpy and scipy are imported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

from .._checks import not_allowed, positive_number

__all__ = [
    "DiscreteModel",
    "FrequencyResponseData",
    "INTERSAMPLE",
    "PADE13",
    "as_pair",
    "as_samples",
    "as_tf",
    "as_ts",
    "check_delay",
    "check_intersample",
    "delayed",
    "discretise",
    "expm_balanced",
    "expm_pade13",
    "fit_linear_terms",
    "fit_percent",
    "foh_matrices",
    "foh_numerators",
    "frequency_response",
    "linear_columns",
    "markov_parameters",
    "observability_form",
    "readonly",
    "simulate_tf",
    "split_delay",
    "state_numerators",
    "zoh_matrices",
]


# ---------------------------------------------------------------------------
# arguments
# ---------------------------------------------------------------------------
def readonly(array) -> np.ndarray:
    """A read-only float/complex copy, so frozen results stay frozen."""
    out = np.array(array, copy=True)
    out.setflags(write=False)
    return out


def as_samples(values, name: str, *, allow_2d: bool = False) -> np.ndarray:
    """``values`` as a finite real 1-D (or, with ``allow_2d``, 2-D) float array.

    ``name`` is the argument's name in the messages of the ValueError raised
    for anything else.
    """
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise not_allowed(name, values, "must be an array of numbers (one sample per row)") from None
    if arr.ndim == 0:
        raise not_allowed(name, values, "must be an array of samples, not a single number")
    if arr.ndim > (2 if allow_2d else 1):
        allowed = "1-D or 2-D (one row per sample)" if allow_2d else "1-D (one value per sample)"
        raise not_allowed(name, f"an array of shape {arr.shape}", f"must be {allowed}")
    if arr.shape[0] == 0:
        raise not_allowed(name, arr, "must hold at least one sample")
    finite = np.isfinite(arr)
    if not np.all(finite):
        where = tuple(int(i) for i in np.argwhere(~finite)[0])
        index = ", ".join(str(i) for i in where)
        raise not_allowed(name, arr, f"{name}[{index}] is {arr[where]:g}; "
                                            "every sample must be a finite number")
    return arr


def as_pair(first, second, names: tuple[str, str] = ("u", "y")) -> tuple[np.ndarray, np.ndarray]:
    """Two 1-D sample arrays of the same length (an input and its output, say).

    A length mismatch is reported against the second, ``names[1]``.
    """
    a = as_samples(first, names[0])
    b = as_samples(second, names[1])
    if a.shape != b.shape:
        raise not_allowed(names[1], b, f"it has {b.size} samples where {names[0]} has {a.size}; "
                                              "need one sample of each per instant")
    return a, b


def as_ts(ts) -> float:
    """The sample time in seconds, a finite number > 0."""
    return positive_number("ts", ts, "must be a finite sample time > 0 s")


def check_delay(value, name: str = "input_delay") -> float:
    """An input delay in seconds: a finite number >= 0 (not a bool)."""
    allowed = "must be a finite delay >= 0 s"
    if isinstance(value, (bool, np.bool_)) or isinstance(value, str):
        raise not_allowed(name, value, allowed)
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise not_allowed(name, value, allowed) from None
    if not (np.isfinite(out) and out >= 0.0):
        raise not_allowed(name, value, allowed)
    return out


#: The input's behaviour between samples (MATLAB's ``InterSample``): held, or linear.
INTERSAMPLE = ("zoh", "foh")


def check_intersample(value, name: str = "intersample") -> str:
    """``"zoh"`` (the input held between samples) or ``"foh"`` (linear between them)."""
    if not isinstance(value, str) or value not in INTERSAMPLE:
        raise not_allowed(name, value, "use zoh (held between samples) or foh (linear between samples)")
    return value


def _coefficients(value, name: str) -> np.ndarray:
    """A polynomial's coefficients as a finite 1-D float array."""
    allowed = "must be a 1-D sequence of finite coefficients in descending powers of s"
    try:
        arr = np.atleast_1d(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        raise not_allowed(name, value, allowed) from None
    if arr.ndim != 1:
        raise not_allowed(name, f"an array of shape {arr.shape}", allowed)
    if not np.all(np.isfinite(arr)):
        raise not_allowed(name, arr, allowed)
    return arr


def as_tf(num, den, names: tuple[str, str] = ("num", "den")) -> tuple[np.ndarray, np.ndarray]:
    """Validate and normalise a transfer function: monic ``den``, proper ``num``.

    Leading zeros are stripped from both polynomials (as python-control does).
    ``names`` are the arguments' names in the messages (``("num0", "den0")``
    for a start model, say).
    """
    num_name, den_name = names
    num_arr = _coefficients(num, num_name)
    den_arr = _coefficients(den, den_name)
    nonzero = np.flatnonzero(den_arr)
    if nonzero.size == 0:
        raise not_allowed(den_name, den_arr, "the denominator needs a non-zero coefficient")
    den_arr = den_arr[nonzero[0]:]
    nonzero = np.flatnonzero(num_arr)
    num_arr = num_arr[nonzero[0]:] if nonzero.size else np.zeros(1)
    if num_arr.size > den_arr.size:
        raise not_allowed(
            num_name, num_arr,
            f"its degree {num_arr.size - 1} exceeds the degree {den_arr.size - 1} of {den_name}: the transfer "
            f"function must be proper (degree of {num_name} <= degree of {den_name})",
        )
    lead = den_arr[0]
    return num_arr / lead, den_arr / lead


# ---------------------------------------------------------------------------
# observability canonical form
# ---------------------------------------------------------------------------
def markov_parameters(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``h_0..h_n`` of ``num/den = sum h_k s^-k`` (den monic, num padded)."""
    n = den.size - 1
    b = np.zeros(n + 1)
    b[n + 1 - num.size:] = num
    h = np.zeros(n + 1)
    for k in range(n + 1):
        h[k] = b[k] - np.dot(den[1:k + 1], h[k - 1::-1][:k]) if k else b[0]
    return h


def observability_form(num: np.ndarray, den: np.ndarray):
    """(A, B, C, D) of the observability canonical form.

    ``x_1 = y - h_0 u``, ``x_{i+1} = x_i' - h_i u`` with the Markov parameters
    ``h_k`` (see :mod:`eha_core.identify.validate` for the state convention).
    """
    n = den.size - 1
    h = markov_parameters(num, den)
    a_mat = np.eye(n, k=1)
    a_mat[-1, :] = -den[:0:-1]  # last row: -a_n, ..., -a_1
    b_vec = h[1:].copy()
    c_vec = np.zeros(n)
    c_vec[0] = 1.0
    return a_mat, b_vec, c_vec, float(h[0])


# ---------------------------------------------------------------------------
# matrix exponential
# ---------------------------------------------------------------------------
def expm_balanced(m: np.ndarray) -> np.ndarray:
    """``expm(m)`` after diagonal balancing.

    Companion matrices of physical models have coefficients spanning many
    orders of magnitude (1, 430.1, 1.721e4, 2437); balancing by a diagonal
    similarity keeps the exponential accurate.
    """
    balanced, t = scipy.linalg.matrix_balance(m, permute=False, separate=True)
    scale = t[0]
    e = expm_pade13(balanced)
    return e * scale[:, None] / scale[None, :]


#: Coefficients ``b_0 .. b_13`` of the [13/13] Pade approximant of exp (Higham 2005).
PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
          1187353796428800.0, 129060195264000.0, 10559470521600.0,
          670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0,
          16380.0, 182.0, 1.0)


def expm_pade13(m: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with the [13/13] Pade
    approximant (Higham 2005, the algorithm behind ``scipy.linalg.expm``).

    Written out with numpy because ``scipy.linalg.expm`` costs 0.5-5 ms per
    call on tiny matrices (BLAS threading overhead) and the estimators call
    it hundreds of times; this takes tens of microseconds for a 5 x 5 matrix.
    """
    b = PADE13
    norm = np.linalg.norm(m, 1)
    squarings = max(0, int(np.ceil(np.log2(norm / 5.371920351148152)))) if norm > 0 else 0
    a = m / 2.0**squarings
    ident = np.eye(m.shape[0])
    a2 = a @ a
    a4 = a2 @ a2
    a6 = a4 @ a2
    u = a @ (a6 @ (b[13] * a6 + b[11] * a4 + b[9] * a2)
             + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * ident)
    v = (a6 @ (b[12] * a6 + b[10] * a4 + b[8] * a2)
         + b[6] * a6 + b[4] * a4 + b[2] * a2 + b[0] * ident)
    r = np.linalg.solve(v - u, v + u)
    for _ in range(squarings):
        r = r @ r
    return r


# ---------------------------------------------------------------------------
# exact ZOH discretisation and simulation
# ---------------------------------------------------------------------------
def zoh_matrices(a_mat: np.ndarray, b_vec: np.ndarray, ts: float):
    """Exact ZOH discretisation ``(Ad, Bd)`` via the augmented exponential (Van Loan 1978)."""
    n = a_mat.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n] = a_mat * ts
    m[:n, n] = b_vec * ts
    e = expm_balanced(m)
    return e[:n, :n], e[:n, n]


def foh_matrices(a_mat: np.ndarray, b_vec: np.ndarray, h: float):
    """``(e^(A h), Gamma(h), R(h))`` over an interval of length ``h``, from one exponential.

    ``Gamma(h) = int_0^h e^(A s) ds B`` is the response of the state to a
    unit input held over the interval, ``h R(h) = int_0^h e^(A (h - s)) s ds B``
    the response to a unit ramp (slope 1 per second): the exponential of
    ``[[A h, B h, 0], [0, 0, 1], [0, 0, 0]]`` holds ``e^(A h)``, ``Gamma(h)``
    and ``R(h)`` (``scipy.signal.cont2discrete``'s ``foh``, whose ``gamma2`` is
    ``R(ts)``).
    """
    n = a_mat.shape[0]
    block = np.zeros((n + 2, n + 2))
    block[:n, :n] = a_mat * h
    block[:n, n] = b_vec * h
    block[n, n + 1] = 1.0
    e = expm_balanced(block)
    return e[:n, :n], e[:n, n], e[:n, n + 1]


def foh_numerators(a_mat, b_vec, c_mat, d_vec, ts, frac, ad, gamma, ramp, den_z):
    """Exact discretisation for an input linear between samples, delayed by ``(d + frac) ts``.

    ``ad, gamma, ramp`` are :func:`foh_matrices` over ``ts`` and ``den_z`` the
    characteristic polynomial of ``ad``. Returns ``(num, start)``, rows per
    row of ``c_mat``, numerators over ``den_z`` in powers of ``z^-1``, both
    acting from ``d`` samples on:

    * ``num`` (``n + 1`` columns, ``n + 2`` with a fraction): the response to
      ``u`` linearly interpolated between its samples, the samples before the
      first taken as zero. Over a sample interval the delayed input is one
      linear piece (two with a fraction, which puts the knot ``frac ts`` into
      the interval), so ``x[k+1] = Ad x[k] + p_lead u[k-d+1] + p_mid u[k-d]
      + p_lag u[k-d-1]`` (``p_lag = 0`` without a fraction; ``u[k-d+1]``, one
      sample ahead, because the piece ends there), and the output adds
      ``D`` times the delayed input at the sample instant.
    * ``start``: that interpolation ramps up from zero to ``u[0]`` over the
      sample interval before the input starts; the record starts instead at
      rest, the input jumping to ``u[0]`` at ``tau`` (as a held input does,
      and as ``scipy.signal.lsim`` simulates a linearly interpolated input).
      The response is exact when ``u[0]`` times the impulse response of
      ``start`` (delayed by ``d``), the response to that ramp, is subtracted.
    """
    n = ad.shape[0]
    if frac == 0.0:
        num = state_numerators(ad, gamma - ramp + ad @ ramp, den_z, c_mat, d_vec + c_mat @ ramp)
        return num, state_numerators(ad, ad @ ramp, den_z, c_mat, c_mat @ ramp)
    # the interval [k ts, (k+1) ts) in two pieces, of frac ts and (1 - frac) ts
    _, gamma_a, ramp_a = foh_matrices(a_mat, b_vec, frac * ts)
    e_b, gamma_b, ramp_b = foh_matrices(a_mat, b_vec, (1.0 - frac) * ts)
    p_lag = frac * e_b @ (gamma_a - ramp_a)
    p_mid = e_b @ ((1.0 - frac) * gamma_a + frac * ramp_a) + gamma_b - (1.0 - frac) * ramp_b
    p_lead = (1.0 - frac) * ramp_b
    num = np.zeros((c_mat.shape[0], n + 2))
    num[:, :n + 1] = state_numerators(ad, ad @ p_lead + p_mid, den_z, c_mat, c_mat @ p_lead + (1.0 - frac) * d_vec)
    num[:, 1:] += state_numerators(ad, p_lag, den_z, c_mat, frac * d_vec)
    # the ramp before the start: at sample d (inside it) the partial ramp's state
    # and input, then the free response from the full ramp's state at tau
    start = state_numerators(ad, e_b @ ramp, den_z, c_mat, c_mat @ p_lead + (1.0 - frac) * d_vec)
    return num, start


def state_numerators(ad: np.ndarray, bd: np.ndarray, den_z: np.ndarray,
                     c_mat: np.ndarray, d_vec: np.ndarray) -> np.ndarray:
    """Numerators over ``den_z`` of ``c_mat (zI - Ad)^-1 bd + d_vec``, one per row.

    Uses the Markov parameters ``g_0 = d``, ``g_k = C Ad^(k-1) bd`` and
    ``num = (den_z * g)`` truncated to ``n + 1`` terms.
    """
    n = ad.shape[0]
    g = np.empty((c_mat.shape[0], n + 1))
    g[:, 0] = d_vec
    v = bd.copy()
    for k in range(1, n + 1):
        g[:, k] = c_mat @ v
        v = ad @ v
    num = np.zeros_like(g)
    for k in range(n + 1):
        num[:, k] = g[:, k::-1] @ den_z[:k + 1]
    return num


def split_delay(input_delay: float, ts: float) -> tuple[int, float]:
    """``(d, f)`` with ``input_delay = (d + f) ts``, ``d`` whole, ``0 <= f < 1``.

    A fraction within 1e-10 of a whole sample is taken as that sample, so a
    delay written as a multiple of ``ts`` (``3 * 0.01``, not exactly
    ``0.03 / 0.01 = 3`` in floating point) is a pure shift.
    """
    x = input_delay / ts
    d = int(np.floor(x))
    f = x - d
    if f > 1.0 - 1e-10:
        return d + 1, 0.0
    if f < 1e-10:
        return d, 0.0
    return d, float(f)


def delayed(u: np.ndarray, samples: int) -> np.ndarray:
    """``u`` shifted ``samples`` later along axis 0, zeros before the first sample."""
    if samples <= 0:
        return u
    out = np.zeros_like(u)
    if samples < u.shape[0]:
        out[samples:] = u[:u.shape[0] - samples]
    return out


@dataclass(frozen=True, eq=False)
class DiscreteModel:
    """Exact discrete equivalent of ``num/den`` (with an input delay): state space and ``num_z/den_z``.

    ``num_z / den_z`` (powers of ``z^-1``) acts on the input delayed by
    ``delay_samples``; with a fractional delay ``num_z`` has one more
    coefficient than ``den_z`` (the ``Gamma1`` term one sample later, see
    :func:`discretise`). ``bd`` is the delay-free input vector (ZOH). The free
    response (:meth:`free_basis`) is that of the state, which a delay does
    not touch; the input before the first sample is taken as zero.

    For an input linear between samples (``intersample="foh"``),
    ``start_num / den_z`` is the response to the ramp from zero up to the
    first sample that ``num_z / den_z`` implies before the start
    (:func:`foh_numerators`); :meth:`forced` subtracts it. None for a held
    input.
    """

    ad: np.ndarray
    bd: np.ndarray
    c: np.ndarray
    d: float
    num_z: np.ndarray
    den_z: np.ndarray
    delay_samples: int = 0
    start_num: np.ndarray | None = None

    @property
    def order(self) -> int:
        return self.ad.shape[0]

    def forced(self, u: np.ndarray) -> np.ndarray:
        """Zero-state response to the input ``u`` (C speed via lfilter)."""
        if self.start_num is not None:
            return self._forced_linear(u)
        u = delayed(u, self.delay_samples)
        if self.order == 0 and self.num_z.size == 1:
            return self.d * u
        return scipy.signal.lfilter(self.num_z, self.den_z, u)

    def _forced_linear(self, u: np.ndarray) -> np.ndarray:
        """:meth:`forced` for an input linear between samples: the ramp before the start taken off."""
        y = scipy.signal.lfilter(self.num_z, self.den_z, delayed(u, self.delay_samples))
        if u.size == 0 or u[0] == 0.0:
            return y
        impulse = np.zeros(u.size)
        impulse[0] = 1.0
        start = scipy.signal.lfilter(self.start_num, self.den_z, impulse)
        return y - u[0] * delayed(start, self.delay_samples)

    def free_basis(self, n_samples: int) -> np.ndarray:
        """``O[k, i] = C Ad^k e_i``: the free response is ``O @ initial_state``."""
        n = self.order
        obs = np.empty((n + 1, n))
        row = self.c.copy()
        for k in range(n + 1):
            obs[k] = row
            row = row @ self.ad
        impulse = np.zeros(n_samples)
        impulse[0] = 1.0
        basis = np.empty((n_samples, n))
        for i in range(n):
            num_i = np.array([obs[k::-1, i] @ self.den_z[:k + 1] for k in range(n + 1)])
            basis[:, i] = scipy.signal.lfilter(num_i, self.den_z, impulse)
        return basis


def discretise(num: np.ndarray, den: np.ndarray, ts: float, input_delay: float = 0.0,
               intersample: str = "zoh") -> DiscreteModel:
    """Exact discretisation of a normalised (monic, proper) transfer function.

    ``intersample="zoh"`` (default): the input held between samples;
    ``"foh"``: linear between samples (:func:`_discretise_foh`). The rest of
    this docstring is the held input's.

    With ``input_delay = (d + f) ts`` > 0 (seconds, :func:`split_delay`) the
    model is ``G(s) e^(-s input_delay)``. Over ``[k ts, (k+1) ts)`` the
    delayed held input is ``u[k-d-1]`` for the first ``f ts`` and ``u[k-d]``
    after, so ``x[k+1] = Ad x[k] + Gamma0 u[k-d] + Gamma1 u[k-d-1]`` with
    ``Gamma0 = int_0^((1-f) ts) e^(A s) ds B`` (the augmented exponential at
    ``(1-f) ts``) and ``Gamma1 = Bd - Gamma0``
    (``= e^(A (1-f) ts) int_0^(f ts) e^(A s) ds B``); the direct term sees
    ``u(k ts - tau) = u[k-d-1]``. Exact for a held input, whatever ``f``.
    ``input_delay`` is not checked here (see :func:`check_delay`).
    """
    if intersample != "zoh":
        return _discretise_foh(num, den, ts, input_delay)
    n = den.size - 1
    if n == 0:
        gain = float(num[-1])
        empty = np.zeros((0, 0))
        if input_delay == 0.0:
            return DiscreteModel(empty, np.zeros(0), np.zeros(0), gain,
                                 np.array([gain]), np.array([1.0]))
        d_samples, frac = split_delay(input_delay, ts)
        num_z = np.array([gain]) if frac == 0.0 else np.array([0.0, gain])
        return DiscreteModel(empty, np.zeros(0), np.zeros(0), gain, num_z, np.array([1.0]), d_samples)
    a_mat, b_vec, c_vec, d = observability_form(num, den)
    ad, bd = zoh_matrices(a_mat, b_vec, ts)
    den_z = np.real(np.poly(np.linalg.eigvals(ad)))
    if input_delay == 0.0:
        num_z = state_numerators(ad, bd, den_z, c_vec[None, :], np.array([d]))[0]
        return DiscreteModel(ad, bd, c_vec, d, num_z, den_z)
    d_samples, frac = split_delay(input_delay, ts)
    if frac == 0.0:  # a whole number of samples: a pure shift of the delay-free model
        num_z = state_numerators(ad, bd, den_z, c_vec[None, :], np.array([d]))[0]
        return DiscreteModel(ad, bd, c_vec, d, num_z, den_z, d_samples)
    _, gamma0 = zoh_matrices(a_mat, b_vec, (1.0 - frac) * ts)
    gamma1 = bd - gamma0
    num0 = state_numerators(ad, gamma0, den_z, c_vec[None, :], np.array([0.0]))[0]
    num1 = state_numerators(ad, gamma1, den_z, c_vec[None, :], np.array([d]))[0]
    num_z = np.zeros(n + 2)
    num_z[:n + 1] += num0
    num_z[1:] += num1  # u[k-d-1]: one sample later
    return DiscreteModel(ad, bd, c_vec, d, num_z, den_z, d_samples)


def _discretise_foh(num: np.ndarray, den: np.ndarray, ts: float, input_delay: float) -> DiscreteModel:
    """:func:`discretise` for an input linear between samples (first-order hold, MATLAB's ``foh``).

    The input is taken as zero before its first sample and linear between
    samples from there, delayed by ``input_delay = (d + f) ts``: exact for
    such an input (:func:`foh_numerators`), whatever ``f``.
    """
    n = den.size - 1
    d_samples, frac = (0, 0.0) if input_delay == 0.0 else split_delay(input_delay, ts)
    if n == 0:
        gain = float(num[-1])
        empty = np.zeros((0, 0))
        if frac == 0.0:  # y[k] = gain u[k-d]: nothing between the samples shows
            return DiscreteModel(empty, np.zeros(0), np.zeros(0), gain, np.array([gain]), np.array([1.0]),
                                 d_samples)
        # the delayed input at a sample instant is f u[k-d-1] + (1 - f) u[k-d], zero before tau
        return DiscreteModel(empty, np.zeros(0), np.zeros(0), gain, np.array([(1.0 - frac) * gain, frac * gain]),
                             np.array([1.0]), d_samples, np.array([(1.0 - frac) * gain]))
    a_mat, b_vec, c_vec, d = observability_form(num, den)
    ad, gamma, ramp = foh_matrices(a_mat, b_vec, ts)
    den_z = np.real(np.poly(np.linalg.eigvals(ad)))
    num_z, start = foh_numerators(a_mat, b_vec, c_vec[None, :], np.array([d]), ts, frac, ad, gamma, ramp, den_z)
    return DiscreteModel(ad, gamma, c_vec, d, num_z[0], den_z, d_samples, start[0])


def linear_columns(model: DiscreteModel, n_samples: int, *, offset: bool,
                   initial_state: bool) -> np.ndarray:
    """Responses that enter the output linearly: ``[step, free basis]``.

    Column 0 (with ``offset``) is the exact unit-step response (held or linear: the same step), the
    response to a unit input offset; then (with ``initial_state``) the ``n`` columns of
    :meth:`DiscreteModel.free_basis`. Shape ``(n_samples, k)``.
    """
    cols = []
    if offset:
        cols.append(model.forced(np.ones(n_samples))[:, None])
    if initial_state and model.order:
        cols.append(model.free_basis(n_samples))
    return np.hstack(cols) if cols else np.zeros((n_samples, 0))


def fit_linear_terms(columns: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of ``columns`` for ``residual``.

    The columns are normalised first: the step response of an integrating or
    slow model can be orders of magnitude larger than the free responses, and
    the rank cut-off of :func:`numpy.linalg.lstsq` is relative to the largest
    singular value.
    """
    if columns.shape[1] == 0:
        return np.zeros(0)
    if not (np.all(np.isfinite(columns)) and np.all(np.isfinite(residual))):
        # a diverging model's free responses (inf - inf): LAPACK would print "DLASCL ... illegal value"
        # to the server's stderr; the coefficients are undefined, and NaN says so to the caller
        return np.full(columns.shape[1], np.nan)
    norms = np.linalg.norm(columns, axis=0)
    norms[(norms == 0) | ~np.isfinite(norms)] = 1.0
    coef, *_ = np.linalg.lstsq(columns / norms, residual, rcond=None)
    return coef / norms


def simulate_tf(num, den, u, ts, initial_state=None, input_delay=0.0, intersample="zoh") -> np.ndarray:
    """Exact sampled response of a continuous-time transfer function to a sampled input.

    The input is held constant between samples (ZOH, the default) or linear
    between them (``intersample="foh"``), so the sampled output is exact: the
    model is discretised with the matrix exponential of the augmented state
    matrix and simulated with :func:`scipy.signal.lfilter`.
    Integrators and poles faster than the Nyquist frequency are handled.

    Parameters
    ----------
    num, den : array_like
        Coefficients in descending powers of s; ``len(num) <= len(den)``.
    u : array_like, shape (N,)
        Input samples ``u[k] = u(k ts)``, held over ``[k ts, (k+1) ts)``.
    ts : float
        Sampling time in seconds.
    initial_state : array_like, shape (n,), optional
        Initial state of the observability canonical form (see
        :mod:`eha_core.identify.validate`; for ``b / A(s)`` it is
        ``[y, y', ...]`` at t = 0). Default: zero.
    input_delay : float
        Input delay ``tau >= 0`` in seconds, any multiple of ``ts`` or not:
        the response is that of ``G(s) e^(-s tau)`` to the held input, exact
        (see :func:`discretise`); the input before the first sample is
        zero. Default 0.
    intersample : {"zoh", "foh"}
        The input between samples (MATLAB's ``InterSample``): ``"zoh"``
        (default) held over ``[k ts, (k+1) ts)``; ``"foh"`` linear from
        ``u[k]`` to ``u[k+1]``, as a smooth signal sampled, the system at rest
        until the input starts at ``u[0]`` (``scipy.signal.lsim``'s
        interpolation). The last sample is the end of the record either way.

    Returns
    -------
    numpy.ndarray, shape (N,)
        Output samples ``y(k ts)``.

    Examples
    --------
    >>> import numpy as np
    >>> y = simulate_tf([2.0], [1.0, 2.0], np.ones(4), ts=0.5)
    >>> np.allclose(y, 1.0 - np.exp(-2.0 * 0.5 * np.arange(4)))
    True
    >>> simulate_tf([1.0], [1.0, 0.0], np.zeros(3), ts=0.1, initial_state=[2.0])
    array([2., 2., 2.])

    An integrator fed a unit step delayed by 1.5 samples:

    >>> simulate_tf([1.0], [1.0, 0.0], np.ones(5), ts=1.0, input_delay=1.5)
    array([0. , 0. , 0.5, 1.5, 2.5])

    An integrator fed the ramp ``u = t`` sampled, linear between samples
    (``y = t^2 / 2``):

    >>> simulate_tf([1.0], [1.0, 0.0], np.arange(5.0), ts=1.0, intersample="foh")
    array([0. , 0.5, 2. , 4.5, 8. ])
    """
    num_n, den_n = as_tf(num, den)
    u_arr = as_samples(u, "u")
    model = discretise(num_n, den_n, as_ts(ts), check_delay(input_delay), check_intersample(intersample))
    y = model.forced(u_arr)
    if initial_state is not None:
        state_arr = np.atleast_1d(np.asarray(initial_state, dtype=float))
        if state_arr.shape != (model.order,):
            raise not_allowed("initial_state", state_arr,
                              f"must have shape ({model.order},), one initial state per pole; "
                              f"it has shape {state_arr.shape}")
        if model.order:
            y = y + model.free_basis(u_arr.size) @ state_arr
    return y


# ---------------------------------------------------------------------------
# fit
# ---------------------------------------------------------------------------
def fit_percent(y, y_hat):
    """Normalised root-mean-square fit in percent, exactly as MATLAB ``compare``.

    ``fit = 100 (1 - ||y - y_hat|| / ||y - mean(y)||)``, per column for 2-D
    input. 100 is a perfect fit; 0 is no better than the mean; it can be
    negative. A constant ``y`` gives ``-inf`` (or ``nan`` if ``y_hat == y``),
    as MATLAB does.

    Parameters
    ----------
    y, y_hat : array_like, shape (N,) or (N, ny)
        Measured and simulated outputs.

    Returns
    -------
    float or numpy.ndarray
        Fit in percent (an array of ``ny`` values for 2-D input).

    Examples
    --------
    >>> fit_percent([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    100.0
    >>> round(fit_percent([0.0, 2.0], [0.5, 1.5]), 6)
    50.0
    """
    y_arr = as_samples(y, "y", allow_2d=True)
    y_hat_arr = as_samples(y_hat, "y_hat", allow_2d=True)
    if y_arr.shape != y_hat_arr.shape:
        raise not_allowed("y_hat", y_hat_arr,
                          f"it has shape {y_hat_arr.shape}; it must have the shape of y, {y_arr.shape}")
    err = np.linalg.norm(y_arr - y_hat_arr, axis=0)
    spread = np.linalg.norm(y_arr - y_arr.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        fit = 100.0 * (1.0 - err / spread)
    return float(fit) if np.ndim(fit) == 0 else fit


# ---------------------------------------------------------------------------
# frequency response
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrequencyResponseData:
    """Complex frequency response with Bode-ready magnitude and phase.

    Attributes
    ----------
    w : numpy.ndarray
        Frequencies in rad/s.
    response : numpy.ndarray
        Complex values ``G(j w)``.
    magnitude_db : numpy.ndarray
        ``20 log10 |G|``.
    phase_deg : numpy.ndarray
        Phase in degrees, unwrapped along ``w``.
    """

    w: np.ndarray
    response: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray

    @classmethod
    def from_response(cls, w, response) -> FrequencyResponseData:
        """The data of complex values ``response`` (``G(j w)``) at the frequencies ``w`` [rad/s]: their
        magnitude in dB and phase in degrees, unwrapped along ``w``."""
        response = np.asarray(response, dtype=complex)
        with np.errstate(divide="ignore"):
            magnitude_db = 20.0 * np.log10(np.abs(response))
        phase_deg = np.degrees(np.unwrap(np.angle(response))) if response.size else response.real
        return cls(readonly(np.asarray(w, dtype=float)), readonly(response),
                   readonly(magnitude_db), readonly(phase_deg))


def frequency_response(num, den, w, input_delay=0.0) -> FrequencyResponseData:
    """Frequency response ``G(j w) e^(-j w tau)`` of a continuous-time transfer function.

    Parameters
    ----------
    num, den : array_like
        Coefficients, descending powers of s.
    w : array_like
        Frequencies in rad/s.
    input_delay : float
        Delay ``tau >= 0`` in seconds (default 0). Its phase ``-w tau`` is
        added to the unwrapped phase of ``G`` exactly, so it is right however
        sparse ``w`` is (unwrapping the delayed response itself would not be).

    Returns
    -------
    FrequencyResponseData
        ``w``, complex ``response``, ``magnitude_db`` and unwrapped
        ``phase_deg``.

    Examples
    --------
    >>> fr = frequency_response([1.0], [1.0, 1.0], [1.0])
    >>> round(float(fr.magnitude_db[0]), 3), round(float(fr.phase_deg[0]), 3)
    (-3.01, -45.0)
    >>> fr = frequency_response([1.0], [1.0, 1.0], [1.0], input_delay=np.pi / 4)
    >>> round(float(fr.magnitude_db[0]), 3), round(float(fr.phase_deg[0]), 3)
    (-3.01, -90.0)
    """
    tau = check_delay(input_delay)
    num_n, den_n = as_tf(num, den)
    allowed = "must be a 1-D array of finite frequencies in rad/s"
    try:
        w_arr = np.atleast_1d(np.asarray(w, dtype=float))
    except (TypeError, ValueError):
        raise not_allowed("w", w, allowed) from None
    if w_arr.ndim != 1 or not np.all(np.isfinite(w_arr)):
        raise not_allowed("w", w_arr if w_arr.ndim == 1 else f"an array of shape {w_arr.shape}", allowed)
    s = 1j * w_arr
    fr = FrequencyResponseData.from_response(w_arr, np.polyval(num_n, s) / np.polyval(den_n, s))
    if tau == 0.0:
        return fr
    lag = w_arr * tau
    return FrequencyResponseData(fr.w, readonly(fr.response * np.exp(-1j * lag)), fr.magnitude_db,
                                 readonly(fr.phase_deg - np.degrees(lag)))
