"""create_app(): the three tabs in one page; a new instance (and state) per session.

A page is cheap to open: only the first tab is built when a student arrives;
the simulation and identification tabs are built the first time they are
shown (each costs the server's event loop some 50-100 ms, which thirty students
opening the page together would otherwise all pay at once).
"""

from __future__ import annotations

import html
import io
import logging
import os
from collections.abc import Callable
from functools import lru_cache

import panel as pn

from eha_core.params import PARAM_NAMES

from .connection import ConnectionWatch
from .state import AppState, shown_text
from .tables import CSS
from .tabs.parameters import ParametersTab
from .tasks import SessionRunner, apply_locked, frozen_models, layout_once_per_message, on_click, served_document, watch

__all__ = ["create_app", "serve_session", "warm_up", "CSS", "TAB_NAMES"]

TAB_NAMES = ("1. Parameters", "2. Simulation", "3. Identification")

log = logging.getLogger("eha_app")


def _session_style() -> None:
    """The tables' and formulas' styles for this session's components.

    Panel keeps ``raw_css`` per session when set inside one (the module is
    first imported inside the first session), so it is set for each page; it
    reaches the browser once, as one stylesheet shared by every component.
    """
    if CSS not in pn.config.raw_css:
        pn.config.raw_css = [*pn.config.raw_css, CSS]


_warm = False


def warm_up() -> None:
    """Load the compiled kernels (numba cache) and the identification code once
    per server process, so that the first student does not wait for them."""
    global _warm
    if _warm:
        return
    from eha_core.experiments import FrequencyExperiment, run_frequency_identification, run_lse

    run_frequency_identification(config=FrequencyExperiment(n_samples=400))
    run_lse(t_end=0.5)
    _warm = True


class LazyTabs:
    """A ``pn.Tabs`` whose tabs are built when first shown.

    In a server, a build waits its turn with the other sessions' big page
    changes (:class:`~eha_app.tasks.PageUpdates`), and the tab says it is
    being prepared meanwhile. Even the first tab is built that way, right
    after the page has loaded: opening a page then costs the server's event
    loop only its frame (about 10 ms instead of 60), so thirty students
    arriving together do not hold up the ones already working.
    """

    def __init__(self, tabs: list[tuple[str, Callable[[], object]]], active: int = 0):
        self._builders = {i: make for i, (_, make) in enumerate(tabs)}
        self._slots = {i: pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing this tab…</p>"),
                                    sizing_mode="stretch_width") for i in range(len(tabs))}
        self.built: dict[int, object] = {}
        # the open tab is set before the watcher: building it is the page's
        # first update, once the browser has the page (see create_app)
        self.tabs = pn.Tabs(*((name, self._slots[i]) for i, (name, _) in enumerate(tabs)), active=active,
                            dynamic=False, sizing_mode="stretch_width", css_classes=["eha-main-tabs"])
        watch(self.tabs, self._on_active, "active")

    def _on_active(self, event) -> None:
        if event.new in self._builders:
            apply_locked(lambda: self.build(event.new))

    def build(self, index: int):
        """The tab's content, building it now if it was never shown."""
        if index not in self.built and index in self._builders:
            with frozen_models():
                content = self._builders.pop(index)()
                self.built[index] = content
                self._slots[index].objects = [content]
        return self.built.get(index)


@lru_cache(maxsize=4)
def _exercise_at(path: str, mtime: float):
    from eha_core.exercise import Exercise

    from .handins import HandIns
    from .redaction import keep_out_of_logs

    exercise = Exercise.load(path)
    keep_out_of_logs(exercise.secret)
    return exercise, HandIns(path)


def current_exercise():
    """The exercise this server runs (``eha serve --exercise FILE`` sets EHA_EXERCISE), as
    ``(Exercise, HandIns)``, or None. Read by the server only: nothing of it goes to a page
    but its title and the names of the hidden parameters."""
    path = os.environ.get("EHA_EXERCISE", "").strip()
    if not path:
        return None
    return _exercise_at(path, os.path.getmtime(path))


class ExerciseGate:
    """The first screen of an exercise: the student's name or id, then their actuator."""

    def __init__(self, exercise, handins, state: AppState, on_start: Callable[[], None]):
        self.exercise, self.handins, self.state, self.on_start = exercise, handins, state, on_start
        hidden = ", ".join(exercise.hide)
        self.intro = pn.pane.HTML(
            f"<h3>{html.escape(exercise.title)}</h3><p>Your actuator is your own: its {hidden} are hidden and "
            f"differ from the paper's by up to ±{100 * exercise.vary:g} %. Simulate it, identify it (tab 3) and hand "
            f"in your estimates; an estimate within ±{100 * exercise.tolerance:g} % counts. The same name or id "
            "always gives the same actuator.</p>", sizing_mode="stretch_width")
        self.student_id = pn.widgets.TextInput(label="Your name or student id", placeholder="e.g. s1234567",
                                               width=300, css_classes=["eha-student-id"])
        self.button = pn.widgets.Button(label="Start", color="primary", width=120, css_classes=["eha-start"])
        self.message = pn.pane.HTML("", css_classes=["eha-error", "eha-error-student"],
                                    styles={"color": "#b00020", "font-size": "12px"})
        on_click(self.button, lambda _e: self.start())
        self.layout = pn.Column(self.intro, self.student_id, self.button, self.message, margin=(10, 20),
                                width=620, css_classes=["eha-gate"])

    def start(self) -> None:
        try:
            self.state.start_exercise(self.exercise, self.student_id.value_input or self.student_id.value,
                                      handins=self.handins)
        except ValueError as exc:
            self.message.object = html.escape(" ".join(str(exc).split()))
            return
        self.on_start()


def _log_to_stderr() -> None:
    """The app's notices (a closed page's cancelled runs, failures) in the server's log: through the
    server's own handler (``eha serve`` sets its format), or one of their own if it has none."""
    from .serving import LOG_FORMAT

    logger = logging.getLogger("eha_app")
    logger.setLevel(logging.INFO)
    if not logger.handlers and not logging.getLogger().handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter(LOG_FORMAT))
        logger.addHandler(handler)


def serve_session() -> None:
    """Make this browser session's page (the server runs :mod:`eha_app.eha` for every session)."""
    from .patches import strict_mode_on, strict_page_changes
    from .redaction import redact_server_logs
    from .serving import quiet_closed_websockets, use_local_resources
    from .tasks import note_loop_thread

    _log_to_stderr()
    redact_server_logs()
    note_loop_thread()
    if strict_mode_on():
        strict_page_changes()
    warm_up()
    quiet_closed_websockets()
    use_local_resources(pn.state.curdoc)
    # Neither the browser's details (language, time zone, ...) nor Panel's URL
    # model are used: without them a page sends the server 8 fewer messages when
    # it opens (the address is kept by eha_app.connection instead).
    pn.config.browser_info = False
    query = {k: v[-1].decode("utf-8", "replace") for k, v in (pn.state.session_args or {}).items() if v}
    create_app(query=query).servable(title="EHA: modeling and identification", location=False)


def create_app(state: AppState | None = None, *, query: dict | None = None, runner: SessionRunner | None = None):
    """The whole page for one session.

    ``query`` holds the page address's fields (``{"M": "6000", "tab": "2"}``):
    what the student had typed before a reload, or a shared link. A value that
    is not allowed is shown with its message, as if typed.
    """
    from .tabs.identification import IdentificationTab
    from .tabs.simulation import SimulationTab

    _session_style()
    # before the page is sent (an exercise's runner is made only after the student's id)
    layout_once_per_message(served_document())
    query = {str(k): str(v) for k, v in (query or {}).items()}
    state = state if state is not None else AppState()
    exercise = current_exercise()
    if exercise is not None and not state.student:
        return _exercise_page(state, exercise, query, runner)
    for name in (*PARAM_NAMES, "kp"):
        if name in query:
            state.set_text(name, query[name])
    runner = runner if runner is not None else SessionRunner(state)
    tab = query.get("tab", "").strip()
    first = int(tab) - 1 if tab in ("2", "3") else 0
    lazy = LazyTabs([(TAB_NAMES[0], lambda: ParametersTab(state)),
                     (TAB_NAMES[1], lambda: SimulationTab(state, runner=runner, query=query)),
                     (TAB_NAMES[2], lambda: IdentificationTab(state, runner=runner, query=query))], active=first)
    if served_document() is not None:
        # The page's frame goes out now; its first tab once the browser has it
        # (document_ready). A change made between the browser's pull of the
        # document and that moment can be lost (Panel holds the changes of an
        # unconnected session and relies on the pull): the page would stay at
        # "Preparing this tab..." for good.
        pn.state.onload(lambda: apply_locked(lambda: lazy.build(first)))
    else:
        lazy.build(first)
    who = (f'<span class="eha-student" style="color:#1a56c4">{html.escape(state.exercise.title)} — '
           f'{html.escape(state.student)}</span>' if state.student else "")
    header = pn.pane.HTML(
        '<div style="display:flex;align-items:baseline;gap:16px;flex-wrap:wrap">'
        '<h2 style="margin:4px 0">Electro-hydraulic actuator: modeling and identification</h2>'
        f'<span style="color:#666">a single-rod cylinder driven by a proportional valve</span>{who}</div>',
        sizing_mode="stretch_width")
    page = pn.Column(ConnectionWatch(), header, sizing_mode="stretch_width", margin=(0, 10))
    page.eha_query = query
    page.eha_state = state
    page.eha_tabs = lazy.tabs
    page.eha_lazy = lazy
    page.eha_runner = runner
    page.extend([settings_row(page), lazy.tabs])
    if served_document() is not None:
        def closed(_context):
            # nobody will see these results: free the workers for the others
            jobs = runner.cancel_all("the page was closed")
            if jobs:
                log.info("a page was closed: cancelled %s", ", ".join(j.label for j in jobs))
        pn.state.on_session_destroyed(closed)
    return page


def settings_row(page) -> pn.Row:
    """Save the session's settings as JSON, or load a saved file (every input of every tab)."""
    from . import settings
    from .tabs.uploads import FileUpload

    save = pn.widgets.FileDownload(callback=lambda: io.BytesIO(settings.to_bytes(page)), filename="eha_settings.json",
                                   label="Save settings", width=130, css_classes=["eha-save-settings"],
                                   description="every input of every tab, as a JSON file")
    load = FileUpload(accept=".json", max_bytes=settings.MAX_SETTINGS_BYTES, width=230,
                      css_classes=["eha-load-settings"])

    note = pn.pane.HTML("", css_classes=["eha-settings-note"], styles={"font-size": "12px"},
                        sizing_mode="stretch_width")
    # The report takes about 0.8 s to draw: a worker prepares it (the page's thread serves the
    # other students meanwhile), then it is offered for download.
    lab_report = pn.widgets.Button(label="Report of this session", width=190, css_classes=["eha-session-report"],
                                   description="what you ran, as one HTML file: settings, plots, estimates")
    lab_download = pn.widgets.FileDownload(filename="eha_session_report.html", label="Download the report",
                                           visible=False, width=190, color="success",
                                           css_classes=["eha-session-report-download"])

    def prepare(_event):
        from .report import session_report

        def show(data, _job):
            lab_download.file = io.BytesIO(data)
            lab_download.label = f"Download the report ({len(data) / 1e6:.1f} MB)"
            lab_download.visible = True

        def fail(message):
            note.object = f"<span class='eha-warn'>The report could not be made: {html.escape(message)}</span>"

        lab_download.visible = False
        page.eha_runner.run("session report", lambda _token: session_report(page), show, fail=fail)

    on_click(lab_report, prepare)
    page.eha_report_button, page.eha_report_download = lab_report, lab_download

    def loaded(_event):
        if load.value is None:
            return
        try:
            notes = settings.apply(page, bytes(load.value), shown_text(load.filename or "settings.json", 60))
        except settings.SettingsError as exc:
            note.object = f"<span class='eha-warn'>{html.escape(str(exc))}</span>"
            return
        note.object = ("<span class='eha-ok'>Settings loaded.</span> "
                       + " ".join(f"<span class='eha-note'>{html.escape(n)}</span>" for n in notes))

    watch(load, loaded, "value")
    page.eha_settings_note = note
    return pn.Row(save, pn.pane.HTML("<span class='eha-note'>Load settings:</span>", margin=(12, 4, 0, 10)), load,
                  lab_report, lab_download, note, sizing_mode="stretch_width", css_classes=["eha-settings-row"])


def _exercise_page(state: AppState, exercise, query: dict, runner):
    """An exercise's page: the gate, replaced by the app once the student has given an id."""
    ex, handins = exercise
    page = pn.Column(sizing_mode="stretch_width")

    def start() -> None:
        app = create_app(state, query={k: v for k, v in query.items() if k not in ex.hide}, runner=runner)
        page.objects = [app]
        page.eha_state, page.eha_tabs = app.eha_state, app.eha_tabs
        page.eha_lazy, page.eha_runner = app.eha_lazy, app.eha_runner
        if served_document() is not None:
            apply_locked(lambda: app.eha_lazy.build(app.eha_tabs.active))

    gate = ExerciseGate(ex, handins, state, start)
    page.objects = [gate.layout]
    page.eha_state, page.eha_gate = state, gate
    return page
