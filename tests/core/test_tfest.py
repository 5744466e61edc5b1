"""Tests of eha_core.identify.tfest on known continuous-time systems."""

import dataclasses

import numpy as np
import pytest

from eha_core.identify.tfest import TFEstimate, oe_fit, tfest
from eha_core.identify.validate import fit_percent, simulate_tf

TS = 0.01
# H(s) of the paper's linearised closed loop: poles -0.142, -44.5, -385.5 rad/s;
# the last one is faster than the Nyquist frequency pi/TS = 314 rad/s.
H_NUM = np.array([2437.0])
H_DEN = np.array([1.0, 430.1, 1.721e4, 2437.0])
# Open-loop plant with an integrator (a_3 = 0).
P_NUM = np.array([243.7])
P_DEN = np.array([1.0, 430.1, 1.721e4, 0.0])
# A lightly damped second-order system with a zero.
Z_NUM = np.array([3.0, 5.0])
Z_DEN = np.array([1.0, 0.8, 4.0])


def _binary_input(n, hold=5, seed=0):
    """Random binary signal held for ``hold`` samples (ZOH)."""
    rng = np.random.default_rng(seed)
    return np.repeat(rng.choice([-1.0, 1.0], n // hold + 1), hold)[:n]


def _multisine(n, n_sines=40, seed=0):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    bins = np.linspace(1, n // 2 - 1, n_sines).round()
    u = sum(np.cos(2 * np.pi * b * k / n + rng.uniform(0, 2 * np.pi)) for b in bins)
    return u / np.abs(u).max()


def _theta(num, den):
    return np.concatenate([np.asarray(den)[1:], num])


# --- noiseless recovery ---------------------------------------------------------
@pytest.mark.parametrize("make_input", [_binary_input, _multisine], ids=["rbs", "multisine"])
def test_recovers_third_order_with_pole_beyond_nyquist(make_input):
    u = make_input(1000)
    y = simulate_tf(H_NUM, H_DEN, u, TS)
    est = tfest(u, y, TS, n_poles=3, n_zeros=0)
    assert est.success, est.message
    assert est.den[0] == 1.0
    np.testing.assert_allclose(est.den, H_DEN, rtol=1e-4)
    np.testing.assert_allclose(est.num, H_NUM, rtol=1e-4)
    assert est.fit_percent == pytest.approx(100.0, abs=1e-4)
    assert est.method in ("srivc+oe", "srivc")
    assert est.nit_srivc > 0 and est.nfev_oe > 0
    assert est.initial_condition == "zero" and est.initial_state is None
    assert np.min(est.poles().real) == pytest.approx(-385.47, rel=1e-4)


def test_recovers_second_order_with_zero():
    u = _binary_input(800, hold=10, seed=1)
    y = simulate_tf(Z_NUM, Z_DEN, u, TS)
    est = tfest(u, y, TS, n_poles=2, n_zeros=1)
    assert est.success, est.message
    np.testing.assert_allclose(_theta(est.num, est.den), _theta(Z_NUM, Z_DEN), rtol=1e-4)
    np.testing.assert_allclose(est.zeros(), [-5.0 / 3.0], rtol=1e-4)


def test_recovers_open_loop_integrator():
    u = _binary_input(1000, seed=2)
    y = simulate_tf(P_NUM, P_DEN, u, TS)
    est = tfest(u, y, TS, n_poles=3)
    assert est.success, est.message
    np.testing.assert_allclose(est.den[:3], P_DEN[:3], rtol=1e-4)
    np.testing.assert_allclose(est.num, P_NUM, rtol=1e-4)
    # a_3 ~ 0: an integrator pole within 1e-6 rad/s of the origin
    assert abs(est.den[3]) < 1e-6 * est.den[2]
    assert np.min(np.abs(est.poles())) < 1e-6


def test_srivc_alone_and_result_fields():
    u = _binary_input(1000)
    y = simulate_tf(H_NUM, H_DEN, u, TS)
    est = tfest(u, y, TS, refine=False)
    assert est.method == "srivc" and est.nfev_oe == 0
    np.testing.assert_allclose(est.den, H_DEN, rtol=1e-4)
    np.testing.assert_allclose(est.srivc_den, est.den)
    assert est.param_std.shape == (4,) and est.covariance.shape == (4, 4)
    assert est.n_poles == 3 and est.n_zeros == 0 and est.n_samples == 1000
    assert isinstance(est, TFEstimate)
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.num = np.ones(1)
    np.testing.assert_allclose(est.simulate(u), y, atol=1e-6 * np.abs(y).max())
    # a continuous-time model can be simulated at another sampling time
    u_fine = np.repeat(u[:200], 2)
    np.testing.assert_allclose(est.simulate(u_fine, ts=TS / 2)[::2],
                               simulate_tf(H_NUM, H_DEN, u_fine, TS / 2)[::2],
                               atol=1e-6 * np.abs(y).max())


def test_tf_property_returns_control_transfer_function():
    control = pytest.importorskip("control")
    u = _binary_input(300, hold=10)
    est = tfest(u, simulate_tf([20.0], [1.0, 6.0, 20.0], u, TS), TS, n_poles=2)
    sys = est.tf
    assert isinstance(sys, control.TransferFunction)
    np.testing.assert_allclose(np.ravel(sys.den[0][0]), [1.0, 6.0, 20.0], rtol=1e-6)


# --- initial conditions -------------------------------------------------------------
def test_estimated_initial_condition_recovers_state():
    u = _binary_input(1000, seed=4)
    initial_state = np.array([0.3, -2.0, 10.0])  # y(0), y'(0), y''(0)
    y = simulate_tf(H_NUM, H_DEN, u, TS, initial_state=initial_state)
    est = tfest(u, y, TS, initial_condition="estimate")
    assert est.success, est.message
    assert est.initial_condition == "estimate"
    np.testing.assert_allclose(est.den, H_DEN, rtol=1e-4)
    np.testing.assert_allclose(est.num, H_NUM, rtol=1e-4)
    np.testing.assert_allclose(est.initial_state, initial_state, rtol=1e-4)
    assert est.fit_percent == pytest.approx(100.0, abs=1e-4)
    # ignoring the initial state cannot explain these data as well
    zero = tfest(u, y, TS, initial_condition="zero")
    assert zero.fit_percent < est.fit_percent - 0.01


# --- noise: consistency and statistics ------------------------------------------------
def _noisy_estimate(n_samples, seed, noise=0.1):
    rng = np.random.default_rng(seed)
    u = _binary_input(n_samples, hold=20, seed=seed)
    y = simulate_tf(Z_NUM, Z_DEN, u, TS) + noise * rng.standard_normal(n_samples)
    return tfest(u, y, TS, n_poles=2, n_zeros=1)


def test_error_shrinks_with_record_length_and_std_is_consistent():
    true = _theta(Z_NUM, Z_DEN)
    median_error = []
    for n_samples in (1000, 4000, 16000):
        errors = []
        for seed in range(3):
            est = _noisy_estimate(n_samples, seed)
            assert est.success, est.message
            theta = _theta(est.num, est.den)
            errors.append(np.linalg.norm((theta - true) / true))
            # the true value lies within 3.5 reported standard errors
            assert np.all(np.abs(theta - true) < 3.5 * est.param_std), (theta, est.param_std)
        median_error.append(np.median(errors))
    assert median_error[0] > median_error[1] > median_error[2]
    # the error falls roughly like 1/sqrt(N): 16x the data, about 4x less error
    assert median_error[2] < median_error[0] / 2


def test_reported_standard_errors_match_the_spread():
    true = _theta(Z_NUM, Z_DEN)
    estimates = np.array([_theta(e.num, e.den) for e in
                          (_noisy_estimate(1000, seed) for seed in range(12))])
    std = _noisy_estimate(1000, 100).param_std
    ratio = estimates.std(axis=0) / std
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio
    assert np.all(np.abs(estimates.mean(axis=0) - true) < 3 * std / np.sqrt(12) + 1e-12)


# --- plain output error ---------------------------------------------------------------
def test_oe_fit_from_perturbed_start_matches_tfest():
    u = _binary_input(1000, seed=5)
    rng = np.random.default_rng(5)
    y = simulate_tf(H_NUM, H_DEN, u, TS) + 1e-4 * rng.standard_normal(1000)
    full = tfest(u, y, TS)
    plain = oe_fit(u, y, TS, H_NUM * 1.3, H_DEN * [1.0, 0.8, 1.2, 1.3])
    assert plain.method == "oe" and plain.nit_srivc == 0 and plain.srivc_den is None
    assert plain.success, plain.message
    # same criterion: both reach the same minimum
    assert plain.cost == pytest.approx(full.cost, rel=1e-6)
    # each stops when its cost falls by < tol = 1e-10 of itself: within ~sqrt(tol N) = 3e-4 standard errors
    # of the minimum (with OpenBLAS's kernels they differ by 5e-6 to 9e-5 of one, up to 2e-6 relative)
    assert plain.den[0] == full.den[0] == 1.0
    np.testing.assert_array_less(np.abs(_theta(plain.num, plain.den) - _theta(full.num, full.den)),
                                 1e-3 * full.param_std)
    assert plain.fit_percent == pytest.approx(
        fit_percent(y, simulate_tf(plain.num, plain.den, u, TS)), abs=1e-9)


def test_oe_fit_estimates_initial_state():
    u = _binary_input(600, seed=6)
    initial_state = np.array([1.0, -0.5])
    y = simulate_tf(Z_NUM, Z_DEN, u, TS, initial_state=initial_state)
    est = oe_fit(u, y, TS, [2.0, 4.0], [1.0, 1.0, 3.0], initial_condition="estimate")
    np.testing.assert_allclose(_theta(est.num, est.den), _theta(Z_NUM, Z_DEN), rtol=1e-4)
    np.testing.assert_allclose(est.initial_state, initial_state, rtol=1e-4, atol=1e-8)


# --- failures are data, bad arguments are errors -------------------------------------
def test_unexciting_input_is_reported_not_raised():
    est = tfest(np.zeros(500), np.ones(500), TS, n_poles=2)
    assert not est.success
    assert "SRIVC failed" in est.message
    assert np.all(np.isnan(est.num))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_poles": 0}, r"n_poles = 0 is not allowed: must be a whole number >= 1"),
        ({"n_poles": 2, "n_zeros": 2}, r"n_zeros = 2 is not allowed: .*\[0, 1\]"),
        ({"n_zeros": -1}, r"n_zeros = -1 is not allowed: .*\[0, 2\]"),
        ({"ts": 0.0}, r"ts = 0 is not allowed: must be a finite sample time > 0 s"),
        ({"initial_condition": "random"}, r"initial_condition = random is not allowed: use zero or estimate"),
        ({"init": ([1.0], [1.0, 2.0])},
         r"init = \[\[1\], \[1, 2\]\] is not allowed: must have 3 poles and at most 0 zeros .*it has 1 poles"),
        ({"init": ([1.0], [0.0])}, r"init\[1\] = \[0\] is not allowed: .*non-zero coefficient"),
        ({"init": 5}, r"init = 5 is not allowed: must be a \(num, den\) pair or a transfer function"),
        ({"max_iter": 0}, r"max_iter = 0 is not allowed"),
        ({"tol": -1.0}, r"tol = -1 is not allowed"),
        ({"lambda_svf": -3.0}, r"lambda_svf = -3 is not allowed"),
        ({"refine": 1}, r"refine = 1 is not allowed: must be True or False"),
    ],
)
def test_bad_arguments_raise_value_error_naming_them_and_their_value(kwargs, message):
    u = _binary_input(100)
    args = {"u": u, "y": u, "ts": TS, **kwargs}
    with pytest.raises(ValueError, match="^" + message):
        tfest(**args)


def test_bad_data_raise_value_error_naming_them_and_their_value():
    u = _binary_input(100)
    with pytest.raises(ValueError, match=r"^y = an array of shape \(99,\) is not allowed: it has 99 samples "
                                         r"where u has 100"):
        tfest(u, u[:-1], TS)
    with pytest.raises(ValueError, match=r"^u = \[.*\] is not allowed: it has 5 samples; this model needs at "
                                         r"least 6"):
        tfest(u[:5], u[:5], TS)
    with pytest.raises(ValueError, match=r"^y = an array of shape \(100,\) is not allowed: y\[3\] is nan"):
        tfest(u, np.r_[u[:3], np.nan, u[4:]], TS)
    with pytest.raises(ValueError, match=r"^num0 = \[1, 1\] is not allowed: the start model must have fewer "
                                         r"zeros than poles"):
        oe_fit(u, u, TS, [1.0, 1.0], [1.0, 1.0])
    with pytest.raises(ValueError, match=r"^den0 = \[2\] is not allowed: the start model needs at least 1 pole"):
        oe_fit(u, u, TS, [1.0], [2.0])
    with pytest.raises(ValueError, match=r"^num0 = \[1, 0, 0\] is not allowed: its degree 2 exceeds the degree 1 "
                                         r"of den0"):
        oe_fit(u, u, TS, [1.0, 0.0, 0.0], [1.0, 1.0])


def test_tfest_and_validate_share_one_simulator_and_fit():
    """The estimator's fit and compare's are computed by the same code."""
    from eha_core.identify import _ctmodels, validate
    from eha_core.identify import tfest as tfest_module

    assert tfest_module.simulate_tf is validate.simulate_tf is _ctmodels.simulate_tf
    assert tfest_module.fit_percent is validate.fit_percent is _ctmodels.fit_percent
    u = _binary_input(300)
    y = simulate_tf(H_NUM, H_DEN, u, TS) + 1e-3 * np.random.default_rng(5).standard_normal(300)
    est = tfest(u, y, TS)
    assert est.fit_percent == pytest.approx(validate.compare(est.num, est.den, u, y, TS).fit_percent, abs=1e-12)


def test_import_is_light():
    # numpy/scipy only at import time: python-control (1.4 s) is imported lazily
    import subprocess
    import sys

    code = (
        "import sys, eha_core.identify.tfest, eha_core.identify.validate\n"
        "heavy = {'control', 'panel', 'holoviews', 'bokeh'} & set(sys.modules)\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# --- input offset: y = G(s) (u + c) -------------------------------------------------
# (num, den, n_poles, n_zeros, input, offset c, initial state for the "estimate" case)
_OFFSET_CASES = {
    "closed-loop-H": (H_NUM, H_DEN, 3, 0, _binary_input(1000, seed=4), 0.3,
                      np.array([0.3, -2.0, 10.0])),
    "second-order-with-zero": (Z_NUM, Z_DEN, 2, 1, _binary_input(800, hold=10, seed=1), -0.4,
                               np.array([1.0, -0.5])),
}


def _offset_data(case, initial_condition):
    num, den, n, m, u, c, initial_state = _OFFSET_CASES[case]
    initial_state = initial_state if initial_condition == "estimate" else None
    return num, den, n, m, u, c, initial_state, simulate_tf(num, den, u + c, TS, initial_state=initial_state)


@pytest.mark.parametrize("initial_condition", ["zero", "estimate"])
@pytest.mark.parametrize("case", list(_OFFSET_CASES))
def test_estimated_input_offset_recovers_noiseless_model(case, initial_condition):
    num, den, n, m, u, c, initial_state, y = _offset_data(case, initial_condition)
    est = tfest(u, y, TS, n, m, initial_condition=initial_condition, input_offset="estimate")
    assert est.success, est.message
    np.testing.assert_allclose(_theta(est.num, est.den), _theta(num, den), rtol=1e-8)
    assert est.input_offset == pytest.approx(c, rel=1e-8)
    assert est.fit_percent == pytest.approx(100.0, abs=1e-6)
    if initial_state is not None:
        np.testing.assert_allclose(est.initial_state, initial_state, rtol=1e-6)
    assert "input offset estimated" in est.message
    assert np.isfinite(est.input_offset_std) and est.input_offset_std >= 0.0
    # the offset is part of the model: simulating with it reproduces the data
    np.testing.assert_allclose(est.simulate(u, initial_state=est.initial_state, input_offset=est.input_offset), y,
                               atol=1e-7 * np.abs(y).max())
    # a model without the offset cannot explain the same data as well
    plain = tfest(u, y, TS, n, m, initial_condition=initial_condition)
    assert plain.input_offset is None and plain.input_offset_std is None
    assert plain.fit_percent < 99.0


@pytest.mark.parametrize("initial_condition", ["zero", "estimate"])
@pytest.mark.parametrize("case", list(_OFFSET_CASES))
def test_srivc_alone_with_input_offset_recovers_noiseless_model(case, initial_condition):
    # no output-error stage: this checks the offset regressor of SRIVC itself
    # (with a zero initial state and a zero, the B_hat-weighted step regressor)
    num, den, n, m, u, c, initial_state, y = _offset_data(case, initial_condition)
    est = tfest(u, y, TS, n, m, initial_condition=initial_condition, input_offset="estimate",
                refine=False)
    assert est.method == "srivc" and est.nfev_oe == 0
    assert est.success, est.message
    np.testing.assert_allclose(_theta(est.srivc_num, est.srivc_den), _theta(num, den), rtol=1e-8)
    assert est.input_offset == pytest.approx(c, rel=1e-8)


def test_oe_fit_estimates_input_offset_and_state():
    u = _binary_input(600, seed=6)
    initial_state = np.array([1.0, -0.5])
    y = simulate_tf(Z_NUM, Z_DEN, u - 0.25, TS, initial_state=initial_state)
    est = oe_fit(u, y, TS, [2.0, 4.0], [1.0, 1.0, 3.0], initial_condition="estimate",
                 input_offset="estimate")
    assert est.method == "oe" and est.success, est.message
    np.testing.assert_allclose(_theta(est.num, est.den), _theta(Z_NUM, Z_DEN), rtol=1e-8)
    assert est.input_offset == pytest.approx(-0.25, rel=1e-8)
    np.testing.assert_allclose(est.initial_state, initial_state, rtol=1e-6)


def test_input_offset_of_an_integrating_model():
    # the offset's response is a ramp: large next to the free response
    u = _binary_input(1000, seed=2)
    y = simulate_tf(P_NUM, P_DEN, u + 0.05, TS, initial_state=[0.1, 0.2, -3.0])
    est = tfest(u, y, TS, initial_condition="estimate", input_offset="estimate")
    assert est.success, est.message
    np.testing.assert_allclose(est.den[:3], P_DEN[:3], rtol=1e-8)
    np.testing.assert_allclose(est.num, P_NUM, rtol=1e-8)
    assert abs(est.den[3]) < 1e-8 * est.den[2]
    assert est.input_offset == pytest.approx(0.05, rel=1e-8)


def test_input_offset_standard_error_matches_the_spread():
    offsets, stds = [], []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        u = _binary_input(1000, hold=20, seed=seed)
        y = simulate_tf(Z_NUM, Z_DEN, u + 0.5, TS) + 0.1 * rng.standard_normal(1000)
        est = tfest(u, y, TS, n_poles=2, n_zeros=1, input_offset="estimate")
        assert est.success, est.message
        offsets.append(est.input_offset)
        stds.append(est.input_offset_std)
    ratio = np.std(offsets) / np.mean(stds)
    assert 0.5 < ratio < 2.0, ratio
    assert abs(np.mean(offsets) - 0.5) < 3 * np.mean(stds) / np.sqrt(12)


@pytest.mark.parametrize(("value", "typed"), [("random", "random"), (0.5, "0.5"), (None, "None"), (True, "True")])
def test_bad_input_offset_raises_value_error_naming_it(value, typed):
    u = _binary_input(100)
    message = f"^input_offset = {typed} is not allowed: use zero or estimate"
    with pytest.raises(ValueError, match=message):
        tfest(u, u, TS, input_offset=value)
    with pytest.raises(ValueError, match=message):
        oe_fit(u, u, TS, [1.0], [1.0, 1.0], input_offset=value)


def test_simulate_rejects_bad_input_offset():
    u = _binary_input(300, hold=10)
    est = tfest(u, simulate_tf([20.0], [1.0, 6.0, 20.0], u, TS), TS, n_poles=2)
    assert est.input_offset is None
    np.testing.assert_allclose(est.simulate(u, input_offset=0.0), est.simulate(u))
    with pytest.raises(ValueError, match=r"^input_offset = big is not allowed: must be None or a finite number"):
        est.simulate(u, input_offset="big")


def test_srivc_stops_once_two_starts_agree_and_finds_what_every_start_finds():
    """tfest's SRIVC stops trying starts once two converged ones reached the lowest cost: on a record
    where every start reaches one minimum, the same estimate from fewer iterations."""
    from eha_core.identify._oe_criterion import OutputError
    from eha_core.identify._srivc import default_lambdas, srivc_candidates

    rng = np.random.default_rng(3)
    u = np.repeat(rng.choice([-1.0, 1.0], 200), 5)
    y = simulate_tf([20.0], [1.0, 4.0, 20.0], u, 0.01) + 0.01 * rng.standard_normal(u.size)
    lambdas = default_lambdas(u.size, 0.01)
    starts, names = [("lambda", lam) for lam in lambdas], [f"{lam:g}" for lam in lambdas]
    criterion = OutputError(u, y, 0.01, 2, False)
    every, nit_every = srivc_candidates(criterion, 0, starts, names, 100, 1e-8)
    agreed, nit_agreed = srivc_candidates(criterion, 0, starts, names, 100, 1e-8, until_agreed=2)
    assert len(every) == len(lambdas) == 4 and len(agreed) == 2 and nit_agreed < nit_every
    best_every = min(every, key=lambda c: c[1])
    best_agreed = min(agreed, key=lambda c: c[1])
    assert best_agreed[1] == pytest.approx(best_every[1], rel=1e-6)
    np.testing.assert_allclose(best_agreed[0], best_every[0], rtol=1e-3)
    # a start that fails to converge never counts as agreeing
    assert len(srivc_candidates(criterion, 0, starts, names, 1, 1e-8, until_agreed=2)[0]) == 4
