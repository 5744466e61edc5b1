"""Input delay of tfest (MATLAB's IODelay): exact simulation, fixed and estimated delays."""

import numpy as np
import pytest
import scipy.signal

from eha_core.identify._ctmodels import frequency_response, simulate_tf
from eha_core.identify.tfest import TFEstimate, tfest
from eha_core.identify.validate import compare

TS = 0.01
NUM, DEN = [400.0], [1.0, 16.0, 400.0]  # 20 rad/s, damping 0.4
#: the paper's closed loop H(s) (eq. 24): a pole at -390 rad/s, 0.26 samples, trades off with a delay
H_NUM, H_DEN = [2437.0], [1.0, 430.1, 1.721e4, 2437.0]


def rich_input(n=1000, hold=5, seed=0):
    """A random level held for ``hold`` samples: broadband up to about a tenth of Nyquist and beyond."""
    rng = np.random.default_rng(seed)
    return np.repeat(rng.standard_normal(n // hold), hold)


def brute_force(num, den, u, ts, tau, upsample=40):
    """lsim on a finely sampled, delayed, held input (the delay a whole number of fine steps)."""
    shift = tau / ts * upsample
    assert abs(shift - round(shift)) < 1e-9
    fine = np.repeat(u, upsample)
    delayed = np.r_[np.zeros(round(shift)), fine[:fine.size - round(shift)]]
    t = np.arange(fine.size) * ts / upsample
    _, y, _ = scipy.signal.lsim((num, den), delayed, t, interp=False)
    return y[::upsample]


# -- simulation ----------------------------------------------------------------------------

@pytest.mark.parametrize("num, den, tau_samples", [
    (NUM, DEN, 3.4),                     # the brief's case
    (NUM, DEN, 0.375),                   # less than a sample
    ([2.0, 3.0, 20.0], [1.0, 6.0, 20.0], 3.4),  # a direct term: it sees u[k-d-1]
    ([5.0], [1.0, 2.0, 0.0], 2.95),      # an integrator
    (NUM, DEN, 7.0),                     # a whole number of samples
])
def test_simulate_with_a_delay_equals_a_brute_force_reference(num, den, tau_samples):
    u = rich_input(300)
    y = simulate_tf(num, den, u, TS, input_delay=tau_samples * TS)
    ref = brute_force(num, den, u, TS, tau_samples * TS)
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-11 * np.max(np.abs(ref)))


def test_a_whole_sample_delay_is_an_exact_shift_and_zero_changes_nothing():
    u = rich_input(300)
    y0 = simulate_tf(NUM, DEN, u, TS)
    # 3 * 0.01 / 0.01 is 2.9999999999999996 in floating point: still a pure shift
    np.testing.assert_array_equal(simulate_tf(NUM, DEN, u, TS, input_delay=3 * TS), np.r_[np.zeros(3), y0[:-3]])
    np.testing.assert_array_equal(simulate_tf(NUM, DEN, u, TS, input_delay=0.0), y0)
    np.testing.assert_array_equal(simulate_tf(NUM, DEN, u, TS, input_delay=500 * TS), np.zeros(u.size))


def test_the_delay_acts_on_the_input_not_on_the_initial_state():
    u = rich_input(300)
    y = simulate_tf(NUM, DEN, u, TS, initial_state=[0.3, -1.0], input_delay=2.5 * TS)
    free = simulate_tf(NUM, DEN, np.zeros(u.size), TS, initial_state=[0.3, -1.0])
    np.testing.assert_allclose(y - free, simulate_tf(NUM, DEN, u, TS, input_delay=2.5 * TS), atol=1e-13)


def test_the_frequency_response_phase_includes_minus_w_tau():
    w = np.logspace(-1, 3, 200)
    tau = 3.4 * TS
    plain = frequency_response(NUM, DEN, w)
    delayed = frequency_response(NUM, DEN, w, input_delay=tau)
    np.testing.assert_allclose(delayed.phase_deg, plain.phase_deg - np.degrees(w * tau), rtol=0, atol=1e-9)
    np.testing.assert_allclose(delayed.response, plain.response * np.exp(-1j * w * tau), rtol=1e-13)
    np.testing.assert_array_equal(delayed.magnitude_db, plain.magnitude_db)
    # right even where the points are too sparse to unwrap the delayed response: -360 deg per step
    sparse = frequency_response(NUM, DEN, [1.0, 1.0 + 2 * np.pi / tau], input_delay=tau)
    assert sparse.phase_deg[1] - sparse.phase_deg[0] < -360.0


# -- estimation ----------------------------------------------------------------------------

def test_delay_zero_gives_exactly_the_delay_free_estimate():
    u = rich_input()
    rng = np.random.default_rng(1)
    y = simulate_tf(NUM, DEN, u + 0.1, TS) + 0.01 * rng.standard_normal(u.size)
    kwargs = {"initial_condition": "estimate", "input_offset": "estimate"}
    plain = tfest(u, y, TS, 2, **kwargs)
    zero = tfest(u, y, TS, 2, input_delay=0.0, **kwargs)
    for name in ("num", "den", "covariance", "initial_state"):
        np.testing.assert_array_equal(getattr(zero, name), getattr(plain, name))
    assert (zero.fit_percent, zero.input_offset, zero.message) == (plain.fit_percent, plain.input_offset,
                                                                   plain.message)
    assert plain.input_delay == 0.0 and plain.input_delay_std is None
    np.testing.assert_array_equal(plain.simulate(u), simulate_tf(plain.num, plain.den, u, TS))


@pytest.mark.parametrize("refine", [True, False])
def test_a_fixed_correct_delay_gives_the_true_coefficients(refine):
    u = rich_input()
    tau = 3.4 * TS
    y = simulate_tf(NUM, DEN, u, TS, input_delay=tau)
    est = tfest(u, y, TS, 2, input_delay=tau, refine=refine)
    # SRIVC alone is exact too: the delayed input is filtered exactly
    np.testing.assert_allclose(est.den, DEN, rtol=1e-8)
    np.testing.assert_allclose(est.num, NUM, rtol=1e-8)
    assert est.input_delay == tau and est.input_delay_std is None
    assert est.fit_percent == pytest.approx(100.0, abs=1e-6)
    # without the delay the same data fit worse
    assert tfest(u, y, TS, 2).fit_percent < 99.0


def test_a_fixed_delay_with_a_zero_an_offset_and_an_initial_state():
    u = rich_input()
    num, den, tau = [3.0, 20.0], [1.0, 6.0, 20.0], 2.6 * TS
    y = simulate_tf(num, den, u - 0.3, TS, initial_state=[0.5, 0.0], input_delay=tau)
    est = tfest(u, y, TS, 2, 1, initial_condition="estimate", input_offset="estimate", input_delay=tau)
    np.testing.assert_allclose(est.den, den, rtol=1e-7)
    np.testing.assert_allclose(est.num, num, rtol=1e-7)
    assert est.input_offset == pytest.approx(-0.3, abs=1e-7)
    np.testing.assert_allclose(est.initial_state, [0.5, 0.0], atol=1e-7)


@pytest.mark.parametrize("tau_samples", [3.4, 7.0, 0.0])
def test_an_estimated_delay_is_exact_on_noise_free_data(tau_samples):
    u = rich_input()
    y = simulate_tf(NUM, DEN, u, TS, input_delay=tau_samples * TS)
    est = tfest(u, y, TS, 2, input_delay="estimate")
    assert est.success
    assert abs(est.input_delay / TS - tau_samples) < 1e-4
    np.testing.assert_allclose(est.den, DEN, rtol=1e-6)
    np.testing.assert_allclose(est.num, NUM, rtol=1e-6)
    assert est.input_delay_std is not None and est.input_delay_std < 1e-3 * TS
    assert "input delay estimated" in est.message


@pytest.mark.parametrize("tau_samples, seed", [(3.4, 2), (7.0, 3)])
def test_an_estimated_delay_with_output_noise(tau_samples, seed):
    u = rich_input(seed=seed)
    y0 = simulate_tf(NUM, DEN, u, TS, input_delay=tau_samples * TS)
    y = y0 + 0.05 * np.std(y0) * np.random.default_rng(seed).standard_normal(u.size)
    est = tfest(u, y, TS, 2, input_delay="estimate")
    error = est.input_delay / TS - tau_samples
    assert abs(error) < 0.2       # well within one sample; about 0.01 in practice
    assert abs(error) < 5 * est.input_delay_std / TS   # and the standard error is honest
    np.testing.assert_allclose(est.den, DEN, rtol=0.02)


def stiff_case_sines():
    rng = np.random.default_rng(3)
    k = np.arange(1000)
    u = sum(np.sin(2 * np.pi * f * k * TS + rng.uniform(0, 6)) for f in np.linspace(0.1, 20, 30)) / 5
    y0 = simulate_tf(H_NUM, H_DEN, u + 0.2, TS, initial_state=[0.05, 0, 0], input_delay=3.4 * TS)
    rng.standard_normal(k.size)
    return u, y0 + 0.02 * np.std(y0) * rng.standard_normal(k.size)


def stiff_case_held():
    rng = np.random.default_rng(1)
    u = np.repeat(rng.standard_normal(200), 5)
    y0 = simulate_tf(H_NUM, H_DEN, u, TS, input_delay=3.4 * TS)
    return u, y0 + 0.05 * np.std(y0) * rng.standard_normal(u.size)


@pytest.mark.parametrize("case", [stiff_case_sines, stiff_case_held])
def test_a_delay_traded_off_against_a_fast_pole_is_within_a_sample(case):
    # With noise, ARX puts these delays at 5 samples (3.4 true); too long a
    # delay makes SRIVC end in unstable models whose costs point the wrong
    # way (the second case once walked up to 12 samples): the whole-sample
    # search must walk down to the stable ones.
    u, y = case()
    est = tfest(u, y, TS, 3, initial_condition="estimate", input_offset="estimate", input_delay="estimate")
    assert est.success
    assert abs(est.input_delay / TS - 3.4) < 1.0
    assert np.all(est.poles().real < 0)
    assert est.fit_percent > 90.0  # the noise alone keeps it under 95 %


def test_the_estimate_carries_its_delay_to_simulate_frequency_response_compare_and_to_dict():
    u = rich_input()
    tau = 3.4 * TS
    y = simulate_tf(NUM, DEN, u, TS, input_delay=tau)
    est = tfest(u, y, TS, 2, input_delay="estimate")
    np.testing.assert_allclose(est.simulate(u), y, atol=1e-9)
    w = np.array([1.0, 10.0, 100.0])
    np.testing.assert_allclose(est.frequency_response(w).phase_deg,
                               frequency_response(est.num, est.den, w).phase_deg - np.degrees(w * est.input_delay))
    assert compare(est.num, est.den, u, y, TS, input_delay=est.input_delay).fit_percent == pytest.approx(100, abs=1e-6)
    assert compare(est.num, est.den, u, y, TS).fit_percent < 99.0
    assert compare(est.num, est.den, u, y, TS, input_delay=tau).input_delay == tau
    data = est.to_dict()
    assert data["input_delay"] == pytest.approx(tau, abs=1e-9) and data["input_delay_std"] >= 0.0
    assert tfest(u, y, TS, 2, input_delay=tau).to_dict()["input_delay_std"] is None
    assert "does not" in TFEstimate.tf.__doc__ and "delay" in TFEstimate.tf.__doc__


def test_max_delay_bounds_the_search():
    u = rich_input()
    y = simulate_tf(NUM, DEN, u, TS, input_delay=7.0 * TS)
    est = tfest(u, y, TS, 2, input_delay="estimate", max_delay=4 * TS)
    assert est.input_delay <= 4 * TS + 1e-15


def test_a_failed_estimate_of_the_delay_is_data():
    est = tfest(np.zeros(200), np.zeros(200), TS, 2, input_delay="estimate")
    assert not est.success and np.isnan(est.input_delay) and np.isnan(est.input_delay_std)


@pytest.mark.parametrize("kwargs, message", [
    ({"input_delay": -0.01}, "input_delay = -0.01 is not allowed: must be a finite delay >= 0 s"),
    ({"input_delay": np.nan}, "input_delay = nan is not allowed: must be a finite delay >= 0 s"),
    ({"input_delay": True}, "input_delay = True is not allowed: must be a finite delay >= 0 s"),
    ({"input_delay": "soon"}, "input_delay = soon is not allowed: use a delay >= 0 s or estimate"),
    ({"input_delay": 1.5}, "input_delay = 1.5 is not allowed: must be at most half the record, "
                           "N ts / 2 = 1 s"),
    ({"input_delay": 0.02, "max_delay": 0.1}, "max_delay = 0.1 is not allowed: bounds an estimated delay: "
                                              "give it with input_delay = estimate"),
    ({"input_delay": "estimate", "max_delay": 0}, "max_delay = 0 is not allowed: must be a delay > 0 s"),
    ({"input_delay": "estimate", "max_delay": 2.0}, "max_delay = 2 is not allowed: must be at most half"),
])
def test_bad_delays_are_refused_with_their_name(kwargs, message):
    u = rich_input(200)
    with pytest.raises(ValueError) as info:
        tfest(u, u, TS, 2, **kwargs)
    assert str(info.value).startswith(message)


def test_bad_delays_elsewhere():
    with pytest.raises(ValueError, match=r"^input_delay = -1 is not allowed"):
        simulate_tf(NUM, DEN, np.ones(5), TS, input_delay=-1)
    with pytest.raises(ValueError, match=r"^input_delay = x is not allowed"):
        compare(NUM, DEN, np.ones(5), np.ones(5), TS, input_delay="x")
    with pytest.raises(ValueError, match=r"^input_delay = inf is not allowed"):
        frequency_response(NUM, DEN, [1.0], input_delay=np.inf)


# -- a delay search with several local minima ----------------------------------------------

#: a right-half-plane zero behind 8 s, sampled at 0.5 s: its initial undershoot is mimicked by
#: a longer delay (about 9.4 s) with a zero in the left half-plane, a second local minimum
RHP_NUM, RHP_DEN, RHP_TS, RHP_TAU = [-1.0, 1.0], [1.0, 1.0, 1.0], 0.5, 8.0


def rhp_case(seed, snr_db=5.0, n=600, ts=RHP_TS, hold=4):
    """A random binary level held ``hold`` samples, output noise at ``snr_db`` (signal over noise variance)."""
    rng = np.random.default_rng(seed)
    u = np.repeat(np.sign(rng.standard_normal(n // hold)), hold)
    y0 = simulate_tf(RHP_NUM, RHP_DEN, u, ts, input_delay=RHP_TAU)
    return u, y0 + np.std(y0) / 10 ** (snr_db / 20) * rng.standard_normal(n)


@pytest.mark.parametrize("seed", [5, 16, 27])
def test_the_delay_search_finds_the_lower_of_two_local_minima(seed):
    # Before the sweep of the whole range, ARX pointed at 9.5 s and the local search stopped
    # there: seed 5 returned success at 9.42 s with a cost of 115.1, against 109.6 with the
    # delay fixed at the true 8 s (17 of 200 seeds of rhp_case failed so).
    u, y = rhp_case(seed)
    est = tfest(u, y, RHP_TS, 2, 1, input_delay="estimate")
    at_true_delay = tfest(u, y, RHP_TS, 2, 1, input_delay=RHP_TAU)
    assert est.success
    assert abs(est.input_delay - RHP_TAU) < 0.5 * RHP_TS
    assert est.cost <= at_true_delay.cost * (1 + 1e-4)
    assert est.num[0] < 0  # the zero in the right half-plane


def test_a_coarse_sweep_of_a_long_range_is_descended_to_the_right_minimum():
    # ts = 0.1 s, 3000 samples: max_delay is 300 samples, swept every 3rd; before the
    # sweep 20 of 20 seeds ended near 9.3 s (seed 0: 9.32 s, cost 611.2 against 550.4 at 8 s)
    ts = 0.1
    u, y = rhp_case(0, n=3000, ts=ts, hold=20)
    est = tfest(u, y, ts, 2, 1, input_delay="estimate")
    at_true_delay = tfest(u, y, ts, 2, 1, input_delay=RHP_TAU)
    assert est.success and abs(est.input_delay - RHP_TAU) < 0.5 * ts
    assert est.cost <= at_true_delay.cost * (1 + 1e-4)


def capture_candidates(monkeypatch):
    """Record what the delay search hands to the output-error stage."""
    import eha_core.identify.tfest as tfest_module

    seen = {}

    def recording(*args, **kwargs):
        seen["candidates"], seen["nit"], seen["basins"] = tfest_module_delay_candidates(*args, **kwargs)
        return seen["candidates"], seen["nit"], seen["basins"]

    tfest_module_delay_candidates = tfest_module.delay_candidates
    monkeypatch.setattr(tfest_module, "delay_candidates", recording)
    return seen


@pytest.mark.parametrize("seed", [5, 62])
def test_the_returned_cost_is_at_most_every_candidates(monkeypatch, seed):
    seen = capture_candidates(monkeypatch)
    u, y = rhp_case(seed)
    est = tfest(u, y, RHP_TS, 2, 1, input_delay="estimate")
    costs = [c[1] for c in seen["candidates"]]
    assert len(costs) > 20 and len(seen["basins"]) >= 1  # the range was swept
    assert est.cost <= min(costs) * (1 + 1e-12)
    # the basins are local minima of the swept cost, the lowest first
    basin_costs = [b[1] for b in seen["basins"]]
    assert basin_costs == sorted(basin_costs) and basin_costs[0] == pytest.approx(min(costs), rel=1e-12)


def test_a_refinement_that_ends_worse_than_a_candidate_keeps_the_candidate(monkeypatch):
    # an output-error stage that walks away to a worse model (here forced) must not be
    # reported: the lowest candidate of the search is kept, with SRIVC's own success
    import eha_core.identify.tfest as tfest_module

    seen = capture_candidates(monkeypatch)

    def worse(criterion, theta0, n, m, max_nfev, tol):
        theta = theta0.copy()
        theta[:-1] *= 1.2
        return theta, criterion.cost(theta), True, "forced worse"

    monkeypatch.setattr(tfest_module, "oe_refine", worse)
    u, y = rhp_case(5)
    est = tfest(u, y, RHP_TS, 2, 1, input_delay="estimate")
    assert est.method == "srivc" and "kept the SRIVC estimate" in est.message
    assert est.cost == pytest.approx(min(c[1] for c in seen["candidates"]), rel=1e-12)
    assert abs(est.input_delay - RHP_TAU) < 0.5 * RHP_TS


# -- a lightly damped third-order plant: the search is right or says it may not be ----------

#: third-order plants behind 3.7 samples of 0.01 s (benchmarks/bench_tfest_delay.py's THIRD_PLANTS):
#: a 20 rad/s resonance, damping 0.1 / 0.2 / 0.4, and a real pole
THIRD = {"z0.1": ([20000.0], [1.0, 54.0, 600.0, 20000.0]),
         "z0.2": ([20000.0], [1.0, 58.0, 800.0, 20000.0]),
         "z0.4": ([2000.0], [1.0, 21.0, 480.0, 2000.0])}
THIRD_TAU = 3.7 * TS


def third_case(plant, seed, snr_db):
    """1000 samples of a random level held 5 samples, white output noise at ``snr_db``."""
    num, den = THIRD[plant]
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.standard_normal(200), 5)
    y0 = simulate_tf(num, den, u, TS, input_delay=THIRD_TAU)
    return u, y0 + np.std(y0) / 10 ** (snr_db / 20) * rng.standard_normal(u.size)


@pytest.mark.parametrize("plant, seed", [("z0.1", 1), ("z0.1", 12), ("z0.2", 4)])
def test_a_delay_search_that_was_confidently_wrong_is_right_or_says_so(plant, seed):
    # Before the default starts were tried over the whole range, these records (5 dB) ended
    # with success at 20 to 68 samples, 2.2 to 3.7 times the cost at the true 3.7 samples: the
    # local search from ARX's delay (8 samples) had converged to a poor model whose sweep was
    # carried down to the true delay, never reaching the model that fits there.
    u, y = third_case(plant, seed, 5.0)
    est = tfest(u, y, TS, 3, input_delay="estimate")
    at_true_delay = tfest(u, y, TS, 3, input_delay=THIRD_TAU)
    right = est.cost <= at_true_delay.cost * (1 + 1e-4)
    assert right or not est.success
    assert right  # and, since the fresh starts, right
    assert abs(est.input_delay - THIRD_TAU) < 1.5 * TS  # 5 dB: the delay's own spread is about half a sample
    # the noise variance of a right answer is the noise's: near the floor of a long linear model
    assert 0.8 < est.noise_variance / est.noise_floor < 1.25


@pytest.mark.parametrize("seed", [0, 1])
def test_the_well_damped_plant_at_10_db_is_still_right(seed):
    u, y = third_case("z0.4", seed, 10.0)
    est = tfest(u, y, TS, 3, input_delay="estimate")
    at_true_delay = tfest(u, y, TS, 3, input_delay=THIRD_TAU)
    assert est.success and est.optimizer_success
    assert est.cost <= at_true_delay.cost * (1 + 1e-4)
    assert abs(est.input_delay - THIRD_TAU) < TS


def test_a_search_held_in_a_wrong_minimum_is_not_a_success(monkeypatch):
    # The search is forced to a wrong basin (only delays of 15 samples and more are kept, here
    # and in the second, wider search): the answer fits markedly worse than a long linear model
    # of the record, so it is not claimed; the message says what to try, and the optimiser's
    # own flag is kept apart.
    import eha_core.identify.tfest as tfest_module

    real = tfest_module.delay_candidates
    calls = []

    def late_only(*args, **kwargs):
        candidates, nit, basins = real(*args, **kwargs)
        calls.append(kwargs.get("everywhere", False))
        late = [c for c in candidates if c[0][-1] >= 15 * TS]
        return late, nit, [b for b in basins if b[0][-1] >= 15 * TS] or late[:1]

    monkeypatch.setattr(tfest_module, "delay_candidates", late_only)
    u, y = third_case("z0.1", 1, 5.0)
    est = tfest(u, y, TS, 3, input_delay="estimate", max_delay=30 * TS)  # a short range: a quick second search
    assert est.input_delay > 10 * TS
    assert not est.success and est.optimizer_success
    assert calls == [False, True]  # the second search, the default starts at every delay
    assert est.noise_variance > 1.4 * est.noise_floor
    for words in ("local minimum", "longer record", "richer input", "max_delay", "fixed", "more poles"):
        assert words in est.message
    data = est.to_dict()
    assert data["success"] is False and data["optimizer_success"] is True and data["noise_floor"] > 0


def test_a_fixed_delay_has_no_floor_and_keeps_the_optimisers_flag():
    u, y = third_case("z0.4", 0, 10.0)
    est = tfest(u, y, TS, 3, input_delay=THIRD_TAU)
    assert est.noise_floor is None and est.success == est.optimizer_success
