"""create_app(): the three tabs in one page; a new instance (and state) per session."""

from __future__ import annotations

import panel as pn

from .state import AppState
from .tables import CSS
from .tabs.parameters import ParametersTab
from .tabs.identification import IdentificationTab
from .tabs.simulation import SimulationTab

__all__ = ["create_app", "CSS"]




def warm_up() -> None:
    """Load the compiled kernels once per server process (numba cache), so the
    first student does not wait for them. Cheap after the first call."""
    from eha_core.experiments import run_paper_cases

    run_paper_cases(cases=(1,), dt=0.01)


def create_app(state: AppState | None = None):
    """The whole page for one session."""
    pn.extension(raw_css=[CSS], notifications=False)
    state = state if state is not None else AppState()
    tabs = pn.Tabs(
        ("1. Parameters", ParametersTab(state)),
        ("2. Simulation", SimulationTab(state)),
        ("3. Identification", IdentificationTab(state)),
        dynamic=False, sizing_mode="stretch_width",
    )
    header = pn.pane.HTML(
        '<div style="display:flex;align-items:baseline;gap:16px">'
        '<h2 style="margin:4px 0">Electro-hydraulic actuator: modeling and identification</h2>'
        '<span style="color:#666">a single-rod cylinder driven by a proportional valve</span></div>',
        sizing_mode="stretch_width")
    page = pn.Column(header, tabs, sizing_mode="stretch_width", margin=(0, 10))
    page.eha_state = state
    page.eha_tabs = tabs
    return page
