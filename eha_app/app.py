"""create_app(): the three tabs in one page; a new instance (and state) per session.

A page is cheap to open: only the first tab is built when a student arrives;
the simulation and identification tabs are built the first time they are
shown (each costs the server's event loop some 50-100 ms, which thirty students
opening the page together would otherwise all pay at once).
"""

from __future__ import annotations

from typing import Callable

import panel as pn

from eha_core.params import PARAM_NAMES

from .connection import ConnectionWatch
from .state import AppState
from .tables import CSS
from .tabs.parameters import ParametersTab
from .tasks import SessionRunner, served_document

__all__ = ["create_app", "warm_up", "CSS", "TAB_NAMES"]

TAB_NAMES = ("1. Parameters", "2. Simulation", "3. Identification")


def _session_style() -> None:
    """The tables' and formulas' styles for this session's components.

    Panel keeps ``raw_css`` per session when set inside one (the module is
    first imported inside the first session), so it is set for each page; it
    reaches the browser once, as one stylesheet shared by every component.
    """
    if CSS not in pn.config.raw_css:
        pn.config.raw_css = [*pn.config.raw_css, CSS]


def warm_up() -> None:
    """Load the compiled kernels once per server process (numba cache), so the
    first student does not wait for them. Cheap after the first call."""
    from eha_core.experiments import run_paper_cases

    run_paper_cases(cases=(1,), dt=0.01)


class LazyTabs:
    """A ``pn.Tabs`` whose tabs after the first are built when first shown."""

    def __init__(self, first: tuple[str, object], later: list[tuple[str, Callable[[], object]]]):
        self._builders = {i + 1: make for i, (_, make) in enumerate(later)}
        self._slots = {i + 1: pn.Column(sizing_mode="stretch_width") for i in range(len(later))}
        self.built: dict[int, object] = {0: first[1]}
        self.tabs = pn.Tabs(first, *((name, self._slots[i + 1]) for i, (name, _) in enumerate(later)),
                            dynamic=False, sizing_mode="stretch_width", css_classes=["eha-main-tabs"])
        self.tabs.param.watch(self._on_active, "active")

    def _on_active(self, event) -> None:
        self.build(event.new)

    def build(self, index: int):
        """The tab's content, building it now if it was never shown."""
        if index not in self.built and index in self._builders:
            content = self._builders.pop(index)()
            self.built[index] = content
            self._slots[index].objects = [content]
        return self.built.get(index)


def create_app(state: AppState | None = None, *, query: dict | None = None, runner: SessionRunner | None = None):
    """The whole page for one session.

    ``query`` holds the page address's fields (``{"M": "6000", "tab": "2"}``):
    what the student had typed before a reload, or a shared link. A value that
    is not allowed is shown with its message, as if typed.
    """
    from .tabs.identification import IdentificationTab
    from .tabs.simulation import SimulationTab

    _session_style()
    query = {str(k): str(v) for k, v in (query or {}).items()}
    state = state if state is not None else AppState()
    for name in (*PARAM_NAMES, "kp"):
        if name in query:
            state.set_text(name, query[name])
    runner = runner if runner is not None else SessionRunner(state)
    lazy = LazyTabs((TAB_NAMES[0], ParametersTab(state)),
                    [(TAB_NAMES[1], lambda: SimulationTab(state, runner=runner, query=query)),
                     (TAB_NAMES[2], lambda: IdentificationTab(state, runner=runner, query=query))])
    tab = query.get("tab", "").strip()
    if tab in ("2", "3"):
        lazy.tabs.active = int(tab) - 1
    header = pn.pane.HTML(
        '<div style="display:flex;align-items:baseline;gap:16px">'
        '<h2 style="margin:4px 0">Electro-hydraulic actuator: modeling and identification</h2>'
        '<span style="color:#666">a single-rod cylinder driven by a proportional valve</span></div>',
        sizing_mode="stretch_width")
    page = pn.Column(ConnectionWatch(), header, lazy.tabs, sizing_mode="stretch_width", margin=(0, 10))
    page.eha_state = state
    page.eha_tabs = lazy.tabs
    page.eha_lazy = lazy
    page.eha_runner = runner
    if served_document() is not None:
        def closed(_context):
            # nobody will see these results: free the workers for the others
            runner.queue.cancel_owner(runner.owner, "the page was closed")
            runner.queue.cancel_owner((runner.owner, "preview"), "the page was closed")
        pn.state.on_session_destroyed(closed)
    return page
