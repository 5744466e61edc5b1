"""What one request may cost on a shared server, checked before it is queued.

The heaviest frequency experiment the form allows (N = 20000 samples at
Ts = 0.5 s) is 2 x 10000 s of closed-loop simulation, 40 M integration steps:
tens of seconds of a core that thirty students share. Each section prices the
run its inputs describe (:meth:`~eha_app.session.section.Section.run_cost`: a
:class:`RunCost` from the core's estimates, :func:`eha_core.simulate.simulation_cost`
and friends, no simulation needed), and a run beyond these limits is refused with
a message that says what was asked, what is allowed and what to change
(:func:`check_run`). ``EHA_MAX_STEPS`` and ``EHA_MAX_MEMORY_MB`` change them for
a server with more to spare.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from eha_core.errors import FieldError, not_allowed
from eha_core.simulate import DEFAULT_H_MAX

__all__ = ["max_steps", "max_bytes", "RunCost", "check_run", "check_cost"]

#: Integration steps per request: about 1.5 s of one core with the compiled kernel.
DEFAULT_MAX_STEPS = 10_000_000
#: Estimated peak memory per request.
DEFAULT_MAX_MEMORY_MB = 256


def _env_int(name: str, default: int) -> int:
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = int(float(text))
    except ValueError:
        raise not_allowed(name, text, "use a whole number > 0") from None
    if value <= 0:
        raise not_allowed(name, text, "use a whole number > 0")
    return value


def max_steps() -> int:
    return _env_int("EHA_MAX_STEPS", DEFAULT_MAX_STEPS)


def max_bytes() -> int:
    return _env_int("EHA_MAX_MEMORY_MB", DEFAULT_MAX_MEMORY_MB) * 2**20


@dataclass(frozen=True)
class RunCost:
    """What one run would cost the server, estimated before it is queued: what was asked as the message
    names it (``asked = value_text``, e.g. ``N × Ts = 20000 × 0.5 s``), the integration steps and the
    peak memory, the simulated time the steps stand for, and what the student can change (``hint``)."""

    asked: str
    value_text: str
    steps: int
    peak_bytes: int
    simulated_s: float
    hint: str


def check_run(cost: RunCost | None) -> None:
    """A :class:`~eha_core.errors.FieldError` when ``cost`` exceeds the limits (None: nothing priced)."""
    if cost is not None:
        check_cost(cost.asked, cost.value_text, cost.steps, cost.peak_bytes, cost.simulated_s, cost.hint)


def _millions(n: float) -> str:
    return f"{n / 1e6:.3g} M"


def check_cost(name: str, value_text: str, steps: int, peak_bytes: int, simulated_s: float, hint: str) -> None:
    """A :class:`~eha_core.errors.FieldError` when ``steps`` or ``peak_bytes`` exceed the limits.

    ``name = value_text`` is what was asked (``N × Ts = 20000 × 0.5 s``),
    ``simulated_s`` the simulated time the steps stand for, ``hint`` what the
    user can change.
    """
    limit_steps, limit_bytes = max_steps(), max_bytes()
    if steps > limit_steps:
        per_second = steps / simulated_s if simulated_s > 0 else 1.0 / DEFAULT_H_MAX
        raise FieldError(name, value_text, f"it simulates {simulated_s:.6g} s, {_millions(steps)} integration "
                         f"steps, and this server allows {_millions(limit_steps)} per run (about "
                         f"{limit_steps / per_second:.4g} s simulated): {hint}.", context="here")
    if peak_bytes > limit_bytes:
        raise FieldError(name, value_text, f"it needs about {peak_bytes / 2**20:.0f} MB of memory and this server "
                         f"allows {limit_bytes / 2**20:.0f} MB per run: {hint}.", context="here")
