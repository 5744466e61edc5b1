"""A model of the plant on the board (a grey-box estimate): its loop closed with the controller, simulated on
the validation record and for the step, its linearisation's bands carried from the parameters' covariance."""

import dataclasses

import numpy as np
import pytest

from eha_core.board import (
    PlantModel,
    compare_on_record,
    greybox_plant,
    linearised_estimate,
    model_views,
    nonlinear_step,
    plant_model,
    reference_models,
    validation_record,
)
from eha_core.params import ActuatorParams

TRUTH = ActuatorParams()


def test_the_true_actuator_as_a_plant_model_is_eq24_and_fits_its_own_record_exactly():
    model = plant_model(PlantModel(TRUTH), 10.0, name="P", description="the truth")
    (eq24, _) = reference_models(TRUTH, 10.0)
    np.testing.assert_allclose(model.den, eq24.den / eq24.den[0], rtol=1e-12)
    np.testing.assert_allclose(model.num, eq24.num / eq24.den[0], rtol=1e-12)
    assert model.estimate is None and model.kind == "greybox"
    # the noise-free record of the same actuator is the model's own simulation: a fit of 100 %, where
    # eq. 24's linearisation (the same values) misses the friction
    record = validation_record(TRUTH, kp=10.0, seed=3)
    assert compare_on_record(model, record).fit_percent == pytest.approx(100.0, abs=1e-6)
    assert compare_on_record(eq24, record).fit_percent < 95
    # its step is the nonlinear loop's at the board's height, per unit step
    views = model_views(model, amplitude_m=0.02)
    plant = nonlinear_step(TRUTH, 10.0, 0.02)
    np.testing.assert_allclose(views.step.y * 0.02, plant.y, rtol=0, atol=1e-12)
    assert views.step_amplitude == 0.02 and views.step.info.rise_time_s == plant.info.rise_time_s
    assert views.band is None


def test_another_gain_closes_another_loop():
    a = plant_model(PlantModel(TRUTH), 10.0, name="P", description="")
    b = plant_model(PlantModel(TRUTH), 25.0, name="P", description="")
    (ref25, _) = reference_models(TRUTH, 25.0)
    np.testing.assert_allclose(b.den, ref25.den / ref25.den[0], rtol=1e-12)
    assert not np.allclose(a.den, b.den) and b.kp == 25.0
    record = validation_record(TRUTH, kp=25.0, seed=3)
    assert compare_on_record(b, record).fit_percent == pytest.approx(100.0, abs=1e-6)
    assert compare_on_record(a, record).fit_percent < 99.9


def test_the_coefficients_covariance_is_the_parameters_carried_by_the_delta_method():
    names = ("M", "B", "Af", "beta_e")
    std = np.array([40.0, 150.0, 30.0, 5e7])
    corr = np.array([[1, 0.3, -0.2, 0.1], [0.3, 1, 0.4, 0], [-0.2, 0.4, 1, -0.3], [0.1, 0, -0.3, 1]])
    assert np.all(np.linalg.eigvalsh(corr) > 0)
    cov = np.outer(std, std) * corr
    est = linearised_estimate(PlantModel(TRUTH, names, cov), 10.0, 0.001)
    # Monte Carlo: draw the parameters, linearise each draw; its coefficients' covariance is J C J^T
    rng = np.random.default_rng(7)
    draws = np.array([getattr(TRUTH, n) for n in names]) + rng.standard_normal((4000, 4)) @ np.linalg.cholesky(cov).T
    thetas = []
    for d in draws:
        m = plant_model(PlantModel(dataclasses.replace(TRUTH, **dict(zip(names, d, strict=True)))), 10.0, name="",
                        description="")
        thetas.append(np.concatenate([m.den[1:], m.num]))
    mc = np.cov(np.array(thetas).T)
    np.testing.assert_allclose(np.sqrt(np.diag(est.covariance)), np.sqrt(np.diag(mc)), rtol=0.06)
    # and the Bode band of the views is that spread, around the nominal curve
    views = model_views(plant_model(PlantModel(TRUTH, names, cov), 10.0, name="P", description=""))
    band = views.band
    assert np.all(band.lower.magnitude_db <= views.magnitude_db + 1e-9)
    assert np.all(band.upper.magnitude_db >= views.magnitude_db - 1e-9)
    assert np.max(band.upper.magnitude_db - band.lower.magnitude_db) > 0.05
    # a covariance four times smaller: bands half as wide (first order)
    narrow = model_views(plant_model(PlantModel(TRUTH, names, cov / 4), 10.0, name="P", description="")).band
    ratio = (narrow.upper.magnitude_db - narrow.lower.magnitude_db)[150] / (
        band.upper.magnitude_db - band.lower.magnitude_db)[150]
    assert ratio == pytest.approx(0.5, rel=0.15)


def test_a_grey_box_estimate_gives_its_free_parameters_covariance_and_holds_the_rest():
    from eha_core.identify.greybox import greybox_data, identify_greybox
    from eha_core.signals import parse_signal

    # a small excitation: the piston stays where the friction law is linear, B is not determined
    data = greybox_data(TRUTH, parse_signal("sine:0.5:2"), t_end=5.0, noise={"x": 1e-5, "p1": 5e4, "p2": 5e4},
                        seed=2, measured=("x", "p1", "p2"))
    res = identify_greybox(data, ("M", "B", "Af", "k_f"), measured=("x", "p1", "p2"))
    plant = greybox_plant(res)
    assert plant.actuator == res.params
    free = tuple(n for n in res.names if n not in res.held)
    assert res.held == ("B",) and plant.names == free == ("M", "Af", "k_f")
    np.testing.assert_allclose(np.sqrt(np.diag(plant.covariance)), [res.std_errors[n] for n in free], rtol=1e-12)
    i, j = res.names.index("M"), res.names.index("Af")
    assert plant.covariance[0, 1] == pytest.approx(res.correlation[i, j] * res.std_errors["M"] * res.std_errors["Af"])
    # the model on a record of the truth with a load it does not know: close, not exact
    model = plant_model(plant, 10.0, name="GB", description="")
    fit = compare_on_record(model, validation_record(TRUTH, kp=10.0, seed=1, disturbance="sine:5000:1")).fit_percent
    assert 80 < fit < 99.9
