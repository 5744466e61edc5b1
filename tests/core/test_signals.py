"""Tests of eha_core.signals: values at known times, the text form, hashing, noise, sampled data."""

import math
import re

import numpy as np
import pytest

from eha_core.signals import (
    ZERO,
    Chirp,
    Constant,
    Sampled,
    Signal,
    SignalSpecError,
    Sine,
    Square,
    Step,
    Sum,
    WhiteNoise,
    parse_signal,
)

# ---------------------------------------------------------------------------
# values at known times
# ---------------------------------------------------------------------------


def test_sine_with_phase_and_offset_at_known_times():
    s = Sine(2.0, 5.0, phase=0.3, offset=-1.0)
    t = np.array([0.0, 1 / 20, 1 / 10, 3 / 20])      # quarter periods of 5 Hz
    expected = [2.0 * math.sin(0.3) - 1.0, 2.0 * math.cos(0.3) - 1.0,
                -2.0 * math.sin(0.3) - 1.0, -2.0 * math.cos(0.3) - 1.0]
    np.testing.assert_allclose(s(t), expected, rtol=0, atol=1e-12)
    assert s(np.zeros((2, 3))).shape == (2, 3)


def test_step_before_at_and_after_t0():
    s = Step(4.0, t0=0.5)
    np.testing.assert_array_equal(s(np.array([0.0, 0.4999999, 0.5, 0.7, 10.0])), [0.0, 0.0, 4.0, 4.0, 4.0])
    s = Step(4.0, t0=0.5, initial=-1.0)
    np.testing.assert_array_equal(s(np.array([0.0, 0.5])), [-1.0, 4.0])
    assert Step(3.0)(np.array([0.0]))[0] == 3.0      # t0 = 0: on from the start


def test_square_halves():
    s = Square(1.5, 2.0)                               # period 0.5 s
    t = np.array([0.0, 0.1, 0.2499, 0.25, 0.3, 0.4999, 0.5, 0.6])
    np.testing.assert_array_equal(s(t), [1.5, 1.5, 1.5, -1.5, -1.5, -1.5, 1.5, 1.5])
    np.testing.assert_array_equal(Square(1.0, 1.0, offset=2.0)(np.array([0.25, 0.75])), [3.0, 1.0])
    # over whole periods the halves balance: zero mean
    t = np.arange(4000) / 4000.0
    assert abs(Square(1.0, 5.0)(t).mean()) < 1e-12


def _derivative(sig, t, h=1e-6):
    return (sig(np.array([t + h])) - sig(np.array([t - h])))[0] / (2 * h)


def test_chirp_instantaneous_frequency_at_0_and_t1():
    # phase 2 pi (f0 t + (f1 - f0) t^2 / (2 t1)): its rate is 2 pi f0 at t = 0 and
    # 2 pi f1 at t = t1; with f0 = 1, f1 = 3, t1 = 1 the phase there is 4 pi, so
    # the slope of A sin(phase) is A times the phase rate at both ends
    c = Chirp(2.0, 1.0, 3.0, t1=1.0)
    assert c(np.array([0.0]))[0] == 0.0
    assert _derivative(c, 0.0) == pytest.approx(2.0 * 2 * np.pi * 1.0, rel=1e-8)
    assert _derivative(c, 1.0) == pytest.approx(2.0 * 2 * np.pi * 3.0, rel=1e-8)
    # and the same sweep over a longer t1 reaches f1 later: at t = 2 s, 2 pi * 2 Hz
    c2 = Chirp(1.0, 1.0, 3.0, t1=2.0)                  # phase at 2 s: 2 pi (2 + 2) = 8 pi
    assert _derivative(c2, 2.0) == pytest.approx(2 * np.pi * 3.0, rel=1e-8)
    assert _derivative(c2, 1.0) / np.cos(2 * np.pi * 1.5) == pytest.approx(2 * np.pi * 2.0, rel=1e-8)


def test_constants_and_zero():
    np.testing.assert_array_equal(Constant(3.5)(np.linspace(0, 9, 7)), np.full(7, 3.5))
    assert Constant(2.0)(0.3).shape == ()
    np.testing.assert_array_equal(ZERO(np.arange(3.0)), np.zeros(3))
    assert ZERO == Constant(0.0) and ZERO.spec == "none" and ZERO.label == "0"


def test_sums_add_values_and_flatten():
    a, b, c = Sine(6.0, 2.0), Step(1.0, t0=0.5), Constant(-2.0)
    s = a + b + c
    assert isinstance(s, Sum) and s.terms == (a, b, c)
    assert (a + (b + c)).terms == (a, b, c)
    t = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(s(t), a(t) + b(t) + c(t), rtol=0, atol=1e-15)
    assert a + ZERO == a and ZERO + a == a and ZERO + ZERO == ZERO
    with pytest.raises(TypeError):
        a + 1.0                                        # only signals add


def test_continuity_flags():
    assert Sine(1.0, 1.0).continuous and Chirp(1.0, 1.0, 2.0).continuous and Constant(1.0).continuous
    assert not Step(1.0).continuous and not Square(1.0, 1.0).continuous and not WhiteNoise(1.0).continuous
    assert (Sine(1.0, 1.0) + Constant(2.0)).continuous
    assert not (Sine(1.0, 1.0) + Step(1.0)).continuous


# ---------------------------------------------------------------------------
# text form: spec and label
# ---------------------------------------------------------------------------
ROUND_TRIP = [
    Constant(2.5),
    ZERO,
    Sine(6.0, 2.0),
    Sine(6.0, 2.0, phase=0.3),
    Step(1.0),
    Step(1.0, t0=0.5),
    Square(3.0, 4.0),
    Chirp(1.0, 0.5, 20.0, t1=8.0),
    WhiteNoise(100.0, seed=7, hold_s=0.002),
    Sine(6.0, 2.0) + Step(1.0, t0=0.5),
    Sine(5000.0, 1.0) + WhiteNoise(100.0, seed=7) + Constant(3.0),
]


@pytest.mark.parametrize("signal", ROUND_TRIP, ids=lambda s: s.spec)
def test_spec_reads_back_as_the_same_signal(signal):
    again = parse_signal(signal.spec)
    assert again == signal
    assert hash(again) == hash(signal)
    assert again.spec == signal.spec


def test_spec_of_a_sine_with_offset_reads_back_with_the_same_values():
    s = Sine(2.0, 3.0, offset=1.5)
    assert s.spec == "sine:2:3+const:1.5"
    t = np.linspace(0, 1, 17)
    np.testing.assert_allclose(parse_signal(s.spec)(t), s(t), rtol=0, atol=1e-12)


@pytest.mark.parametrize("signal", [Square(1.0, 1.0, offset=2.0), Step(1.0, t0=0.5, initial=-1.0)],
                         ids=["square offset", "step initial"])
def test_spec_keeps_offsets_and_initial_values(signal):
    t = np.linspace(0, 1, 17)
    np.testing.assert_allclose(parse_signal(signal.spec)(t), signal(t), rtol=0, atol=1e-12)


def test_labels():
    assert Sine(6.0, 2.0).label == "6 sin(4πt)"
    assert Sine(1.0, 0.5).label == "1 sin(πt)"
    assert Sine(2.0, 1.0, phase=0.5, offset=3.0).label == "2 sin(2πt + 0.5) + 3"
    assert Step(1.0, t0=0.5).label == "1 step at 0.5 s"
    assert Square(3.0, 4.0).label == "3 square 4 Hz"
    assert Chirp(1.0, 0.5, 20.0).label == "1 chirp 0.5-20 Hz"
    assert WhiteNoise(2.0).label == "white noise σ=2"
    assert Constant(-4.0).label == "-4"
    assert (Sine(6.0, 2.0) + Step(1.0, t0=0.5)).label == "6 sin(4πt) + 1 step at 0.5 s"


# ---------------------------------------------------------------------------
# hashing and equality
# ---------------------------------------------------------------------------


def test_equal_signals_hash_equal_and_serve_as_dict_keys():
    pairs = [(Sine(1.0, 2.0), Sine(1, 2)), (Step(3.0, 0.1), Step(3.0, t0=0.1)),
             (Sine(1.0, 2.0) + Step(3.0), Sine(1.0, 2.0) + Step(3.0)),
             (WhiteNoise(1.0, 4), WhiteNoise(1.0, seed=4, hold_s=1e-3))]
    for a, b in pairs:
        assert a == b and hash(a) == hash(b)
    cache = {a: i for i, (a, _) in enumerate(pairs)}
    assert [cache[b] for _, b in pairs] == [0, 1, 2, 3]
    assert Sine(1.0, 2.0) != Sine(1.0, 2.5) and Sine(1.0, 2.0) + Step(3.0) != Step(3.0) + Sine(1.0, 2.0)
    assert WhiteNoise(1.0, 4) != WhiteNoise(1.0, 5)


def test_a_noise_keeps_its_hash_and_equality_after_use():
    """Its generator states are cached on the object, outside the compared fields."""
    w = WhiteNoise(1.0, seed=2)
    before = hash(w)
    w(np.arange(0.0, 100.0, 1e-3))
    assert hash(w) == before and w == WhiteNoise(1.0, seed=2)


def test_sampled_signals_hash_by_identity():
    a = Sampled(np.arange(3.0), np.ones(3))
    b = Sampled(np.arange(3.0), np.ones(3))
    assert {a: 1}[a] == 1 and a != b                  # arrays are not compared


# ---------------------------------------------------------------------------
# white noise
# ---------------------------------------------------------------------------


def test_noise_samples_are_the_draws_of_its_seed_held_over_hold_s():
    hold = 0.01
    w = WhiteNoise(2.0, seed=11, hold_s=hold)
    draws = 2.0 * np.random.default_rng(11).standard_normal(50)
    k = np.arange(50)
    np.testing.assert_array_equal(w(k * hold), draws)            # t = k hold_s is sample k
    np.testing.assert_array_equal(w((k + 0.5) * hold), draws)    # held in between
    np.testing.assert_array_equal(w((k + 0.999) * hold), draws)
    np.testing.assert_array_equal(w(np.array([-1.0, -1e-3])), draws[[0, 0]])   # before 0: the first value
    assert w(np.array([])).shape == (0,)


def test_noise_is_reproducible_by_seed_and_differs_between_seeds():
    t = np.arange(1000) * 1e-3
    np.testing.assert_array_equal(WhiteNoise(1.0, seed=3)(t), WhiteNoise(1.0, seed=3)(t))
    a, b = WhiteNoise(1.0, seed=3)(t), WhiteNoise(1.0, seed=4)(t)
    assert np.mean(a == b) < 0.01
    # independent seeds: correlation within 5 standard errors of 0
    assert abs(np.corrcoef(a, b)[0, 1]) < 5 / np.sqrt(t.size)


def test_noise_mean_and_standard_deviation():
    n, sigma = 400_000, 3.0
    x = WhiteNoise(sigma, seed=1, hold_s=1e-3)(np.arange(n) * 1e-3)
    # standard errors: sigma / sqrt(n) for the mean, about sigma / sqrt(2 n) for the std
    assert abs(x.mean()) < 5 * sigma / np.sqrt(n)
    assert abs(x.std() - sigma) < 5 * sigma / np.sqrt(2 * n)


def test_noise_values_do_not_depend_on_the_horizon_or_the_chunks():
    # 300 000 samples span several of the 65 536-draw blocks whose generator states are kept
    t = np.arange(300_000) * 1e-3
    whole = WhiteNoise(1.0, seed=5)(t)
    short = WhiteNoise(1.0, seed=5)(t[:1000])
    np.testing.assert_array_equal(short, whole[:1000])
    w = WhiteNoise(1.0, seed=5)
    edges = [0, 1, 65_535, 65_537, 70_000, 131_072, 200_001, 300_000]
    pieces = [w(t[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    np.testing.assert_array_equal(np.concatenate(pieces), whole)
    # out of order and from a fresh object (no cached states) the values are the same
    late = WhiteNoise(1.0, seed=5)(t[250_000:250_010])
    np.testing.assert_array_equal(late, whole[250_000:250_010])
    np.testing.assert_array_equal(w(t[10:20]), whole[10:20])


# ---------------------------------------------------------------------------
# sampled data
# ---------------------------------------------------------------------------


def test_sampled_linear_interpolates_and_holds_the_ends():
    s = Sampled(np.array([0.0, 1.0, 3.0]), np.array([0.0, 2.0, -2.0]), hold="linear")
    np.testing.assert_allclose(s(np.array([-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 5.0])),
                               [0.0, 0.0, 1.0, 2.0, 0.0, -2.0, -2.0], rtol=0, atol=1e-15)
    assert s.continuous


def test_sampled_zoh_holds_each_value_until_the_next_time():
    s = Sampled(np.array([0.0, 1.0, 3.0]), np.array([5.0, 6.0, 7.0]), hold="zoh", name="u")
    np.testing.assert_array_equal(s(np.array([-0.5, 0.0, 0.999, 1.0, 2.999, 3.0, 9.0])),
                                  [5.0, 5.0, 5.0, 6.0, 6.0, 7.0, 7.0])
    assert not s.continuous
    assert s.spec == "<u: 3 samples>"


@pytest.mark.parametrize(("args", "kwargs", "message"), [
    (([0.0, 1.0], [1.0]), {"name": "u"}, r"u = \[1\] is not allowed: 1 values for 2 times"),
    (([], []), {}, r"t = \[\] is not allowed: need at least one sample time"),
    (([0.0, 1.0], [1.0, np.nan]), {"name": "d"}, r"d = \[1, nan\] is not allowed: sample 1 is nan"),
    (([0.0, np.inf], [1.0, 2.0]), {}, r"t = \[0, inf\] is not allowed: sample 1 is inf"),
    (([0.0, 1.0, 1.0], [1.0, 2.0, 3.0]), {},
     r"t = \[0, 1, 1\] is not allowed: the times must increase strictly; sample 2 is 1 after 1"),
    (([0.0, 1.0], [1.0, 2.0]), {"hold": "cubic"}, r"hold = cubic is not allowed: use zoh or linear"),
])
def test_sampled_refusals_name_the_argument_and_the_value(args, kwargs, message):
    with pytest.raises(ValueError, match="^" + message):
        Sampled(np.asarray(args[0], dtype=float), np.asarray(args[1], dtype=float), **kwargs)


# ---------------------------------------------------------------------------
# the text grammar
# ---------------------------------------------------------------------------


def test_grammar_defaults_aliases_and_numbers():
    assert parse_signal("sine:5000") == Sine(5000.0, 1.0)              # 1 Hz without a frequency
    assert parse_signal("SINE:2:3:0.5") == Sine(2.0, 3.0, phase=0.5)   # kinds are case-insensitive
    assert parse_signal("white:5:2:0.01") == parse_signal("noise:5:2:0.01") == WhiteNoise(5.0, 2, 0.01)
    # a noise without a seed or hold time takes the ones given to parse_signal
    assert parse_signal("noise:5", seed=9, hold_s=0.02) == WhiteNoise(5.0, seed=9, hold_s=0.02)
    assert parse_signal("white:5:3", seed=9, hold_s=0.02) == WhiteNoise(5.0, seed=3, hold_s=0.02)
    assert parse_signal("noise:5") == WhiteNoise(5.0, seed=0, hold_s=1e-3)
    # '+' inside a number's exponent is not a sum
    assert parse_signal("1e+3") == Constant(1000.0)
    assert parse_signal("sine:1e+3:2") == Sine(1000.0, 2.0)
    assert parse_signal("1e+3+step:1") == Constant(1000.0) + Step(1.0)
    assert parse_signal("2.5") == parse_signal("const:2.5") == Constant(2.5)
    for zero in ("none", "zero", "0", "NONE", " none "):
        assert parse_signal(zero) == ZERO
    assert parse_signal(" sine : 1 : 2 + step : 3 ") == Sine(1.0, 2.0) + Step(3.0)
    s = Sine(1.0, 2.0)
    assert parse_signal(s) is s                                         # a Signal is returned as is


@pytest.mark.parametrize(("text", "what"), [
    ("sine:two:2", "amplitude two is not a number"),
    ("step:1:soon", "t0 soon is not a number"),
    ("sine:1:nan", "freq_hz nan is not a finite number"),
    ("gust:3", "unknown signal kind gust; use sine:AMP"),
    ("sine", "sine takes sine:AMPLITUDE:[FREQ_HZ]:[PHASE] (0 fields given)"),
    ("square:1", "square takes square:AMPLITUDE:FREQ_HZ (1 field given)"),
    ("sine:1:2:3:4", "sine takes sine:AMPLITUDE:[FREQ_HZ]:[PHASE] (4 fields given)"),
    ("const:1:2", "const takes const:VALUE (2 fields given)"),
    ("noise:-1", "sigma -1 must be >= 0"),
    ("white:-0.5:3", "sigma -0.5 must be >= 0"),
    ("noise:1:2.5", "seed 2.5 is not a whole number >= 0"),
    ("noise:1:-2", "seed -2 is not a whole number >= 0"),
    ("noise:1:2:0", "hold_s 0 must be > 0"),
    ("sine:1:0", "freq_hz 0 must be > 0"),
    ("square:1:-2", "freq_hz -2 must be > 0"),
    ("chirp:1:-1:2", "f0_hz -1 must be >= 0"),
    ("chirp:1:1:2:0", "t1 0 must be > 0"),
    ("sine:1:2+gust:3", "unknown signal kind gust"),
])
def test_bad_texts_are_refused_naming_the_field(text, what):
    with pytest.raises(SignalSpecError) as info:
        parse_signal(text, name="--u")
    message = str(info.value)
    # the whole text, unquoted, then what is wrong with which field
    assert message.startswith(f"--u = {text} is not allowed: ")
    assert what in message
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(("text", "typed"), [("", "(empty)"), ("   ", "(empty)"), (5, "5"), (None, "None")])
def test_empty_or_non_text_is_refused(text, typed):
    with pytest.raises(SignalSpecError, match="^" + re.escape(f"signal = {typed} is not allowed: expected sine:")):
        parse_signal(text)


def test_every_signal_is_a_signal():
    for s in ROUND_TRIP + [Sampled(np.arange(2.0), np.ones(2))]:
        assert isinstance(s, Signal)
        assert np.asarray(s(np.linspace(0.0, 1.0, 5))).shape == (5,)
