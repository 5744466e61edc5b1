"""The paper's cases and experiments as named presets.

Examples
--------
>>> from eha_core.experiments import PAPER_CASES, run_paper_cases
>>> PAPER_CASES[3].title
'Case 3: u = 6 sin(4πt), d = 5000 sin(2πt)'
>>> [round(float(r.x.max()), 4) for r in run_paper_cases()]
[0.0118, 0.0118, 0.0353, 0.0353]
"""

from __future__ import annotations

from dataclasses import dataclass

from .params import ActuatorParams
from .signals import ZERO, Signal, Sine
from .simulate import SimulationResult, simulate_many

__all__ = ["Case", "PAPER_CASES", "run_paper_cases"]


@dataclass(frozen=True)
class Case:
    """An open-loop experiment: valve command u(t) [V] and disturbance d(t) [N]."""

    number: int
    u: Signal
    d: Signal
    t_end: float = 5.0

    @property
    def name(self) -> str:
        return f"case_{self.number}"

    @property
    def title(self) -> str:
        return f"Case {self.number}: u = {self.u.label}, d = {self.d.label}"


#: Section II-A, Figs. 2-7: horizon 5 s from the initial conditions.
PAPER_CASES: dict[int, Case] = {
    1: Case(1, Sine(2.0, 2.0), Sine(5e3, 1.0)),
    2: Case(2, Sine(2.0, 2.0), ZERO),
    3: Case(3, Sine(6.0, 2.0), Sine(5e3, 1.0)),
    4: Case(4, Sine(6.0, 2.0), ZERO),
}


def run_paper_cases(params: ActuatorParams | None = None, model: str = "nonlinear",
                    cases=(1, 2, 3, 4), *, dt: float = 1e-3, branch: str = "switching",
                    **kwargs) -> list[SimulationResult]:
    """Simulate the chosen paper cases as one batch (Fig. 2: nonlinear, Fig. 3: linear)."""
    chosen = []
    for c in cases:
        if c not in PAPER_CASES:
            raise ValueError(f"case = {c!r} is not allowed: use one of 1, 2, 3, 4")
        chosen.append(PAPER_CASES[c])
    t_end = chosen[0].t_end if chosen else 5.0
    return simulate_many(params, [c.u for c in chosen], [c.d for c in chosen], t_end=t_end, dt=dt,
                         model=model, branch=branch, labels=[c.name for c in chosen], **kwargs)
