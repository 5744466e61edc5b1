"""Grey-box estimates on records no rig should give but students upload: units off by 1e6, a dead
sensor. Each was an ``OverflowError: math range error`` (``math.exp`` of a 95 % interval's bound in
log units beyond 709), or claimed a standard error of 0 for a parameter the signals do not move
with; each is now a result with ``success=False`` and a message that says what is wrong."""

import math

import numpy as np
import pytest

from eha_core.experiments import LSE_INPUT
from eha_core.identify.greybox import GreyBoxData, greybox_data, identify_greybox
from eha_core.params import ActuatorParams

ALL = ("M", "B", "Af", "beta_e", "Kq1", "Kq2", "L0", "k_f", "d0")


@pytest.fixture(scope="module")
def record():
    return greybox_data(ActuatorParams(), LSE_INPUT, t_end=3.0, noise={"x": 1e-5, "p1": 5e4, "p2": 5e4}, seed=1,
                        measured=("x", "p1", "p2"))


def _changed(record, **signals) -> GreyBoxData:
    return GreyBoxData(t=record.t, u=signals.pop("u", record.u), signals={**record.signals, **signals})


def _assert_honest_failure(res):
    """Not a success; the message says what the checks found and names the units to check; no interval is
    given as if it held (each is NaN, the fit's own kept aside without an overflow)."""
    assert not res.success
    assert res.message.startswith("the estimate may be wrong") and "SI units" in res.message, res.message
    assert "math range error" not in res.message
    assert res.failed_checks and res.advice
    for n in res.names:
        assert all(math.isnan(c) for c in res.ci95[n]) and math.isnan(res.std_errors[n]), (n, res.ci95[n])
    for n, (lo, hi) in res.extras["ci95_unchecked"].items():
        assert not (lo > hi), (n, lo, hi)


@pytest.mark.parametrize("names", [("M", "B", "Af", "beta_e"), ALL], ids=["four", "nine"])
def test_a_position_in_micrometres_is_a_failure_with_a_message_not_an_overflow(record, names):
    # x in µm instead of m: the fit drives the model where its x hardly moves with the parameters
    data = _changed(record, x=record.signals["x"] * 1e6)
    _assert_honest_failure(identify_greybox(data, names, measured=("x",)))


def test_a_command_off_by_a_million_is_a_failure_with_a_message(record):
    data = _changed(record, u=record.u * 1e6)
    _assert_honest_failure(identify_greybox(data, ("M", "B", "Af", "beta_e")))


def test_a_dead_position_sensor_is_a_failure_with_a_message(record):
    data = _changed(record, x=np.zeros_like(record.t))
    _assert_honest_failure(identify_greybox(data, ALL, measured=("x",)))


def test_a_parameter_the_signals_do_not_move_with_has_no_bound_rather_than_a_zero_error(record):
    # (where the signals do not change at all with a parameter, a pseudo-inverse of the Fisher information
    # gave it a standard error of 0, a perfectly known value; the fit's own standard errors are kept aside)
    res = identify_greybox(_changed(record, x=record.signals["x"] * 1e6), ALL, measured=("x",))
    unchecked = res.extras["std_errors_unchecked"]
    assert not res.success and all(not (unchecked[n] == 0) for n in res.names if n not in res.held), unchecked


def test_a_sound_record_keeps_its_finite_intervals_and_success(record):
    res = identify_greybox(record, ("M", "B", "Af", "beta_e"))
    assert res.success and res.message and "SI units" not in res.message
    assert all(0 < res.ci95[n][0] < res.estimates[n] < res.ci95[n][1] < math.inf for n in res.names)
