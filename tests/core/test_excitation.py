"""Tests of eha_core.excitation: MATLAB idinput conventions, as real properties."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eha_core.excitation import Excitation, idinput

# MATLAB idinput.m's PRBS register taps, written out again here so the module's
# table is checked against an independent transcription.
MATLAB_TAPS = {
    3: (1, 3), 4: (1, 4), 5: (2, 5), 6: (1, 6), 7: (1, 7), 8: (1, 2, 7, 8),
    9: (4, 9), 10: (3, 10), 11: (9, 11), 12: (6, 8, 11, 12),
}  # fmt: skip


def dft_bins_with_energy(x: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Indices k (0..P/2) where |DFT| of one period is above rel_tol * max."""
    mag = np.abs(np.fft.rfft(x))
    return np.flatnonzero(mag > rel_tol * mag.max())


def matlab_prbs_register(order: int) -> list[float]:
    """MATLAB's loop, literally: fi starts at -1, output fi(n), shift in prod(fi(ind))."""
    fi = [-1.0] * order
    out = []
    for _ in range(2**order - 1):
        out.append(fi[order - 1])
        new = math.prod(fi[j - 1] for j in MATLAB_TAPS[order])
        fi = [new] + fi[:-1]
    return out


def circular_autocorrelation(c: np.ndarray) -> np.ndarray:
    spectrum = np.fft.fft(c)
    return np.real(np.fft.ifft(spectrum * np.conj(spectrum)))


# ---------------------------------------------------------------------------
# The paper's signal: idinput([1000 1 1], 'sine', [0 1], [-1 1], [100 50 1])
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def paper_signal() -> Excitation:
    return idinput([1000, 1, 1], "sine", [0, 1], [-1, 1], [100, 50, 1], seed=2024)


def test_paper_signal_shape_and_record_length(paper_signal):
    assert paper_signal.u.shape == (1000,)
    assert paper_signal.freqs.shape == (100,)
    assert (paper_signal.period, paper_signal.n_channels, paper_signal.n_periods) == (1000, 1, 1)
    assert paper_signal.sinedata == (100, 50, 1)
    # Ts = 0.01 s: a 10 s record (the axes of Figs. 11 and 13)
    assert paper_signal.time_s(0.01)[-1] + 0.01 == pytest.approx(10.0)


def test_paper_signal_frequencies_follow_matlab_choose(paper_signal):
    k = paper_signal.freqs * 1000 / (2 * np.pi)
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)  # on the grid 2*pi*k/P
    k = np.round(k).astype(int)
    assert len(set(k)) == 100
    assert k.min() >= 1 and k.max() < 500  # strictly inside (0, pi): k = 500 is pi
    # choose(499, 100) by hand: k = floor(499/99) = 5 -> picks 1 and 499, keeps
    # 6..494; then floor(489/97) = 5 -> 6 and 494; then 11 and 489, ...
    assert list(k[:3]) == [1, 6, 11]
    assert list(k[-3:]) == [489, 494, 499]
    hz = paper_signal.freqs_hz(0.01)
    assert hz[0] == pytest.approx(0.1) and hz[-1] == pytest.approx(49.9)
    np.testing.assert_allclose(paper_signal.freqs_rad_s(0.01), 2 * np.pi * hz)


def test_paper_signal_spectrum_only_at_the_chosen_bins(paper_signal):
    k = np.round(paper_signal.freqs * 1000 / (2 * np.pi)).astype(int)
    np.testing.assert_array_equal(dft_bins_with_energy(paper_signal.u), k)


def test_paper_signal_symmetric_scaling_into_range(paper_signal):
    u = paper_signal.u
    assert u.min() >= -1 - 1e-12 and u.max() <= 1 + 1e-12
    assert max(-u.min(), u.max()) == pytest.approx(1.0, abs=1e-12)
    assert u.mean() == pytest.approx(0.0, abs=1e-12)  # 0 maps to the mid-range


# ---------------------------------------------------------------------------
# 'sine'
# ---------------------------------------------------------------------------


def test_kept_trial_has_the_smallest_peak_to_peak():
    period, n_sines, n_trials, seed = 240, 6, 12, 5
    exc = idinput([period, 1, 1], "sine", [0.1, 0.7], [-1, 1], [n_sines, n_trials, 1], seed=seed)
    # Recompute the trials the slow, literal way from the documented draw order.
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, (1, n_trials, n_sines))[0]
    t = np.arange(period)[:, None]
    trials = np.array([np.cos(t * exc.freqs + ph).sum(axis=1) for ph in phases])
    ptp = np.ptp(trials, axis=1)
    assert ptp.max() - ptp.min() > 0.1  # the choice matters for this case
    best = trials[np.argmin(ptp)]
    peak = np.abs(best).max()
    np.testing.assert_allclose(exc.u, (best + peak) / peak - 1, atol=1e-12)
    for j in np.flatnonzero(ptp > ptp.min() + 1e-9):  # any other trial differs
        assert not np.allclose(exc.u, trials[j] / np.abs(trials[j]).max())


def test_sine_band_edges_are_excluded_and_too_many_sinusoids_is_an_error():
    # P = 100, band [0.2, 0.6]: 2k/P strictly inside -> k = 11..29 (19 of them)
    exc = idinput(100, "sine", [0.2, 0.6], [-1, 1], [19, 3, 1], seed=0)
    k = np.round(exc.freqs * 100 / (2 * np.pi)).astype(int)
    np.testing.assert_array_equal(k, np.arange(11, 30))
    with pytest.raises(ValueError, match=r"sinedata = \[20, 3, 1\] is not allowed: NumSinusoids = 20 .* <= 19"):
        idinput(100, "sine", [0.2, 0.6], [-1, 1], [20, 3, 1], seed=0)


def test_gridskip_two_gives_odd_harmonics_inside_the_band():
    exc = idinput([512, 1, 1], "sine", [0.05, 0.5], [-1, 1], [12, 4, 2], seed=3)
    k = np.round(exc.freqs * 512 / (2 * np.pi)).astype(int)
    assert len(k) == 12 and np.all(k % 2 == 1)
    assert np.all(exc.freqs > 0.05 * np.pi) and np.all(exc.freqs < 0.5 * np.pi)
    np.testing.assert_array_equal(dft_bins_with_energy(exc.u), k)


def test_multichannel_sine_uses_different_frequencies_per_channel():
    period, nu = 256, 3
    exc = idinput([period, nu, 2], "sine", [0, 0.8], [0, 10], [4, 5, 1], seed=11)
    assert exc.u.shape == (2 * period, nu)
    assert exc.freqs.shape == (4, nu)
    k = np.round(exc.freqs * period / (2 * np.pi)).astype(int)
    assert len(set(k.ravel())) == 4 * nu  # no frequency shared between channels
    # MATLAB interleaves: channel ku gets chosen(ku::Nu) of the sorted choice
    np.testing.assert_array_equal(np.sort(k.ravel()).reshape(4, nu), k)
    for j in range(nu):
        np.testing.assert_array_equal(dft_bins_with_energy(exc.u[:period, j] - 5.0), k[:, j])
    np.testing.assert_array_equal(exc.u[:period], exc.u[period:])


def test_sine_asymmetric_range_is_scaled_about_the_mid_range():
    exc = idinput([300, 1, 1], "sine", [0, 1], [2, 5], [7, 8, 1], seed=4)
    u = exc.u
    assert u.min() >= 2 - 1e-12 and u.max() <= 5 + 1e-12
    assert np.abs(u - 3.5).max() == pytest.approx(1.5, abs=1e-12)
    assert u.mean() == pytest.approx(3.5, abs=1e-12)
    assert min(u.max() - 5, 2 - u.min()) < -1e-3  # only one bound is reached here


# ---------------------------------------------------------------------------
# 'rgs' and 'rbs'
# ---------------------------------------------------------------------------


def test_rgs_mean_and_std_match_range_exactly_per_period():
    exc = idinput([4000, 2, 3], "rgs", [0, 1], [-2, 6], seed=1)
    one = exc.u[:4000]
    np.testing.assert_allclose(one.mean(axis=0), [2.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(one.std(axis=0), [4.0, 4.0], rtol=1e-12)
    np.testing.assert_array_equal(exc.u[4000:8000], one)
    np.testing.assert_array_equal(exc.u[8000:], one)


def test_rgs_is_gaussian_and_channels_are_independent():
    u = idinput([20000, 2], "rgs", seed=8).u
    within_one_std = np.mean(np.abs(u) <= 1.0, axis=0)
    np.testing.assert_allclose(within_one_std, 0.6827, atol=0.02)  # ~6 sigma
    assert abs(np.corrcoef(u.T)[0, 1]) < 0.05


def test_rgs_spectrum_is_band_limited_to_the_band():
    period, band = 1000, (0.2, 0.5)
    u = idinput([period, 1, 2], "rgs", band, [-1, 1], seed=2).u
    bins = dft_bins_with_energy(u[:period] - u[:period].mean(), rel_tol=1e-9)
    x = 2 * bins / period
    assert np.all((x >= 0.2 - 1e-12) & (x <= 0.5 + 1e-12))
    assert len(bins) > 0.9 * (0.5 - 0.2) * period / 2  # and fills the band
    # the two-period signal has lines only at multiples of its fundamental
    assert np.all(dft_bins_with_energy(u - u.mean()) % 2 == 0)


def test_rbs_takes_two_levels_and_band_lowers_the_switching_rate():
    white = idinput([5000, 1, 2], "rbs", [0, 1], [-3, 7], seed=6).u
    assert set(np.unique(white)) == {-3.0, 7.0}
    assert np.mean(white == 7.0) == pytest.approx(0.5, abs=0.03)
    np.testing.assert_array_equal(white[:5000], white[5000:])
    slow = idinput(5000, "rbs", [0, 0.1], [0, 1], seed=6).u
    assert set(np.unique(slow)) == {0.0, 1.0}
    # switching rate: 1/2 for white noise, 0.1/sqrt(3) ~ 0.058 for an ideal
    # low-pass Gaussian process at 0.1 Nyquist (Rice's formula)
    assert np.mean(np.diff(white) != 0) > 0.45
    assert np.mean(np.diff(slow) != 0) < 0.09


# ---------------------------------------------------------------------------
# 'prbs'
# ---------------------------------------------------------------------------


def test_prbs_order_3_by_hand():
    # MATLAB's register from [-1 -1 -1] with taps [1 3]: -1 -1 -1 1 -1 1 1
    exc = idinput(7, "prbs", [0, 1], [0, 1])
    np.testing.assert_array_equal(exc.u, [0, 0, 0, 1, 0, 1, 1])
    assert exc.clock_period == 1 and exc.freqs.size == 0


@pytest.mark.parametrize("order", sorted(MATLAB_TAPS))
def test_prbs_matches_matlab_shift_register(order):
    u = idinput(2**order - 1, "prbs").u
    np.testing.assert_array_equal(u, matlab_prbs_register(order))


@pytest.mark.parametrize("order", range(3, 19))
def test_prbs_is_a_maximum_length_sequence(order):
    length = 2**order - 1
    u = idinput(length, "prbs").u
    assert set(np.unique(u)) == {-1.0, 1.0}
    assert np.sum(u == -1.0) == 2 ** (order - 1)  # one more -1 than +1
    r = np.round(circular_autocorrelation(u)).astype(int)
    assert r[0] == length
    assert np.all(r[1:] == -1)


def test_prbs_clock_period_follows_band():
    exc = idinput([3 * 31, 1, 2], "prbs", [0, 1 / 3], [-1, 1])
    assert exc.clock_period == 3 and exc.period == 93 and exc.u.shape == (186,)
    blocks = exc.u[:93].reshape(31, 3)
    assert np.all(blocks == blocks[:, :1])  # held over 3 samples
    chips = blocks[:, 0]
    r = np.round(circular_autocorrelation(chips)).astype(int)
    assert r[0] == 31 and np.all(r[1:] == -1)
    np.testing.assert_array_equal(exc.u[93:], exc.u[:93])
    # MATLAB takes floor(1/B), not round: B = 0.6 -> clock period 1, not 2
    assert idinput(7, "prbs", [0, 0.6]).clock_period == 1


def test_prbs_channels_are_maximally_shifted_copies():
    u = idinput([15, 3], "prbs").u
    for j in range(3):
        np.testing.assert_array_equal(u[:, j], np.roll(u[:, 0], -5 * j))


def test_prbs_period_not_a_full_sequence():
    with pytest.warns(UserWarning, match="changed from 100 to 63"):
        periodic = idinput([100, 1, 2], "prbs")
    assert periodic.period == 63 and periodic.u.shape == (126,)
    np.testing.assert_array_equal(periodic.u[:63], idinput(63, "prbs").u)
    with pytest.warns(UserWarning, match="100 first values .* length 127"):
        once = idinput(100, "prbs")
    assert once.period == 100
    np.testing.assert_array_equal(once.u, idinput(127, "prbs").u[:100])
    with pytest.raises(ValueError, match=r"n = 262144 is not allowed: P = 262144 is too long for type prbs"):
        idinput(2**18, "prbs")


# ---------------------------------------------------------------------------
# Seeds, result object, argument forms
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["rgs", "rbs", "sine"])
def test_same_seed_same_signal_different_seed_different_signal(kind):
    a = idinput([128, 2], kind, [0, 0.9], seed=42)
    b = idinput([128, 2], kind, [0, 0.9], seed=42)
    c = idinput([128, 2], kind, [0, 0.9], seed=43)
    np.testing.assert_array_equal(a.u, b.u)
    assert not np.array_equal(a.u, c.u)
    fresh = idinput([128, 2], kind, [0, 0.9])  # seed drawn and recorded
    np.testing.assert_array_equal(idinput([128, 2], kind, [0, 0.9], seed=fresh.seed).u, fresh.u)


def test_argument_forms_and_defaults():
    assert idinput(50, seed=0).u.shape == (50,)
    assert idinput(50, seed=0).type == "rgs"
    assert idinput([50], "SINE", seed=0).sinedata == (10, 10, 1)
    assert idinput(np.array([50, 2]), "Rbs", seed=0).u.shape == (50, 2)
    assert idinput([50.0, 1, 3], "rgs", seed=0).u.shape == (150,)
    assert idinput(200, "sine", sinedata=[5], seed=0).sinedata == (5, 10, 1)
    assert idinput(200, "sine", sinedata=(5, 3), seed=0).sinedata == (5, 3, 1)


def test_result_object():
    exc = idinput([64, 2, 2], "sine", [0, 1], [-1, 1], [3, 2, 1], seed=0)
    with pytest.raises(ValueError):
        exc.u[0, 0] = 5.0  # read-only arrays in a frozen result
    with pytest.raises(AttributeError):
        exc.period = 3
    df = exc.to_pandas()
    assert list(df.columns) == ["k", "u1", "u2"] and len(df) == 128
    np.testing.assert_array_equal(df["u2"].to_numpy(), exc.u[:, 1])
    assert list(idinput(10, seed=0).to_pandas(ts=0.1).columns) == ["k", "t_s", "u"]
    assert idinput(10, seed=0).freqs.shape == (0,)
    with pytest.raises(ValueError, match=r"ts = 0 is not allowed: need .* > 0"):
        exc.freqs_hz(0)


# ---------------------------------------------------------------------------
# Validation: every message names the argument, the value and what is allowed
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"type": "chirp"}, r"type = chirp is not allowed: need one of rgs, rbs, prbs, sine"),
        ({"type": 3}, r"type = 3 is not allowed: need one of"),
        ({"n": 0}, r"n = 0 is not allowed: need a positive integer N or a sequence"),
        ({"n": -5}, r"n = -5 is not allowed: need a positive integer"),
        ({"n": 10.5}, r"n = 10.5 is not allowed: need a positive integer"),
        ({"n": [100, 0, 1]}, r"n = \[100, 0, 1\] is not allowed: need .* positive integers"),
        ({"n": [100, 1, 2.5]}, r"n = \[100, 1, 2.5\] is not allowed"),
        ({"n": np.array([100, 0])}, r"n = \[100, 0\] is not allowed"),
        ({"n": [10, 1, 1, 1]}, r"n = \[10, 1, 1, 1\] is not allowed: need .*\[P, Nu, M\]"),
        ({"n": True}, r"n = True is not allowed"),
        ({"band": [0.2, 1.5]},
         r"band = \[0.2, 1.5\] is not allowed: need \[wlow, whigh\] with 0 <= wlow < whigh <= 1"),
        ({"band": [0.5, 0.2]}, r"band = \[0.5, 0.2\] is not allowed: need .*0 <= wlow < whigh <= 1"),
        ({"band": [-0.1, 0.5]}, r"band = \[-0.1, 0.5\] is not allowed"),
        ({"band": [0.3]}, r"band = \[0.3\] is not allowed: need \[wlow, whigh\]"),
        ({"type": "prbs", "band": [0.1, 0.5]},
         r"band = \[0.1, 0.5\] is not allowed: type prbs needs \[0, B\] with 0 < B <= 1"),
        ({"range": [1, -1]}, r"range = \[1, -1\] is not allowed: need \[min, max\] .* min < max"),
        ({"range": [2, 2]}, r"range = \[2, 2\] is not allowed: need \[min, max\]"),
        ({"range": [0, float("inf")]}, r"range = \[0, inf\] is not allowed: need \[min, max\] of finite"),
        ({"type": "sine", "sinedata": [0, 10, 1]},
         r"sinedata = \[0, 10, 1\] is not allowed: need \[NumSinusoids, NumTrials, GridSkip\] of positive integers"),
        ({"type": "sine", "sinedata": [10, -1, 1]}, r"sinedata = \[10, -1, 1\] is not allowed"),
        ({"type": "sine", "sinedata": [10, 10, 0]}, r"sinedata = \[10, 10, 0\] is not allowed"),
        ({"type": "rgs", "n": 10, "band": [0.01, 0.1]},
         r"band = \[0.01, 0.1\] is not allowed: with period P = 10 no DFT frequency"),
        ({"type": "rgs", "n": 1}, r"band = \[0, 1\] is not allowed: with period P = 1 "),
        ({"seed": -1}, r"seed = -1 is not allowed: need None or a non-negative integer"),
        ({"seed": 1.5}, r"seed = 1.5 is not allowed"),
    ],
)
def test_validation_messages(kwargs, message):
    args = {"n": 100, "type": "rgs"} | kwargs
    with pytest.raises(ValueError, match=message):
        idinput(args.pop("n"), **args)


def test_too_many_sinusoids_message_names_everything():
    with pytest.raises(ValueError) as info:
        idinput([1000, 2, 1], "sine", [0, 1], [-1, 1], [300, 5, 1], seed=0)
    text = str(info.value)
    assert text.startswith("sinedata = [300, 5, 1] is not allowed: ")
    for part in ("NumSinusoids = 300", "Nu = 2", "P = 1000", "<= 499", "MATLAB errors"):
        assert part in text
