"""Tests of eha_core.identify.polynomial: ARX, ARMAX, OE and BJ by the prediction-error method."""

import json

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from eha_core._checks import FieldError
from eha_core.identify.blackbox import IdData, merge
from eha_core.identify.polynomial import PolynomialModel, _errors, _Spec, armax, arx, bj, oe, pem

lfilter = scipy.signal.lfilter

# the true systems: G = B/F (or B/A) with poles 0.75 +- 0.37j, H of low order
A_TRUE = np.array([1.0, -1.5, 0.7])
B_TRUE = np.array([0.0, 1.0, 0.5])          # nk = 1, nb = 2
C_TRUE = np.array([1.0, 0.5])
D_TRUE = np.array([1.0, -0.8])
SIGMA = 0.5


def _record(structure, n, seed, skip=0):
    """A record of the true system of ``structure`` and the true parameters: simulated from rest,
    or, with ``skip``, from the state it has after ``skip`` samples of an input of mean 3."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n + skip) + (3.0 if skip else 0.0)
    e = SIGMA * rng.standard_normal(n + skip)
    if structure == "arx":
        y = lfilter(B_TRUE, A_TRUE, u) + lfilter([1.0], A_TRUE, e)
        truth = np.r_[A_TRUE[1:], B_TRUE[1:]]
    elif structure == "armax":
        y = lfilter(B_TRUE, A_TRUE, u) + lfilter(C_TRUE, A_TRUE, e)
        truth = np.r_[A_TRUE[1:], B_TRUE[1:], C_TRUE[1:]]
    elif structure == "oe":
        y = lfilter(B_TRUE, A_TRUE, u) + e
        truth = np.r_[B_TRUE[1:], A_TRUE[1:]]
    else:
        y = lfilter(B_TRUE, A_TRUE, u) + lfilter(C_TRUE, D_TRUE, e)
        truth = np.r_[B_TRUE[1:], C_TRUE[1:], D_TRUE[1:], A_TRUE[1:]]
    return IdData(y[skip:], u[skip:], 0.01), truth


ESTIMATORS = {
    "armax": lambda d, initial="zero": armax(d, 2, 2, 1, 1, initial=initial),
    "oe": lambda d, initial="zero": oe(d, 2, 2, 1, initial=initial),
    "bj": lambda d, initial="zero": bj(d, 2, 1, 1, 2, 1, initial=initial),
}


# --- ARX is least squares ---------------------------------------------------------
def _regression_rows(y, u, na, nb, nk):
    """ARX rows built sample by sample, independently of the module."""
    start = max(na, nb + nk - 1)
    rows, target = [], []
    for t in range(start, y.size):
        rows.append([-y[t - k] for k in range(1, na + 1)] + [u[t - nk - j] for j in range(nb)])
        target.append(y[t])
    return np.array(rows), np.array(target)


@pytest.mark.parametrize("na, nb, nk", [(2, 2, 1), (0, 3, 0), (3, 1, 4)])
def test_arx_equals_plain_least_squares(na, nb, nk):
    data, _ = _record("arx", 400, seed=1)
    model = arx(data, na, nb, nk)
    phi, target = _regression_rows(data.y, data.u, na, nb, nk)
    theta, *_ = np.linalg.lstsq(phi, target, rcond=None)
    np.testing.assert_allclose(model.params, theta, rtol=1e-10, atol=1e-12)
    residuals = target - phi @ theta
    sigma2 = residuals @ residuals / (phi.shape[0] - phi.shape[1])
    np.testing.assert_allclose(model.noise_variance, sigma2, rtol=1e-10)
    np.testing.assert_allclose(model.covariance, sigma2 * np.linalg.inv(phi.T @ phi), rtol=1e-8)
    assert model.success and model.name == f"ARX(na={na}, nb={nb}, nk={nk})"
    np.testing.assert_array_equal(model.B[:nk], 0.0)
    assert model.B.size == nk + nb and model.A.size == na + 1
    assert model.fit.horizon == 1


def test_merged_experiments_stack_their_regression_rows():
    first, _ = _record("arx", 300, seed=2)
    second, _ = _record("arx", 200, seed=3)
    model = arx(merge(first, second), 2, 2, 1)
    rows = [_regression_rows(d.y, d.u, 2, 2, 1) for d in (first, second)]
    phi, target = np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])
    theta, *_ = np.linalg.lstsq(phi, target, rcond=None)
    np.testing.assert_allclose(model.params, theta, rtol=1e-10)
    # a row straddling the join would change the estimate: the concatenation as one record differs
    joined = arx(IdData(np.r_[first.y, second.y], np.r_[first.u, second.u], 0.01), 2, 2, 1)
    assert np.max(np.abs(joined.params - model.params)) > 1e-8


def test_merged_experiments_restart_the_filters_of_pem():
    first, _ = _record("oe", 300, seed=4)
    second, _ = _record("oe", 300, seed=5)
    model = oe(merge(first, second), 2, 2, 1)
    spec = _Spec("oe", nb=2, nf=2, nk=1)
    e, _ = _errors(spec, model.params, merge(first, second).segments())
    e1, _ = _errors(spec, model.params, first.segments())
    np.testing.assert_allclose(e[:300], e1)
    np.testing.assert_allclose(e[300:], second.y - lfilter(model.B, model.F, second.u))


def test_merge_with_another_sample_time_is_refused():
    first, _ = _record("arx", 200, seed=6)
    other = IdData(first.y, first.u, 0.02)
    with pytest.raises(FieldError, match="sample time"):
        arx(merge(first, other), 2, 2, 1)


# --- the Jacobian is the derivative of the prediction errors ------------------------
@pytest.mark.parametrize("structure, orders", [("armax", dict(na=2, nb=2, nc=2, nk=1)), ("oe", dict(nb=2, nf=2, nk=2)),
                                               ("bj", dict(nb=2, nc=2, nd=2, nf=2, nk=0))])
def test_analytic_jacobian_matches_finite_differences(structure, orders):
    data, _ = _record("bj", 200, seed=7)
    spec = _Spec(structure, **orders)
    rng = np.random.default_rng(8)
    theta = 0.3 * rng.standard_normal(spec.n_params)
    theta = spec.stabilized(theta)
    _e, jac = _errors(spec, theta, data.segments())
    step = 1e-6
    numeric = np.column_stack([
        (_errors(spec, theta + step * np.eye(spec.n_params)[i], data.segments(), False)[0]
         - _errors(spec, theta - step * np.eye(spec.n_params)[i], data.segments(), False)[0]) / (2 * step)
        for i in range(spec.n_params)])
    np.testing.assert_allclose(jac, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


@pytest.mark.parametrize("structure, orders", [("armax", dict(na=2, nb=2, nc=1, nk=1)), ("oe", dict(nb=2, nf=2, nk=3)),
                                               ("bj", dict(nb=2, nc=2, nd=1, nf=2, nk=1))])
def test_estimated_initial_conditions_give_the_exact_gradient(structure, orders):
    # variable projection: J^T e is the gradient of e^T e / 2 minimised over the initial conditions
    data, _ = _record("bj", 200, seed=17, skip=50)
    spec = _Spec(structure, **orders, estimate_initial=True)
    theta = spec.stabilized(0.3 * np.random.default_rng(18).standard_normal(spec.n_params))
    e, jac = _errors(spec, theta, data.segments())

    def loss(th):
        residuals = _errors(spec, th, data.segments(), False)[0]
        return 0.5 * residuals @ residuals

    step = 1e-6
    numeric = np.array([(loss(theta + step * unit) - loss(theta - step * unit)) / (2 * step)
                        for unit in np.eye(spec.n_params)])
    np.testing.assert_allclose(jac.T @ e, numeric, rtol=1e-5, atol=1e-7 * np.abs(numeric).max())


# --- the intervals cover the truth at their level ------------------------------------
N_SEEDS = 200
LOW, HIGH = scipy.stats.binom.interval(0.999, N_SEEDS, 0.95)


@pytest.mark.parametrize("structure, initial", [("armax", "zero"), ("oe", "zero"), ("bj", "zero"),
                                                ("armax", "estimate"), ("oe", "estimate"), ("bj", "estimate")])
def test_intervals_cover_the_truth_at_their_level(structure, initial):
    # "zero" on records from rest; "estimate" on records that start in motion (after 100 samples of an
    # input of mean 3), where zero initial conditions would be far off
    covered, scores = [], []
    for seed in range(N_SEEDS):
        data, truth = _record(structure, 400, seed=1000 + seed, skip=0 if initial == "zero" else 100)
        model = ESTIMATORS[structure](data, initial)
        assert model.initial == model.fit.initial == initial
        assert model.success, model.message
        low, high = model.intervals(0.95)
        covered.append((low <= truth) & (truth <= high))
        scores.append((model.params - truth) / model.param_std)
    hits = np.sum(covered, axis=0)
    scores = np.array(scores)
    # each parameter's coverage inside the 99.9 % binomial band of 200 trials at 0.95
    assert np.all((hits >= LOW) & (hits <= HIGH)), (hits, LOW, HIGH)
    # standardised errors: mean 0 (its standard error is 1/sqrt(200) = 0.07), spread 1
    assert np.all(np.abs(scores.mean(axis=0)) < 0.3), scores.mean(axis=0)
    assert np.all((scores.std(axis=0) > 0.8) & (scores.std(axis=0) < 1.25)), scores.std(axis=0)


# --- the model and its exports ---------------------------------------------------------
@pytest.mark.parametrize("structure", ["armax", "oe", "bj"])
def test_model_shape_and_names(structure):
    data, truth = _record(structure, 2000, seed=9)
    model = ESTIMATORS[structure](data)
    assert isinstance(model, PolynomialModel) and model.success, model.message
    names = {"armax": ("a1", "a2", "b0", "b1", "c1"), "oe": ("b0", "b1", "f1", "f2"),
             "bj": ("b0", "b1", "c1", "d1", "f1", "f2")}[structure]
    assert model.param_names == names
    np.testing.assert_allclose(model.params, truth, atol=6 * model.param_std.max())
    gb, ga = model.g_poly()
    hc, hd = model.h_poly()
    np.testing.assert_allclose(ga, np.convolve(model.A, model.F))
    np.testing.assert_allclose(hd, np.convolve(model.A, model.D))
    np.testing.assert_allclose(gb, model.B)
    np.testing.assert_allclose(hc, model.C)
    for poly in (model.A, model.C, model.D, model.F):
        assert poly[0] == 1.0
    assert model.fit.horizon == (None if structure == "oe" else 1)
    assert model.fit.initial == model.initial == "zero"
    assert model.criteria.n_params == len(names)
    assert np.isclose(model.noise_variance, SIGMA ** 2, rtol=0.15)


def test_estimated_initial_conditions_on_a_record_from_rest_change_little():
    data, _ = _record("bj", 1000, seed=19)
    zero, estimate = bj(data, 2, 1, 1, 2, 1), bj(data, 2, 1, 1, 2, 1, initial="estimate")
    assert estimate.success, estimate.message
    assert np.all(np.abs(estimate.params - zero.params) < 0.5 * zero.param_std)
    assert estimate.criteria.loss <= zero.criteria.loss * (1 + 1e-9)


def test_names_follow_matlab():
    data, _ = _record("bj", 500, seed=10)
    assert armax(data, 2, 2, 1, 1).name == "ARMAX(na=2, nb=2, nc=1, nk=1)"
    assert oe(data, 2, 2, 1).name == "OE(nb=2, nf=2, nk=1)"
    assert bj(data, 2, 1, 1, 2, 1).name == "BJ(nb=2, nc=1, nd=1, nf=2, nk=1)"


def test_pem_dispatches_by_name_or_matlab_order():
    data, _ = _record("bj", 500, seed=11)
    direct = bj(data, 2, 1, 1, 2, 1)
    by_list = pem(data, "BJ", [2, 1, 1, 2, 1])
    by_dict = pem(data, "bj", {"nb": 2, "nc": 1, "nd": 1, "nf": 2, "nk": 1})
    np.testing.assert_allclose(by_list.params, direct.params)
    np.testing.assert_allclose(by_dict.params, direct.params)
    np.testing.assert_allclose(pem(data, "arx", [2, 2, 1]).params, arx(data, 2, 2, 1).params)


def test_to_json_round_trip():
    data, _ = _record("armax", 500, seed=12)
    model = armax(data, 2, 2, 1, 1)
    back = json.loads(model.to_json())
    np.testing.assert_array_equal(back["params"], model.params)
    np.testing.assert_array_equal(np.array(back["covariance"]), model.covariance)
    assert back["param_names"] == list(model.param_names)
    assert back["name"] == model.name and back["orders"] == model.orders
    np.testing.assert_array_equal(back["G"]["den"], np.convolve(model.A, model.F))


@pytest.mark.parametrize("structure", ["arx", "armax", "oe", "bj"])
def test_to_control_has_the_model_poles(structure):
    data, _ = _record(structure if structure != "arx" else "armax", 800, seed=13)
    model = pem(data, structure, {"arx": [2, 2, 1], "armax": [2, 2, 1, 1], "oe": [2, 2, 1],
                                  "bj": [2, 1, 1, 2, 1]}[structure])
    system = model.to_control()
    assert system.dt == model.ts
    np.testing.assert_allclose(np.sort_complex(system.poles()), np.sort_complex(model.poles()), atol=1e-10)


def test_repr_is_short():
    data, _ = _record("oe", 300, seed=14)
    text = repr(oe(data, 2, 2, 1))
    assert text.startswith("<OE(nb=2, nf=2, nk=1): fit") and "simulation" in text


# --- refusals ------------------------------------------------------------------------
@pytest.mark.parametrize("call, field", [
    (lambda d: arx(d, 2, 0, 1), "nb"),
    (lambda d: arx(d, -1, 2, 1), "na"),
    (lambda d: arx(d, 2.5, 2, 1), "na"),
    (lambda d: arx(d, True, 2, 1), "na"),
    (lambda d: arx(d, 2, 2, -1), "nk"),
    (lambda d: oe(d, 2, "two", 1), "nf"),
    (lambda d: armax(d, 2, 2, -2, 1), "nc"),
    (lambda d: bj(d, 2, 1, 1.5, 2, 1), "nd"),
    (lambda d: arx(d, 2, 40, 1), "nb"),
    (lambda d: oe(d, 2, 2, 40), "nk"),
    (lambda d: armax(d, 2, 2, 1, 1, initial="auto"), "initial"),
    (lambda d: oe(d, 2, 2, 1, initial="guess"), "initial"),
    (lambda d: bj(d, 2, 1, 1, 2, 1, max_iterations=0), "max_iterations"),
    (lambda d: pem(d, "ssest", [2, 2, 1]), "structure"),
    (lambda d: pem(d, "arx", [2, 2]), "orders"),
    (lambda d: pem(d, "oe", {"nb": 2, "na": 2, "nk": 1}), "orders"),
])
def test_bad_input_is_refused_naming_the_field(call, field):
    data = IdData(np.sin(np.arange(30.0)), np.cos(np.arange(30.0) * 0.3), 0.1)
    with pytest.raises(FieldError) as info:
        call(data)
    assert info.value.field == field
    assert str(info.value).startswith(f"{field} = ")


def test_short_experiment_of_a_merge_is_refused():
    long, _ = _record("arx", 300, seed=15)
    short = IdData(long.y[:5], long.u[:5], long.ts)
    with pytest.raises(FieldError, match="shortest experiment has 5"):
        arx(merge(long, short), 2, 2, 1)


def test_failure_is_data_not_an_exception():
    # an over-parametrised OE of a first-order system: a pole cancels a zero, the covariance is singular
    rng = np.random.default_rng(16)
    u = rng.standard_normal(400)
    y = lfilter([0, 1.0], [1, -0.5], u)
    model = oe(IdData(y, u, 1.0), 3, 3, 1)
    assert not model.success
    assert "lower the orders" in model.message


def test_an_integrator_held_at_the_stability_limit_is_not_a_success():
    # OE keeps F stable; an integrating plant pushes its root to the unit circle, where the intervals fail
    rng = np.random.default_rng(20)
    u = np.repeat(rng.choice([-1.0, 1.0], 100), 10)
    y = lfilter([0, 0.1], [1, -1], u) + 0.05 * rng.standard_normal(1000)
    model = oe(IdData(y, u, 0.01), 1, 1, 1)
    assert not model.success
    assert "unit circle" in model.message and "ARX" in model.message
    np.testing.assert_allclose(model.F, [1.0, -1.0], atol=1e-4)      # the estimate itself is still shown
    assert arx(IdData(y, u, 0.01), 1, 1, 1).success


def test_reflection_keeps_the_spectrum_shape_and_stabilises():
    from eha_core.identify.polynomial import _stable

    unstable = np.convolve([1.0, -2.0], [1.0, 0.5])                 # roots z = 2 and z = -0.5
    stable = _stable(unstable)
    assert stable[0] == 1.0 and np.all(np.abs(np.roots(stable)) < 1.0)
    np.testing.assert_allclose(np.sort(np.roots(stable).real), [-0.5, 0.5])
    _w, h_unstable = scipy.signal.freqz(unstable, worN=64)
    _w, h_stable = scipy.signal.freqz(stable, worN=64)
    ratio = np.abs(h_unstable) / np.abs(h_stable)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)          # |C| changes by a constant only (2)


def test_orders_given_as_whole_floats_or_numpy_integers_are_taken():
    data, _ = _record("oe", 300, seed=21)
    model = pem(data, "oe", {"nb": np.int64(2), "nf": 2.0, "nk": 1})
    assert model.orders == {"nb": 2, "nf": 2, "nk": 1} and model.name == "OE(nb=2, nf=2, nk=1)"


# --- the global minimum, not a local one -------------------------------------------------
# The closed-loop actuator record (BlackBoxExperiment(n_samples=2000), seed 0, detrended): its OE(2,2,1)
# and BJ(2,1,1,2,1) criteria have a local minimum where a pole near z = 1 cancels a zero (Steiglitz-
# McBride starts in it). The global minima below were found by least squares (scipy, method "lm") from
# 60 random stable starts (F, C, D with random roots inside the unit circle, B by least squares): all
# 60 OE runs and 59 of 60 BJ runs ended here (OE loss 0.016028, BJ 0.0034074; BJ's other minimum,
# 0.02886, is the local one). The test polishes them again on the record it builds, with the criterion
# written here from lfilter alone, and adds a few random starts of its own.
GLOBAL_MINIMUM = {
    "oe": np.array([0.01851261, 0.02595724, -0.21960444, -0.73596586]),                       # b0 b1 f1 f2
    "bj": np.array([0.0161144, 0.02785607, -0.71513731, -0.99307103, -0.25936109, -0.69526796]),  # b c d f
}


@pytest.fixture(scope="module")
def actuator_records():
    from eha_core.identify.blackbox_experiment import BlackBoxExperiment

    est, val = BlackBoxExperiment(n_samples=2000, ts=0.02, band=0.1, kp=100.0).records()
    return est.detrended(), val.detrended(), est


def _independent_errors(structure, theta, y, u):
    """The one-step prediction errors from rest, written from lfilter alone (not the module's)."""
    b, rest = theta[:2], theta[2:]
    c, d, f = (rest[0:1], rest[1:2], rest[2:]) if structure == "bj" else ([], [], rest)
    polys = [np.r_[1.0, p] for p in (c, d, f)]
    if any(np.max(np.abs(np.roots(p)), initial=0.0) >= 1.0 for p in polys):
        return np.full(y.size, 1e3)                       # outside the model set: a wall
    C, D, F = polys
    return lfilter(D, C, y - lfilter(np.r_[0.0, b], F, u))


def _reference_loss(structure, y, u, n_random=4):
    import scipy.optimize

    rng = np.random.default_rng(2024)
    starts = [GLOBAL_MINIMUM[structure]]
    for _ in range(n_random):
        f = np.real(np.poly(rng.uniform(-0.99, 0.99, 2)))
        w = lfilter([1.0], f, u)
        phi = np.column_stack([np.r_[0.0, w[:-1]], np.r_[0.0, 0.0, w[:-2]]])
        b = np.linalg.lstsq(phi, y, rcond=None)[0]
        noise = list(rng.uniform(-0.99, 0.99, 2)) if structure == "bj" else []
        starts.append(np.r_[b, noise, f[1:]])
    losses = []
    for start in starts:
        result = scipy.optimize.least_squares(lambda th: _independent_errors(structure, th, y, u), start,
                                              method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
        losses.append(np.mean(result.fun ** 2))
    return min(losses)


@pytest.mark.parametrize("structure", ["oe", "bj"])
def test_closed_loop_actuator_estimate_reaches_the_global_minimum(structure, actuator_records):
    from eha_core.identify.blackbox import compare

    est, val, _raw = actuator_records
    model = oe(est, 2, 2, 1) if structure == "oe" else bj(est, 2, 1, 1, 2, 1)
    assert model.success, model.message
    reference = _reference_loss(structure, est.y, est.u)
    # the module's loss is the same criterion: its own errors, recomputed independently
    mine = np.mean(_independent_errors(structure, model.params, est.y, est.u) ** 2)
    np.testing.assert_allclose(model.criteria.loss, mine, rtol=1e-9)
    assert model.criteria.loss <= reference * (1 + 1e-3), (model.criteria.loss, reference)
    # the local minimum cancels a pole against a zero near z = 1; the global one keeps both poles apart
    assert np.min(np.abs(np.roots(model.F) - 1.0)) > 0.01 and np.min(np.roots(model.F).real) < -0.5
    assert compare(model, val, None).fit_percent >= 94.0


def _soderstrom_record(seed, n=1000):
    """Söderström's situation: OE(nb=1, nf=2) of G = q^-1 / (1 - 0.7 q^-1)^2 with an input coloured by
    1 / (1 + 0.8 q^-2) (a resonance at a quarter of the sample rate). Its criterion has a second
    minimum near b0 = -0.26, F = 1 + 1.05 q^-1 + 0.72 q^-2, at 400 times the noise variance."""
    rng = np.random.default_rng(seed)
    u = lfilter([1.0], [1.0, 0.0, 0.8], rng.standard_normal(n))
    y = lfilter([0.0, 1.0], np.poly([0.7, 0.7]), u) + 0.1 * rng.standard_normal(n)
    return IdData(y, u, 1.0)


@pytest.mark.parametrize("seed", [30, 31, 32])
def test_oe_with_a_known_local_minimum_reaches_the_global_one(seed):
    from eha_core.identify.polynomial import _levenberg_marquardt, _multistart

    data = _soderstrom_record(seed)
    spec = _Spec("oe", nb=1, nf=2, nk=1)
    poor = np.array([-0.3, 1.1, 0.7])
    # the local minimum is real: Levenberg-Marquardt from a poor start converges there
    trapped = _levenberg_marquardt(spec, poor, data.segments(), 100)
    assert trapped[4] and np.mean(trapped[1] ** 2) > 100 * 0.1 ** 2
    model = oe(data, 1, 2, 1)
    assert model.success, model.message
    np.testing.assert_allclose(model.params, [1.0, -1.4, 0.49], atol=6 * model.param_std.max())
    assert model.criteria.loss < 1.2 * 0.1 ** 2
    # the search itself: given the poor start first and a good one second, it keeps the global minimum
    good = np.array([0.8, -1.2, 0.4])
    theta, e, *_ = _multistart(spec, [poor, good], data.segments(), 100)
    np.testing.assert_allclose(theta, model.params, atol=1e-3)


def test_long_record_searches_on_its_first_part_and_polishes_on_the_whole():
    # 10,000 samples: the basins are told apart on the first 2000, and the estimate is the whole record's
    data = _soderstrom_record(33, n=10_000)
    model = oe(data, 1, 2, 1)
    assert model.success, model.message
    spec = _Spec("oe", nb=1, nf=2, nk=1)
    e, jac = _errors(spec, model.params, data.segments())
    gradient = jac.T @ e
    # a stationary point of the whole record's loss: the Gauss-Newton step changes it by less than noise
    step = np.linalg.lstsq(jac, e, rcond=None)[0]
    assert gradient @ step <= 1e-6 * (e @ e)


def test_closed_loop_record_with_its_offset_converges(actuator_records):
    # not detrended, the offset makes the criterion flat along the unit circle: the search still ends
    # by a convergence test, and BJ, whose D takes the offset as a root at z = 1, says so
    _est, _val, raw = actuator_records
    model = armax(raw, 2, 2, 1, 1)
    assert model.success, model.message
    model = bj(raw, 2, 1, 1, 2, 1)
    assert "no convergence" not in model.message and "optimiser stopped" not in model.message, model.message
    assert model.success or "D ended with a root on the unit circle" in model.message, model.message
