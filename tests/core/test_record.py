"""A transfer function from a measured record: the paper's closed loop as a file would hold it."""

import numpy as np
import pytest

from eha_core.experiments import FrequencyExperiment
from eha_core.identify.record import identify_record
from eha_core.params import ActuatorParams


@pytest.fixture(scope="module")
def record():
    cfg = FrequencyExperiment(model="linear", n_samples=1500)
    data = cfg.closed_loop(ActuatorParams(), cfg.excitation())
    return data


def test_the_closed_loop_record_is_identified_and_validated_on_its_last_third(record):
    rec = identify_record(record.t, record.r, record.x, n_poles=3)
    assert rec.n_estimation == 1000 and rec.estimate.success
    assert rec.estimate.fit_percent > 95 and rec.validation.fit_percent > 90
    assert rec.data_response.method in ("etfe", "spa") and rec.residuals is not None


def test_a_drift_is_removed_by_the_linear_detrend():
    from eha_core.identify.validate import simulate_tf

    t = np.arange(3000) * 0.01
    rng = np.random.default_rng(0)
    u = np.repeat(rng.choice([-1.0, 1.0], 300), 10)            # a random binary input, zero mean
    u -= u.mean()
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, 0.01)
    drift = y + 0.02 * t                                       # a sensor creeping 0.02 per second
    plain = identify_record(t, u, drift, n_poles=2)
    fixed = identify_record(t, u, drift, n_poles=2, detrend="linear")
    assert fixed.validation.fit_percent > 95 > plain.validation.fit_percent
    np.testing.assert_allclose(fixed.estimate.den, [1.0, 6.0, 20.0], rtol=0.05)
    assert np.isclose(fixed.y.mean(), 0, atol=1e-12) and np.isclose(fixed.u.mean(), 0, atol=1e-12)
    with pytest.raises(ValueError, match="detrend = cubic is not allowed"):
        identify_record(t, u, y, detrend="cubic")


def test_prepare_record_keeps_what_it_removes_and_checks_the_range():
    from eha_core.identify.record import prepare_record

    t = np.arange(500) * 0.01
    u = np.sin(t) + 2.0
    y = 0.3 * t + np.cos(3 * t)
    p = prepare_record(t, u, y, detrend="linear", t_from="1", t_to=4.0)
    assert p.t[0] == 1.0 and p.t[-1] == pytest.approx(4.0) and p.t.size == 301
    np.testing.assert_allclose(p.y + p.y_removed, y[100:401], atol=1e-12)     # used + removed = the file's
    np.testing.assert_allclose(p.u + p.u_removed, u[100:401], atol=1e-12)
    assert abs(np.polyfit(np.arange(p.t.size), p.y, 1)[0]) < 1e-12
    assert p.n_estimation == 201 and p.t_split == pytest.approx(t[301])
    m = prepare_record(t, u, y, detrend="mean")
    assert abs(m.u.mean()) < 1e-12 and np.ptp(m.u_removed) == 0
    none = prepare_record(t, u, y)
    assert np.array_equal(none.y, y) and not none.y_removed.any()
    with pytest.raises(ValueError, match=r"^to t = 9 is not allowed: your record runs from 0 to 4.99 s$"):
        prepare_record(t, u, y, t_to=9)
    with pytest.raises(ValueError, match=r"^from t = abc is not allowed: enter a time in s, or leave it blank$"):
        prepare_record(t, u, y, t_from="abc")
    with pytest.raises(ValueError, match=r"holds 11 samples; need at least 30"):
        prepare_record(t, u, y, t_from=2.0, t_to=2.1)


def test_a_record_with_a_dead_time_is_estimated_with_it():
    from eha_core.identify.validate import simulate_tf

    t = np.arange(1500) * 0.01
    rng = np.random.default_rng(3)
    u = np.repeat(rng.choice([-1.0, 1.0], 300), 5)
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, 0.01, input_delay=0.043)
    rec = identify_record(t, u, y, n_poles=2, input_delay="estimate", input_offset="zero")
    assert abs(rec.estimate.input_delay - 0.043) < 0.01 * 0.1          # a tenth of a sample
    assert rec.validation.input_delay == rec.estimate.input_delay and rec.validation.fit_percent > 99
    plain = identify_record(t, u, y, n_poles=2, input_offset="zero")
    assert plain.validation.fit_percent < rec.validation.fit_percent
