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
