"""Tests of eha_core.identify.step: figures equal python-control's step_info."""

import time

import control
import numpy as np
import pytest

from eha_core.identify.step import (
    StepComparison,
    StepInfo,
    default_step_horizon,
    nonlinear_step_response,
    step_comparison,
    step_info,
    step_response,
)
from eha_core.linear import linearize
from eha_core.params import ActuatorParams

H24 = (np.array([2437.0]), np.array([1.0, 430.1, 1.721e4, 2437.0]))   # eq. 24, Kp = 10

MODELS = {
    # name: (num, den, time grid): each grid long enough to settle, and (for the
    # monotone ones) short enough that the response still rises at its end: a
    # response flat to rounding has its peak at whichever sample rounds highest
    "eq. 24": (*H24, np.arange(6001) * 0.01),
    "oscillatory": ([4.0], [1.0, 0.8, 4.0], np.arange(2001) * 0.01),
    "overdamped": ([6.0], [1.0, 5.0, 6.0], np.arange(801) * 0.01),
    "non-minimum phase": ([-1.0, 1.0], [1.0, 1.0, 1.0], np.arange(1501) * 0.01),
    "negative gain": ([-3.0], [1.0, 2.0, 3.0], np.arange(1001) * 0.01),
    "resonance (estimate)": ([2108.5], [1.0, 9.4595, 1.70915e4, 2056.34], np.arange(6001) * 0.01),
}


def _assert_same_figures(info: StepInfo, reference: dict):
    ours = info.to_control_dict()
    assert ours.keys() == reference.keys()
    for key, value in reference.items():
        assert ours[key] == pytest.approx(value, rel=1e-9, abs=1e-12, nan_ok=True), key


@pytest.mark.parametrize("name", list(MODELS))
def test_figures_equal_control_step_info(name):
    num, den, t = MODELS[name]
    ours = step_response((num, den), t, name=name)
    _assert_same_figures(ours.info, control.step_info(control.tf(num, den), t))
    _, y_control = control.step_response(control.tf(num, den), t)
    np.testing.assert_allclose(ours.y, y_control, rtol=0, atol=1e-10 * np.max(np.abs(y_control)))
    assert ours.source == "transfer function" and ours.message == "ok"


def test_the_figures_say_what_the_models_do():
    osc = step_response(MODELS["oscillatory"][:2], MODELS["oscillatory"][2]).info
    # zeta = 0.2: overshoot exp(-pi zeta / sqrt(1 - zeta^2)) = 52.7 %, peak at pi / wd = 1.60 s
    assert osc.overshoot_percent == pytest.approx(52.66, abs=0.05)
    assert osc.peak_time_s == pytest.approx(np.pi / (2 * np.sqrt(1 - 0.04)), abs=0.01)
    over = step_response(MODELS["overdamped"][:2], MODELS["overdamped"][2]).info
    assert over.overshoot_percent == 0.0 and over.undershoot_percent == 0.0
    nmp = step_response(MODELS["non-minimum phase"][:2], MODELS["non-minimum phase"][2]).info
    assert nmp.undershoot_percent > 20.0
    h24 = step_response(H24, MODELS["eq. 24"][2]).info
    # the pole at -0.142 rad/s dominates: rise ln(9)/0.142 = 15.5 s, 2 % settling ln(50)/0.142 = 27.5 s
    assert h24.rise_time_s == pytest.approx(np.log(9) / 0.1421, rel=0.01)
    assert h24.settling_time_s == pytest.approx(np.log(50) / 0.1421, rel=0.01)
    assert h24.steady_state == 1.0


def test_step_info_of_data_uses_the_last_sample_as_control_does():
    t = np.arange(3001) * 0.01
    y = 1.0 - np.exp(-0.5 * t) * np.cos(3.0 * t)
    _assert_same_figures(step_info(t, y), control.step_info(y, t))
    _assert_same_figures(step_info(t, y, steady_state=1.0), control.step_info(y, t, yfinal=1.0))


def test_integrator_has_undefined_figures():
    r = step_response(([243.7], [1.0, 430.1, 1.721e4, 0.0]), np.arange(101) * 0.01)   # eq. 23, open loop
    assert np.isnan(r.info.rise_time_s) and np.isnan(r.info.steady_state)
    assert "infinite" in r.message
    assert r.y[-1] > r.y[50] > 0


def test_amplitude_scales_the_response_not_the_figures():
    t = np.arange(4001) * 0.01
    unit = step_response(H24, t)
    big = step_response(H24, t, amplitude=0.05)
    np.testing.assert_allclose(big.y, 0.05 * unit.y, rtol=1e-12)
    assert big.info == unit.info and big.amplitude == 0.05


def test_default_grid_and_horizon():
    assert default_step_horizon(H24) == pytest.approx(np.log(1000) / 0.14214, rel=1e-3)
    assert default_step_horizon(([1.0], [1.0, 0.0])) == 10.0            # nothing settles
    assert default_step_horizon(([1.0], [1.0, 1e-6])) == 120.0          # a near-integrator: clipped
    r = step_response(H24)
    assert r.t[0] == 0.0 and r.t[-1] == pytest.approx(48.6, abs=0.1) and r.t.size == 1001


def test_control_transfer_function_and_estimate_are_accepted():
    t = np.arange(501) * 0.01
    a = step_response(control.tf(*H24), t)
    b = step_response(H24, t)
    np.testing.assert_array_equal(a.y, b.y)


def test_bad_input_is_refused_with_the_common_message():
    with pytest.raises(ValueError, match=r"^t = .* is not allowed: must be a uniform time grid"):
        step_response(H24, [0.0, 0.1, 0.3])
    with pytest.raises(ValueError, match=r"^amplitude = 0 is not allowed: "):
        step_response(H24, amplitude=0.0)
    with pytest.raises(ValueError, match=r"^model\[1\] = \[0\] is not allowed: "):
        step_response(([1.0], [0.0]))


# --- the nonlinear closed loop ------------------------------------------------------
@pytest.fixture(scope="module")
def comparison() -> StepComparison:
    coeffs = linearize(ActuatorParams()).closed_loop_coeffs(10.0)
    return step_comparison({"eq. 24": coeffs, "control.tf": control.tf(*coeffs)},
                           amplitude_m=0.02, t_end_s=40.0, dt_s=0.01)


def test_nonlinear_step_response_figures_follow_the_same_definitions(comparison):
    nl = comparison["nonlinear plant"]
    assert nl.source == "nonlinear simulation" and nl.message == "ok", nl.message
    _assert_same_figures(nl.info, control.step_info(nl.y / nl.amplitude, nl.t))
    # the same loop linearised (eq. 24) is close: the friction's saturation and
    # the sampled controller make the difference
    lin = comparison["eq. 24"].info
    assert nl.info.rise_time_s == pytest.approx(lin.rise_time_s, rel=0.15)
    assert nl.info.settling_time_s == pytest.approx(lin.settling_time_s, rel=0.15)
    assert nl.info.steady_state == pytest.approx(1.0, abs=0.02)


def test_comparison_holds_every_model_on_one_grid_in_metres(comparison):
    assert comparison.names == ("eq. 24", "control.tf", "nonlinear plant")
    assert comparison.t[-1] == pytest.approx(40.0) and comparison.t.size == 4001
    for r in comparison.responses:
        np.testing.assert_array_equal(r.t, comparison.t)
        assert r.amplitude == 0.02
        assert r.y[-1] == pytest.approx(0.02, rel=0.02)          # metres, not per unit
    np.testing.assert_allclose(comparison["eq. 24"].y, comparison["control.tf"].y, rtol=1e-12)
    assert set(comparison.to_dict()["figures"]) == set(comparison.names)
    with pytest.raises(ValueError, match=r"^name = nope is not allowed: use one of eq. 24, control.tf, "):
        comparison["nope"]


def test_nonlinear_step_reports_an_end_stop():
    # 0.3 m of step on a 0.24 m half-stroke: the piston runs into the stop
    nl = nonlinear_step_response(amplitude_m=0.3, t_end_s=40.0, dt_s=0.01)
    assert "end stop" in nl.message and "ends at 0.8 of the step" in nl.message, nl.message


def test_timings():
    t0 = time.perf_counter()
    step_response(H24)
    t1 = time.perf_counter()
    nonlinear_step_response(amplitude_m=0.01, t_end_s=60.0, dt_s=0.001)
    t2 = time.perf_counter()
    print(f"step_response {1e3 * (t1 - t0):.1f} ms, nonlinear 60 s {1e3 * (t2 - t1):.0f} ms")
    assert t2 - t0 < 10.0
