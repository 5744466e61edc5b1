"""How well an estimated transfer function is known: pole/zero regions and a Bode band.

A :class:`~eha_core.identify.tfest.TFEstimate` carries the covariance ``Sigma``
of its coefficients ``theta = [den[1:], num]`` (Gauss-Newton, from the
output-error Jacobian). Two ways to carry it over to what a student looks at:

* **First order** (:func:`root_derivatives`): a simple root ``r`` of
  ``p(s) = c_0 s^n + ... + c_n`` moves by ``dr/dc_k = -r^(n-k) / p'(r)`` when
  the coefficient ``c_k`` moves (differentiate ``p(r(c), c) = 0``). With the
  2 x p real Jacobian ``J = [Re dr/dtheta; Im dr/dtheta]`` the root's
  covariance in the plane is ``J Sigma J^T``. A complex root's region is the
  ellipse of the chi-square quantile with 2 degrees of freedom
  (``-2 ln(1 - level)``, 5.99 for 95 %). A real root stays real to first order
  (its derivatives are real), so its 2 x 2 covariance is singular and the
  ellipse degenerates to a segment of the real axis: its region is the
  interval ``r +- z sigma`` with the 1-degree-of-freedom quantile
  (``z = 1.96`` for 95 %), so that both kinds cover at the nominal rate.
* **Monte Carlo**: draws of ``theta`` from ``N(theta_hat, Sigma)``, the roots
  of each draw matched one to one to the nominal roots (the assignment of
  least total distance). Needed where the linearisation is poor: a root
  whose derivative is large (``p'(r)`` small, two roots close together), a
  slow pole next to the origin, a fast pole the data barely see.

A root is flagged ``weakly_determined`` (with a reason) when its region is
large against its distance to the origin (its frequency is not known within
a factor of about 2 at the chosen level; default: a half-width above 0.5
``|r|``), when it or its region lies beyond the Nyquist frequency ``pi / ts``
of the estimation data (sampled at ``ts``, the data hold nothing above it;
the linearised closed loop of eq. 24 has a pole at -385 rad/s, beyond the
314 rad/s of the paper's Ts = 0.01 s), when its mode decays faster than the
sampling (``-Re r ts > 1``: a time constant shorter than one sample, gone
before the next sample; estimates of that -385 rad/s pole from noisy data
land anywhere between about -200 and -750 rad/s, and this catches those
below the Nyquist frequency), when its first-order region is undefined
(a repeated root) and, with the Monte Carlo cloud, when the draws scatter
that far or more than ``1 - level`` of them cross into the other half-plane.
How far the first-order region can be trusted is reported, not flagged:
``RootRegion.cloud_outside`` is the fraction of draws outside it (about
``1 - level`` where the linearisation holds; on the paper's eq. 24 with 5 %
output noise, 6-11 % for the poles at -0.14 and -44.5 rad/s, whose regions
are small: they are flagged only in the few estimates where a tail of the
draws strays far, e.g. where a draw's fast pole comes down to -44.5 rad/s
and the two merge).

:func:`bode_band` gives the pointwise band of magnitude and phase from the
same draws: per frequency, the ``(1 - level)/2`` and ``(1 + level)/2``
quantiles, each draw's phase taken on the branch nearest the nominal one.

Only numpy and scipy are imported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.special

from .._checks import not_allowed, positive_integer
from ._ctmodels import FrequencyResponseData, as_tf, frequency_response, readonly

__all__ = [
    "BodeBand",
    "BodeCurve",
    "PoleZeroMap",
    "RootRegion",
    "bode_band",
    "pole_zero_regions",
    "reference_roots",
    "root_derivatives",
]

#: A root whose region's half-width exceeds this fraction of its distance to
#: the origin is flagged: at 0.5 its frequency is uncertain by a factor ~2.
MAX_RELATIVE_SIZE = 0.5


# ---------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RootRegion:
    """A pole or zero and the region where it lies at the chosen level.

    Attributes
    ----------
    kind : str
        ``"pole"`` or ``"zero"``.
    location : complex
        The nominal root [rad/s].
    covariance : numpy.ndarray or None
        First-order 2 x 2 covariance of ``(Re r, Im r)``; singular for a real
        root (it stays on the real axis). None for a reference model.
    outline : numpy.ndarray or None
        Complex points of the region's boundary, closed (first == last): the
        ellipse of a complex root; for a real root the degenerate ellipse,
        i.e. the interval traced along the real axis. None without a region.
    interval : tuple of float or None
        ``(low, high)`` [rad/s] of a real root's region; None otherwise.
    cloud : numpy.ndarray or None
        Monte Carlo draws of this root (complex, one per draw), or None.
    cloud_outside : float
        Fraction of the draws outside the first-order region (about
        ``1 - level`` where the linearisation holds); NaN without a cloud.
    half_width : float
        The region's half-width [rad/s]: the ellipse's semi-major axis, or
        half the interval (NaN without a region).
    level : float
        Confidence level of the region (NaN without one).
    weakly_determined : bool
    reason : str
        Why it is flagged (several reasons joined by ``"; "``); empty if not.
    """

    kind: str
    location: complex
    covariance: np.ndarray | None
    outline: np.ndarray | None
    interval: tuple[float, float] | None
    cloud: np.ndarray | None
    cloud_outside: float
    half_width: float
    level: float
    weakly_determined: bool
    reason: str

    @property
    def is_real(self) -> bool:
        return self.location.imag == 0.0

    @property
    def frequency(self) -> float:
        """``|r|`` [rad/s], the root's natural frequency."""
        return float(abs(self.location))

    @property
    def damping(self) -> float:
        """``-Re r / |r|`` (1 for a stable real root); NaN at the origin."""
        return float(-self.location.real / abs(self.location)) if self.location != 0 else float("nan")

    def contains(self, point) -> bool:
        """Whether ``point`` lies in the first-order region drawn by ``outline``.

        For a real root the interval (``point`` must then be real), for a
        complex one the ellipse. False when there is no region.
        """
        if self.covariance is None or not np.all(np.isfinite(self.covariance)):
            return False
        p = complex(point)
        if self.is_real:
            if abs(p.imag) > 1e-9 * max(1.0, abs(p)):
                return False
            return bool(self.interval[0] <= p.real <= self.interval[1])
        d = np.array([p.real - self.location.real, p.imag - self.location.imag])
        try:
            distance2 = float(d @ np.linalg.solve(self.covariance, d))
        except np.linalg.LinAlgError:
            return False
        return bool(distance2 <= _chi2_2dof(self.level))


@dataclass(frozen=True, eq=False)
class PoleZeroMap:
    """Poles and zeros of one model, with their regions (if estimated).

    Attributes
    ----------
    name : str
    poles, zeros : tuple of RootRegion
        Sorted by distance to the origin, the upper of a complex pair first.
    level : float
        Confidence level of the regions (e.g. 0.95).
    ts : float or None
        Sampling time of the data [s] (for the Nyquist frequency), or None.
    method : str
        ``"first order"``, ``"first order + monte carlo"`` or ``"none"``
        (a reference model).
    n_draws : int
        Monte Carlo draws (0 without a cloud).
    seed : int or None
    """

    name: str
    poles: tuple[RootRegion, ...]
    zeros: tuple[RootRegion, ...]
    level: float
    ts: float | None
    method: str
    n_draws: int
    seed: int | None

    @property
    def nyquist(self) -> float | None:
        """``pi / ts`` [rad/s], or None."""
        return None if self.ts is None else float(np.pi / self.ts)

    @property
    def roots(self) -> tuple[RootRegion, ...]:
        return self.poles + self.zeros

    @property
    def weakly_determined(self) -> tuple[RootRegion, ...]:
        """The flagged roots."""
        return tuple(r for r in self.roots if r.weakly_determined)


@dataclass(frozen=True, eq=False)
class BodeCurve:
    """One Bode curve: ``magnitude_db`` (20 log10 |G|) and ``phase_deg``."""

    magnitude_db: np.ndarray
    phase_deg: np.ndarray


@dataclass(frozen=True, eq=False)
class BodeBand:
    """Pointwise confidence band of an estimate's Bode diagram.

    Attributes
    ----------
    w : numpy.ndarray
        Frequencies [rad/s].
    nominal, lower, upper : BodeCurve
        The estimate's curve and the band's bounds; the phase of every draw
        is taken within 180 degrees of the nominal phase (same branch).
    level : float
    n_draws : int
    n_unstable : int
        Draws with a pole in the right half-plane (their frequency response
        is still defined, and kept).
    seed : int
    """

    w: np.ndarray
    nominal: BodeCurve
    lower: BodeCurve
    upper: BodeCurve
    level: float
    n_draws: int
    n_unstable: int
    seed: int


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------
def _chi2_2dof(level: float) -> float:
    """Quantile of the chi-square with 2 degrees of freedom (closed form)."""
    return -2.0 * np.log1p(-level)


def _z_1dof(level: float) -> float:
    """Two-sided normal quantile: ``sqrt`` of the chi-square quantile with 1 dof."""
    return float(scipy.special.ndtri(0.5 * (1.0 + level)))


def _check_level(level) -> float:
    try:
        out = float(level)
    except (TypeError, ValueError):
        out = np.nan
    if not (0.0 < out < 1.0):
        raise not_allowed("level", level, "must be a confidence level in (0, 1), e.g. 0.95")
    return out


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise not_allowed("seed", seed, "must be a whole number >= 0")
    return int(seed)


def _sorted_roots(roots: np.ndarray) -> np.ndarray:
    """Roots by distance to the origin, the upper of a pair first (stable for matching)."""
    order = np.lexsort((-roots.imag, np.round(np.abs(roots), 12)))
    return roots[order]


def root_derivatives(coefficients) -> tuple[np.ndarray, np.ndarray]:
    """Roots of a polynomial and their derivatives with respect to its coefficients.

    Differentiating ``p(r(c), c) = 0`` gives ``dr/dc_k = -r^(n-k) / p'(r)``
    for ``p(s) = c_0 s^n + ... + c_n`` and a simple root ``r``; at a repeated
    root ``p'(r) = 0`` and the derivative is infinite (the root moves as a
    fractional power of the perturbation).

    Parameters
    ----------
    coefficients : array_like, shape (n + 1,)
        Descending powers of s, ``c_0 != 0``.

    Returns
    -------
    roots : numpy.ndarray, shape (n,)
        Complex, sorted by distance to the origin (upper of a pair first).
    derivatives : numpy.ndarray, shape (n, n + 1)
        ``derivatives[i, k] = d roots[i] / d c_k`` (complex).

    Examples
    --------
    >>> r, d = root_derivatives([1.0, 3.0, 2.0])  # (s + 1)(s + 2)
    >>> r.real, d.real
    (array([-1., -2.]), array([[-1.,  1., -1.],
           [ 4., -2.,  1.]]))
    """
    c = np.atleast_1d(np.asarray(coefficients, dtype=float))
    if c.ndim != 1 or c.size < 2 or not np.all(np.isfinite(c)) or c[0] == 0:
        raise not_allowed("coefficients", c, "must be finite polynomial coefficients in descending powers of s, "
                                             "of degree >= 1, with a non-zero leading one")
    n = c.size - 1
    roots = _sorted_roots(np.roots(c).astype(complex))
    slope = np.polyval(np.polyder(c), roots)
    powers = roots[:, None] ** np.arange(n, -1, -1)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        derivatives = -powers / slope[:, None]
    return roots, derivatives


def _estimate_parts(estimate):
    """``(num, den, cov, n, m, ts)`` of a TFEstimate, its covariance checked."""
    for attr in ("num", "den", "covariance", "ts"):
        if not hasattr(estimate, attr):
            raise not_allowed("estimate", estimate, "must be a TFEstimate (num, den, covariance, ts)")
    num = np.asarray(estimate.num, dtype=float)
    den = np.asarray(estimate.den, dtype=float)
    n, m = den.size - 1, num.size - 1
    p = n + m + 1
    cov = np.asarray(estimate.covariance, dtype=float)
    # the coefficients' block [den[1:], num] leads; any further estimated
    # quantity would follow it
    if cov.ndim != 2 or cov.shape[0] < p or cov.shape[1] < p:
        raise not_allowed("estimate", estimate, f"its covariance has shape {cov.shape}; "
                                                f"it needs ({p}, {p}) for [den[1:], num]")
    cov = cov[:p, :p]
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den)) and np.all(np.isfinite(cov))):
        raise not_allowed("estimate", estimate, "its coefficients or covariance are not finite (did the "
                                                "estimation fail?); there is no uncertainty to show")
    return num, den, 0.5 * (cov + cov.T), n, m, float(estimate.ts)


def _draws(theta: np.ndarray, cov: np.ndarray, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """``n_draws`` samples of ``N(theta, cov)`` (eigen-factor: cov may be singular)."""
    values, vectors = np.linalg.eigh(cov)
    factor = vectors * np.sqrt(np.clip(values, 0.0, None))[None, :]
    z = rng.standard_normal((n_draws, theta.size))
    return theta[None, :] + z @ factor.T


def _batch_roots(polys: np.ndarray) -> np.ndarray:
    """Roots of each row (leading coefficient first) via companion eigenvalues."""
    k, n1 = polys.shape
    n = n1 - 1
    if n == 0:
        return np.zeros((k, 0), dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        monic = polys[:, 1:] / polys[:, :1]
    companion = np.zeros((k, n, n))
    companion[:, 0, :] = -monic
    companion[:, np.arange(1, n), np.arange(n - 1)] = 1.0
    ok = np.all(np.isfinite(companion), axis=(1, 2))
    roots = np.full((k, n), np.nan + 0j)
    if np.any(ok):
        roots[ok] = np.linalg.eigvals(companion[ok])
    return roots


def _match(nominal: np.ndarray, drawn: np.ndarray) -> np.ndarray:
    """Each draw's roots reordered to the nominal roots (least total distance)."""
    out = np.full(drawn.shape, np.nan + 0j)
    for j, row in enumerate(drawn):
        if not np.all(np.isfinite(row)):
            continue
        cost = np.abs(row[:, None] - nominal[None, :])
        rows, cols = scipy.optimize.linear_sum_assignment(cost)
        out[j, cols] = row[rows]
    return out


# ---------------------------------------------------------------------------
# pole/zero regions
# ---------------------------------------------------------------------------
def _flag_reasons(root: complex, half_width: float, ts: float | None, max_relative_size: float) -> list[str]:
    """The reasons that do not need the Monte Carlo cloud."""
    reasons = []
    size = abs(root)
    nyquist = np.inf if ts is None else np.pi / ts
    if size > nyquist:
        reasons.append(f"at {size:.4g} rad/s it lies beyond the Nyquist frequency pi/Ts = {nyquist:.4g} rad/s: "
                       f"data sampled every {ts:g} s cannot resolve it")
    elif np.isfinite(half_width) and size + half_width > nyquist:
        reasons.append(f"its region reaches {size + half_width:.4g} rad/s, beyond the Nyquist frequency pi/Ts = "
                       f"{nyquist:.4g} rad/s: data sampled every {ts:g} s cannot pin it down")
    elif ts is not None and -root.real * ts > 1.0:
        reasons.append(f"its mode decays faster than the sampling (time constant {1e3 / -root.real:.3g} ms < "
                       f"Ts = {1e3 * ts:.3g} ms): the samples barely see it")
    if np.isnan(half_width):
        return reasons
    if not np.isfinite(half_width):
        reasons.append("its first-order region is unbounded (a repeated root, or a singular covariance)")
    elif size == 0.0 or half_width > max_relative_size * size:
        reasons.append(f"its region's half-width {half_width:.3g} rad/s exceeds {max_relative_size:g} times its "
                       f"distance {size:.3g} rad/s to the origin: its frequency is barely determined")
    return reasons


def _cloud_reasons(root: complex, cloud: np.ndarray, half_width: float, level: float,
                   max_relative_size: float) -> list[str]:
    """Reasons the Monte Carlo cloud adds (the linearisation is poor)."""
    finite = cloud[np.isfinite(cloud)]
    if finite.size == 0:
        return ["no Monte Carlo draw gave a finite root"]
    reasons = []
    spread = float(np.quantile(np.abs(finite - root), level))
    size = abs(root)
    if spread > max_relative_size * size and not (np.isfinite(half_width) and half_width > max_relative_size * size):
        reasons.append(f"the Monte Carlo draws scatter {spread:.3g} rad/s from it, more than {max_relative_size:g} "
                       f"times its distance {size:.3g} rad/s to the origin")
    crossed = np.mean(np.sign(finite.real) != np.sign(root.real)) if root.real != 0 else 0.0
    if crossed > 1.0 - level:
        side = "right" if root.real < 0 else "left"
        reasons.append(f"{100 * crossed:.0f} % of the draws lie in the {side} half-plane")
    return reasons


def _region(kind: str, root: complex, jac: np.ndarray, cov: np.ndarray, level: float, n_outline: int,
            ts: float | None, max_relative_size: float, cloud: np.ndarray | None) -> RootRegion:
    """The first-order region of one root, its flags, and its cloud."""
    is_real = root.imag == 0.0
    t = np.linspace(0.0, 2.0 * np.pi, n_outline)
    jr = np.vstack([jac.real, jac.imag])
    cov2 = jr @ cov @ jr.T
    interval = None
    if not np.all(np.isfinite(cov2)):
        cov2 = np.full((2, 2), np.inf)
        outline, half_width = None, float("inf")
    elif is_real:
        # a real root of a real polynomial stays real to first order: its
        # covariance is singular and its region an interval (1 dof)
        sigma = float(np.sqrt(max(cov2[0, 0], 0.0)))
        half_width = _z_1dof(level) * sigma
        interval = (root.real - half_width, root.real + half_width)
        outline = root.real + half_width * np.cos(t) + 0j
    else:
        values, vectors = np.linalg.eigh(cov2)
        axes = vectors * np.sqrt(np.clip(values, 0.0, None) * _chi2_2dof(level))[None, :]
        xy = axes @ np.vstack([np.cos(t), np.sin(t)])
        outline = root + xy[0] + 1j * xy[1]
        half_width = float(np.sqrt(max(values[-1], 0.0) * _chi2_2dof(level)))
    reasons = _flag_reasons(root, half_width, ts, max_relative_size)
    cloud_outside = float("nan")
    if cloud is not None:
        reasons += _cloud_reasons(root, cloud, half_width, level, max_relative_size)
        cloud_outside = _fraction_outside(root, cloud, cov2, interval, level)
    return RootRegion(
        kind=kind, location=complex(root), covariance=readonly(cov2),
        outline=None if outline is None else readonly(outline), interval=interval,
        cloud=None if cloud is None else readonly(cloud), cloud_outside=cloud_outside,
        half_width=float(half_width), level=level, weakly_determined=bool(reasons), reason="; ".join(reasons),
    )


def _fraction_outside(root: complex, cloud: np.ndarray, cov2: np.ndarray, interval, level: float) -> float:
    """Fraction of the draws outside the first-order region (a real root's: the interval's
    span along the real axis, wherever the draw lies off it)."""
    finite = cloud[np.isfinite(cloud)]
    if finite.size == 0 or not np.all(np.isfinite(cov2)):
        return float("nan")
    if interval is not None:
        return float(np.mean((finite.real < interval[0]) | (finite.real > interval[1])))
    d = np.vstack([finite.real - root.real, finite.imag - root.imag])
    try:
        distance2 = np.einsum("ij,ij->j", d, np.linalg.solve(cov2, d))
    except np.linalg.LinAlgError:
        return float("nan")
    return float(np.mean(distance2 > _chi2_2dof(level)))


def pole_zero_regions(estimate, *, level=0.95, monte_carlo=False, n_draws=500, seed=0, n_outline=65,
                      max_relative_size=MAX_RELATIVE_SIZE, name="estimate") -> PoleZeroMap:
    """Poles and zeros of an estimate with their confidence regions.

    Parameters
    ----------
    estimate : TFEstimate
        With ``num``, ``den``, ``covariance`` (of ``[den[1:], num]``) and ``ts``.
    level : float
        Confidence level of the regions (default 0.95).
    monte_carlo : bool
        Also draw ``n_draws`` coefficient vectors from ``N(theta, covariance)``
        and attach each root's matched cloud (``RootRegion.cloud``); the cloud
        adds flags where it disagrees with the first-order region.
    n_draws, seed : int
        Monte Carlo draws and the seed of their generator.
    n_outline : int
        Points of each outline (closed).
    max_relative_size : float
        Flag a root whose region's half-width exceeds this fraction of ``|r|``.
    name : str
        The model's name, kept in the map.

    Returns
    -------
    PoleZeroMap

    Raises
    ------
    ValueError
        For a failed estimate (non-finite coefficients or covariance) or bad
        arguments.

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify.tfest import tfest
    >>> from eha_core.identify.validate import simulate_tf
    >>> rng = np.random.default_rng(1)
    >>> u = np.repeat(rng.choice([-1.0, 1.0], 200), 5)
    >>> y = simulate_tf([20.0], [1.0, 4.0, 20.0], u, 0.01) + 0.01 * rng.standard_normal(1000)
    >>> pz = pole_zero_regions(tfest(u, y, 0.01, n_poles=2))
    >>> [complex(np.round(p.location, 1)) for p in pz.poles]
    [(-2+4j), (-2-4j)]
    >>> pz.poles[0].contains(-2 + 4j), pz.poles[0].weakly_determined
    (True, False)
    """
    num, den, cov, n, m, ts = _estimate_parts(estimate)
    level = _check_level(level)
    n_outline = positive_integer("n_outline", n_outline)
    if not np.isfinite(max_relative_size) or max_relative_size <= 0:
        raise not_allowed("max_relative_size", max_relative_size, "must be a finite number > 0")
    if not isinstance(monte_carlo, (bool, np.bool_)):
        raise not_allowed("monte_carlo", monte_carlo, "must be True or False")
    seed = _check_seed(seed)
    n_draws = positive_integer("n_draws", n_draws)
    theta = np.concatenate([den[1:], num])
    # the zeros are those of num without its leading zeros (as_tf strips them)
    num_n, _ = as_tf(num, den)
    lead = m + 1 - num_n.size          # stripped leading coefficients of num
    groups = []
    poles, jac_den = root_derivatives(den)
    groups.append(("pole", poles, np.hstack([jac_den[:, 1:], np.zeros((n, m + 1))])))
    if num_n.size > 1:
        zeros, jac_num = root_derivatives(num_n)
        jac = np.zeros((zeros.size, n + m + 1), dtype=complex)
        jac[:, n + lead:] = jac_num
        groups.append(("zero", zeros, jac))
    clouds = {}
    if monte_carlo:
        draws = _draws(theta, cov, n_draws, np.random.default_rng(seed))
        clouds["pole"] = _match(poles, _batch_roots(np.hstack([np.ones((n_draws, 1)), draws[:, :n]])))
        if num_n.size > 1:
            clouds["zero"] = _match(groups[1][1], _batch_roots(draws[:, n + lead:]))
    built = {"pole": [], "zero": []}
    for kind, roots, jac in groups:
        for i, root in enumerate(roots):
            cloud = clouds[kind][:, i] if kind in clouds else None
            built[kind].append(_region(kind, root, jac[i], cov, level, n_outline, ts, max_relative_size, cloud))
    return PoleZeroMap(
        name=str(name), poles=tuple(built["pole"]), zeros=tuple(built["zero"]), level=level, ts=ts,
        method="first order + monte carlo" if monte_carlo else "first order",
        n_draws=n_draws if monte_carlo else 0, seed=seed if monte_carlo else None,
    )


def reference_roots(num, den, *, ts=None, name="reference") -> PoleZeroMap:
    """Poles and zeros of a known model (no region).

    With ``ts`` (the sampling time of the data it is compared with), a root
    beyond the Nyquist frequency ``pi / ts`` is flagged ``weakly_determined``:
    such data cannot show it. The linearised closed loop of eq. 24 at the
    paper's Ts = 0.01 s has one such pole.

    Parameters
    ----------
    num, den : array_like
        The model's numerator and denominator coefficients, highest power of s first.
    ts : float, optional
        Sampling time [s] of the data it is compared with; None: no root is flagged.
    name : str
        The model's name, kept in the map.

    Examples
    --------
    >>> pz = reference_roots([2437.0], [1.0, 430.1, 1.721e4, 2437.0], ts=0.01, name="eq. 24")
    >>> [round(p.location.real, 1) for p in pz.poles]
    [-0.1, -44.5, -385.5]
    >>> [p.weakly_determined for p in pz.poles]
    [False, False, True]
    """
    num_n, den_n = as_tf(num, den)
    if ts is not None:
        try:
            ts = float(ts)
        except (TypeError, ValueError):
            ts = np.nan
        if not np.isfinite(ts) or ts <= 0:
            raise not_allowed("ts", ts, "must be None or a finite sample time > 0 s")
    regions = {"pole": [], "zero": []}
    for kind, poly in (("pole", den_n), ("zero", num_n)):
        if poly.size < 2:
            continue
        for root in _sorted_roots(np.roots(poly).astype(complex)):
            reasons = _flag_reasons(root, float("nan"), ts, MAX_RELATIVE_SIZE)
            regions[kind].append(RootRegion(kind=kind, location=complex(root), covariance=None, outline=None,
                                            interval=None, cloud=None, cloud_outside=float("nan"),
                                            half_width=float("nan"), level=float("nan"),
                                            weakly_determined=bool(reasons), reason="; ".join(reasons)))
    return PoleZeroMap(name=str(name), poles=tuple(regions["pole"]), zeros=tuple(regions["zero"]), level=float("nan"),
                       ts=ts, method="none", n_draws=0, seed=None)


# ---------------------------------------------------------------------------
# Bode band
# ---------------------------------------------------------------------------
def _quantiles(values: np.ndarray, q) -> np.ndarray:
    """``np.nanquantile(values, q, axis=0)``: the same numbers, but vectorised when nothing is NaN
    (numpy's nanquantile goes column by column, 20x slower for a band of 400 draws x 600 frequencies)."""
    if np.isnan(values).any():
        return np.nanquantile(values, q, axis=0)
    return np.quantile(values, q, axis=0)


def bode_band(estimate, w, *, level=0.95, n_draws=400, seed=0) -> BodeBand:
    """Pointwise confidence band of an estimate's magnitude and phase.

    ``n_draws`` coefficient vectors are drawn from ``N(theta, covariance)``
    (seeded), each one's frequency response evaluated at ``w``, and the band
    is the ``(1 - level)/2`` and ``(1 + level)/2`` quantiles per frequency.
    Each draw's phase is brought within 180 degrees of the nominal phase at
    the same frequency (the nominal is unwrapped along ``w``), so that a
    branch jump of 360 degrees does not widen the band. An estimate's
    ``input_delay`` is included in the phase (``-w tau``); an estimated one
    is drawn from ``N(tau, input_delay_std^2)``, independently of the
    coefficients (tfest reports no covariance between them).

    Parameters
    ----------
    estimate : TFEstimate
        An estimate with a covariance of its coefficients (and possibly an input delay).
    w : array_like
        Frequencies [rad/s].
    level : float
        Confidence level of the band, in (0, 1).
    n_draws, seed : int
        Coefficient vectors drawn, and the seed of the draws.

    Returns
    -------
    BodeBand

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify.tfest import tfest
    >>> from eha_core.identify.validate import simulate_tf
    >>> rng = np.random.default_rng(1)
    >>> u = np.repeat(rng.choice([-1.0, 1.0], 200), 5)
    >>> y = simulate_tf([20.0], [1.0, 4.0, 20.0], u, 0.01) + 0.01 * rng.standard_normal(1000)
    >>> band = bode_band(tfest(u, y, 0.01, n_poles=2), [1.0, 4.0, 10.0])
    >>> bool(np.all(band.lower.magnitude_db < band.nominal.magnitude_db))
    True
    >>> bool(np.all(band.upper.magnitude_db - band.lower.magnitude_db < 0.5))
    True
    """
    num, den, cov, n, m, _ = _estimate_parts(estimate)
    level = _check_level(level)
    n_draws = positive_integer("n_draws", n_draws)
    seed = _check_seed(seed)
    w_arr = frequency_response(num, den, w).w   # checks w
    s = 1j * w_arr
    rng = np.random.default_rng(seed)
    draws = _draws(np.concatenate([den[1:], num]), cov, n_draws, rng)
    # an input delay tau multiplies G by e^(-j w tau): the phase moves, the
    # magnitude does not. tfest gives its standard error but no covariance
    # with the coefficients: an estimated delay is drawn independently.
    tau = float(getattr(estimate, "input_delay", 0.0) or 0.0)
    tau_std = getattr(estimate, "input_delay_std", None)
    taus = np.full(n_draws, tau)
    if tau_std is not None and np.isfinite(tau_std) and tau_std > 0:
        taus = tau + tau_std * rng.standard_normal(n_draws)
    nominal = FrequencyResponseData.from_response(
        w_arr, np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * tau))
    # polynomials evaluated at s for every draw at once (Horner)
    den_val = np.ones((n_draws, s.size), dtype=complex)
    for k in range(n):
        den_val = den_val * s[None, :] + draws[:, k:k + 1]
    num_val = np.zeros((n_draws, s.size), dtype=complex)
    for k in range(m + 1):
        num_val = num_val * s[None, :] + draws[:, n + k:n + k + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        response = num_val / den_val * np.exp(-taus[:, None] * s[None, :])
        magnitude = 20.0 * np.log10(np.abs(response))
    # each draw's phase on the nominal's branch: within +-180 degrees of it
    phase = np.degrees(np.angle(response))
    phase = nominal.phase_deg[None, :] + (phase - nominal.phase_deg[None, :] + 180.0) % 360.0 - 180.0
    q = [(1.0 - level) / 2.0, (1.0 + level) / 2.0]
    mag_q = _quantiles(magnitude, q)
    phase_q = _quantiles(phase, q)
    unstable = int(np.sum(np.any(_batch_roots(np.hstack([np.ones((n_draws, 1)), draws[:, :n]])).real > 0, axis=1)))
    return BodeBand(
        w=nominal.w,
        nominal=BodeCurve(nominal.magnitude_db, nominal.phase_deg),
        lower=BodeCurve(readonly(mag_q[0]), readonly(phase_q[0])),
        upper=BodeCurve(readonly(mag_q[1]), readonly(phase_q[1])),
        level=level, n_draws=n_draws, n_unstable=unstable, seed=seed,
    )
