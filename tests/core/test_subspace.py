"""Subspace state-space estimation (MATLAB n4sid): poles over seeds, exactness, the order's gap, refusals."""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.signal

from eha_core._checks import FieldError
from eha_core.identify.blackbox import IdData, compare, merge
from eha_core.identify.subspace import StateSpaceModel, n4sid, ss_order_svd

# a second-order system with white output noise (output error) ...
OE2 = {"b": [0.0, 1.0, 0.5], "a": [1.0, -1.5, 0.7]}
# ... and a third-order one in innovation form (coloured noise through K)
A3 = np.array([[0.9, 0.0, 0.0], [0.0, 0.6, 0.4], [0.0, -0.4, 0.6]])
B3 = np.array([[1.0], [0.5], [-0.3]])
C3 = np.array([[1.0, 1.0, 0.5]])
K3 = np.array([[0.3], [0.2], [0.1]])


def _oe2(n_samples, noise_std, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n_samples)
    y = scipy.signal.lfilter(OE2["b"], OE2["a"], u) + noise_std * rng.standard_normal(n_samples)
    return IdData(y, u, 1.0)


def _inn3(n_samples, noise_std, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n_samples)
    e = noise_std * rng.standard_normal(n_samples)
    gb, ga = scipy.signal.ss2tf(A3, B3, C3, np.zeros((1, 1)))
    hc, hd = scipy.signal.ss2tf(A3, K3, C3, np.ones((1, 1)))
    return IdData(scipy.signal.lfilter(gb[0], ga, u) + scipy.signal.lfilter(hc[0], hd, e), u, 1.0)


def _sorted_poles(poles):
    return np.sort_complex(np.asarray(poles, complex))


CASES = {
    "second order, output error": (_oe2, 2, _sorted_poles(np.roots(OE2["a"]))),
    "third order, innovation form": (_inn3, 3, _sorted_poles(np.linalg.eigvals(A3))),
}


@pytest.mark.parametrize("case", list(CASES))
def test_poles_over_noise_seeds_are_unbiased_and_tight(case):
    """Over 50 seeds the mean estimated pole lies within 3 standard errors of the true pole."""
    make, order, true_poles = CASES[case]
    n_seeds = 50
    estimates = []
    for seed in range(n_seeds):
        model = n4sid(make(2000, 0.5, seed), order)
        assert model.success, model.message
        estimates.append(_sorted_poles(model.poles()))
    estimates = np.array(estimates)
    for part in (np.real, np.imag):
        values, truth = part(estimates), part(true_poles)
        spread = values.std(axis=0, ddof=1)
        mean_error = np.abs(values.mean(axis=0) - truth)
        assert np.all(spread < 0.05), spread
        # a real pole's imaginary part is exactly zero in every seed: no spread to compare with
        assert np.all(mean_error <= 3.0 * spread / np.sqrt(n_seeds) + 1e-12), (mean_error, spread)


def test_covariance_matches_the_spread_over_seeds():
    """The reported standard errors of a1, a2 match their spread over seeds (z-scores of unit spread)."""
    z_scores = []
    for seed in range(50):
        model = n4sid(_oe2(2000, 0.5, seed), 2)
        z_scores.append((model.params[:2] - np.array(OE2["a"][1:])) / model.param_std[:2])
    spread = np.std(z_scores, axis=0, ddof=1)
    # the sample standard deviation of 50 unit normals lies in [0.75, 1.25] with probability > 0.998
    assert np.all((spread > 0.75) & (spread < 1.35)), spread


@pytest.mark.parametrize("case", list(CASES))
def test_noise_free_data_give_the_exact_system(case):
    make, order, true_poles = CASES[case]
    model = n4sid(make(600, 0.0, seed=1), order)
    assert isinstance(model, StateSpaceModel) and model.success, model.message
    assert model.weighting == "moesp"                   # auto: CVA needs noise
    np.testing.assert_allclose(_sorted_poles(model.poles()), true_poles, atol=1e-8)
    assert model.fit.fit_percent > 99.9999


def test_polynomials_state_space_and_control_agree():
    model = n4sid(_oe2(600, 0.0, seed=2), 2)
    gb, ga = model.g_poly()
    np.testing.assert_allclose(ga, OE2["a"], atol=1e-8)
    np.testing.assert_allclose(gb, OE2["b"], atol=1e-8)
    sys = model.to_control()
    assert isinstance(sys, control.StateSpace) and sys.dt == 1.0
    np.testing.assert_allclose(control.dcgain(sys), sum(OE2["b"]) / sum(OE2["a"]), rtol=1e-8)
    # the parameters are G's and H's coefficients
    hc, _hd = model.h_poly()
    np.testing.assert_allclose(model.params, np.concatenate([ga[1:], gb[1:], hc[1:]]))
    assert model.param_names == ("a1", "a2", "b1", "b2", "c1", "c2")
    assert model.name == "State space (n4sid, n=2)"
    assert model.to_dict()["structure"] == "ss"


def test_innovation_form_noise_model_is_recovered():
    model = n4sid(_inn3(20000, 0.5, seed=3), 3)
    hc, hd = model.h_poly()
    true_c, _ = scipy.signal.ss2tf(A3, K3, C3, np.ones((1, 1)))
    np.testing.assert_allclose(hc, true_c[0], atol=0.05)
    assert model.noise_variance == pytest.approx(0.25, rel=0.05)


def test_singular_values_show_the_order():
    for make, order in ((_oe2, 2), (_inn3, 3)):
        sv = ss_order_svd(make(3000, 0.05, seed=4), 6)
        ratios = sv[:-1] / sv[1:]
        assert np.argmax(ratios) == order - 1, sv       # the largest drop is after the true order
        assert ratios[order - 1] > 10.0, sv                # a clear gap there ...
        assert np.all(ratios[order:] < 2.0), sv            # ... and a flat noise floor after it


def test_merged_experiments_and_estimated_initial_states():
    first, second = _oe2(400, 0.0, seed=5), _oe2(300, 0.0, seed=6)
    merged = merge(first, second)
    model = n4sid(merged, 2)
    assert model.success, model.message
    np.testing.assert_allclose(_sorted_poles(model.poles()), CASES["second order, output error"][2], atol=1e-8)
    # concatenated as one record, the join is a false transient; merged it is not
    # an experiment that starts away from rest: its initial state is estimated
    rng = np.random.default_rng(7)
    u = rng.standard_normal(500)
    zi = scipy.signal.lfiltic(OE2["b"], OE2["a"], [3.0, -2.0])
    y, _ = scipy.signal.lfilter(OE2["b"], OE2["a"], u, zi=zi)
    data = IdData(y, u, 1.0)
    est = n4sid(data, 2, initial="estimate")
    assert est.success, est.message
    np.testing.assert_allclose(_sorted_poles(est.poles()), CASES["second order, output error"][2], atol=1e-6)
    assert np.any(np.abs(est.x0) > 0.1)
    assert compare(est, data, None, "estimate").fit_percent > 99.99
    assert est.x0.shape == (1, 2)


def test_feedthrough_is_estimated_when_asked():
    rng = np.random.default_rng(8)
    u = rng.standard_normal(800)
    y = scipy.signal.lfilter([0.4, 1.0, 0.5], OE2["a"], u)
    model = n4sid(IdData(y, u, 1.0), 2, feedthrough=True)
    assert model.D[0, 0] == pytest.approx(0.4, abs=1e-8)
    assert model.param_names[2] == "b0"


def test_bad_input_is_refused_naming_the_field():
    data = _oe2(200, 0.1, seed=9)
    for kwargs, field in (
        ({"n": 0}, "n"),
        ({"n": 2.5}, "n"),
        ({"n": 10, "horizon": 10}, "n"),        # not below the horizon
        ({"n": 2, "horizon": 150}, "horizon"),  # 2 * 150 + 1 samples exceed the record
        ({"n": 2, "horizon": 60}, "n"),         # the record is too short for the LQ with this horizon
        ({"n": 2, "weighting": "pca"}, "weighting"),
        ({"n": 2, "initial": "guess"}, "initial"),
    ):
        with pytest.raises(FieldError) as info:
            n4sid(data, **kwargs)
        assert info.value.field == field, (kwargs, str(info.value))
    with pytest.raises(FieldError) as info:
        n4sid((data.y, data.u), 2)
    assert info.value.field == "data"
    with pytest.raises(FieldError) as info:
        ss_order_svd(data, 0)
    assert info.value.field == "max_order"


def test_an_unstable_estimate_from_data_that_do_not_grow_is_a_failure():
    """Too high an order on a short noisy record can give a pole outside the unit circle; if it does,
    the estimate says so; a stable estimate says success. Either way it is data, not an exception."""
    outcomes = []
    for seed in range(20):
        model = n4sid(_oe2(80, 2.0, seed), 6, horizon=8)
        radius = np.max(np.abs(np.linalg.eigvals(model.A)))
        if radius > 1.005:
            assert not model.success and "unstable" in model.message
        outcomes.append(radius)
    assert np.all(np.isfinite(outcomes))
