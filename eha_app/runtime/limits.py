"""What one request may cost on a shared server, checked before it is queued.

The heaviest frequency experiment the form allows (N = 20000 samples at
Ts = 0.5 s) is 2 x 10000 s of closed-loop simulation, 40 M integration steps:
tens of seconds of a core that thirty students share. Each request's cost is
estimated by the core (:func:`eha_core.simulate.simulation_cost` and friends,
no simulation needed) and refused beyond these limits with a message that says
what was asked, what is allowed and what to change. ``EHA_MAX_STEPS`` and
``EHA_MAX_MEMORY_MB`` change them for a server with more to spare.
"""

from __future__ import annotations

import os

from eha_core.errors import FieldError, not_allowed
from eha_core.simulate import DEFAULT_H_MAX, simulation_cost

__all__ = ["max_steps", "max_bytes", "check_cost", "check_simulation", "check_frequency", "check_lse",
           "check_greybox"]

#: A grey-box estimate simulates its record some 25 times, each with one more evaluation of the model
#: per estimated parameter (the sensitivities); multiple shooting about three times as much.
GREYBOX_SIMULATIONS = 25

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


def check_simulation(t_end: float, dt: float, *, n_runs: int = 1) -> None:
    """The simulation tab's runs (open loop, ``n_runs`` runs of ``t_end`` s)."""
    cost = simulation_cost(t_end, dt, n_runs=n_runs)
    check_cost("runs × horizon", f"{n_runs} × {t_end:g} s", cost.steps, cost.peak_bytes, n_runs * t_end,
               "shorten the horizon")


def check_frequency(config) -> None:
    """The closed-loop experiment (estimation and validation runs, tfest)."""
    cost = config.cost()
    duration = config.n_samples * config.ts
    check_cost("N × Ts", f"{config.n_samples} × {config.ts:g} s", cost.steps, cost.peak_bytes, 2 * duration,
               "lower N or Ts")


def check_lse(t_end: float, estimator: str = "ls") -> None:
    """The least-squares experiment (simulation and estimation; the instrumental variables' passes too)."""
    from eha_core.experiments import lse_cost

    cost = lse_cost(t_end, resimulation=True, estimator=estimator)
    check_cost("least-squares excitation", f"{t_end:g} s", cost.steps, cost.peak_bytes, t_end,
               "use a shorter excitation")


def check_greybox(t_end: float, n_params: int, n_samples: int, n_signals: int, shooting: str = "single") -> None:
    """A grey-box estimate: its simulations with sensitivities, counted as plain integration steps."""
    runs = GREYBOX_SIMULATIONS * (3 if shooting == "multiple" else 1)
    steps = int(t_end / DEFAULT_H_MAX * (1 + n_params) * runs)
    peak = n_samples * (4 + n_signals) * (1 + n_params) * 8 * 3     # states, sensitivities, the Jacobian
    check_cost("record length × (1 + parameters)", f"{t_end:g} s × {1 + n_params}", steps, peak, t_end * runs,
               "estimate fewer parameters at once, or use a shorter record")
