"""create_app(): the three tabs in one page; a new instance (and state) per session."""

from __future__ import annotations

import panel as pn

from .state import AppState
from .tabs.parameters import ParametersTab
from .tabs.identification import IdentificationTab
from .tabs.simulation import SimulationTab

__all__ = ["create_app", "CSS"]

CSS = """
.eha-tf { display: flex; align-items: center; gap: 8px; margin: 4px 0; font-size: 15px; }
.eha-frac { display: inline-flex; flex-direction: column; text-align: center; }
.eha-frac .eha-num { border-bottom: 1px solid #333; padding: 0 6px; }
.eha-frac .eha-den { padding: 0 6px; }
.eha-tf-note { color: #666; font-size: 12px; margin-left: 8px; }
.eha-table { border-collapse: collapse; font-size: 13px; margin: 4px 12px 8px 0; }
.eha-table th, .eha-table td { border-bottom: 1px solid #ddd; padding: 3px 8px; text-align: left; }
.eha-table th { background: #f3f5f8; }
.eha-two { display: flex; flex-wrap: wrap; }
.eha-ok { color: #1b5e20; }
.eha-warn { color: #b00020; font-weight: 600; }
.eha-stale { color: #b00020; font-style: italic; }
.eha-invalid input { border-color: #b00020 !important; background: #fff4f4 !important; }
h4 { margin: 12px 0 4px 0; }
.eha-note { color: #555; font-size: 12px; }
.eha-table4 td { vertical-align: top; }
"""


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
