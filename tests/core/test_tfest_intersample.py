"""The input's intersample behaviour (MATLAB's InterSample): held (zoh, the default) or linear (foh)."""

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from eha_core.identify._ctmodels import discretise
from eha_core.identify.tfest import oe_fit, simulate_tf, tfest
from eha_core.identify.validate import compare

TS = 0.01


def smooth_input(n=1000, seed=0):
    """A sum of sines: a smooth signal, sampled."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    return sum(np.sin(2 * np.pi * f * k * TS + rng.uniform(0, 6)) for f in np.linspace(0.2, 15, 12))


def linear_between_samples(num, den, u, ts, tau=0.0, upsample=200):
    """lsim of ``u`` linearly interpolated, delayed by ``tau`` (on the fine grid), from rest at t = 0.

    The input is zero before ``tau`` and jumps to ``u[0]`` there: lsim is started at ``tau``
    (its own interpolation would smear the jump over a fine step).
    """
    t = np.arange((u.size - 1) * upsample + 1) * ts / upsample
    start = round(tau / (ts / upsample))
    assert abs(start * ts / upsample - tau) < 1e-12
    v = np.interp(t - tau, np.arange(u.size) * ts, u)
    y = np.zeros(t.size)
    _, y[start:], _ = scipy.signal.lsim((num, den), v[start:], t[start:] - t[start], interp=True)
    return y[::upsample]


# -- simulation ----------------------------------------------------------------------------

@pytest.mark.parametrize("num, den", [
    ([400.0], [1.0, 16.0, 400.0]),
    ([2.0, 3.0, 20.0], [1.0, 6.0, 20.0]),   # a direct term
    ([5.0], [1.0, 2.0, 0.0]),               # an integrator
    ([3.0, 1.0], [1.0, 4.0, 3.0]),
    ([2.0], [1.0]),                         # a static gain
])
@pytest.mark.parametrize("tau_samples", [0.0, 3.0, 3.4, 0.375])
def test_simulate_foh_equals_lsim_of_the_linearly_interpolated_input(num, den, tau_samples):
    u = np.random.default_rng(0).standard_normal(60) + 1.0  # u[0] != 0: the start matters
    y = simulate_tf(num, den, u, TS, input_delay=tau_samples * TS, intersample="foh")
    ref = linear_between_samples(num, den, u, TS, tau_samples * TS)
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


def test_simulate_foh_without_delay_is_lsim_on_the_samples_themselves():
    # lsim(interp=True) is exact for an input linear between the points given
    u = smooth_input(300) + 0.5
    t = TS * np.arange(u.size)
    _, ref, _ = scipy.signal.lsim(([3.0, 20.0], [1.0, 6.0, 20.0]), u, t, interp=True)
    y = simulate_tf([3.0, 20.0], [1.0, 6.0, 20.0], u, TS, intersample="foh")
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12)
    # a step is the same step whatever the intersample behaviour
    ones = np.ones(300)
    np.testing.assert_allclose(simulate_tf([3.0, 20.0], [1.0, 6.0, 20.0], ones, TS, intersample="foh"),
                               simulate_tf([3.0, 20.0], [1.0, 6.0, 20.0], ones, TS), atol=1e-14)


def test_the_default_is_zoh_and_unchanged():
    u = np.repeat(np.random.default_rng(7).standard_normal(200), 5)
    y = simulate_tf([3.0, 20.0], [1.0, 6.0, 20.0], u + 0.1, TS, input_delay=0.026)
    np.testing.assert_array_equal(y, simulate_tf([3.0, 20.0], [1.0, 6.0, 20.0], u + 0.1, TS, input_delay=0.026,
                                                 intersample="zoh"))
    # known values (computed before intersample existed)
    np.testing.assert_allclose(y[[10, 100, 500, 999]], [0.04412772236669037, -0.48273454679240824,
                                                         -0.21067273122976637, 0.5783671720960528], rtol=1e-12)
    rng = np.random.default_rng(7)
    rng.standard_normal(200)
    y = y + 0.05 * np.std(y) * rng.standard_normal(u.size)
    est = tfest(u, y, TS, 2, 1, input_offset="estimate", input_delay=0.026)
    zoh = tfest(u, y, TS, 2, 1, input_offset="estimate", input_delay=0.026, intersample="zoh")
    for name in ("num", "den", "covariance"):
        np.testing.assert_array_equal(getattr(zoh, name), getattr(est, name))
    assert (zoh.cost, zoh.message, zoh.intersample, est.intersample) == (est.cost, est.message, "zoh", "zoh")
    # An iterative estimate: its last digits are the BLAS kernel's rounding. The solver stops when the cost
    # falls by less than tol = 1e-10 of itself, which leaves each coefficient free by about sqrt(tol N) = 3e-4
    # of its standard error (OpenBLAS's kernels here move them by up to 5e-5 of it). Each is pinned to a
    # thousandth of its own standard error (param_std is [den[1:], num]); the cost, flat at its minimum, to
    # 1e-8 (>= tol); the standard errors, which move with the estimate, to 1e-5.
    std = np.array([0.05347524893670936, 0.2459939008478595, 0.013147663592091, 0.27388525213961273])
    np.testing.assert_array_less(np.abs(est.num - [2.9761695540972988, 20.52423247704192]), 1e-3 * std[2:])
    np.testing.assert_array_less(np.abs(est.den[1:] - [6.081267326512156, 20.533682024647238]), 1e-3 * std[:2])
    assert est.den[0] == 1.0
    np.testing.assert_allclose(est.param_std, std, rtol=1e-5)
    assert est.cost == pytest.approx(0.09983344423889794, rel=1e-8)
    assert est.input_offset == pytest.approx(0.09912263577785124, rel=0, abs=1e-3 * 0.000484657591536)  # 1e-3 std


def test_a_held_model_is_the_default_discretisation():
    model = discretise(np.array([400.0]), np.array([1.0, 16.0, 400.0]), TS, 0.034)
    assert model.start_num is None
    assert discretise(np.array([400.0]), np.array([1.0, 16.0, 400.0]), TS, 0.034, "foh").start_num is not None


# -- estimation, noise-free -----------------------------------------------------------------

@pytest.mark.parametrize("refine", [False, True])
@pytest.mark.parametrize("num, den, tau", [
    ([400.0], [1.0, 16.0, 400.0], 0.0),
    ([400.0], [1.0, 16.0, 400.0], 0.034),
    ([3.0, 20.0], [1.0, 6.0, 20.0], 0.03),
])
@pytest.mark.parametrize("estimated", [False, True])
def test_foh_data_give_the_exact_model(refine, num, den, tau, estimated):
    # SRIVC alone is exact too: the input is filtered exactly for its interpolation, the
    # ramp before the start taken off; with an initial state and an offset (held: a step)
    u = smooth_input()
    n, m = len(den) - 1, len(num) - 1
    if estimated:
        y = simulate_tf(num, den, u + 0.2, TS, initial_state=np.r_[0.3, np.zeros(n - 1)], input_delay=tau,
                        intersample="foh")
        kwargs = {"initial_condition": "estimate", "input_offset": "estimate"}
    else:
        y = linear_between_samples(num, den, u, TS, tau)
        kwargs = {}
    est = tfest(u, y, TS, n, m, input_delay=tau, intersample="foh", refine=refine, **kwargs)
    assert est.success and est.intersample == "foh"
    np.testing.assert_allclose(est.den, den, rtol=1e-7)
    np.testing.assert_allclose(est.num, num, rtol=1e-7)
    if estimated:
        assert est.input_offset == pytest.approx(0.2, abs=1e-7)
        np.testing.assert_allclose(est.initial_state, np.r_[0.3, np.zeros(n - 1)], atol=1e-7)
    # the same data taken as held: off by several per cent
    held = tfest(u, y, TS, n, m, input_delay=tau, refine=refine, **kwargs)
    assert np.max(np.abs(held.den - den) / den) > 0.02


@pytest.mark.parametrize("tau_samples", [3.4, 7.0])
def test_an_estimated_delay_on_foh_data_is_exact(tau_samples):
    u = smooth_input()
    y = linear_between_samples([400.0], [1.0, 16.0, 400.0], u, TS, tau_samples * TS)
    est = tfest(u, y, TS, 2, input_delay="estimate", intersample="foh")
    assert est.success
    assert abs(est.input_delay / TS - tau_samples) < 1e-4
    np.testing.assert_allclose(est.den, [1.0, 16.0, 400.0], rtol=1e-6)
    np.testing.assert_allclose(est.num, [400.0], rtol=1e-6)


def test_oe_fit_takes_the_intersample_behaviour():
    u = smooth_input(600)
    y = linear_between_samples([3.0], [1.0, 1.5], u, TS)
    est = oe_fit(u, y, TS, [1.0], [1.0, 1.0], intersample="foh")
    np.testing.assert_allclose(est.num, [3.0], rtol=1e-7)
    np.testing.assert_allclose(est.den, [1.0, 1.5], rtol=1e-7)
    assert est.intersample == "foh"


def test_compare_simulate_and_to_dict_carry_it():
    u = smooth_input()
    y = linear_between_samples([400.0], [1.0, 16.0, 400.0], u, TS, 0.034)
    est = tfest(u, y, TS, 2, input_delay=0.034, intersample="foh")
    np.testing.assert_allclose(est.simulate(u), y, atol=1e-9)  # the estimate's own by default
    assert np.max(np.abs(est.simulate(u, intersample="zoh") - y)) > 1e-3
    res = compare(est.num, est.den, u, y, TS, input_delay=0.034, intersample="foh")
    assert res.fit_percent == pytest.approx(100.0, abs=1e-6) and res.intersample == "foh"
    assert compare(est.num, est.den, u, y, TS, input_delay=0.034).fit_percent < 99.0
    assert compare(est.num, est.den, u, y, TS).intersample == "zoh"
    assert est.to_dict()["intersample"] == "foh"
    assert tfest(u, y, TS, 2).to_dict()["intersample"] == "zoh"


# -- estimation with noise: bias and coverage -----------------------------------------------

#: (num, den, ts): b0 is 16-17 % low when the linear input is taken as held (a ts of 0.4 of the time constant)
NOISY_CASES = [([10.0], [1.0, 10.0], 0.04), ([1.0, 0.0], [1.0, 2.0, 10.0], 0.15)]
SEEDS = 40


@pytest.mark.parametrize("num, den, ts", NOISY_CASES)
def test_foh_makes_b0_unbiased_and_its_interval_honest(num, den, ts):
    # white samples, linear between them (lsim's interpolation), 10 % output noise, 400 samples
    n, m = len(den) - 1, len(num) - 1
    results = {"foh": [], "zoh": []}
    for seed in range(SEEDS):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal(400)
        _, y0, _ = scipy.signal.lsim((num, den), u, ts * np.arange(u.size), interp=True)
        y = y0 + 0.1 * np.std(y0) * rng.standard_normal(u.size)
        for hold, found in results.items():
            est = tfest(u, y, ts, n, m, intersample=hold)
            assert est.success
            found.append((est.num[0], est.param_std[n]))
    b0 = num[0]
    foh, zoh = np.array(results["foh"]), np.array(results["zoh"])
    error = foh[:, 0] - b0
    # unbiased: the mean error within 4 standard errors of the mean (about 0.1 % of b0 here)
    assert abs(error.mean()) < 4 * error.std(ddof=1) / np.sqrt(SEEDS)
    # the 95 % intervals cover b0 about 95 % of the time: at least the 0.1 % binomial quantile
    covered = int(np.sum(np.abs(error) <= 1.96 * foh[:, 1]))
    assert covered >= scipy.stats.binom.ppf(0.001, SEEDS, 0.95)  # 33 of 40
    # and are not too wide: the standard error near the spread over the seeds
    assert 0.7 < np.mean(foh[:, 1]) / error.std(ddof=1) < 1.4
    # taken as held, b0 is biased by many standard errors and the intervals miss it
    assert (zoh[:, 0].mean() - b0) / b0 < -0.1
    assert np.sum(np.abs(zoh[:, 0] - b0) <= 1.96 * zoh[:, 1]) <= 2


# -- refusals ------------------------------------------------------------------------------

def test_a_bad_intersample_is_refused_with_its_name():
    u = smooth_input(200)
    message = "intersample = linear is not allowed: use zoh (held between samples) or foh (linear between samples)"
    for call in (lambda: tfest(u, u, TS, 2, intersample="linear"),
                 lambda: oe_fit(u, u, TS, [1.0], [1.0, 1.0], intersample="linear"),
                 lambda: simulate_tf([1.0], [1.0, 1.0], u, TS, intersample="linear"),
                 lambda: compare([1.0], [1.0, 1.0], u, u, TS, intersample="linear")):
        with pytest.raises(ValueError) as info:
            call()
        assert str(info.value) == message
    with pytest.raises(ValueError, match=r"^intersample = None is not allowed"):
        tfest(u, u, TS, 2, intersample=None)
