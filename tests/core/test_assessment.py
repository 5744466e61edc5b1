"""Tests of eha_core.identify.assessment: verdicts on the residual correlations."""


import numpy as np
import pytest
import scipy.signal

from eha_core.identify.assessment import CorrelationVerdict, ResidualAssessment, assess_residuals, chance_allowance
from eha_core.identify.tfest import tfest
from eha_core.identify.validate import residual_analysis, simulate_tf

TS = 0.01
# a resonance and a real pole: 3 poles, 1 zero
NUM = np.array([40.0, 80.0])
DEN = np.polymul([1.0, 2.0, 40.0], [1.0, 4.0])


def _data(seed, noise, n=2000):
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], n // 2), 2)
    y0 = simulate_tf(NUM, DEN, u, TS)
    return u, y0, y0 + noise(rng, n) * 0.05 * np.std(y0)


def _white(rng, n):
    return rng.standard_normal(n)


def _coloured(rng, n):
    # AR(1) with pole 0.9, scaled to unit variance: slow, correlated noise
    return scipy.signal.lfilter([np.sqrt(1 - 0.81)], [1.0, -0.9], rng.standard_normal(n))


def _assessment(u, y, n_poles, n_zeros):
    est = tfest(u, y, TS, n_poles=n_poles, n_zeros=n_zeros)
    assert est.success, est.message
    return assess_residuals(residual_analysis(y - est.simulate(u), u))


def test_correct_model_on_white_noise_passes_both():
    u, _, y = _data(1, _white)
    a = _assessment(u, y, 3, 1)
    assert isinstance(a, ResidualAssessment) and a.passed
    for v in a.verdicts:
        assert isinstance(v, CorrelationVerdict) and v.passed and v.n_outside <= v.allowed
    assert a.independence.sentence.startswith("The residuals are uncorrelated with the input (")
    assert f"{a.independence.n_outside} of 51 lags" in a.independence.sentence
    assert "the model explains what the input does" in a.independence.sentence
    assert a.whiteness.sentence.startswith("The residuals are white (")
    assert f"{a.whiteness.n_outside} of 25 lags" in a.whiteness.sentence
    assert "the noise model is adequate" in a.whiteness.sentence


def test_under_ordered_model_fails_the_cross_correlation():
    u, _, y = _data(2, _white)
    a = _assessment(u, y, 1, 0)               # one pole for a resonance and a pole
    v = a.independence
    assert not v.passed and not a.passed
    assert v.n_outside > v.allowed and v.n_lags == 51
    assert f"({v.n_outside} of 51 lags outside the 99 % band, largest at lag {v.worst_lag}" in v.sentence
    assert v.worst_lag >= 0 and "the model misses dynamics — try more poles or a delay" in v.sentence
    assert v.sentence.startswith("The residuals are correlated with the input")


def test_coloured_noise_fails_the_autocorrelation_only():
    u, _, y = _data(3, _coloured)
    a = _assessment(u, y, 3, 1)
    w = a.whiteness
    assert not w.passed and w.n_outside > w.allowed
    assert w.sentence.startswith(f"The residuals are correlated with themselves ({w.n_outside} of 25 lags")
    assert f"largest at lag {w.worst_lag}" in w.sentence and "coloured noise or unmodelled dynamics" in w.sentence
    # the output-error model is still right: the dynamics pass
    assert a.independence.passed, a.independence.sentence


def test_chance_allowance_is_the_binomial_quantile():
    # P(Binomial(25, 0.01) > 1) = 2.6 %, > 0: 22 %; P(Binomial(51, 0.01) > 2) = 1.5 %, > 1: 9.4 %
    assert chance_allowance(25) == 1 and chance_allowance(51) == 2
    assert chance_allowance(51, false_alarm=0.2) == 1 and chance_allowance(1) == 0


def test_the_rule_fails_white_residuals_rarely():
    """On white residuals and a white input the false alarm is near its 5 % setting.

    Measured with 3000 trials: 4.8 % (whiteness) and 3-4 % (independence).
    400 trials give a binomial standard deviation of about 1 %, so the
    window [1.5 %, 9 %] leaves three of them on each side.
    """
    rng = np.random.default_rng(11)
    trials = 400
    failed = np.zeros(2)
    for _ in range(trials):
        a = assess_residuals(residual_analysis(rng.standard_normal(1000), rng.standard_normal(1000)))
        failed += [not a.whiteness.passed, not a.independence.passed]
    rate = failed / trials
    print(f"false alarms over {trials} white trials: whiteness {rate[0]:.3f}, independence {rate[1]:.3f}")
    assert np.all((0.015 <= rate) & (rate <= 0.09)), rate


def test_one_lag_far_outside_fails_even_when_the_count_is_small():
    rng = np.random.default_rng(4)
    n = 2000
    u = rng.standard_normal(n)
    e = rng.standard_normal(n) + 0.2 * np.roll(u, 3)       # a missed 3-sample delay
    v = assess_residuals(residual_analysis(e, u)).independence
    assert v.n_outside <= v.allowed and not v.passed
    assert v.worst_lag == 3 and "too far out to be chance" in v.sentence


def test_negative_lag_speaks_of_feedback():
    rng = np.random.default_rng(5)
    n = 2000
    e = rng.standard_normal(n)
    u = rng.standard_normal(n) + 0.5 * np.roll(e, 2)       # the input follows the residual
    v = assess_residuals(residual_analysis(e, u)).independence
    assert not v.passed and v.worst_lag == -2
    assert "feedback" in v.sentence and "largest at lag -2" in v.sentence


def test_bad_input_is_refused():
    res = residual_analysis(np.random.default_rng(0).standard_normal(100), np.ones(100))
    with pytest.raises(ValueError, match=r"^false_alarm = 0.7 is not allowed: "):
        assess_residuals(res, false_alarm=0.7)
    with pytest.raises(ValueError, match=r"^analysis = \[1, 2\] is not allowed: must be a ResidualAnalysis"):
        assess_residuals([1, 2])
