"""The black-box course's shared ground: data of several experiments, horizons, initial conditions,
fits and criteria (eha_core.identify.blackbox), and its experiment on the actuator."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import pytest
import scipy.signal

from eha_core._checks import FieldError
from eha_core.identify.blackbox import (
    IdData,
    LinearModel,
    compare,
    criteria,
    fit_percent,
    horizon_words,
    merge,
    predict,
    simulate,
)
from eha_core.identify.blackbox_experiment import BlackBoxExperiment

A = np.array([1.0, -1.5, 0.7])
B = np.array([0.0, 1.0, 0.5])
C = np.array([1.0, 0.3])


@dataclass(frozen=True, eq=False)
class Armax(LinearModel):
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    ts: float = 0.1

    def g_poly(self):
        return self.b, self.a

    def h_poly(self):
        return self.c, self.a


@dataclass(frozen=True, eq=False)
class OutputError(LinearModel):
    b: np.ndarray
    f: np.ndarray
    ts: float = 0.1

    def g_poly(self):
        return self.b, self.f


def armax_data(n=1500, seed=0, sigma=0.1):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = sigma * rng.standard_normal(n)
    y = scipy.signal.lfilter(B, A, u) + scipy.signal.lfilter(C, A, e)
    return IdData(y, u, 0.1), e


def test_one_step_prediction_of_the_true_model_leaves_its_innovations():
    data, e = armax_data()
    resid = data.y - predict(Armax(A, B, C), data, 1)
    np.testing.assert_allclose(resid, e, atol=1e-12)


def test_a_long_horizon_predicts_as_the_simulation_and_an_output_error_model_predicts_by_simulating():
    data, _e = armax_data()
    model = Armax(A, B, C)
    # H's impulse response decays as the poles of A (|z| = 0.84): after 300 steps it is below 1e-20
    np.testing.assert_allclose(predict(model, data, 300), simulate(model, data), atol=1e-9)
    oe = OutputError(B, A)
    for k in (1, 3, 10):
        np.testing.assert_allclose(predict(oe, data, k), simulate(oe, data), atol=1e-12)
    # a shorter horizon predicts better than a longer one, on the true model
    fits = [compare(model, data, k).fit_percent for k in (1, 2, 5, None)]
    assert fits == sorted(fits, reverse=True)


def test_estimated_initial_conditions_take_up_a_start_away_from_rest():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(400)
    model = OutputError(B, A)
    zi = np.array([2.0, -1.0])                      # the filter's state at t = 0, not at rest
    y, _ = scipy.signal.lfilter(B, A, u, zi=zi)
    data = IdData(y, u, 0.1)
    assert compare(model, data, None, "estimate").fit_percent == pytest.approx(100.0, abs=1e-8)
    assert compare(model, data, None, "zero").fit_percent < 99.0


def test_merged_experiments_restart_the_filters_and_match_each_experiment_alone():
    one, _ = armax_data(300, seed=2)
    two, _ = armax_data(200, seed=3)
    both = merge(one, two)
    assert both.n_experiments == 2 and both.starts == (0, 300) and both.n_samples == 500
    model = Armax(A, B, C)
    np.testing.assert_allclose(predict(model, both, 1), np.concatenate([predict(model, one, 1),
                                                                        predict(model, two, 1)]))
    np.testing.assert_allclose(both.experiments()[1].y, two.y)
    with pytest.raises(FieldError, match=r"experiment 2's sample time = 0.2 s is not allowed.*0.1 s"):
        merge(one, IdData(two.y, two.u, 0.2))
    with pytest.raises(FieldError, match="merged experiments are not split"):
        both.split(0.5)


def test_split_and_detrend():
    data = IdData(np.arange(10.0), np.ones(10) * 3, 0.5, name="rec")
    est, val = data.split(0.7)
    assert (est.n_samples, val.n_samples) == (7, 3) and est.ts == val.ts == 0.5
    np.testing.assert_allclose(np.concatenate([est.y, val.y]), data.y)
    d = merge(est, val).detrended()
    assert abs(d.experiments()[0].y.mean()) < 1e-12 and abs(d.experiments()[1].u.mean()) < 1e-12
    for bad in (0.0, 1.0, 0.05):
        with pytest.raises(FieldError, match="estimation fraction"):
            data.split(bad)


@pytest.mark.parametrize("kwargs, field", [
    ({"y": [1.0, 2.0], "u": [1.0], "ts": 0.1}, "u"),
    ({"y": [1.0, np.nan], "u": [1.0, 2.0], "ts": 0.1}, "y, u"),
    ({"y": [1.0, 2.0], "u": [1.0, 2.0], "ts": 0.0}, "ts"),
    ({"y": [1.0, 2.0, 3.0], "u": [1.0, 2.0, 3.0], "ts": 0.1, "starts": (0, 3)}, "starts"),
])
def test_bad_data_are_refused_naming_the_field(kwargs, field):
    with pytest.raises(FieldError) as err:
        IdData(**kwargs)
    assert err.value.field == field


def test_bad_horizons_and_initial_conditions_are_refused():
    data, _ = armax_data(50)
    for bad in (0, -1, 1.5, "two"):
        with pytest.raises(FieldError, match="horizon"):
            predict(Armax(A, B, C), data, bad)
    with pytest.raises(FieldError, match="initial conditions = backcast"):
        predict(Armax(A, B, C), data, 1, "backcast")
    assert horizon_words(math.inf) == "simulation" and horizon_words(5) == "5-step prediction"


def test_fit_and_criteria_follow_their_definitions():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)
    e = np.random.default_rng(4).standard_normal(1000)
    c = criteria(e, 6)
    v = np.mean(e ** 2)
    assert c.loss == pytest.approx(v)
    assert c.aic == pytest.approx(1000 * np.log(v) + 12 + 1000 * (np.log(2 * np.pi) + 1))
    assert c.bic - c.aic == pytest.approx(6 * np.log(1000) - 12)
    assert c.fpe == pytest.approx(v * (1 + 6 / 1000) / (1 - 6 / 1000))
    label = compare(Armax(A, B, C), armax_data(200)[0], 1, "estimate").label
    assert label.startswith("fit ") and "(1-step prediction, initial conditions estimated)" in label


def test_models_convert_to_python_control_with_their_poles():
    model = Armax(A, B, C)
    g = model.to_control()
    assert g.dt == 0.1
    np.testing.assert_allclose(np.sort_complex(g.poles()), np.sort_complex(model.poles()), atol=1e-12)
    np.testing.assert_allclose(np.abs(model.poles()), math.sqrt(0.7), rtol=1e-12)
    np.testing.assert_allclose(model.zeros(), [-0.5], atol=1e-12)
    # H = C/A = (z^2 + 0.3 z) / (z^2 - 1.5 z + 0.7) in z: zeros at -0.3 and the origin
    np.testing.assert_allclose(np.sort_complex(model.noise_to_control().zeros()), [-0.3, 0.0], atol=1e-12)


def test_the_experiment_is_reproducible_and_validates_on_fresh_data():
    exp = BlackBoxExperiment(n_samples=300)
    est, val = exp.records()
    est2, _ = exp.records()
    np.testing.assert_array_equal(est.y, est2.y)
    assert not np.allclose(est.u, val.u)                         # another excitation, another seed
    prbs = BlackBoxExperiment(n_samples=300, signal_type="prbs").records()
    assert not np.allclose(prbs[0].u, prbs[1].u)                 # a PRBS too: its period starts elsewhere
    assert np.max(np.abs(est.u)) == pytest.approx(10.0)          # the reference's levels, mm
    # the loop follows its reference: x within the reference's range, and correlated with it
    assert np.max(np.abs(est.y)) < 12.0
    assert max(np.corrcoef(est.u[:-lag], est.y[lag:])[0, 1] for lag in range(1, 100, 5)) > 0.5
    split = BlackBoxExperiment(n_samples=300, validation="split", estimation_fraction=0.6).records()
    assert (split[0].n_samples, split[1].n_samples) == (180, 120)
    merged, val3 = BlackBoxExperiment(n_samples=300, n_experiments=3).records()
    assert merged.starts == (0, 300, 600) and "seeds 0-2" in merged.name and val3.name.endswith("(seed 3)")
    np.testing.assert_array_equal(merged.experiments()[0].y, est.y)          # the first is seed 0's record
    opened = BlackBoxExperiment(n_samples=300, loop="open").record()
    assert np.max(np.abs(opened.u)) == pytest.approx(1.0)        # volts


@pytest.mark.parametrize("kwargs, field", [
    ({"loop": "half"}, "loop"), ({"signal_type": "chirp"}, "excitation"), ({"n_samples": 10}, "samples"),
    ({"ts": 0.0}, "ts"), ({"noise_x": -1.0}, "noise_x"), ({"validation": "none"}, "validation"),
    ({"estimation_fraction": 0.99}, "estimation fraction"), ({"kp": float("nan")}, "kp"),
    ({"n_experiments": 0}, "experiments"), ({"n_experiments": 2, "validation": "split"}, "experiments"),
])
def test_a_bad_experiment_is_refused_naming_the_field(kwargs, field):
    with pytest.raises(FieldError) as err:
        BlackBoxExperiment(**kwargs)
    assert err.value.field == field


def test_an_estimate_exports_with_its_covariance():
    from eha_core.identify.blackbox import Criteria, EstimateFields

    data, _ = armax_data(200)

    @dataclass(frozen=True, eq=False)
    class Est(EstimateFields, Armax):
        structure: str = "armax"
        name: str = "ARMAX(na=2, nb=2, nc=1, nk=1)"
        orders: dict = None
        params: np.ndarray = None
        param_names: tuple = ()
        covariance: np.ndarray = None
        noise_variance: float = 0.01
        criteria: Criteria = None
        fit: object = None
        initial: str = "zero"
        n_samples: int = 200
        success: bool = True
        message: str = "ok"
        nfev: int = 3

    base = Armax(A, B, C)
    est = Est(A, B, C, orders={"na": 2}, params=np.array([-1.5, 0.7]), param_names=("a1", "a2"),
              covariance=np.diag([4e-4, 9e-4]), criteria=criteria(data.y - predict(base, data, 1), 5),
              fit=compare(base, data, 1))
    back = json.loads(est.to_json())
    assert back["params"] == [-1.5, 0.7] and back["param_std"] == pytest.approx([0.02, 0.03])
    assert back["covariance"] == [[4e-4, 0.0], [0.0, 9e-4]] and back["G"]["den"] == A.tolist()
    lo, hi = est.intervals(0.95)
    np.testing.assert_allclose(hi - lo, 2 * 1.959964 * np.array([0.02, 0.03]), rtol=1e-6)
    assert "1-step prediction" in repr(est)


def test_the_predictor_never_divides_by_a_so_an_unstable_a_predicts_as_arx_does():
    @dataclass(frozen=True, eq=False)
    class Arx(Armax):
        def polynomial_form(self):
            return self.a, self.b, self.c, np.array([1.0]), np.array([1.0])

    rng = np.random.default_rng(5)
    u, y = rng.standard_normal(5000), rng.standard_normal(5000)
    a = np.array([1.0, -1.01])                      # a pole just outside the unit circle: 1.01^5000 overflows
    model = Arx(a, np.array([0.0, 0.5]), np.array([1.0]))
    expected = 0.5 * np.r_[0.0, u[:-1]] + 1.01 * np.r_[0.0, y[:-1]]      # B u + (1 - A) y
    np.testing.assert_allclose(predict(model, IdData(y, u, 0.1), 1), expected, atol=1e-12)
