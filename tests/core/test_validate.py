"""Tests of eha_core.identify.validate: ZOH simulation, fit, compare, ETFE, residuals."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from eha_core.identify.validate import (
    compare,
    etfe_periodic,
    fit_percent,
    frequency_response,
    residual_analysis,
    simulate_tf,
)

TS = 0.01
H_NUM = [2437.0]
H_DEN = [1.0, 430.1, 1.721e4, 2437.0]  # a pole near -385 rad/s, beyond pi/TS = 314 rad/s


def _binary_input(n, hold=5, seed=0):
    rng = np.random.default_rng(seed)
    return np.repeat(rng.choice([-1.0, 1.0], n // hold + 1), hold)[:n]


# --- simulate_tf -------------------------------------------------------------
def test_simulate_first_order_step_matches_analytic():
    k = np.arange(200)
    y = simulate_tf([3.0], [1.0, 2.0], np.ones(200), TS)
    np.testing.assert_allclose(y, 1.5 * (1.0 - np.exp(-2.0 * TS * k)), rtol=1e-12, atol=1e-15)


def test_simulate_matches_scipy_zoh_with_fast_pole():
    u = _binary_input(1000)
    num_z, den_z, _ = scipy.signal.cont2discrete((H_NUM, H_DEN), TS, method="zoh")
    expected = scipy.signal.lfilter(num_z.ravel(), den_z, u)
    np.testing.assert_allclose(simulate_tf(H_NUM, H_DEN, u, TS), expected,
                               rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def test_simulate_integrator_ramp():
    # P(s) = 1/s: a unit step held gives a ramp y(k ts) = k ts exactly
    y = simulate_tf([1.0], [1.0, 0.0], np.ones(50), TS)
    np.testing.assert_allclose(y, TS * np.arange(50), atol=1e-14)


def test_simulate_x0_is_output_and_derivatives_for_all_pole_model():
    initial_state = np.array([0.5, -3.0, 40.0])  # y(0), y'(0), y''(0)
    companion = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-2437.0, -1.721e4, -430.1]])
    expected = [(scipy.linalg.expm(companion * TS * k) @ initial_state)[0] for k in range(30)]
    y = simulate_tf(H_NUM, H_DEN, np.zeros(30), TS, initial_state=initial_state)
    np.testing.assert_allclose(y, expected, rtol=1e-10, atol=1e-13)


def test_simulate_biproper_and_static_models():
    u = _binary_input(100)
    # (s + 3)/(s + 1) = 1 + 2/(s + 1): feedthrough plus a first-order part
    y = simulate_tf([1.0, 3.0], [1.0, 1.0], u, TS)
    np.testing.assert_allclose(y, u + simulate_tf([2.0], [1.0, 1.0], u, TS), atol=1e-13)
    np.testing.assert_allclose(simulate_tf([6.0], [2.0], u, TS), 3.0 * u)


@pytest.mark.parametrize(("args", "kwargs", "message"), [
    (([1.0], [1.0, 1.0], np.ones(5), -0.1), {}, r"ts = -0.1 is not allowed: must be a finite sample time > 0 s"),
    (([1.0, 0.0, 0.0], [1.0, 1.0], np.ones(5), TS), {},
     r"num = \[1, 0, 0\] is not allowed: its degree 2 exceeds the degree 1 of den"),
    (([1.0], [0.0, 0.0], np.ones(5), TS), {}, r"den = \[0, 0\] is not allowed: .*non-zero coefficient"),
    (([1.0], [1.0, np.inf], np.ones(5), TS), {}, r"den = \[1, inf\] is not allowed: .*finite coefficients"),
    (([1.0], [1.0, 1.0], np.ones(5), TS), {"initial_state": [1.0, 2.0]},
     r"initial_state = \[1, 2\] is not allowed: must have shape \(1,\), one initial state per pole"),
    (([1.0], [1.0, 1.0], [1.0, np.nan], TS), {}, r"u = \[1, nan\] is not allowed: u\[1\] is nan"),
    (([1.0], [1.0, 1.0], np.r_[np.ones(20), np.inf], TS), {},
     r"u = an array of shape \(21,\) is not allowed: u\[20\] is inf"),
    (([1.0], [1.0, 1.0], 3.0, TS), {}, r"u = 3 is not allowed: must be an array of samples"),
    (([1.0], [1.0, 1.0], [], TS), {}, r"u = \[\] is not allowed: must hold at least one sample"),
    (([1.0], [1.0, 1.0], np.ones((3, 2)), TS), {}, r"u = an array of shape \(3, 2\) is not allowed: must be 1-D"),
])
def test_simulate_rejects_bad_arguments_naming_them_and_their_value(args, kwargs, message):
    with pytest.raises(ValueError, match="^" + message):
        simulate_tf(*args, **kwargs)


# --- fit_percent and compare ---------------------------------------------------
def test_fit_percent_matches_hand_computation():
    y = np.array([1.0, 3.0, 2.0, 6.0])
    y_hat = np.array([1.5, 2.0, 2.0, 5.0])
    # ||y - y_hat|| = sqrt(0.25 + 1 + 0 + 1) = 1.5; mean 3, ||y - 3|| = sqrt(4+0+1+9)
    expected = 100.0 * (1.0 - 1.5 / np.sqrt(14.0))
    assert fit_percent(y, y_hat) == pytest.approx(expected, rel=1e-14)
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0, abs=1e-12)


def test_fit_percent_per_column():
    y = np.column_stack([[1.0, 3.0, 2.0, 6.0], [0.0, 1.0, 0.0, 1.0]])
    y_hat = np.column_stack([[1.0, 3.0, 2.0, 6.0], [0.5, 0.5, 0.5, 0.5]])
    np.testing.assert_allclose(fit_percent(y, y_hat), [100.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match=r"^y_hat = \[1, 3, 2, 6\] is not allowed: it has shape \(4,\); "
                                         r"it must have the shape of y, \(4, 2\)"):
        fit_percent(y, y_hat[:, 0])


def test_compare_estimated_x0_recovers_state_and_beats_zero():
    u = _binary_input(600)
    initial_state = np.array([0.2, 1.5, -30.0])
    y = simulate_tf(H_NUM, H_DEN, u, TS, initial_state=initial_state)
    zero = compare(H_NUM, H_DEN, u, y, TS)
    est = compare(H_NUM, H_DEN, u, y, TS, initial_condition="estimate")
    assert zero.initial_condition == "zero" and zero.initial_state is None
    assert est.initial_condition == "estimate"
    assert est.fit_percent >= zero.fit_percent
    assert zero.fit_percent < 99.0
    assert est.fit_percent == pytest.approx(100.0, abs=1e-8)
    np.testing.assert_allclose(est.initial_state, initial_state, rtol=1e-6)
    given = compare(H_NUM, H_DEN, u, y, TS, initial_condition=initial_state)
    assert given.initial_condition == "given"
    np.testing.assert_allclose(given.y_hat, y, atol=1e-12)


def test_compare_estimate_never_worse_on_noisy_data():
    rng = np.random.default_rng(3)
    u = _binary_input(400, seed=3)
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, TS) + 0.1 * rng.standard_normal(400)
    zero = compare([20.0], [1.0, 6.0, 20.0], u, y, TS)
    est = compare([20.0], [1.0, 6.0, 20.0], u, y, TS, initial_condition="estimate")
    assert est.fit_percent >= zero.fit_percent


def test_compare_result_is_frozen_and_validates():
    u = _binary_input(50)
    res = compare([1.0], [1.0, 1.0], u, u, TS)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.fit_percent = 1.0
    with pytest.raises(ValueError, match=r"^initial_condition = guess is not allowed: use zero, estimate or"):
        compare([1.0], [1.0, 1.0], u, u, TS, initial_condition="guess")
    with pytest.raises(ValueError, match=r"^initial_condition = \[1, 2\] is not allowed: .*shape \(1,\)"):
        compare([1.0], [1.0, 1.0], u, u, TS, initial_condition=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"^y = an array of shape \(49,\) is not allowed: it has 49 samples "
                                         r"where u has 50"):
        compare([1.0], [1.0, 1.0], u, u[:-1], TS)


# --- frequency response and ETFE --------------------------------------------------
def test_frequency_response_first_order_and_unwrapped_phase():
    fr = frequency_response([1.0], [1.0, 1.0], [1.0])
    assert fr.magnitude_db[0] == pytest.approx(-10 * np.log10(2.0), rel=1e-12)
    assert fr.phase_deg[0] == pytest.approx(-45.0, rel=1e-12)
    w = np.logspace(-3, 5, 400)
    bode = frequency_response(H_NUM, H_DEN, w)
    assert np.all(np.diff(bode.phase_deg) < 0)  # monotone: no wrap jumps
    assert bode.phase_deg[-1] == pytest.approx(-270.0, abs=0.5)
    assert bode.magnitude_db[0] == pytest.approx(0.0, abs=1e-3)


def _multisine(period, bins, seed=0):
    rng = np.random.default_rng(seed)
    k = np.arange(period)
    return sum(np.cos(2 * np.pi * b * k / period + rng.uniform(0, 2 * np.pi)) for b in bins)


def test_etfe_periodic_equals_true_response_after_dropping_transient():
    # the slowest pole (-0.142 rad/s) needs ~120 s to settle to 1e-7: drop 12
    # periods of 10 s, average the next 2
    period, n_periods = 1000, 14
    bins = np.arange(1, 300, 7)
    u = np.tile(_multisine(period, bins), n_periods)
    y = simulate_tf(H_NUM, H_DEN, u, TS)
    est = etfe_periodic(u, y, period, TS, drop_periods=12)
    np.testing.assert_allclose(est.w, 2 * np.pi * bins / (period * TS))
    # the sampled response of a ZOH-driven system in periodic steady state is
    # exactly the ZOH-equivalent discrete transfer function at those bins
    num_z, den_z, _ = scipy.signal.cont2discrete((H_NUM, H_DEN), TS, method="zoh")
    _, g_zoh = scipy.signal.freqz(num_z.ravel(), den_z, worN=2 * np.pi * bins / period)
    np.testing.assert_allclose(est.response, g_zoh, rtol=1e-6)
    # and it is close to the continuous-time H(jw) at low frequency (the ZOH
    # adds half a sample of delay): check the magnitude within 1 % below 10 rad/s
    true = frequency_response(H_NUM, H_DEN, est.w)
    low = est.w < 10
    np.testing.assert_allclose(np.abs(est.response[low]), np.abs(true.response[low]), rtol=1e-2)
    # keeping the transient visibly spoils the slowly settling bins
    with_transient = etfe_periodic(u, y, period, TS, drop_periods=1)
    assert np.max(np.abs(with_transient.response / g_zoh - 1)) > 1e-3


def test_etfe_periodic_explicit_frequencies_and_errors():
    period = 600  # 6 s: the transient of poles at -3 +/- 3.3j rad/s decays to 1e-8
    u = np.tile(_multisine(period, [2, 5]), 3)
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, TS)
    est = etfe_periodic(u, y, period, TS, freqs=[2 * np.pi * 5 / period], drop_periods=1)
    num_z, den_z, _ = scipy.signal.cont2discrete(([20.0], [1.0, 6.0, 20.0]), TS)
    _, g = scipy.signal.freqz(num_z.ravel(), den_z, worN=[2 * np.pi * 5 / period])
    np.testing.assert_allclose(est.response, g, rtol=1e-6)
    with pytest.raises(ValueError, match=r"^period = 1 is not allowed: must be a whole number of samples in "
                                         r"\[2, 1800\]"):
        etfe_periodic(u, y, 1, TS)
    with pytest.raises(ValueError, match=r"^drop_periods = 1 is not allowed: must be a whole number in \[0, 0\]"):
        etfe_periodic(u[:900], y[:900], period, TS, drop_periods=1)
    with pytest.raises(ValueError, match=r"^freqs = \[4\] is not allowed: .*rad/sample in \(0, pi\]"):
        etfe_periodic(u, y, period, TS, freqs=[4.0])
    with pytest.raises(ValueError, match=r"^threshold = 1.5 is not allowed: .*\[0, 1\)"):
        etfe_periodic(u, y, period, TS, threshold=1.5)


# --- residual analysis -------------------------------------------------------------
def test_residual_analysis_white_noise_passes():
    rng = np.random.default_rng(1)
    res = residual_analysis(rng.standard_normal(3000), rng.standard_normal(3000), max_lag=20)
    assert res.whiteness_ok and res.independence_ok
    assert res.autocorrelation[0] == pytest.approx(1.0)
    assert res.lags.tolist() == list(range(21))
    assert res.cross_lags.tolist() == list(range(-20, 21))
    assert res.confidence_bound == pytest.approx(2.58 / np.sqrt(3000))


def test_residual_analysis_coloured_and_correlated_fail():
    rng = np.random.default_rng(2)
    white = rng.standard_normal(3000)
    coloured = scipy.signal.lfilter([1.0], [1.0, -0.9], white)
    assert not residual_analysis(coloured, rng.standard_normal(3000)).whiteness_ok
    # residual that still contains the input delayed by 3 samples
    u = rng.standard_normal(3000)
    e = 0.5 * np.roll(u, 3) + rng.standard_normal(3000)
    res = residual_analysis(e, u, max_lag=10)
    assert res.whiteness_ok and not res.independence_ok
    assert res.cross_lags[np.argmax(np.abs(res.cross_correlation))] == 3


def test_residual_analysis_rejects_bad_arguments():
    e = np.ones(10)
    with pytest.raises(ValueError, match=r"^max_lag = 10 is not allowed: must be a whole number in \[1, 9\]"):
        residual_analysis(e, e, max_lag=10)
    with pytest.raises(ValueError, match=r"^u = \[1, 1, 1, 1, 1\] is not allowed: it has 5 samples where e has 10"):
        residual_analysis(e, e[:5])
    with pytest.raises(ValueError, match=r"^e = an array of shape \(10,\) is not allowed: it is constant, zero "
                                         r"after removing its mean"):
        residual_analysis(e, np.arange(10.0), max_lag=3, remove_mean=True)
    with pytest.raises(ValueError, match=r"^u = an array of shape \(10,\) is not allowed: it is identically zero"):
        residual_analysis(np.arange(10.0), np.zeros(10), max_lag=3)


# --- compare with an input offset ---------------------------------------------------
@pytest.mark.parametrize("initial_condition", ["zero", "estimate"])
def test_compare_estimates_input_offset(initial_condition):
    u = _binary_input(600, seed=2)
    initial_state = np.array([0.2, 1.5, -30.0]) if initial_condition == "estimate" else None
    y = simulate_tf(H_NUM, H_DEN, u - 0.35, TS, initial_state=initial_state)
    res = compare(H_NUM, H_DEN, u, y, TS, initial_condition=initial_condition,
                  input_offset="estimate")
    assert res.input_offset == pytest.approx(-0.35, rel=1e-8)
    assert res.fit_percent == pytest.approx(100.0, abs=1e-8)
    if initial_state is not None:  # estimated jointly with the offset
        np.testing.assert_allclose(res.initial_state, initial_state, rtol=1e-6)
    # without the offset the same model fits these data much worse
    plain = compare(H_NUM, H_DEN, u, y, TS, initial_condition=initial_condition)
    assert plain.input_offset is None
    assert plain.fit_percent < 90.0


def test_compare_with_given_input_offset():
    u = _binary_input(400, seed=5)
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u + 0.1, TS)
    res = compare([20.0], [1.0, 6.0, 20.0], u, y, TS, input_offset=0.1)
    assert res.input_offset == 0.1
    np.testing.assert_allclose(res.y_hat, y, atol=1e-12)
    # None means no offset, like "zero" (so an estimate's None can be passed on)
    none = compare([20.0], [1.0, 6.0, 20.0], u, y, TS, input_offset=None)
    zero = compare([20.0], [1.0, 6.0, 20.0], u, y, TS)
    assert none.input_offset is None and none.fit_percent == zero.fit_percent < 99.0
    # a given initial state and an estimated offset
    initial_state = np.array([0.3, -1.0])
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u + 0.1, TS, initial_state=initial_state)
    res = compare([20.0], [1.0, 6.0, 20.0], u, y, TS, initial_condition=initial_state,
                  input_offset="estimate")
    assert res.initial_condition == "given"
    assert res.input_offset == pytest.approx(0.1, rel=1e-9)


@pytest.mark.parametrize(("value", "typed"), [("guess", "guess"), (float("nan"), "nan"), (float("inf"), "inf"),
                                             (True, "True"), ([0.1, 0.2], r"\[0.1, 0.2\]")])
def test_compare_rejects_bad_input_offset(value, typed):
    u = _binary_input(50)
    with pytest.raises(ValueError, match=f"^input_offset = {typed} is not allowed: use zero, estimate, None or a "
                                         "finite number"):
        compare([1.0], [1.0, 1.0], u, u, TS, input_offset=value)


def test_a_diverging_model_prints_nothing_from_lapack(capfd):
    """NaN columns (a diverging model's free responses, inf - inf) went to LAPACK, which printed
    "On entry to DLASCL parameter number 4 had an illegal value" to the server's stderr (long random walk)."""
    from eha_core.identify._ctmodels import fit_linear_terms
    from eha_core.identify.validate import compare

    cols = np.ones((50, 2))
    cols[3, 1] = np.nan
    assert np.isnan(fit_linear_terms(cols, np.ones(50))).all()
    cols[3, 1] = np.inf
    assert np.isnan(fit_linear_terms(cols, np.ones(50))).all()
    # a model whose response overflows on a long record, compared with its initial state fitted
    u = np.ones(4000)
    with pytest.raises(ValueError, match="finite"):       # refused with a message, as before
        compare([1.0], [1.0, -400.0], u, np.zeros(4000), 0.01, initial_condition="estimate",
                input_offset="estimate")
    out, err = capfd.readouterr()
    assert "DLASCL" not in out + err and "illegal value" not in out + err
