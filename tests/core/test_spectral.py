"""The data's frequency response (Fig. 12): ETFE over whole periods, spectral estimate otherwise.

"True" here is the sampled-data system: the input is held between samples
(zero-order hold), so the samples obey the ZOH equivalent of the continuous
plant exactly, and that is what any estimate from the samples converges to.
It differs from the continuous H(j w) by the hold's half-sample delay and
sinc roll-off (up to about 5 dB in magnitude at the Nyquist frequency for the
paper's loop), which is why the comparisons below are with the ZOH equivalent.
"""

import warnings

import numpy as np
import pytest
import scipy.signal

from eha_core.excitation import idinput
from eha_core.experiments import FrequencyExperiment, run_frequency_identification
from eha_core.identify._ctmodels import simulate_tf
from eha_core.identify.spectral import (
    DataFrequencyResponse,
    data_frequency_response,
    detect_period,
    etfe,
    spa,
)
from eha_core.identify.validate import etfe_periodic
from eha_core.linear import linearize
from eha_core.params import ActuatorParams

TS = 0.01
LIN = linearize(ActuatorParams())
#: eq. 24, the linearised closed loop r -> x with Kp = 10: poles -385, -44.5, -0.142 rad/s
H_NUM, H_DEN = LIN.closed_loop_coeffs(10.0)


def zoh_response(num, den, w):
    """G_zoh(exp(j w Ts)), the sampled-data system, at w [rad/s]."""
    num_z, den_z, _ = scipy.signal.cont2discrete((num, den), TS, method="zoh")
    return scipy.signal.freqz(num_z.ravel(), den_z, worN=np.asarray(w) * TS)[1]


def db_error(fr, true):
    return fr.magnitude_db - 20 * np.log10(np.abs(true))


def excitation(kind, n, band, seed=0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # idinput: a prbs that is not a whole period
        return idinput(n, kind, band, [-1, 1], [100, 50, 1], seed=seed)


# (type, idinput's n, band, period stated by the caller, method expected)
CASES = [
    ("sine", [1000, 1, 1], (0, 1), "design", "etfe"),      # the paper's excitation, one period
    ("sine", [1000, 1, 1], (0, 0.3), "design", "etfe"),
    ("prbs", [1023, 1, 1], (0, 1), 1023, "etfe"),          # a whole maximum-length period
    ("prbs", [2046, 1, 1], (0, 0.5), 2046, "etfe"),        # clock period 2
    ("prbs", [1000, 1, 1], (0, 1), 1023, "spa"),           # the first 1000 samples of 1023
    ("rbs", 1000, (0, 1), None, "spa"),
    ("rbs", 1000, (0, 0.5), None, "spa"),
    ("rgs", 1000, (0, 1), None, "spa"),
    ("rgs", 1000, (0, 0.5), None, "spa"),
    ("rbs", [500, 1, 4], (0, 0.5), None, "etfe"),        # repeated: the period is found in the signal
    ("rgs", [500, 1, 2], (0, 1), None, "etfe"),
]


@pytest.mark.parametrize("kind, n, band, period, method", CASES)
def test_points_lie_within_1_db_of_the_zoh_response_over_the_excited_band(kind, n, band, period, method):
    seeds = (0,) if kind == "prbs" else (0, 1, 2)   # prbs draws no random numbers
    for seed in seeds:
        exc = excitation(kind, n, band, seed)
        y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
        fr = data_frequency_response(exc.u, y, TS, period=exc.period if period == "design" else period,
                                     freqs=exc.freqs if exc.freqs.size else None, band=band)
        assert fr.method == method
        error = db_error(fr, zoh_response(H_NUM, H_DEN, fr.w))
        assert np.max(np.abs(error)) < 1.0, (kind, n, band, seed, fr.w[np.argmax(np.abs(error))])
        nyquist = np.pi / TS
        if method == "etfe":
            # every excited line is drawn
            lines = exc.freqs / TS if exc.freqs.size else None
            if lines is not None:
                np.testing.assert_allclose(fr.w, lines)
            assert fr.band == (fr.w.min(), fr.w.max())
            assert fr.lower_db is None and fr.upper_db is None
        else:
            # from the window's resolution to the band's top (less one resolution inside Nyquist)
            resolution = 2 * np.pi / (fr.lags * TS)
            assert fr.lags == exc.u.size // 10
            assert fr.band[0] == pytest.approx(resolution)
            top = nyquist if band[1] == 1 else band[1] * nyquist - resolution
            assert fr.band[1] == pytest.approx(top)
            assert fr.w[0] == pytest.approx(fr.band[0]) and fr.w[-1] == pytest.approx(fr.band[1])
            assert np.all(fr.lower_db <= fr.magnitude_db) and np.all(fr.magnitude_db <= fr.upper_db)


def test_the_plain_etfe_of_the_same_records_is_far_off():
    """What the module fixes: the start-up transient of the 7 s pole swamps the small high-frequency response."""
    exc = excitation("sine", [1000, 1, 1], (0, 1))
    y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    plain = etfe_periodic(exc.u, y, 1000, TS, freqs=exc.freqs)
    assert np.max(np.abs(db_error(plain, zoh_response(H_NUM, H_DEN, plain.w)))) > 10.0
    fixed = etfe(exc.u, y, 1000, TS, freqs=exc.freqs)
    assert np.max(np.abs(db_error(fixed, zoh_response(H_NUM, H_DEN, fixed.w)))) < 0.2
    exc = excitation("prbs", [1000, 1, 1], (0, 1))
    y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    plain = etfe_periodic(exc.u, y, 1000, TS)   # what the app drew for this record
    assert np.max(np.abs(db_error(plain, zoh_response(H_NUM, H_DEN, plain.w)))) > 10.0
    fixed = data_frequency_response(exc.u, y, TS, period=1023)
    assert np.max(np.abs(db_error(fixed, zoh_response(H_NUM, H_DEN, fixed.w)))) < 1.0


def test_a_periodic_record_in_steady_state_gives_the_plain_etfe():
    exc = excitation("rgs", [300, 1, 40], (0, 0.6))
    y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    fr = etfe(exc.u, y, 300, TS, drop_periods=38)    # 114 s: the 7 s pole has settled
    plain = etfe_periodic(exc.u, y, 300, TS, drop_periods=38)
    np.testing.assert_allclose(fr.w, plain.w)
    np.testing.assert_allclose(fr.response, plain.response, rtol=1e-6)
    np.testing.assert_allclose(fr.response, zoh_response(H_NUM, H_DEN, fr.w), rtol=1e-6)


# -- the choice -------------------------------------------------------------------------
def test_the_period_is_found_in_the_input_when_it_repeats():
    exc = excitation("rgs", [200, 1, 3], (0, 0.5), seed=4)
    assert detect_period(exc.u) == 200
    y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    fr = data_frequency_response(exc.u, y, TS)
    assert (fr.method, fr.period, fr.n_periods) == ("etfe", 200, 3)
    assert fr.description == ("ETFE at the 50 excited frequencies: the record holds 3 whole periods of 200 "
                              "samples (the first, which carries the start-up transient, left out).")
    # one period of the same signal cannot be told from a random one
    assert detect_period(exc.u[:200]) is None
    assert data_frequency_response(exc.u[:200], y[:200], TS, lags=20).method == "spa"


def test_descriptions_say_what_was_done_and_why():
    exc = excitation("rbs", 1000, (0, 0.5), seed=1)
    y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    fr = data_frequency_response(exc.u, y, TS, band=(0, 0.5))
    assert fr.description == ("Spectral estimate (Blackman-Tukey, Hann window of 100 lags, 95 % band) from 6.28 "
                              "to 151 rad/s: the input does not repeat within the record.")
    fr = data_frequency_response(exc.u, y, TS, period=1023, band=(0, 0.5), lags=50, confidence=0.9)
    assert fr.description == ("Spectral estimate (Blackman-Tukey, Hann window of 50 lags, 90 % band) from 12.6 "
                              "to 145 rad/s: the record's 1000 samples are not a whole number of periods of "
                              "1023 samples.")
    exc = excitation("sine", [1000, 1, 1], (0, 1))
    fr = data_frequency_response(exc.u, simulate_tf(H_NUM, H_DEN, exc.u, TS), TS, period=1000, freqs=exc.freqs)
    assert fr.description == "ETFE at the 100 excited frequencies: the record holds 1 whole period of 1000 samples."


@pytest.mark.parametrize("signal_type, n_samples, method", [
    ("sine", 1000, "etfe"), ("prbs", 1023, "etfe"), ("prbs", 1000, "spa"), ("rbs", 1000, "spa"),
    ("rgs", 1000, "spa"),
])
def test_the_closed_loop_experiment_draws_the_sampled_loop(signal_type, n_samples, method):
    """The real experiment on the linearised plant: u = Kp (r - x) sampled and held at Ts.

    The sampled-data loop is Kp P_zoh / (1 + Kp P_zoh). The linear model
    switches the valve's gain with the sign of u (Fig. 3), 20 % apart: the
    points must lie between the two branches' loops.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        fi = run_frequency_identification(config=FrequencyExperiment(model="linear", signal_type=signal_type,
                                                                     n_samples=n_samples))
    fr = fi.data_response
    assert isinstance(fr, DataFrequencyResponse) and fr.method == method
    loops = []
    for branch in ("positive", "negative"):
        p = zoh_response(*LIN.tf_coeffs(branch), fr.w)
        loops.append(20 * np.log10(np.abs(10 * p / (1 + 10 * p))))
    low, high = np.minimum(*loops), np.maximum(*loops)
    assert np.all(fr.magnitude_db > low - 0.25) and np.all(fr.magnitude_db < high + 0.25)
    # the names the app reads
    assert fi.etfe is fr.response
    np.testing.assert_array_equal(fi.bode.data_w, fr.w)
    assert fi.bode.etfe_phase_deg is fi.bode.data_phase_deg
    assert (fi.bode.data_method, fi.bode.data_description, fi.bode.data_band) == (method, fr.description, fr.band)
    assert (fi.bode.data_lower_db is None) == (method == "etfe")


def test_the_paper_experiment_draws_the_etfe():
    fi = run_frequency_identification()
    fr = fi.data_response
    assert fr.method == "etfe" and fr.w.size == 100 and fr.n_periods == 1
    assert fi.to_dict()["data_response"]["method"] == "etfe"
    # the nonlinear plant: the points follow H_hat (its lightly damped pair near 130 rad/s), not eq. 24
    model = fi.estimate.frequency_response(fr.w).magnitude_db
    assert np.median(np.abs(fr.magnitude_db - model)) < 1.0 and np.max(np.abs(fr.magnitude_db - model)) < 3.0
    plain = etfe_periodic(fi.data.r, fi.data.x, 1000, TS, freqs=fi.excitation.freqs)   # what the app drew
    assert np.max(np.abs(plain.magnitude_db - model)) > 10.0
    # the phase is drawn on H_hat's branch
    assert np.all(np.abs(fi.bode.data_phase_deg - fi.estimate.frequency_response(fr.w).phase_deg) <= 180.0)


# -- the confidence band -----------------------------------------------------------------
@pytest.mark.parametrize("kind, band", [("rgs", (0, 1)), ("rbs", (0, 0.5))])
@pytest.mark.parametrize("noise", [1e-3, 1e-2])
def test_the_confidence_band_covers_the_true_response_at_its_nominal_rate(kind, band, noise):
    """White output noise on the linear plant: the 95 % band holds the ZOH response at >= 85 % of frequencies."""
    coverage, informative = [], []
    for seed in range(6):
        exc = excitation(kind, 1000, band, seed)
        rng = np.random.default_rng(100 + seed)
        y = simulate_tf(H_NUM, H_DEN, exc.u, TS) + noise * rng.standard_normal(exc.u.size)
        est = spa(exc.u, y, TS, band=band)
        true_db = 20 * np.log10(np.abs(zoh_response(H_NUM, H_DEN, est.w)))
        coverage.append(np.mean((est.lower_db <= true_db) & (true_db <= est.upper_db)))
        informative.append(np.mean(np.isfinite(est.lower_db)))
    assert np.mean(coverage) >= 0.9 and min(coverage) >= 0.8, coverage
    # ... and the band says something: where the noise is weak it bounds the magnitude from below too
    assert np.mean(informative) > (0.7 if noise == 1e-3 else 0.3), informative


def test_the_band_narrows_with_the_noise_and_widens_with_the_window():
    exc = excitation("rgs", 2000, (0, 1), seed=3)
    clean = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    noise = np.random.default_rng(3).standard_normal(exc.u.size)
    widths = {}
    for sigma in (1e-4, 1e-3):
        for lags in (100, 400):
            est = spa(exc.u, clean + sigma * noise, TS, lags=lags, band=(0.1, 0.5))
            assert est.window_energy == pytest.approx(0.75 * lags, rel=0.01)   # Ljung's Table 6.1
            widths[sigma, lags] = np.median(est.upper_db - est.magnitude_db)
    assert widths[1e-4, 100] < widths[1e-3, 100] < widths[1e-3, 400]
    assert widths[1e-4, 100] < widths[1e-4, 400]


# -- arguments ----------------------------------------------------------------------------
def test_refusals_read_name_value_what():
    exc = excitation("rgs", 500, (0, 1))
    y = simulate_tf(H_NUM, H_DEN, exc.u, TS)
    with pytest.raises(ValueError, match=r"^lags = 1 is not allowed: must be a whole number in \[2, 498\]"):
        spa(exc.u, y, TS, lags=1)
    with pytest.raises(ValueError, match=r"^lags = 30 is not allowed: a window of 30 lags resolves 0.209 rad/sample, "
                                         r"too coarse for the excited band \[0.314, 0.377\] rad/sample"):
        spa(exc.u, y, TS, lags=30, band=(0.1, 0.12))
    with pytest.raises(ValueError, match=r"^confidence = 1.5 is not allowed: must be a probability in \(0, 1\)"):
        spa(exc.u, y, TS, confidence=1.5)
    with pytest.raises(ValueError, match=r"^band = \[0.5, 0.2\] is not allowed: need \[wlow, whigh\]"):
        spa(exc.u, y, TS, band=(0.5, 0.2))
    with pytest.raises(ValueError, match=r"^u = .* is not allowed: the input is constant"):
        data_frequency_response(np.ones(100), np.ones(100), TS)
    with pytest.raises(ValueError, match=r"^period = 100 is not allowed: the input does not repeat every 100 samples"):
        data_frequency_response(exc.u, y, TS, period=100)
    with pytest.raises(ValueError, match=r"^freqs = \[0.01\] is not allowed: .*on the period's grid"):
        etfe(exc.u, y, 500, TS, freqs=[0.01])
    with pytest.raises(ValueError, match=r"^period = 8 is not allowed: must be a whole number in \[16, 500\]"):
        etfe(exc.u, y, 8, TS)


def test_a_period_too_short_for_the_etfe_falls_back_to_the_spectral_estimate():
    u = np.tile([1.0, 0.0, 2.0, -1.0, 3.0], 40)
    y = simulate_tf([10.0], [1.0, 10.0], u, TS)
    fr = data_frequency_response(u, y, TS)
    assert fr.method == "spa" and fr.period == 5
    assert fr.description.endswith(": the input repeats every 5 samples, too few for the ETFE (at least 16).")
