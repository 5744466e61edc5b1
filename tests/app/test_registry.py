"""A section registered with one line is everywhere a section is: the page (its sub-tab), settings
files, the page's address, the session report, the guide, the work an exercise keeps for a student
who joins again (after a restart too), the server's limits, and the random walk's actions and forms.

The throwaway section below has one field, a run button with a result, a report part, a guide step
and kept work; it is registered for one test at a time (``SECTIONS.added``) and nothing else is
edited for it. The last test holds the real sections to what they declare for the walk and tests.
"""

from __future__ import annotations

import json

import panel as pn
import pytest

from benchmarks import walker
from eha_app.app import create_app
from eha_app.render.report import session_report
from eha_app.runtime import exercise_file
from eha_app.runtime.handins import HandIns
from eha_app.runtime.limits import RunCost
from eha_app.runtime.tasks import on_click, watch
from eha_app.runtime.work_store import WorkStore
from eha_app.session import (
    SECTIONS,
    GuideStep,
    KeptWork,
    ReportPart,
    RestoreStep,
    Section,
    SectionSnapshot,
    Session,
)
from eha_app.session.form import Field, Form, Group
from eha_app.session.freshness import ResultView
from eha_app.session.state import AppState
from tests.app.test_work import exercise, join  # noqa: F401 - the exercise's fixture and gate, as there


class TallyPanel(Section):
    """A panel of the fewest lines with everything a section can have: one field, a run button whose
    result is marked current or out of date, a report part, a guide step, kept work and a price."""

    key = "tally"
    title = "A tally"
    defaults = {"tally_n": "3"}
    guide_step = GuideStep("3. Tally", "Step 3, a tally: the square of n.", "the tally")
    form_css = "eha-tally-form"
    run_buttons = ("Count the tally",)

    def __init__(self, session, **params):
        super().__init__(session, **params)
        self.form = Form(spec=[Group("Tally", (Field("tally_n", "n", "integer", lo=0, hi=10**9),)).to_spec()],
                         values=self.initial_texts(), url_defaults=self.defaults, css_classes=[self.form_css])
        self.button = pn.widgets.Button(label=self.run_buttons[0])
        on_click(self.button, lambda _e: self.run())
        self.alert = pn.pane.HTML("")
        self.shown = pn.pane.HTML("")
        self.area = pn.Column(self.shown)
        self.view = ResultView("tally", self.area)
        watch(self.form, lambda _e: self.view.inputs_changed(self.n()), "values")

    def n(self) -> int | None:
        text = str(self.form.values.get("tally_n", "")).strip()
        return int(text) if text.isdigit() else None

    def run_cost(self) -> RunCost | None:
        n = self.n()
        return None if n is None else RunCost("n", str(n), 1000 * n, 8 * n, float(n), "count fewer")

    def run(self):
        n = self.n()
        try:
            self.check_cost()
        except ValueError as exc:
            self.alert.object = str(exc)
            return None

        def show(square, _job):
            self.result = square
            self.shown.object = f"<p>{n}² = {square}</p>"
            self.view.shown(n)
        return self.runner.run("tally", lambda _token: n * n, show, fail=lambda m: setattr(self.alert, "object", m))

    def result_views(self) -> list:
        return [self.view]

    def kept_work(self) -> KeptWork | None:
        return KeptWork({"views": ["tally"]}) if self.view.is_current else None

    @classmethod
    def restore_work(cls, kept, texts) -> list[RestoreStep]:
        if "tally" not in (kept.run or {}).get("views", ()):
            return []
        return [RestoreStep(cls.title, lambda section: section.run())]

    def snapshot(self) -> SectionSnapshot:
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(), content=self.result)

    @classmethod
    def report(cls, snapshot, hidden=()):
        if snapshot.content is None:
            return None
        return ReportPart("A tally", f"<p>The tally is {snapshot.content}.</p>")

    def __panel__(self):
        return pn.Column(self.form, self.button, self.alert, self.view.banner, self.area)


@pytest.fixture
def tally():
    with SECTIONS.added(TallyPanel, tab="3. Identification", subtab="Tally"):
        yield TallyPanel
    assert "tally" not in SECTIONS              # the registry is as it was


def _press(button):
    button.clicks += 1


def test_it_is_on_the_page_in_settings_in_the_address_and_in_the_report(tally):
    page = create_app(query={"tally_n": "5", "tab": "3"})           # the page's address holds its field
    assert page.session.section("tally") is None
    assert json.loads(page.session.settings_bytes())["tally"] == {"tally_n": "5"}     # saved before it was shown
    section = page.show("tally")                                   # a sub-tab of tab 3 of its own
    assert page.tabs.active_name == "3. Identification"
    assert page.tabs.built["3. Identification"].lazy.active_name == "Tally"
    assert section.form.values["tally_n"] == "5"
    _press(section.button)
    assert section.result == 25 and section.view.is_current
    text = session_report(page.session, page.session.snapshot()).decode()
    assert "A tally" in text and "The tally is 25." in text

    other = create_app()                                           # a settings file, loaded into another page
    other.session.load_settings(page.session.settings_bytes())
    assert other.show("tally").form.values["tally_n"] == "5"
    section.form.set_values(tally_n="6")
    assert not section.view.is_current                             # its result is marked out of date
    assert page.session.snapshot().section("tally").stale


def test_the_guide_stops_at_it(tally):
    page = create_app()
    guide = page.guide
    assert [s.key for s in guide.steps][-2:] == ["study", "tally"]
    page.show("study")
    assert guide.next.visible and guide.next.label == "Next: the tally →"
    assert guide.next.disabled                              # offered once the study's result is there
    page.session.section("study").guide_done = lambda: True    # (a study of its own would take seconds)
    guide.refresh()
    assert not guide.next.disabled
    _press(guide.next)
    assert guide.current == "tally" and "Step 3, a tally" in guide.where.object and not guide.next.visible
    assert page.tabs.built["3. Identification"].lazy.active_name == "Tally"


def test_its_result_comes_back_after_a_rejoin_and_a_restart(tally, exercise):  # noqa: F811 - the fixture
    _, path = exercise
    page = join("s1")
    section = page.show("tally")
    section.form.set_values(tally_n="7")
    _press(section.button)
    assert section.result == 49
    assert WorkStore(HandIns(path)).load("s1").runs["tally"] == {"views": ["tally"]}

    again = join("s1")
    back = again.session.section("tally")
    assert back is not None and back.result == 49 and back.view.is_current and back.form.values["tally_n"] == "7"
    assert "results of A tally" in again.settings_note.object

    exercise_file._exercise_at.cache_clear()                       # a new server process: a new store
    restarted = join("s1")
    assert restarted.session.state.handins is not again.session.state.handins
    assert restarted.session.section("tally").result == 49


def test_the_servers_limits_price_its_run(tally, monkeypatch):
    monkeypatch.setenv("EHA_MAX_STEPS", "4000")
    section = create_app().show("tally")
    section.form.set_values(tally_n="5")                            # 5000 steps
    assert section.run() is None and section.result is None
    assert "n = 5 is not allowed here" in section.alert.object and "count fewer" in section.alert.object
    section.form.set_values(tally_n="4")
    assert section.run() is not None and section.result == 16


def test_the_random_walk_types_into_it_runs_it_reaches_it_and_loads_it_in_settings(tally):
    (found,) = [p for p in walker.page_sections() if p.key == "tally"]
    assert (found.form_css, found.run_buttons, found.tab, found.subtab) == ("eha-tally-form", ("Count the tally",),
                                                                           2, 6)
    walk = walker.Walker("http://127.0.0.1:1/eha", 1)
    assert walk.WHERE["type-tally"] == walk.WHERE["run-tally"] == (2, 6)
    assert walk.WEIGHTS["type-tally"] > 0 and walk.WEIGHTS["run-tally"] > 0 and "run-tally" in walk.RUNS
    assert walk.subtab_ready[(2, 6)] == ("eha-tally-form", "A tally")
    settings = {"format": "eha-settings/1", "tally": {"tally_n": "2"}}
    assert walk._settings_file(json.dumps(settings).encode()) == settings
    # the app refuses a file whose section is not a table of texts: the walk expects it to
    assert walk._settings_file(json.dumps({**settings, "tally": ["tally_n", 2]}).encode()) is None
    with pytest.raises(Exception, match="not a list of fields"):
        Session(AppState()).load_settings(json.dumps({**settings, "tally": ["tally_n", 2]}))


def test_without_it_the_walk_has_none_of_its_actions():
    walk = walker.Walker("http://127.0.0.1:1/eha", 1)
    assert not any("tally" in k for k in walk.WEIGHTS) and "tally" not in walk.settings_sections


def _on_page(panel) -> tuple[set, set]:
    """The css classes and the button labels of everything in ``panel`` (the Bokeh models in its panes too)."""
    classes, labels = set(), set()
    for obj in panel.select():
        classes.update(getattr(obj, "css_classes", None) or ())
        if isinstance(obj, pn.widgets.Button):
            labels.add(obj.label)
        if isinstance(obj, pn.pane.Bokeh) and obj.object is not None:
            for model in obj.object.references():
                classes.update(getattr(model, "css_classes", None) or ())
    return classes, labels


def test_every_section_has_the_form_content_and_run_buttons_it_declares():
    """What the walk and the tests find a section by is what the section builds."""
    session = Session(AppState())
    for p in SECTIONS:
        top = p
        while top.within is not None:
            top = SECTIONS.get(top.within)
        session.build(p.key)
        classes, labels = _on_page(session.section(top.key).__panel__())
        for css in (p.cls.form_css, p.cls.content_css):
            assert css is None or css in classes, (p.key, css)
        assert set(p.cls.run_buttons) <= labels, (p.key, set(p.cls.run_buttons) - labels)
        assert p.cls.form_css is not None, p.key                     # every section here has a form
