"""Inputs and disturbances: sine, step, square, chirp, white noise, sampled data, sums.

Every signal is a frozen dataclass, callable on an array of times (seconds) and
returning an array of values; ``a + b`` builds a sum. They are hashable, so
results computed from them can be cached.

Signals written as text
-----------------------
The one grammar for inputs and disturbances, read by :func:`parse_signal` for
the command line (``--u``, ``--d``, ``--disturbance``), the app's fields and
the core's presets (:data:`SIGNAL_GRAMMAR` is this text)::

    sine:AMP[:FREQ_HZ[:PHASE_RAD]]   AMP sin(2 pi FREQ_HZ t + PHASE_RAD); 1 Hz if no frequency
    step:AMP[:T0]                    0 before T0, AMP after
    square:AMP:FREQ_HZ               +AMP for the first half period, -AMP after
    chirp:AMP:F0_HZ:F1_HZ[:T1]       linear sweep from F0 at t = 0 to F1 at t = T1
    noise:SIGMA[:SEED[:HOLD_S]]      white Gaussian noise, a new value every HOLD_S
    white:SIGMA[:SEED[:HOLD_S]]      the same (the name of the paper's scenario)
    const:VALUE  (or just VALUE)     a constant
    none                             zero
    A+B                              the sum of two signals

A noise without a seed or hold time takes the ones given to :func:`parse_signal`
(the run's seed, and its sample interval: 1 ms by default).

Examples
--------
>>> import numpy as np
>>> from eha_core.signals import Sine, Step, parse_signal
>>> u = Sine(6.0, 2.0) + Step(1.0, t0=0.5)
>>> np.round(u(np.array([0.0, 0.125, 1.0])), 6)
array([0., 6., 1.])
>>> parse_signal("sine:6:2+step:1:0.5") == u
True
>>> Sine(6.0, 2.0).label
'6 sin(4πt)'
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ._checks import FieldError, not_allowed, shown

__all__ = [
    "Signal", "Constant", "Sine", "Step", "Square", "Chirp", "WhiteNoise",
    "Sampled", "Sum", "ZERO", "parse_signal", "SignalSpecError", "SIGNAL_SYNTAX", "SIGNAL_GRAMMAR",
]

SIGNAL_SYNTAX = (
    "sine:AMP[:FREQ_HZ[:PHASE_RAD]], step:AMP[:T0], square:AMP:FREQ_HZ, "
    "chirp:AMP:F0_HZ:F1_HZ[:T1], noise:SIGMA[:SEED[:HOLD_S]], white:SIGMA[...], const:VALUE, none; "
    "join with + for a sum"
)


#: The grammar of signals as text, for the command line's help.
SIGNAL_GRAMMAR = """signals as text (inputs and disturbances), terms joined with '+':
  sine:AMP[:FREQ_HZ[:PHASE_RAD]]   (1 Hz if no frequency)   step:AMP[:T0]   square:AMP:FREQ_HZ
  chirp:AMP:F0_HZ:F1_HZ[:T1]   noise:SIGMA[:SEED[:HOLD_S]] (or white:...)   const:VALUE   none
  e.g. "sine:5000:1+noise:100:7"; a noise without SEED takes --seed, without HOLD_S the sample interval
"""


class SignalSpecError(FieldError):
    """A signal written as text that cannot be read (a :class:`~eha_core._checks.FieldError`:
    the field is the signal's name, the value the whole text)."""


def _g(x: float) -> str:
    return f"{x:g}"


class Signal:
    """Base class: a function of time, vectorised over numpy arrays.

    ``continuous`` tells the simulator whether the signal can jump; a signal
    that can is also sampled just before each step's end, so that the
    integrator sees the value held until then and not the next one.
    """

    continuous: bool = False

    def __call__(self, t) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def discontinuities(self, t_end: float, start: float = 0.0) -> np.ndarray | None:
        """The times in [start, t_end] where the signal may jump or its slope may (sorted).

        The simulator stops its integrator at each of them, so that no step straddles one.
        None when they are not known (a signal that does not say, a user's function of t).

        Parameters
        ----------
        t_end : float
            End of the interval [s].
        start : float
            Start of the interval [s].
        """
        return None

    def __add__(self, other: Signal) -> Signal:
        if not isinstance(other, Signal):
            return NotImplemented
        terms = (self.terms if isinstance(self, Sum) else (self,)) + (
            other.terms if isinstance(other, Sum) else (other,))
        terms = tuple(s for s in terms if s != ZERO) or (ZERO,)
        return terms[0] if len(terms) == 1 else Sum(terms)

    @property
    def label(self) -> str:
        return self.spec

    @property
    def spec(self) -> str:
        """The text form :func:`parse_signal` reads back."""
        raise NotImplementedError


@dataclass(frozen=True)
class Constant(Signal):
    continuous = True

    value: float = 0.0

    def __call__(self, t):
        return np.full(np.shape(t), float(self.value))

    def discontinuities(self, t_end, start=0.0):
        return np.empty(0)

    @property
    def spec(self):
        return "none" if self.value == 0 else f"const:{_g(self.value)}"

    @property
    def label(self):
        return "0" if self.value == 0 else _g(self.value)


ZERO = Constant(0.0)


@dataclass(frozen=True)
class Sine(Signal):
    """``amplitude sin(2 pi freq_hz t + phase) + offset``."""

    continuous = True

    amplitude: float
    freq_hz: float
    phase: float = 0.0
    offset: float = 0.0

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        return self.amplitude * np.sin(2.0 * np.pi * self.freq_hz * t + self.phase) + self.offset

    def discontinuities(self, t_end, start=0.0):
        return np.empty(0)

    @property
    def spec(self):
        s = f"sine:{_g(self.amplitude)}:{_g(self.freq_hz)}"
        if self.phase:
            s += f":{_g(self.phase)}"
        return s + (f"+const:{_g(self.offset)}" if self.offset else "")

    @property
    def label(self):
        w = 2.0 * self.freq_hz
        wtxt = "π" if w == 1 else f"{_g(w)}π"
        s = f"{_g(self.amplitude)} sin({wtxt}t{' + ' + _g(self.phase) if self.phase else ''})"
        return s + (f" + {_g(self.offset)}" if self.offset else "")


@dataclass(frozen=True)
class Step(Signal):
    """0 (or ``initial``) before ``t0``, ``amplitude`` from ``t0`` on."""

    amplitude: float
    t0: float = 0.0
    initial: float = 0.0

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        return np.where(t >= self.t0, self.amplitude, self.initial).astype(float)

    def discontinuities(self, t_end, start=0.0):
        jumps = self.amplitude != self.initial and start <= self.t0 <= t_end
        return np.array([float(self.t0)]) if jumps else np.empty(0)

    @property
    def spec(self):
        if self.initial:  # the grammar's step starts from 0: a constant carries the level before t0
            return f"const:{_g(self.initial)}+step:{_g(self.amplitude - self.initial)}:{_g(self.t0)}"
        return f"step:{_g(self.amplitude)}" + (f":{_g(self.t0)}" if self.t0 else "")

    @property
    def label(self):
        return f"{_g(self.amplitude)} step" + (f" at {_g(self.t0)} s" if self.t0 else "")


@dataclass(frozen=True)
class Square(Signal):
    """+amplitude for the first half of each period, -amplitude for the second."""

    amplitude: float
    freq_hz: float
    offset: float = 0.0

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        phase = np.mod(t * self.freq_hz, 1.0)
        return np.where(phase < 0.5, self.amplitude, -self.amplitude) + self.offset

    def discontinuities(self, t_end, start=0.0):
        if self.amplitude == 0:
            return np.empty(0)
        # the edges, every half period
        half = 0.5 / self.freq_hz
        k = np.arange(max(0, math.ceil(start / half - 1e-9)), math.floor(t_end / half + 1e-9) + 1)
        return k * half

    @property
    def spec(self):
        s = f"square:{_g(self.amplitude)}:{_g(self.freq_hz)}"
        return s + (f"+const:{_g(self.offset)}" if self.offset else "")

    @property
    def label(self):
        return f"{_g(self.amplitude)} square {_g(self.freq_hz)} Hz"


@dataclass(frozen=True)
class Chirp(Signal):
    """Linear sweep ``amplitude sin(2 pi (f0 t + (f1 - f0) t^2 / (2 t1)))``."""

    continuous = True

    amplitude: float
    f0_hz: float
    f1_hz: float
    t1: float = 5.0

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        k = (self.f1_hz - self.f0_hz) / self.t1
        return self.amplitude * np.sin(2.0 * np.pi * (self.f0_hz * t + 0.5 * k * t * t))

    def discontinuities(self, t_end, start=0.0):
        return np.empty(0)

    @property
    def spec(self):
        return f"chirp:{_g(self.amplitude)}:{_g(self.f0_hz)}:{_g(self.f1_hz)}:{_g(self.t1)}"

    @property
    def label(self):
        return f"{_g(self.amplitude)} chirp {_g(self.f0_hz)}-{_g(self.f1_hz)} Hz"


#: Normal draws between the generator states a :class:`WhiteNoise` keeps.
_NOISE_BLOCK = 1 << 16


@dataclass(frozen=True)
class WhiteNoise(Signal):
    """Zero-mean white Gaussian noise, standard deviation ``sigma``, held over
    each interval of ``hold_s`` seconds (a new sample at every k hold_s).

    The k-th sample is the k-th draw of ``numpy.random.default_rng(seed)``, so
    the value at a time does not depend on the horizon asked for.
    """

    sigma: float
    seed: int = 0
    hold_s: float = 1e-3

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return np.zeros(t.shape)
        # the small offset keeps t = k hold_s on sample k despite rounding
        k = np.floor(t / self.hold_s + 1e-9).astype(np.int64)
        k = np.maximum(k, 0)
        first, draws = self._draws(int(k.min()), int(k.max()))
        return self.sigma * draws[k - first]

    def discontinuities(self, t_end, start=0.0):
        if self.sigma == 0:
            return np.empty(0)
        # a new sample every hold_s
        k = np.arange(max(0, math.ceil(start / self.hold_s - 1e-9)), math.floor(t_end / self.hold_s + 1e-9) + 1)
        return k * self.hold_s

    def _draws(self, k_lo: int, k_hi: int) -> tuple[int, np.ndarray]:
        """``(first, draws)``: draws ``first .. k_hi`` of the stream, ``first <= k_lo``.

        The simulator asks for the noise one integration chunk at a time; drawing
        the stream from its start at every call would make a long run quadratic
        in its length and allocate the whole stream each time. The generator's
        state is kept every :data:`_NOISE_BLOCK` draws, so a call starts from
        the block holding ``k_lo``; the draws are those of one call from the
        start, bit for bit (numpy's normal draws of one generator concatenate).
        The saved states are a few hundred bytes per block, kept on the signal;
        concurrent calls at worst both save the same state.
        """
        states = self.__dict__.setdefault("_states", {})
        target = k_lo // _NOISE_BLOCK
        block = max((b for b in states if b <= target), default=0)
        rng = np.random.default_rng(self.seed)
        if block:
            rng.bit_generator.state = states[block]
        while block < target:  # skip to k_lo's block, saving the states on the way
            rng.standard_normal(_NOISE_BLOCK)
            block += 1
            states.setdefault(block, rng.bit_generator.state)
        first = block * _NOISE_BLOCK
        draws = np.empty(k_hi + 1 - first)
        for start in range(0, draws.size, _NOISE_BLOCK):
            piece = draws[start:start + _NOISE_BLOCK]
            rng.standard_normal(out=piece)
            if piece.size == _NOISE_BLOCK:
                states.setdefault((first + start) // _NOISE_BLOCK + 1, rng.bit_generator.state)
        return first, draws

    @property
    def spec(self):
        return f"noise:{_g(self.sigma)}:{self.seed}:{_g(self.hold_s)}"

    @property
    def label(self):
        return f"white noise σ={_g(self.sigma)}"


@dataclass(frozen=True, eq=False)
class Sampled(Signal):
    """A sampled signal: values at times ``t``, held (``'zoh'``) or interpolated
    (``'linear'``) in between; the last value holds after the end.

    ``name`` is what the samples are called (``u``, ``d``, ``r``, ``data``): in
    :attr:`spec`, and in the message that refuses bad values.
    """

    t: np.ndarray
    values: np.ndarray
    hold: str = "linear"
    name: str = "data"

    def __post_init__(self):
        # The values are named by ``name`` (what the caller calls the signal:
        # u, d, r, data); samples are counted from 0, as numpy indexes them.
        t = np.asarray(self.t, dtype=float).ravel()
        v = np.asarray(self.values, dtype=float).ravel()
        if t.size == 0:
            raise not_allowed("t", t, "need at least one sample time")
        if t.size != v.size:
            raise not_allowed(self.name, v, f"{v.size} values for {t.size} times; give one value per time")
        for label, arr in (("t", t), (self.name, v)):
            if not np.all(np.isfinite(arr)):
                k = int(np.argmin(np.isfinite(arr)))
                raise not_allowed(label, arr, f"sample {k} is {arr[k]:g}; every sample must be a finite number")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise not_allowed("t", t, f"the times must increase strictly; sample {k} is {t[k]:g} "
                                              f"after {t[k - 1]:g}")
        if self.hold not in ("zoh", "linear"):
            raise not_allowed("hold", self.hold, "use zoh or linear")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)

    @property
    def continuous(self):
        return self.hold == "linear"

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        if self.hold == "linear":
            return np.interp(t, self.t, self.values)
        idx = np.searchsorted(self.t, t + 1e-12 * max(1.0, abs(self.t[-1])), side="right") - 1
        return self.values[np.clip(idx, 0, self.t.size - 1)]

    def discontinuities(self, t_end, start=0.0):
        # held: the value jumps at a sample that changes it; interpolated: the slope may jump at any sample
        t = self.t
        if self.hold == "zoh":
            t = np.concatenate([t[:1], t[1:][np.diff(self.values) != 0]])
        return t[(t >= start) & (t <= t_end)]

    @property
    def spec(self):
        return f"<{self.name}: {self.t.size} samples>"


@dataclass(frozen=True)
class Sum(Signal):
    terms: tuple[Signal, ...] = field(default_factory=tuple)

    @property
    def continuous(self):
        return all(s.continuous for s in self.terms)

    def __call__(self, t):
        out = np.zeros(np.shape(t))
        for s in self.terms:
            out = out + s(t)
        return out

    def discontinuities(self, t_end, start=0.0):
        # those of every term (a jump of one term may cancel another's: the answer errs on the safe side)
        parts = [s.discontinuities(t_end, start) for s in self.terms]
        if any(p is None for p in parts):
            return None
        return np.unique(np.concatenate(parts)) if parts else np.empty(0)

    @property
    def spec(self):
        return "+".join(s.spec for s in self.terms)

    @property
    def label(self):
        return " + ".join(s.label for s in self.terms)


# -- text form -----------------------------------------------------------------

_KINDS = {
    # kind: (constructor, names of the required fields, names of optional fields)
    "sine": (Sine, ("amplitude",), ("freq_hz", "phase")),
    "step": (Step, ("amplitude",), ("t0",)),
    "square": (Square, ("amplitude", "freq_hz"), ()),
    "chirp": (Chirp, ("amplitude", "f0_hz", "f1_hz"), ("t1",)),
    "noise": (WhiteNoise, ("sigma",), ("seed", "hold_s")),
    "white": (WhiteNoise, ("sigma",), ("seed", "hold_s")),
    "const": (Constant, ("value",), ()),
}


def parse_signal(text, name: str = "signal", *, seed: int = 0, hold_s: float = 1e-3) -> Signal:
    """Read a signal from its text form ``text`` (:data:`SIGNAL_GRAMMAR`); a Signal is returned as is.

    ``name`` is used in error messages (e.g. ``"--u"``); ``seed`` and
    ``hold_s`` are those of a noise term that gives none.

    >>> parse_signal("noise:1000:3")
    WhiteNoise(sigma=1000.0, seed=3, hold_s=0.001)
    >>> parse_signal("white:1000", seed=7)
    WhiteNoise(sigma=1000.0, seed=7, hold_s=0.001)
    >>> parse_signal("sine:5000")
    Sine(amplitude=5000.0, freq_hz=1.0, phase=0.0, offset=0.0)
    >>> parse_signal("sine:two:2", name="--u")
    Traceback (most recent call last):
    ...
    eha_core.signals.SignalSpecError: --u = sine:two:2 is not allowed: amplitude two is not a number
    """
    if isinstance(text, Signal):
        return text
    if not isinstance(text, str) or not text.strip():
        raise SignalSpecError(name, text, f"expected {SIGNAL_SYNTAX}")
    # '+' joins terms, except inside a number's exponent (1e+3)
    parts = [p.strip() for p in re.split(r"(?<![eE])\+", text.strip())]
    total: Signal = ZERO
    for part in parts:
        total = total + _parse_term(part, text, name, {"seed": int(seed), "hold_s": float(hold_s)})
    return total


def _parse_term(part: str, whole: str, name: str, defaults: dict) -> Signal:
    def fail(why: str) -> SignalSpecError:
        return SignalSpecError(name, whole, why)

    if part.lower() in ("none", "zero", "0"):
        return ZERO
    try:
        return Constant(float(part))
    except ValueError:
        pass
    kind, *args = [a.strip() for a in part.split(":")]
    kind = kind.lower()
    if kind not in _KINDS:
        raise fail(f"unknown signal kind {shown(kind)}; use {SIGNAL_SYNTAX}")
    ctor, required, optional = _KINDS[kind]
    if not len(required) <= len(args) <= len(required) + len(optional):
        usage = ":".join([kind] + [r.upper() for r in required] + [f"[{o.upper()}]" for o in optional])
        raise fail(f"{kind} takes {usage} ({len(args)} field{'s' if len(args) != 1 else ''} given)")
    kwargs = _parse_fields(required + optional, args, fail)
    if ctor is WhiteNoise:
        kwargs = {**defaults, **kwargs}
    if ctor is Sine:
        kwargs.setdefault("freq_hz", 1.0)     # the paper's disturbance frequency
    return ctor(**kwargs)


def _parse_fields(names: tuple[str, ...], texts: list[str], fail) -> dict:
    """The numbers of a term's fields, by name; ``fail(why)`` builds the error.

    ``texts`` may be shorter than ``names`` (optional fields left out).
    """
    kwargs = {}
    for fname, text in zip(names, texts, strict=False):
        try:
            value = float(text)
        except ValueError:
            raise fail(f"{fname} {shown(text)} is not a number") from None
        if not math.isfinite(value):
            raise fail(f"{fname} {text} is not a finite number")
        if fname == "seed":
            if value != int(value) or value < 0:
                raise fail(f"seed {text} is not a whole number >= 0")
            value = int(value)
        if fname in ("freq_hz", "t1", "hold_s") and value <= 0:
            raise fail(f"{fname} {text} must be > 0")
        if fname in ("sigma", "f0_hz", "f1_hz") and value < 0:
            raise fail(f"{fname} {text} must be >= 0")
        kwargs[fname] = value
    return kwargs
