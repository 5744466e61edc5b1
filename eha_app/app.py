"""create_app(): one page per browser session, its tabs made from the registry of sections.

A page is cheap to open: only the first tab is built when a student arrives;
the simulation and identification tabs are built the first time they are
shown (each costs the server's event loop some 50-100 ms, which thirty students
opening the page together would otherwise all pay at once).
"""

from __future__ import annotations

import html
import io
import logging
import secrets
import time
import weakref
from collections.abc import Callable
from functools import partial

import panel as pn

from eha_core.errors import not_allowed
from eha_core.exercise import normalize_id

from . import sections as _sections  # noqa: F401 - registers the page's sections
from .render.layout import BUTTON_CONTRAST, WRAP_TAB_HEADERS
from .render.tables import CSS, SYMBOLS_HTML
from .runtime import store_calls
from .runtime.connection import ConnectionWatch
from .runtime.exercise_file import current_exercise
from .runtime.patches import on_disconnect
from .runtime.tasks import (
    SessionRunner,
    apply_locked,
    frozen_models,
    on_click,
    served_document,
    watch,
)
from .sections.work import keep_work
from .session import MAX_SETTINGS_BYTES, Session, SettingsError
from .session.state import FORM_FIELDS, AppState, shown_text

__all__ = ["create_app", "serve_session", "warm_up", "CSS", "Page"]

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
    """A ``pn.Tabs`` whose tabs are made when first shown.

    In a server, a build waits its turn with the other sessions' big page
    changes (:class:`~eha_app.runtime.tasks.PageUpdates`), and the tab says it is
    being prepared meanwhile. Even the first tab is built that way, right
    after the page has loaded: opening a page then costs the server's event
    loop only its frame (about 10 ms instead of 60), so thirty students
    arriving together do not hold up the ones already working.
    """

    def __init__(self, tabs: list[tuple[str, Callable[[], object]]], active: int = 0, css_class: str = ""):
        self.names = [name for name, _ in tabs]
        self._builders = dict(tabs)
        self._slots = {name: pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing this tab…</p>"),
                                       sizing_mode="stretch_width") for name in self.names}
        self.built: dict[str, object] = {}
        # the open tab is set before the watcher: building it is the page's
        # first update, once the browser has the page (see create_app)
        self.tabs = pn.Tabs(*((name, self._slots[name]) for name in self.names), active=active,
                            dynamic=False, sizing_mode="stretch_width", css_classes=[css_class] if css_class else [],
                            stylesheets=[WRAP_TAB_HEADERS])
        watch(self.tabs, self._on_active, "active")

    def _on_active(self, event) -> None:
        name = self.names[event.new]
        if name in self._builders:
            apply_locked(lambda: self.build(name))

    def build(self, name: str):
        """The tab's content, made now if it was never shown."""
        if name not in self.built and name in self._builders:
            with frozen_models():
                content = self._builders.pop(name)()
                self.built[name] = content
                self._slots[name].objects = [content]
        return self.built.get(name)

    @property
    def active_name(self) -> str:
        return self.names[self.tabs.active]


class SubTabs(pn.viewable.Viewer):
    """A main tab holding several sections, one sub-tab each (tab 3: least squares, transfer
    function, model board, study), made when first shown."""

    def __init__(self, session: Session, placements, **params):
        super().__init__(**params)
        self.session = session
        self.lazy = LazyTabs([(p.subtab or p.cls.title, partial(session.build, p.key)) for p in placements],
                             css_class="eha-ident-tabs")
        self.keys = {p.subtab or p.cls.title: p.key for p in placements}
        self.lazy.build(self.lazy.names[0])

    def __panel__(self):
        return self.lazy.tabs


def signed_in_user() -> str | None:
    """The user an identity provider signed in (``eha serve --oauth-provider ...``: Panel's OAuth),
    or None. Only a server with a provider has one: Panel's ``is_guest`` cookie, which any page can
    set, names no one here."""
    if not pn.config.oauth_provider:
        return None
    user = pn.state.user
    return user if user and user != "guest" else None


def _sentence(text: str) -> str:
    """``text`` with a capital first letter and the rest as written (str.capitalize lowers a deadline's T)."""
    return text[:1].upper() + text[1:]


def client_address() -> str:
    """The address of the browser of the current session (behind nginx with ``--behind-proxy``,
    the one nginx was reached from), or "" without a server."""
    doc = served_document()
    request = getattr(getattr(doc, "session_context", None), "request", None)
    return str(getattr(request, "remote_ip", "") or "")


def _this_machine(address: str) -> bool:
    """Is ``address`` this machine's own (loopback)? A proxy in front of the server without
    ``--behind-proxy`` makes every student's address 127.0.0.1: capping it would stop a whole class."""
    import ipaddress

    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


class WrongCodes:
    """Wrong join codes per client address, for the whole process: a new page (or a reload) does not
    start the count again. After :attr:`FREE_TRIES` wrong codes, each further try waits
    :attr:`WAIT_S`; an address is forgotten after an hour without a wrong code, and the table holds at
    most :attr:`MAX_ADDRESSES` (the oldest go first)."""

    FREE_TRIES = 5
    WAIT_S = 10.0
    FORGET_S = 3600.0
    MAX_ADDRESSES = 10_000

    def __init__(self, clock=time.monotonic):
        self.clock = clock
        self._by_address: dict[str, tuple[int, float, float]] = {}     # address -> (wrong, blocked until, last)

    def wait_s(self, address: str) -> float:
        """Seconds this address must still wait before it may try a code (0: it may now)."""
        wrong, until, last = self._by_address.get(address, (0, 0.0, 0.0))
        now = self.clock()
        if now - last > self.FORGET_S:
            self._by_address.pop(address, None)
            return 0.0
        return max(0.0, until - now)

    def wrong(self, address: str) -> None:
        now = self.clock()
        count, until, last = self._by_address.pop(address, (0, 0.0, now))
        if now - last > self.FORGET_S:
            count = 0
        count += 1
        self._by_address[address] = (count, now + self.WAIT_S if count >= self.FREE_TRIES else until, now)
        while len(self._by_address) > self.MAX_ADDRESSES:
            self._by_address.pop(next(iter(self._by_address)))


_wrong_codes = WrongCodes()


class ExerciseGate:
    """The first screen of an exercise: the student's join code (with a roster) or their id (without
    one), then their actuator. A wrong code is refused without saying whether anyone has it; after
    a few wrong codes from one address its pages wait before they try again (a code has about 50
    bits: guessing is hopeless, but not free). In an open exercise, one address may start only the
    exercise's ``ids_per_client`` new ids an hour (ids that joined before come back freely; this
    machine's own addresses are not capped: see :func:`_this_machine`)."""

    #: Wrong codes an address may try before each further try waits.
    FREE_TRIES = WrongCodes.FREE_TRIES
    WAIT_S = WrongCodes.WAIT_S
    #: The longest an open exercise's new id waits for the database's answer before it is let in [s].
    CHECK_S = 3.0

    def __init__(self, exercise, handins, state: AppState, on_start: Callable[[], None]):
        self.exercise, self.handins, self.state, self.on_start = exercise, handins, state, on_start
        self.address = client_address() or f"page-{id(self)}"
        self.doc = served_document()
        self._checking = False
        # the tables' symbols (β<sub>e</sub>, not beta_e)
        tol = ", ".join(f"{SYMBOLS_HTML.get(n, html.escape(n))} ±{100 * exercise.tolerance_of(n):g} %"
                        for n in exercise.hide)
        hidden = ", ".join(SYMBOLS_HTML.get(n, html.escape(n)) for n in exercise.hide)
        rules = []
        if exercise.deadline:
            rules.append(f"hand in before {html.escape(exercise.deadline)}")
        if exercise.attempts:
            rules.append(f"you may hand in {exercise.attempts} time{'s' if exercise.attempts > 1 else ''}")
        if not exercise.own_files:
            rules.append("a hand-in comes from your actuator's experiment (a file you upload can be identified, "
                         "not handed in)")
        rules.append({"verdict": "each hand-in tells you which values are accepted",
                      "none": "a hand-in is only stored: your teacher tells you the result",
                      "after-deadline": "the verdicts are shown after the deadline"}[exercise.feedback])
        who = ("Type the join code your teacher gave you." if exercise.has_roster else
               "The same name or id always gives the same actuator (ids are not checked in this exercise: type "
               "your own).")
        self.intro = pn.pane.HTML(
            f"<h3>{html.escape(exercise.title)}</h3><p>Your actuator is your own: its {hidden} are hidden and "
            f"differ from the paper's by up to ±{100 * exercise.vary:g} %. Simulate it, identify it (tab 3) and hand "
            f"in your estimates; an estimate counts within {tol}. "
            f"Conditions: {html.escape(exercise.conditions.describe())}. {_sentence('; '.join(rules))}.</p>"
            f"<p>{who}</p>", sizing_mode="stretch_width", css_classes=["eha-gate-intro"])
        if exercise.has_roster:
            self.student_id = pn.widgets.TextInput(label="Your join code", placeholder="e.g. K7M2P-Q9RST", width=300,
                                                   css_classes=["eha-join-code"])
        else:
            self.student_id = pn.widgets.TextInput(label="Your name or student id", placeholder="e.g. s1234567",
                                                   width=300, css_classes=["eha-student-id"])
        self.button = pn.widgets.Button(label="Start", color="primary", width=120, css_classes=["eha-start"])
        self.message = pn.pane.HTML("", css_classes=["eha-error", "eha-error-student"],
                                    styles={"color": "#b00020", "font-size": "12px"})
        on_click(self.button, lambda _e: self.start())
        self.layout = pn.Column(self.intro, self.student_id, self.button, self.message, margin=(10, 20),
                                width=620, css_classes=["eha-gate"])

    def start_as_user(self, user: str) -> None:
        """Join as the identity provider's ``user`` (the roster's id, compared as ids are): their
        actuator without a code; a user not in the roster is told so and may not type a code."""
        entry = self.exercise.entry(user) if self.exercise.has_roster else None
        if self.exercise.has_roster and entry is None:
            self.student_id.disabled = self.button.disabled = True
            self.message.object = (f"You are signed in as {html.escape(user)}, who is not in this exercise's roster: "
                                   "ask your teacher to add you.")
            return
        self.state.start_exercise(self.exercise, entry.id if entry else user, handins=self.handins,
                                  name=entry.name if entry else "")
        self.on_start()

    def start(self) -> None:
        typed = self.student_id.value_input or self.student_id.value
        if self._checking:
            return                              # a second click while the first is checked
        if self.exercise.has_roster:
            wait = _wrong_codes.wait_s(self.address)
            if wait > 0:
                self.message.object = (f"Too many wrong codes: wait {wait:.0f} s and type the code on your slip "
                                       "again.")
                return
            entry = self.exercise.entry_for_code(typed)
            if entry is None:
                _wrong_codes.wrong(self.address)
                shown = " ".join(str(typed).split())[:40] or "(empty)"
                self.message.object = html.escape(str(not_allowed(
                    "join code", shown, "it is no code of this exercise; type the ten characters on your slip "
                                        "(dashes and case do not matter)")))
                return
            self._enter(entry.id, entry.name)
            return
        try:
            student = normalize_id(typed)
        except ValueError as exc:
            self.message.object = html.escape(" ".join(str(exc).split()))
            return
        limit, store = self.exercise.ids_per_client, self.handins
        if store is None or not limit or _this_machine(self.address):
            self._enter(student, "")
            return
        # an open exercise: a new id counts against this address's hourly share (read off the event loop)
        self._checking = True
        self.message.object = "<span class='eha-note'>Starting…</span>"

        def checked(why) -> None:
            self._checking = False
            if why:
                self.message.object = html.escape(why)
                return
            self.message.object = ""
            self._enter(student, "")

        def failed(exc: Exception) -> None:
            # the database cannot say in time (damaged, or locked by another program): the student is let in
            # rather than kept waiting (the hand-ins say what is wrong when it matters)
            log.warning("could not check a new id's address: %s", exc)
            checked(None)

        store_calls.call(lambda: store.new_id_from(self.address, student, limit=limit, patience=self.CHECK_S),
                         checked, fail=failed, doc=self.doc)

    def _enter(self, student: str, name: str) -> None:
        try:
            self.state.start_exercise(self.exercise, student, handins=self.handins, name=name)
        except ValueError as exc:
            self.message.object = html.escape(" ".join(str(exc).split()))
            return
        self.on_start()


#: How often a student's page looks whether their result may be shown (a reveal, the deadline) and
#: whether their id was opened on another page.
RESULT_POLL_MS = 5000
#: This process's live pages of an exercise's students, by page token: a page taken over here gives
#: way at once (one in another process at its next poll).
_live_pages: dict[str, weakref.ref] = {}


def _log_to_stderr() -> None:
    """The app's notices (a closed page's cancelled runs, failures) in the server's log: through the
    server's own handler (``eha serve`` sets its format), or one of their own if it has none."""
    from .runtime.serving import LOG_FORMAT

    logger = logging.getLogger("eha_app")
    logger.setLevel(logging.INFO)
    if not logger.handlers and not logging.getLogger().handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter(LOG_FORMAT))
        logger.addHandler(handler)


def serve_session() -> None:
    """Make this browser session's page (the server runs :mod:`eha_app.eha` for every session)."""
    from bokeh.models import CustomJS

    from .runtime.patches import (
        ACCESSIBLE_WIDGETS_JS,
        CONTROLS_BEFORE_RENDER_JS,
        VIEW_CLASS_JS,
        apply_patches,
        strict_mode_on,
        usable,
    )
    from .runtime.redaction import redact_server_logs
    from .runtime.serving import quiet_closed_websockets, use_local_resources
    from .runtime.tasks import note_loop_thread

    _log_to_stderr()
    redact_server_logs()
    note_loop_thread()
    if strict_mode_on():
        apply_patches(("strict",))
    warm_up()
    quiet_closed_websockets()
    use_local_resources(pn.state.curdoc)
    # Neither the browser's details (language, time zone, ...) nor Panel's URL
    # model are used: without them a page sends the server 8 fewer messages when
    # it opens (the address is kept by eha_app.runtime.connection instead).
    pn.config.browser_info = False
    query = {k: v[-1].decode("utf-8", "replace") for k, v in (pn.state.session_args or {}).items() if v}
    # The session's document starts as an empty column; the page is built into it once the browser
    # has the document (document_ready), as a page change that waits its turn with the others
    # (PageUpdates). Bokeh makes a session in one callback of the event loop, which nothing
    # interrupts: building the page there (60-70 ms) made a student typing wait behind every page
    # opened at the same time (0.7-1.0 s, p95, while thirty opened theirs).
    shell = pn.Column(sizing_mode="stretch_width", css_classes=["eha-page"])
    shell.servable(title="EHA: modeling and identification", location=False)
    # before any widget of the page is built in the browser (see patches.CONTROLS_BEFORE_RENDER_JS)
    if usable("controls_before_render"):
        pn.state.curdoc.js_on_event("document_ready", CustomJS(code=VIEW_CLASS_JS + CONTROLS_BEFORE_RENDER_JS
                                                               + "ehaControlsBeforeRender();"))
    # ... and the tab headers a keyboard opens, the checkboxes named (patches.ACCESSIBLE_WIDGETS_JS)
    if usable("accessible_widgets"):
        pn.state.curdoc.js_on_event("document_ready", CustomJS(code=VIEW_CLASS_JS + ACCESSIBLE_WIDGETS_JS
                                                               + "ehaAccessibleWidgets();"))

    def build() -> None:
        shell.objects = [create_app(query=query).layout]

    pn.state.onload(lambda: apply_locked(build))


_patch_warned: set[str] = set()


def _patches_reported(event) -> None:
    """A page said which library patches took effect: say once per process if one did not."""
    for name, applied in (event.new or {}).items():
        if not applied and name not in _patch_warned:
            _patch_warned.add(name)
            log.warning("the page's %s patch found none of the internals it needs (a newer Bokeh?): pages "
                        "still work, more slowly; see eha_app/runtime/patches.py", name)


def create_app(state: AppState | None = None, *, query: dict | None = None, runner: SessionRunner | None = None):
    """The whole page for one session: a :class:`Page` (``page.session`` is its :class:`Session`).

    ``query`` holds the page address's fields (``{"M": "6000", "tab": "2"}``):
    what the student had typed before a reload, or a shared link. A value that
    is not allowed is shown with its message, as if typed.
    """
    _session_style()
    session = Session(state, query=query, runner=runner)
    page = Page(session)
    if served_document() is not None:
        def closed(_context):
            # nobody will see these results: free the workers for the others
            jobs = session.runner.cancel_all("the page was closed")
            if jobs:
                log.info("a page was closed: cancelled %s", ", ".join(j.label for j in jobs))
        pn.state.on_session_destroyed(closed)
        # at once when its websocket closes (eha serve), not only when the session is discarded
        on_disconnect(served_document(), lambda: closed(None))
    return page


class Page(pn.viewable.Viewer):
    """One student's page: the header, the settings row and the main tabs, each made from the
    registry's sections when first shown; in an exercise, the student's id first."""

    def __init__(self, session: Session, **params):
        super().__init__(**params)
        self.session = session
        self.tabs: LazyTabs | None = None
        self.gate: ExerciseGate | None = None
        self.work = None            # the keeper of an exercise's student's work (eha_app.sections.work)
        self.settings_note = pn.pane.HTML("", css_classes=["eha-settings-note"], styles={"font-size": "12px"},
                                          sizing_mode="stretch_width")
        self.layout = pn.Column(sizing_mode="stretch_width", margin=(0, 10))
        # on every page, the gate of an exercise included: the lost connection's notice and the
        # page's one layout per message, which it reports
        self.connection = ConnectionWatch()
        watch(self.connection, _patches_reported, "patches")
        exercise = current_exercise()
        if exercise is not None and not session.student:
            self.gate = ExerciseGate(*exercise, session.state, self._start)
            self.layout.objects = [self.connection, self.gate.layout]
            user = signed_in_user()
            if user is not None:
                # the identity provider checked who this is: their roster entry, without a code
                self.gate.start_as_user(user)
        else:
            self._start(first=True)

    def _start(self, first: bool = False) -> None:
        """The app itself (after the student's id in an exercise)."""
        session = self.session
        if not first:             # an exercise: the fields of the page's address, but the hidden ones
            session.query = {k: v for k, v in session.query.items() if k not in session.hidden}
        for name in FORM_FIELDS:
            if name in session.query:
                session.state.set_text(name, session.query[name])
        names = session.registry.tabs()
        tab = session.query.get("tab", "").strip()
        active = int(tab) - 1 if tab.isdigit() and 1 <= int(tab) <= len(names) else 0
        self.tabs = LazyTabs([(name, partial(self._make_tab, name)) for name in names], active=active,
                             css_class="eha-main-tabs")
        session.active_tab = active
        watch(self.tabs.tabs, lambda e: setattr(session, "active_tab", e.new), "active")
        # what no one is looking at waits: a section out of sight defers its work until it is shown
        session.sight = self._in_sight
        watch(self.tabs.tabs, lambda _e: session.sight_changed(), "active")
        # the way through the steps: the start card (on a first visit to tab 1) and the guide line
        from .guide import Guide, guide_steps

        self.guide = Guide(self.show, steps=guide_steps(session.registry),
                           start=active == 0 and "tab" not in session.query, done=self._step_done,
                           finish=lambda: self.prepare_report(), lab=bool(session.student))
        # "Next" is offered once the step's result is on the page: the guide hears of each result shown
        for section in session.built():
            self._guide_hears(section)
        session.when_built(self._guide_hears)
        watch(self.tabs.tabs, lambda _e: self._guide_follows(), "active")
        first_tab = names[active]
        if served_document() is not None:
            # The page's frame goes out now; its first tab once the browser has it
            # (document_ready). A change made between the browser's pull of the
            # document and that moment can be lost (Panel holds the changes of an
            # unconnected session and relies on the pull): the page would stay at
            # "Preparing this tab..." for good.
            if first:
                pn.state.onload(lambda: apply_locked(lambda: self.tabs.build(first_tab)))
            else:
                apply_locked(lambda: self.tabs.build(first_tab))
        else:
            self.tabs.build(first_tab)
        who = (f'<span class="eha-student" style="color:#1a56c4">{html.escape(session.exercise.title)} — '
               f'{html.escape(session.state.student_name or session.student)}</span>' if session.student else "")
        header = pn.pane.HTML(
            '<div style="display:flex;align-items:baseline;gap:16px;flex-wrap:wrap">'
            '<h2 style="margin:4px 0">Electro-hydraulic actuator: modeling and identification</h2>'
            f'<span style="color:#666">a single-rod cylinder driven by a proportional valve</span>{who}</div>',
            sizing_mode="stretch_width")
        self.result_pane = pn.pane.HTML("", visible=False, sizing_mode="stretch_width",
                                        css_classes=["eha-student-result"])
        # the lab's rules (deadline, hand-ins left, tolerances, feedback), always in view in an exercise
        self.rules_pane = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-lab-rules-pane"],
                                       margin=(0, 10))
        # the result and rules panes only in an exercise: a page without one sends two models fewer
        shown = [self.rules_pane, self.result_pane] if session.student else []
        self.layout.objects = [self.connection, header, *shown, self._settings_row(), self.guide.start,
                               self.guide.line, self.tabs.tabs]
        self._guide_follows()
        if session.student:
            self._join()
        # in an exercise: the student's kept work back on the page, and kept from now on
        self.work = keep_work(session, lambda text: setattr(self.settings_note, "object", text))

    # -- the student's presence: one live page per id ----------------------------------------------
    def _join(self) -> None:
        """Note the student as here on this page (off the event loop), ask the page their id had open
        before to give way, and look every few seconds whether their result may be shown and whether
        this page is still theirs."""
        state, doc = self.session.state, served_document()
        self.page_token = secrets.token_hex(8)
        self._polling = False
        self._touched = time.monotonic()            # the join itself says "here now"
        self._poller = None
        # the page's presence is in the store (until then its live page is another's, which this page must
        # not give way to); written by the first look, and tried again at every look until it is
        self._noted = state.handins is None
        self.stopped = False
        self.doc = doc
        _live_pages[self.page_token] = weakref.ref(self)
        student, store, token = state.student, state.handins, self.page_token
        # after a hand-in the rules are read again at once (the attempts left, the button off after the last)
        self.session.after_handin.append(self.check_result)
        self.check_result()
        if doc is not None:
            # the teacher's reveal (or the deadline), or this id opened elsewhere, reaches the page within seconds
            self._poller = pn.state.add_periodic_callback(self.check_result, period=RESULT_POLL_MS)

            def closed() -> None:
                _live_pages.pop(token, None)
                state.forget_secrets()
                if store is not None and not self.stopped:
                    store_calls.call(lambda: store.left(student, token), doc=doc)
            on_disconnect(doc, closed)
            # a session discarded without its websocket's close being seen (a server's own cleanup)
            pn.state.on_session_destroyed(lambda _context: closed())

    def _took_over(self, before: str) -> None:
        """This page's presence was written; ``before``, the page of this id that was live (or "")."""
        self._noted = True
        if before:
            # another page of this id was live: it stops (at once here, within a poll elsewhere)
            log.info("an id was opened on a second page: the first gives way")
            other = _live_pages.get(before)
            page = other() if other is not None else None
            if page is not None and page is not self:
                apply_locked(page.give_way, page.doc)

    #: How long one look waits for the store to note the page (a lock held by another program: the
    #: next look tries again) [s].
    NOTE_PATIENCE_S = 2.0
    #: How often an open page writes that its student is still here [s].
    TOUCH_S = 60.0

    def check_result(self) -> None:
        """Note the page as the student's live one (until that is done), show the student's result once
        the exercise allows it, and give way if their id is live on another page now: a few small reads
        (and the one write) of the database, off the event loop."""
        from .runtime.handins import StoreError
        from .sections.handin import result_for_student

        state = self.session.state
        if self._polling or self.stopped:
            return                                  # the last look has not come back yet
        self._polling = True
        exercise, student, store, token = state.exercise, state.student, state.handins, self.page_token
        noted, patience = self._noted, self.NOTE_PATIENCE_S
        # "last seen" on the teacher's dashboard moves while the page is open: a write once a minute, not
        # at every look (thirty pages' looks every 5 s would be six writes a second)
        touch = noted and time.monotonic() - self._touched >= self.TOUCH_S
        if touch:
            self._touched = time.monotonic()

        def read():
            before = None if noted else store.seen(student, token, patience=patience)
            if touch and store is not None:
                store.touch(student, token)
            live = store.live_page(student) if store is not None else token
            if store is None:
                return before, live, "", None, 0
            control = store.control_for(student)     # with their own deadline, if extended
            count = len(store.of(student))
            return before, live, result_for_student(exercise, student, store, control), control, count

        def show(out) -> None:
            self._polling = False
            before, live, text, control, count = out
            if before is not None:
                self._took_over(before)
            if live and live != token and self._noted:
                self.give_way()
                return
            if text != self.result_pane.object:
                self.result_pane.object = text
                self.result_pane.visible = bool(text)
            if control is not None:
                self._rules_read(exercise, control, count)

        def failed(exc: Exception) -> None:
            # a damaged or busy store keeps no student out (hand-ins say so when it matters): tried again next time
            self._polling = False
            if not noted:
                log.warning("could not note a student's arrival (tried again in %d s): %s", RESULT_POLL_MS // 1000,
                            exc)
            elif not isinstance(exc, StoreError):
                log.warning("a student's result could not be read: %s", exc)

        store_calls.call(read, show, fail=failed, doc=self.doc)

    def _rules_read(self, exercise, control: dict, count: int) -> None:
        """The lab's rules as the store says them now: the rules line, and the hand-in buttons off when
        hand-ins are refused (no attempt left, the deadline passed, closed by the teacher)."""
        from .sections.handin import lab_refusal, lab_rules_html

        session = self.session
        why = lab_refusal(exercise, control, count)
        rules = lab_rules_html(exercise, control, count, why=why)
        if rules != self.rules_pane.object:
            self.rules_pane.object = rules
        changed = why != session.lab_refusal or count != session.handins_used
        session.lab_refusal, session.handins_used = why, count
        if changed:
            for box in session.handin_boxes:
                box.rules_changed()

    def give_way(self) -> None:
        """The student's id was opened on another page: this one stops (its runs, its saves, its
        uploads and results are let go), and says so."""
        if self.stopped:
            return
        self.stopped = True
        _live_pages.pop(self.page_token, None)
        session = self.session
        session.runner.cancel_all("the id was opened on another page")
        if self.work is not None:
            self.work.stop()                        # its saves would overwrite the other page's
        if self._poller is not None:
            try:
                self._poller.stop()
            except Exception:  # noqa: BLE001 - already stopped with its session
                pass
        when = time.strftime("%H:%M:%S")
        notice = pn.pane.HTML(
            f"<div class='eha-given-way-box' role='alert'><h3>Your code was opened on another page ({when})</h3>"
            "<p>Your work goes on there: one code works on one page at a time, and your teacher sees a code "
            "used twice. To work on this page again, reload it and type your code (the other page then "
            "stops).</p></div>", sizing_mode="stretch_width", css_classes=["eha-given-way"])
        self.layout.objects = [self.connection, notice]
        session.release()
        self.tabs = None
        self.guide = None

    def _step_done(self, key: str) -> bool | None:
        section = self.session.section(key)
        return None if section is None else section.guide_done()

    def _guide_hears(self, section) -> None:
        """The guide says the step again when ``section`` shows a result (it may offer "Next" then)."""
        def said() -> None:
            if self.guide is not None:
                self.guide.refresh()
        for view in section.result_views():
            view.on_shown.append(said)
        watch(section, lambda _e: said(), "result")
        said()

    def _guide_follows(self) -> None:
        """The guide line says which section is shown (the student may have come by any way)."""
        name = self.tabs.active_name
        placements = self.session.registry.on_tab(name)
        key = placements[0].key
        content = self.tabs.built.get(name)
        if isinstance(content, SubTabs):
            key = content.keys.get(content.lazy.active_name, key)
        if name != self.tabs.names[0]:
            self.guide.hide_start()
        self.guide.show_step(key)

    def _make_tab(self, name: str):
        placements = self.session.registry.on_tab(name)
        if len(placements) == 1:
            return self.session.build(placements[0].key)
        sub = SubTabs(self.session, placements)
        watch(sub.lazy.tabs, lambda _e: self._guide_follows(), "active")
        watch(sub.lazy.tabs, lambda _e: self.session.sight_changed(), "active")
        return sub

    def _placed(self, key: str):
        """The placement of section ``key`` on the page (of the section it is within, if any)."""
        placement = self.session.registry.get(key)
        while placement.within is not None:
            placement = self.session.registry.get(placement.within)
        return placement

    def _in_sight(self, key: str) -> bool:
        """Is section ``key`` on show: its tab open and, on a tab of sub-tabs, its sub-tab?"""
        if self.tabs is None:
            return False
        placement = self._placed(key)
        if self.tabs.active_name != placement.tab:
            return False
        content = self.tabs.built.get(placement.tab)
        if isinstance(content, SubTabs):
            return content.keys.get(content.lazy.active_name) == placement.key
        return True

    def show(self, key: str):
        """Show section ``key`` (its tab and sub-tab), made now if needed; returns it."""
        placement = self._placed(key)
        self.tabs.tabs.active = self.tabs.names.index(placement.tab)
        content = self.tabs.build(placement.tab)
        if isinstance(content, SubTabs):
            name = next(n for n, k in content.keys.items() if k == placement.key)
            content.lazy.tabs.active = content.lazy.names.index(name)
            content.lazy.build(name)
        return self.session.build(key)

    # -- the settings row ---------------------------------------------------------------------------
    def _settings_row(self) -> pn.Row:
        """Save the session's settings as JSON, or load a saved file; the report of the session."""
        from .sections.uploads import FileUpload

        session, note = self.session, self.settings_note
        save = pn.widgets.FileDownload(callback=lambda: io.BytesIO(session.settings_bytes()),
                                       filename="eha_settings.json", label="Save settings", width=130,
                                       css_classes=["eha-save-settings"],
                                       description="every input of every tab, as a JSON file")
        self.load = FileUpload(accept=".json", max_bytes=MAX_SETTINGS_BYTES, width=230,
                               css_classes=["eha-load-settings"], label="Load settings (a JSON file saved here)")
        # The report takes about 0.8 s to draw: a worker draws it from a snapshot of the page taken
        # now (the page's thread serves the other students meanwhile), then it is offered.
        # no tooltip: it would cover the download that appears beside the button under the pointer
        self.report_button = pn.widgets.Button(label="Report of this session", width=190,
                                               css_classes=["eha-session-report"])
        # who the report is of: typed outside an exercise; in one, the student's checked id
        self.report_name = pn.widgets.TextInput(placeholder="your name, for the report", width=190,
                                                css_classes=["eha-report-name"],
                                                visible=not self.session.state.hidden)
        self.report_download = pn.widgets.FileDownload(filename="eha_session_report.html", label="Download the report",
                                                       visible=False, width=190, color="success",
                                                       css_classes=["eha-session-report-download"],
                                                       stylesheets=[BUTTON_CONTRAST])
        on_click(self.report_button, lambda _e: self.prepare_report())
        watch(self.load, lambda _e: self._loaded(), "value")
        # a row that wraps: at 800 px its six parts do not fit one line, and a row that does not wrap
        # widened the whole page (every table and tab header with it)
        return pn.FlexBox(save, pn.pane.HTML("<span class='eha-note'>Load settings:</span>", margin=(12, 4, 0, 10)),
                          self.load, self.report_name, self.report_button, self.report_download, note,
                          flex_wrap="wrap", align_items="flex-start", sizing_mode="stretch_width",
                          css_classes=["eha-settings-row"])

    def prepare_report(self):
        from .render.report import session_report

        session, download, note, button = self.session, self.report_download, self.settings_note, self.report_button
        snapshot = session.snapshot()           # under the page's lock: a click
        author = "" if session.state.hidden else " ".join(str(self.report_name.value or "").split())[:80]

        def done():
            button.label, button.disabled = "Report of this session", False

        def show(data, _job):
            done()
            download.file = io.BytesIO(data)
            download.label = f"Download the report ({len(data) / 1e6:.1f} MB)"
            download.visible = True
            note.object = "<span class='eha-ok'>The report is ready: “Download the report”, beside the button.</span>"

        def fail(message):
            done()
            note.object = f"<span class='eha-warn'>The report could not be made: {html.escape(message)}</span>"

        # at once, where the student looks: the button says it is working (the report takes ~3 s)
        download.visible = False
        button.label, button.disabled = "Preparing the report…", True
        note.object = "<span class='eha-note'>Drawing every tab's results into one file…</span>"
        return session.runner.run("session report", lambda _token: session_report(session, snapshot, author=author),
                                  show, fail=fail)

    def _loaded(self) -> None:
        load, note = self.load, self.settings_note
        if load.value is None:
            return
        try:
            notes = self.session.load_settings(bytes(load.value), shown_text(load.filename or "settings.json", 60))
        except SettingsError as exc:
            note.object = f"<span class='eha-warn'>{html.escape(str(exc))}</span>"
            return
        note.object = ("<span class='eha-ok'>Settings loaded.</span> "
                       + " ".join(f"<span class='eha-note'>{html.escape(n)}</span>" for n in notes))

    def __panel__(self):
        return self.layout
