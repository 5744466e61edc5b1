"""Validation on data the estimate was not fitted to (eha_core.identify.holdout)."""

import math

import numpy as np
import pytest

from eha_core.errors import FieldError
from eha_core.experiments import LSE_INPUT, lse_data
from eha_core.identify.greybox import greybox_data
from eha_core.identify.holdout import (
    DEFAULT_HOLDOUT,
    lse_model_params,
    model_state_at,
    second_greybox_record,
    second_lse_record,
    split_record,
    validate_params,
    validation_input,
    validation_seed,
)
from eha_core.identify.lse import identify_lse
from eha_core.params import ActuatorParams

TRUTH = ActuatorParams()
T_END = 2.0


def test_true_parameters_fit_a_noise_free_second_experiment_exactly():
    # the model is the plant, its initial state the record's: the two simulations are one
    rec = second_lse_record(TRUTH, LSE_INPUT, t_end=T_END)
    val = validate_params(TRUTH, rec, kind="second", u=validation_input(LSE_INPUT, T_END))
    assert val.success
    for s in ("x", "v", "p1", "p2"):
        assert val.fits[s] == pytest.approx(100.0, abs=1e-6)
    assert val.labels["x"] == "fit 100.0 % (simulation, initial conditions estimated)"
    assert "second experiment" in val.record and str(validation_seed(0)) in val.record


def test_greybox_second_experiment_true_parameters_exact_and_with_noise_near_the_floor():
    rec = second_greybox_record(TRUTH, LSE_INPUT, t_end=T_END)
    val = validate_params(TRUTH, rec, kind="second")
    assert all(f == pytest.approx(100.0, abs=1e-6) for f in val.fits.values())
    sigma = {"x": 1e-5, "p1": 5e4, "p2": 5e4}
    noisy = second_greybox_record(TRUTH, LSE_INPUT, t_end=T_END, noise=sigma, seed=4, measured=("x", "p1", "p2"))
    val = validate_params(TRUTH, noisy, kind="second")
    for s, sd in sigma.items():
        # the noise floor: with the true model the residual is the noise, fit = 100 (1 - sigma / std(y)), plus
        # the error of the first sample read as the initial state: the pressures forget it within milliseconds,
        # x (an integrator) keeps it as an offset of ~N(0, sigma), so its residual is up to ~3 sigma (3-sigma draw)
        y = noisy.signals[s]
        gap = 100.0 * sd / np.std(y)
        allowed = 3.5 * gap if s == "x" else 1.1 * gap + 0.05
        assert 100.0 - allowed < val.fits[s] < 100.0 - 0.9 * gap, (s, val.fits[s], gap)
    assert val.initial_how.endswith("v the model's own")


def test_a_wrong_mass_lowers_the_validation_fit():
    rec = second_lse_record(TRUTH, LSE_INPUT, t_end=T_END)
    right = validate_params(TRUTH, rec, kind="second")
    wrong = validate_params(TRUTH.replace(M=1.5 * TRUTH.M), rec, kind="second")
    assert wrong.fits["v"] < right.fits["v"] - 1.0
    assert wrong.fits["p1"] < right.fits["p1"] - 1.0


def test_second_experiment_uses_another_input_and_another_noise_draw():
    u = validation_input(LSE_INPUT, 5.0)
    t = np.arange(5001) * 1e-3
    assert np.max(np.abs(u(t))) == pytest.approx(6.0, rel=0.01)       # the estimation input's peak
    assert not np.allclose(u(t), LSE_INPUT(t))
    first = lse_data(TRUTH, u=u, t_end=T_END, seed=0, measurement_noise={"x": 1e-5})
    second = second_lse_record(TRUTH, LSE_INPUT, t_end=T_END, seed=0, measurement_noise={"x": 1e-5})
    noise_a, noise_b = first.x - lse_data(TRUTH, u=u, t_end=T_END).x, second.x - lse_data(TRUTH, u=u, t_end=T_END).x
    assert abs(np.corrcoef(noise_a, noise_b)[0, 1]) < 0.1


def test_split_holds_out_exactly_the_last_part_and_the_estimator_never_sees_it():
    data = lse_data(TRUTH, "white:1000", t_end=3.0, seed=2)
    est, held = split_record(data, DEFAULT_HOLDOUT)
    n = data.t.size
    k = round((1 - DEFAULT_HOLDOUT) * n)
    assert est.t.size == k and held.t.size == n - k
    np.testing.assert_array_equal(np.concatenate([est.t, held.t]), data.t)
    np.testing.assert_array_equal(held.p1, data.p1[k:])
    # corrupt the held-out part: the estimate from the first part is the same
    bad = data.__class__(data.t, data.x, data.v, np.concatenate([data.p1[:k], data.p1[k:] * 3 + 1e6]),
                         data.p2, data.u, source="corrupted")
    a = identify_lse(split_record(data)[0], TRUTH)
    b = identify_lse(split_record(bad)[0], TRUTH)
    assert a.estimates == b.estimates
    # and the validation on the held-out part sees the corruption
    model, d = lse_model_params(a, TRUTH)
    good_fit = validate_params(model, split_record(data)[1], kind="split", u=LSE_INPUT, d=d).fits["p1"]
    bad_fit = validate_params(model, split_record(bad)[1], kind="split", u=LSE_INPUT, d=d).fits["p1"]
    assert good_fit > 90.0 and bad_fit < good_fit - 10.0


def test_split_of_a_greybox_record_and_the_carried_state():
    rec = greybox_data(TRUTH, LSE_INPUT, t_end=3.0, measured=("x", "p1", "p2"))
    est, held = split_record(rec, 0.25)
    assert held.t.size == rec.t.size - round(0.75 * rec.t.size)
    assert held.u.size == held.t.size and held.d.size == held.t.size
    carried = model_state_at(TRUTH, rec, float(held.t[0]))
    val = validate_params(TRUTH, held, kind="split", carried_state=carried)
    # the true model, its unmeasured v carried from its own simulation: the held-out record exactly
    assert all(f == pytest.approx(100.0, abs=1e-4) for f in val.fits.values())
    assert "continued to the split" in val.initial_how
    np.testing.assert_array_equal(val.t, held.t)


def test_split_with_the_exact_input_shifted_matches_the_sampled_one():
    data = lse_data(TRUTH, t_end=T_END)
    _, held = split_record(data)
    exact = validate_params(TRUTH, held, kind="split", u=LSE_INPUT)
    sampled = validate_params(TRUTH, held, kind="split")
    assert exact.fits["x"] == pytest.approx(100.0, abs=1e-6)
    assert sampled.fits["x"] == pytest.approx(100.0, abs=0.01)      # linear between 1 kHz samples


def test_a_model_that_cannot_be_simulated_is_a_failed_result_not_an_exception():
    rec = second_lse_record(TRUTH, LSE_INPUT, t_end=1.0)
    val = validate_params(TRUTH.replace(M=1e-30, beta_e=1e20), rec, kind="second")
    assert isinstance(val.success, bool)
    if not val.success:
        assert val.simulated is None and val.fits == {} and val.message


def test_bad_choices_are_refused_with_their_field():
    data = lse_data(TRUTH, t_end=1.0)
    with pytest.raises(FieldError, match="held-out share"):
        split_record(data, 1.0)
    with pytest.raises(FieldError, match="validation"):
        validate_params(TRUTH, data, kind="none")
    with pytest.raises(FieldError, match="excitation"):
        validation_input(lambda t: np.zeros_like(t), 1.0)
    assert math.isfinite(validate_params(TRUTH, data, kind="split").fits["x"])
