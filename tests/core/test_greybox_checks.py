"""A grey-box estimate is a success only when its own checks pass, and starts right from where a student
starts: each way it used to be confidently wrong, and each check on its own."""

import math

import numpy as np
import pytest

from eha_core.experiments import LSE_INPUT
from eha_core.identify import _greybox_checks as C
from eha_core.identify.greybox import GreyBoxData, greybox_data, identify_greybox, read_intersample
from eha_core.params import ActuatorParams
from eha_core.signals import Sampled, Sine
from eha_core.simulate import simulate

NAMES = ("M", "B", "Af", "beta_e")
NOISE = {"x": 1e-5, "p1": 5e4, "p2": 5e4}


def _within_se(res, truth, k=3.0):
    return {n: abs(res.estimates[n] - getattr(truth, n)) / res.std_errors[n] for n in res.names}


def test_the_command_lines_example_from_the_papers_values_is_right():
    # `eha identify greybox --param M=5200 --param B=1100 --param Af=2500 --param beta_e=0.8e9 --seed 3`: once
    # M -39 %, B +955 %, Af -19 % with intervals hundreds of standard errors off, and success=True
    truth = ActuatorParams(M=5200.0, B=1100.0, Af=2500.0, beta_e=0.8e9)
    data = greybox_data(truth, LSE_INPUT, t_end=10.0, noise=NOISE, seed=3, measured=("x", "p1", "p2"))
    res = identify_greybox(data, NAMES)
    assert res.success, res.message
    for n in ("M", "Af", "beta_e"):
        assert abs(res.estimates[n] / getattr(truth, n) - 1) < 0.03, n
    assert all(v < 3 for v in _within_se(res, truth).values()), _within_se(res, truth)
    assert all(c.passed for c in res.checks) and {c.name for c in res.checks} == {
        "optimiser", "noise", "residuals", "bounds", "rank"}


@pytest.fixture(scope="module")
def paper_record():
    truth = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8)
    return truth, greybox_data(truth, LSE_INPUT, t_end=3.0, d=Sine(5000.0, 1.0), noise=NOISE, seed=2,
                               measured=("x", "p1", "p2"))


def test_a_students_poor_guess_is_right_or_says_it_may_be_wrong(paper_record):
    # the guess M x3, B x0.1, Af x0.2, beta_e x0.3 by single shooting once gave M +55 % in a tight interval,
    # B 5.8e-18 with a standard error of 0, correlations of 1e130 and no alert
    truth, data = paper_record
    guess = truth.replace(M=3 * truth.M, B=0.1 * truth.B, Af=0.2 * truth.Af, beta_e=0.3 * truth.beta_e)
    for shooting in ("single", "auto"):
        res = identify_greybox(data, NAMES, guess=guess, shooting=shooting)
        if res.success:
            assert all(v < 4 for v in _within_se(res, truth).values()), (shooting, _within_se(res, truth))
        else:
            assert res.message.startswith("the estimate may be wrong") and res.advice
            assert all(math.isnan(v) for n in NAMES for v in res.ci95[n])
            assert np.all(np.isnan(res.correlation))
    assert res.success                       # the default strategy gets there


def test_an_estimate_run_to_a_bound_says_so_and_not_that_the_parameter_does_nothing():
    # 1.5 s of a sine hardly fix B; from x alone, B = 9.6e-35 ± 7.7e-52 once came back as an estimate
    truth = ActuatorParams()
    data = greybox_data(truth, LSE_INPUT, t_end=1.5, d=Sine(5000.0, 1.0),   # (seed 2 drives B to its floor)
                        noise={"x": 2.6e-4, "p1": 7.8e4, "p2": 1.1e5}, seed=2, measured=("x", "p1", "p2"))
    res = identify_greybox(data, NAMES, hold_unidentifiable=False)
    bound = next(c for c in res.checks if c.name == "bounds")
    assert not bound.passed and bound.about == ("B",) and not res.success
    assert "ended at the lower bound" in bound.says and "effectively 0" in bound.says
    lo, _ = C.estimate_range("B")
    assert lo * (1 - 1e-9) <= res.estimates["B"] <= 1.01 * lo                # at the range's floor, within it
    assert not any("B" in who and "does not affect" in s for who, s in res.identifiability)
    assert any("B" in who and "ended at a bound" in s for who, s in res.identifiability)
    for n in NAMES:
        assert C.estimate_range(n)[0] * (1 - 1e-9) <= res.estimates[n] <= C.estimate_range(n)[1] * (1 + 1e-9)


def test_a_stated_noise_that_is_not_the_records_fails_the_noise_check(paper_record):
    truth, data = paper_record
    quieter = GreyBoxData(t=data.t, u=data.u, d=data.d, signals=data.signals, intersample="foh",
                          noise={s: v / 3 for s, v in NOISE.items()})
    res = identify_greybox(quieter, NAMES, guess=truth)
    check = next(c for c in res.checks if c.name == "noise")
    assert not check.passed and "3 times the sensor's σ" in check.says and not res.success
    louder = GreyBoxData(t=data.t, u=data.u, d=data.d, signals=data.signals, intersample="foh",
                         noise={s: v * 3 for s, v in NOISE.items()})
    check = next(c for c in identify_greybox(louder, NAMES, guess=truth).checks if c.name == "noise")
    assert not check.passed and "smaller than the stated sensor σ" in check.says


def test_a_load_the_model_does_not_know_is_not_a_success(paper_record):
    truth, data = paper_record
    blind = GreyBoxData(t=data.t, u=data.u, signals=data.signals, intersample="foh", noise=data.noise)   # no d
    res = identify_greybox(blind, NAMES, guess=truth)
    assert not res.success and {"noise", "residuals"} & {c.name for c in res.failed_checks}
    # the residual verdicts speak of the grey-box model, not of a transfer function's poles
    assert not any("poles" in s for s in res.assessment.sentences)


def test_a_held_parameters_bias_on_the_others_is_stated_and_first_order_right():
    truth = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8)
    data = greybox_data(truth, LSE_INPUT, t_end=3.0, d=Sine(5000.0, 1.0), noise=NOISE, seed=4,
                        measured=("x", "p1", "p2"))
    # hold B by asking only for the others; the bias is for a held parameter the estimator chose: make it
    # choose B by asking for B from x alone at a guess where x does not move with it is fragile, so check
    # the formula directly against a refit with B 10 % high
    base = identify_greybox(data, ("M", "Af", "beta_e"), guess=truth)
    high = identify_greybox(data, ("M", "Af", "beta_e"), guess=truth.replace(B=1.1 * truth.B))
    from eha_core.identify.greybox import _weighted_jacobian, simulate_with_sensitivities

    sigma = np.array([base.noise_std[s] for s in base.measured])
    _, s_free = simulate_with_sensitivities(base.params, base.names, data)
    _, s_held = simulate_with_sensitivities(base.params, ("B",), data)
    rows = [0, 2, 3]
    bias = C.held_bias(_weighted_jacobian(s_free, rows, sigma), _weighted_jacobian(s_held, rows, sigma),
                       base.names, ("B",), [None] * 3, base.estimates)
    for n in base.names:
        moved = high.estimates[n] / base.estimates[n] - 1
        assert bias["B"][n] == pytest.approx(moved, rel=0.3, abs=2e-4), (n, bias["B"][n], moved)


def test_a_parameter_held_at_a_wrong_guess_is_estimated_when_holding_it_fails():
    # `eha study greybox` with M 8000, B 4500, Af 2000, beta_e 6.6e8 from x alone held B at the paper's 1500
    # in every seed; M came out at 2187 with a 96.6 % fit and "success"
    from eha_core.identify.greybox_study import LOAD, snr_noise

    truth = ActuatorParams(M=8000.0, B=4500.0, Af=2000.0, beta_e=6.6e8)
    noise = snr_noise(truth, 30.0, ("x",))
    data = greybox_data(truth, LSE_INPUT, t_end=5.0, d=LOAD, noise=noise, seed=0, measured=("x",))
    res = identify_greybox(data, NAMES)
    assert res.success and "B" not in res.held, res.message
    assert all(v < 3 for v in _within_se(res, truth).values()), _within_se(res, truth)
    assert any("B was not determined at the initial guess" in text for _, text in res.identifiability)


def test_a_command_held_between_samples_is_read_from_the_record():
    # a controller's command held by a DAC at the record's rate, read as linear between samples, biased B
    truth = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8)
    t = np.arange(3001) * 1e-3
    rng = np.random.default_rng(1)
    u = 6 * np.sin(4 * np.pi * t) + 0.5 * rng.standard_normal(t.size)
    run = simulate(truth, Sampled(t, u, hold="zoh", name="u"), t_end=3.0, dt=1e-3)
    signals = {s: getattr(run, s) + NOISE[s] * rng.standard_normal(t.size) for s in NOISE}
    data = GreyBoxData(t=run.t, u=run.u, signals=signals, noise=NOISE)
    assert read_intersample(data)[0] is None                         # the samples alone cannot tell
    res = identify_greybox(data, NAMES, guess=truth)
    assert res.extras["intersample"]["used"] == "zoh" and "held" in res.extras["intersample"]["how"]
    assert res.success and abs(res.estimates["B"] / truth.B - 1) < 0.1
    wrong = identify_greybox(GreyBoxData(t=run.t, u=run.u, signals=signals, noise=NOISE, intersample="foh"), NAMES,
                             guess=truth, shooting="single")
    assert not wrong.success                                          # told foh: it fails its checks


def test_a_piecewise_constant_command_is_read_as_held():
    t = np.arange(1000) * 1e-3
    u = np.repeat(np.sin(np.arange(100)), 10)
    data = GreyBoxData(t=t, u=u, signals={"x": np.zeros(t.size)})
    how, why = read_intersample(data)
    assert how == "zoh" and "every 10" in why


# -- each check on its own ---------------------------------------------------------------------------------

def test_ljung_box_passes_white_noise_and_fails_a_slow_oscillation():
    rng = np.random.default_rng(0)
    white = rng.standard_normal(4000)
    assert C.ljung_box(white)[1] > 1e-3
    slow = white + 3 * np.sin(np.arange(4000) * 2 * np.pi / 500)
    assert C.ljung_box(slow)[1] < 1e-10


def test_the_whiteness_checks_false_alarm_rate_is_its_setting():
    rng = np.random.default_rng(1)
    fails = sum(not C.whiteness_check({"x": rng.standard_normal(3000)}, {"x": 1.0}).passed for _ in range(2000))
    # 1e-3 per signal: 2 expected in 2000; more than 10 is beyond chance (Poisson tail 5e-6)
    assert fails <= 10


def test_the_rank_check_names_the_parameters_that_move_together():
    J = np.column_stack([np.arange(10.0), 2 * np.arange(10.0), np.ones(10)])
    check = C.rank_check(J, ("beta_e", "Kq1", "M"))
    assert not check.passed and check.about == ("beta_e", "Kq1")
    assert C.rank_check(np.eye(3), ("a", "b", "c")).passed


def test_the_bounds_check_finds_an_estimate_at_either_end():
    lo, hi = np.array([0.0, 0.0]), np.array([10.0, 10.0])
    check = C.bounds_check(("B", "M"), np.array([5e-4, 5.0]), lo, hi, {"B": 0.01, "M": 4000.0},
                           lambda n, v: f"{v:g}")
    assert not check.passed and check.about == ("B",) and "effectively 0" in check.says
    assert C.bounds_check(("M",), np.array([5.0]), lo[:1], hi[:1], {"M": 1.0}, str).passed
