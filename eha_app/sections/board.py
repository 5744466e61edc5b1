"""Tab 3, model board: every estimate of the session, side by side.

Each transfer-function estimate (frequency experiment or own record) and each
least-squares run (as eq. 24's H(s) with its estimates) lands here with a
short name. A grey-box estimate lands as what it is, a nonlinear model of the
actuator: the board closes its loop with tab 1's controller, simulates it on
the validation record and for the step, and draws its linearisation's Bode
diagram and poles with the bands its covariance gives. The references (eq. 24 with the actuator's values, the paper's Ĥ)
are always offered. The student ticks models to overlay them, one colour per
model, in four views: the fit on one validation record (MATLAB ``compare``,
with the residual tests' verdicts), the Bode diagram with 95 % bands, the step
response with its figures (and the nonlinear plant's under the same
controller), and the poles and zeros with their 95 % regions. Models can be
renamed and deleted.

The core computes each model's curves once, in a worker (:func:`eha_core.board.model_views`);
ticking only replaces the views' data. On a page, work waits until someone looks: the board computes
the view it opens on (the fit on the validation record) when it is shown, the Bode diagram, steps and
poles (and the nonlinear plant's step) when their tabs are first opened, and a change of tab 1 while
the board is not on show when it is shown again (it says meanwhile that it is out of date).
"""

from __future__ import annotations

import dataclasses
import html
import itertools
from dataclasses import dataclass

import numpy as np
import panel as pn

from eha_core.board import (
    BoardModel,
    compare_on_record,
    model_views,
    nonlinear_step,
    plant_model,
    plant_step,
    reference_models,
    validation_record,
)
from eha_core.errors import ComputationError

from ..render import board_plots, plots
from ..render.layout import LABEL_FOR_SCREEN_READERS, WRAP_TAB_HEADERS, side_by_side
from ..runtime.tasks import on_click, watch
from ..session import GuideStep, ReportPart, Section, SectionSnapshot, stale_note
from ..session.form import Field, Form, Group, parse_fields
from ..session.freshness import ResultView, param_changes

__all__ = ["ModelBoard", "BOARD_FORM", "BOARD_DEFAULTS", "MAX_MODELS", "fit_table", "step_table"]

#: Models the board holds at most (beside the references): a student deletes one to keep more.
MAX_MODELS = 12
BOARD_FORM = (Group("Comparison", (
    Field("board_seed", "validation seed", "integer", lo=0, hi=10**6, short="validation seed",
          tip="seed of the idinput excitation of the validation record: a closed-loop experiment on tab 1's "
              "actuator that none of the models was estimated from (unless you used this seed)"),
    Field("board_step", "step of r", "number", unit="mm", lo=0.01, hi=200.0, short="step of r",
          tip="height of the reference step for the step responses"),
)),)
BOARD_DEFAULTS = {"board_seed": "1000", "board_step": "10"}
_FIELDS = {f.name: f for g in BOARD_FORM for f in g.fields}
_VIEWS = (("Fit on validation data", "fit"), ("Bode", "bode"), ("Step response", "step"),
          ("Poles and zeros", "pz"))


def _tick_label(name: str) -> str:
    """What a screen reader says of a model's tick on the board's list."""
    return f"Draw {name} on the views"


@dataclass
class BoardEntry:
    """A model on the board, as the student sees it (name editable, ticked or not)."""

    key: int
    model: BoardModel
    color: str
    name: str
    ticked: bool = True
    dash: str = "solid"             # with the colour, tells its lines apart (board_plots.BOARD_STYLES)

    @property
    def kind(self) -> str:
        return self.model.kind


class ModelBoard(Section):
    """The model board of one session (see the module docstring).

    It is made when a student first opens it (forms, figures, its references'
    linearisation: about 40 ms and 0.4 MB a session), and takes the estimates the
    other sections posted before (:meth:`receive`), naming them in the order they
    were made: H1, H2, ... LS1, ... R1.
    """

    key = "board"
    title = "Model board"
    defaults = BOARD_DEFAULTS
    #: Estimates kept for a board not opened yet (a student deletes one to keep more).
    max_mail = MAX_MODELS
    guide_step = GuideStep("3. Model board", "Step 3, comparison: every model you made, on one validation record.",
                           "the model board", "Each route's run puts its model here: tick the ones to compare.",
                           runs=False)
    form_css = "eha-board-form"
    # No kept work of its own (Section.kept_work): a student who joins again gets the board filled by the
    # runs computed again, each posting its model as a click does; names typed, ticks and deletions are not kept.

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state, runner = self.state, self.runner
        self._keys = itertools.count(1)
        self._counters: dict[str, itertools.count] = {}
        self.entries: list[BoardEntry] = []
        self._failed: set[int] = set()      # models whose views could not be computed
        self.views: dict = {}           # key -> ModelViews
        self.fits: dict = {}            # key -> RecordComparison on the current record
        self.record = None
        self.record_key = None
        self.plant = None               # the nonlinear plant's step response
        self.plant_key = None
        # the board's jobs: its requests never replace the tabs' own, and close with the page
        self.views_runner = runner.sub("board views")
        self.record_runner = runner.sub("board record")
        self.plant_runner = runner.sub("board plant")
        self.figures: dict = {}
        self._panes: dict = {}
        self._ticks: dict = {}          # key -> the list's tick of that model (named after it)
        self.built = False
        # On a page, the views out of sight are computed when first shown: opening the board computes the
        # validation record and the fits (its first view); the Bode diagrams, steps and poles (and the
        # nonlinear plant's step) wait for their tabs. Without a page everything is computed.
        self._views_wanted = session.sight is None
        self._plant_wanted = session.sight is None
        texts = self.initial_texts()
        self.form = Form(spec=[g.to_spec() for g in BOARD_FORM], values=texts, url_defaults=BOARD_DEFAULTS,
                         width=270, css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, lambda _e: self._settings_changed(), "values")
        self.bands = pn.widgets.Checkbox(label="95 % bands on the Bode diagram", value=True, width=260,
                                         css_classes=["eha-board-bands"])
        watch(self.bands, lambda _e: self.refresh(), "value")
        self.list = pn.Column(width=280, css_classes=["eha-board-list"])
        self.note = pn.pane.HTML("", width=270, css_classes=["eha-board-note"])
        self.tables = {key: pn.pane.HTML("", sizing_mode="stretch_width", css_classes=[f"eha-board-{key}-table"])
                       for _, key in _VIEWS}
        self._slots = {key: pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing…</p>"), min_height=200,
                                      sizing_mode="stretch_width") for _, key in _VIEWS}
        self.view_tabs = pn.Tabs(*((title, pn.Column(self._slots[key], self.tables[key],
                                                     sizing_mode="stretch_width")) for title, key in _VIEWS),
                                 dynamic=False, sizing_mode="stretch_width", css_classes=["eha-board-views"],
                                 stylesheets=[WRAP_TAB_HEADERS])
        # only the view in sight is drawn: the others when their tab is opened
        watch(self.view_tabs, lambda _e: self._view_opened(), "active")
        self.area = pn.Column(self.view_tabs, sizing_mode="stretch_width")
        self.record_view = ResultView("board-record", self.area,
                                      run_hint="The board updates it by itself in a moment.")
        self._references()
        # "valid" too: an invalid tab 1 keeps its last valid parameters, and the record must say it
        # no longer describes what tab 1 says
        state.param.watch(lambda *_events: self._plant_changed(), ["params", "kp", "valid"])
        self.build()

    # -- models ------------------------------------------------------------------------------
    def _style(self) -> dict:
        """The first (colour, dash) of board_plots.BOARD_STYLES no model on the board has."""
        used = {(e.color, e.dash) for e in self.entries}
        color, dash = next((s for s in board_plots.BOARD_STYLES if s not in used), board_plots.BOARD_STYLES[0])
        return {"color": color, "dash": dash}

    def _references(self) -> None:
        """eq. 24 (unless an exercise hides the values it is made of) and the paper's Ĥ."""
        old = {e.model.name: e for e in self.entries if e.kind == "reference"}
        refs = reference_models(self.state.params, self.state.kp, linearised=not self.state.hidden)
        for ref in refs:
            entry = old.pop(ref.name, None)
            if entry is None:
                self.entries.insert(len([e for e in self.entries if e.kind == "reference"]),
                                    BoardEntry(next(self._keys), ref, name=ref.name, **self._style(),
                                               ticked=ref.name.startswith("H(s)")))
            elif entry.model.num.tolist() != ref.num.tolist() or entry.model.den.tolist() != ref.den.tolist():
                entry.model = ref
                self.views.pop(entry.key, None)
                self.fits.pop(entry.key, None)

    def next_name(self, prefix: str) -> str:
        """H1, H2, ... LS1, ...: a short name per kind, in the order the estimates were made."""
        return f"{prefix}{next(self._counters.setdefault(prefix, itertools.count(1)))}"

    def receive(self, model: BoardModel, *, settle: bool = True) -> None:
        """An estimate posted by another section; its ``name`` is its kind's prefix (``"LS"``)."""
        self.add(dataclasses.replace(model, name=self.next_name(model.name)), settle=settle)

    def receive_many(self, items: list) -> None:
        """The estimates made before the board was first shown: their views in one job, one list."""
        for item in items:
            self.receive(item, settle=False)
        self._compute_missing()
        self._rebuild_list()

    def add(self, model: BoardModel, *, settle: bool = True) -> BoardEntry | None:
        """Put ``model`` on the board, ticked if it is stable (an unstable one's curves would flatten the
        others'); its views are computed in a worker. ``settle=False``: the caller computes and lists the
        models it adds together, once."""
        if len([e for e in self.entries if e.kind != "reference"]) >= MAX_MODELS:
            self.note.object = (f"<span class='eha-warn'>The board holds {MAX_MODELS} models: delete one to keep "
                                f"{html.escape(model.name)}.</span>")
            return None
        stable = bool(np.all(np.roots(np.asarray(model.den, dtype=float)).real < 0))
        entry = BoardEntry(next(self._keys), model, name=model.name, ticked=stable, **self._style())
        self.entries.append(entry)
        self.note.object = ("" if stable else f"<span class='eha-warn'>{html.escape(model.name)} is unstable: "
                                              "it is on the board unticked.</span>")
        if settle:
            if self.session.in_sight(self.key):
                self._compute_missing()
            else:                       # its curves once the board is on show
                self.session.when_in_sight(self.key, self._compute_missing)
            self._rebuild_list()
        return entry

    def _view_opened(self) -> None:
        """A view's tab was opened: what it needs is computed the first time, then it is drawn."""
        key = self.shown_view()
        if key != "fit" and not self._views_wanted:
            self._views_wanted = True
            self._compute_missing()
        if key == "step" and not self._plant_wanted:
            self._plant_wanted = True
            self.update_record()
        self.refresh()

    def _compute_missing(self) -> None:
        """What is missing, in one job: the views of every model that has none (once a view that draws
        them was opened), and its fit on the current record. A newer request replaces a waiting one,
        and takes its models along."""
        if not self.built:
            return
        record = self.record
        amplitude = self.amplitude()

        def needs_views(e) -> bool:
            # a model of the plant steps as the nonlinear loop does: its step is the board's height's
            return self._views_wanted and (e.key not in self.views or self._step_stale(e, amplitude))

        todo = [(e, e.model, needs_views(e)) for e in self.entries if e.key not in self._failed
                and (needs_views(e) or (record is not None and e.key not in self.fits))]
        if not todo:
            return

        def compute(token):
            out = []
            for entry, model, need_views in todo:
                try:
                    views = None
                    if need_views and model.plant is not None and entry.key in self.views:
                        views = dataclasses.replace(self.views[entry.key], step=plant_step(model, amplitude,
                                                                                           cancel=token),
                                                    step_amplitude=amplitude)
                    elif need_views:
                        views = model_views(model, amplitude_m=amplitude)
                    fit = compare_on_record(model, record) if record is not None else None
                    out.append((entry, model, views, fit, ""))
                except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                    out.append((entry, model, None, None, " ".join(str(exc).split())))
            return out

        def show(out, _job):
            for entry, model, views, fit, error in out:
                if entry not in self.entries or entry.model is not model:
                    continue                    # deleted, or rebuilt, while it computed
                if error:
                    self._failed.add(entry.key)
                    self._fail(entry, error)
                    entry.ticked = False
                    continue
                if views is not None and (views.step_amplitude is None or views.step_amplitude == self.amplitude()):
                    self.views[entry.key] = views
                if fit is not None and record is self.record:
                    self.fits[entry.key] = fit
            self.refresh()

        self.views_runner.run("board: model views", compute, show, fail=lambda m: self._fail(None, m))

    def _step_stale(self, entry: BoardEntry, amplitude: float) -> bool:
        views = self.views.get(entry.key)
        return views is not None and views.step_amplitude is not None and views.step_amplitude != amplitude

    def _fail(self, entry: BoardEntry | None, message: str) -> None:
        who = f"{html.escape(entry.name)}: " if entry is not None else ""
        self.note.object = f"<span class='eha-warn'>{who}{html.escape(message)}</span>"

    def delete(self, entry: BoardEntry) -> None:
        if entry.kind == "reference":
            return
        self.entries.remove(entry)
        self.views.pop(entry.key, None)
        self.fits.pop(entry.key, None)
        self._rebuild_list()
        self.refresh()

    def rename(self, entry: BoardEntry, name: str) -> None:
        name = " ".join(str(name).split())[:40]
        if not name:
            return
        entry.name = name
        box = self._ticks.get(entry.key)
        if box is not None:
            box.label = _tick_label(name)
        self.refresh()

    def tick(self, entry: BoardEntry, ticked: bool) -> None:
        entry.ticked = bool(ticked)
        self.refresh()

    def ticked(self) -> list[BoardEntry]:
        return [e for e in self.entries if e.ticked]

    # -- the list ---------------------------------------------------------------------------------
    def _rebuild_list(self) -> None:
        rows = []
        self._ticks = {}
        for e in self.entries:
            # the tick and the name field are named for screen readers; the row shows what they are
            box = pn.widgets.Checkbox(label=_tick_label(e.name), value=e.ticked, width=22, margin=(8, 0, 0, 5),
                                      css_classes=[f"eha-board-tick-{e.key}", "eha-board-tick"],
                                      stylesheets=[LABEL_FOR_SCREEN_READERS])
            self._ticks[e.key] = box
            watch(box, lambda ev, e=e: self.tick(e, ev.new), "value")
            # a line as the model's curves are drawn: its colour and its dash
            swatch = pn.pane.HTML(plots.line_sample(e.color, e.dash), width=24, margin=(12, 0, 0, 2))
            name = pn.widgets.TextInput(label="Model name", value=e.name, width=150, margin=(3, 3),
                                        css_classes=[f"eha-board-name-{e.key}", "eha-board-name"],
                                        stylesheets=[LABEL_FOR_SCREEN_READERS])
            watch(name, lambda ev, e=e: self.rename(e, ev.new), "value")
            parts = [box, swatch, name]
            if e.kind != "reference":
                drop = pn.widgets.Button(label="✕", width=30, margin=(3, 3), description=f"delete {e.name}",
                                         css_classes=[f"eha-board-delete-{e.key}", "eha-board-delete"])
                on_click(drop, lambda _ev, e=e: self.delete(e))
                parts.append(drop)
            desc = pn.pane.HTML(f"<span class='eha-note'>{html.escape(e.model.description)}</span>",
                                width=200, margin=(0, 10, 6, 44), styles={"font-size": "11px"})
            rows.append(pn.Column(pn.Row(*parts, width=280), desc, width=280, margin=0))
        if len(self.entries) <= 2:
            rows.append(pn.pane.HTML("<p class='eha-note'>Estimates land here as you make them: run a "
                                     "transfer-function estimate, one from your own record, the least "
                                     "squares or a grey-box estimate.</p>", width=270))
        self.list.objects = rows

    # -- the validation record and the nonlinear plant -------------------------------------------
    def parsed(self) -> tuple[dict, dict]:
        """The form's values and its messages."""
        return parse_fields(_FIELDS.values(), self.form.values)

    def _settings_changed(self) -> None:
        _, errors = self.parsed()
        self.form.errors = errors
        self.update_record()            # with an invalid field: the record is marked, not recomputed
        if "board_step" not in errors:
            self._compute_missing()     # the steps of the models of the plant, at the new height

    def _plant_changed(self) -> None:
        if not self.session.in_sight(self.key):
            # tab 1 changed while the board is not on show: it is computed again once it is (a student
            # typing on tab 1 recomputes nothing here), and says meanwhile that it is out of date
            keys = self.record_inputs()
            if self.built and (keys is None or not self._current(keys)):
                self.record_view.inputs_changed(self._view_keys(keys), why="" if keys is not None else
                                                "a parameter on tab 1 is not valid")
            self.session.when_in_sight(self.key, self._plant_changed)
            return
        self._references()
        self._controller_changed()
        self._compute_missing()
        self.update_record()

    def _controller_changed(self) -> None:
        """A model of the plant is closed with tab 1's controller: a new Kp makes a new loop of it (its
        curves and fit computed again); a transfer function stays the loop it was estimated in."""
        kp = self.state.kp
        if not self.state.valid:
            return
        changed = False
        for e in self.entries:
            m = e.model
            if m.plant is None or m.kp == kp:
                continue
            try:
                e.model = plant_model(m.plant, kp, name=m.name, description=_with_kp(m.description, kp),
                                      ts=m.ts or 0.01, params=m.params)
            except ValueError as exc:
                self._fail(e, " ".join(str(exc).split()))
                continue
            self.views.pop(e.key, None)
            self.fits.pop(e.key, None)
            changed = True
        if changed:
            self._rebuild_list()        # the descriptions name the new gain

    def record_inputs(self):
        """(record key, plant key) of the current inputs, or None when they are not valid."""
        values, errors = self.parsed()
        if errors or not self.state.valid:
            return None
        params, kp = self.state.params, self.state.kp
        return (params, kp, values["board_seed"]), (params, kp, values["board_step"] * 1e-3)

    def update_record(self) -> None:
        """The validation record with every model's fit on it, and the nonlinear plant's step: two jobs,
        each re-run only when its own inputs change."""
        if not self.built:
            return
        keys = self.record_inputs()
        if keys is None:
            self.record_view.inputs_changed(None, why="a field of the comparison is not valid" if self.state.valid
                                            else "a parameter on tab 1 is not valid")
            return
        record_key, plant_key = keys
        if self._current(keys):
            self._mark_record()
            return
        self.record_view.inputs_changed(self._view_keys(keys), updating=True)
        if record_key != self.record_key:
            self._run_record(record_key)
        if plant_key != self.plant_key and self._plant_wanted:
            self._run_plant(plant_key)

    def _view_keys(self, keys):
        """What the board's results are computed from, as its out-of-date mark compares them: the plant's
        step (its height) only once the step view was opened (None: the inputs are not valid)."""
        return None if keys is None else (keys[0], keys[1] if self._plant_wanted else None)

    def _current(self, keys) -> bool:
        """Are the record (and the plant's step, once the step view was opened) those of ``keys``?"""
        return keys[0] == self.record_key and (not self._plant_wanted or keys[1] == self.plant_key)

    def _mark_record(self) -> None:
        keys = self.record_inputs()
        if keys is not None and self._current(keys):
            self.record_view.shown(self._view_keys(keys))

    def _run_record(self, key) -> None:
        params, kp, seed = key
        models = [(e, e.model) for e in self.entries if e.key not in self._failed]
        noise_x, disturbance = self._measured()

        def compute(token):
            record = validation_record(params, kp=kp, seed=seed, noise_x=noise_x, disturbance=disturbance,
                                       cancel=token)
            fits = {}
            for entry, model in models:
                try:
                    fits[entry.key] = compare_on_record(model, record)
                except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                    continue                    # that model's row says it could not be compared
            return record, fits

        def show(out, _job):
            keys = self.record_inputs()
            if keys is None or keys[0] != key:
                return                          # the inputs changed again: a newer request follows
            self.record, self.fits = out
            self.record_key = key
            self._compute_missing()             # the fits of models whose views came while it computed
            self.refresh()
            self._mark_record()

        def fail(message):
            self.note.object = (f"<span class='eha-warn'>The validation record failed: {html.escape(message)}"
                                "</span>")
            self.record_view.inputs_changed(self._view_keys(self.record_inputs()), why="the validation record failed")

        self.record_runner.run("board: validation record", compute, show, fail=fail)

    def _measured(self) -> tuple[float, str]:
        """The position sensor's σ and the load of an exercise (the student's actuator is only ever seen
        through its sensors), none outside one."""
        ex = self.state.exercise if self.state.hidden else None
        return (ex.conditions.noise_floor("x"), ex.conditions.disturbance) if ex is not None else (0.0, "none")

    def _run_plant(self, key) -> None:
        params, kp, amplitude = key
        noise_x, _ = self._measured()

        def compute(token):
            return nonlinear_step(params, kp, amplitude, noise_x=noise_x, cancel=token)

        def show(plant, _job):
            keys = self.record_inputs()
            if keys is None or keys[1] != key:
                return
            self.plant, self.plant_key = plant, key
            self.refresh()
            self._mark_record()

        def fail(message):
            self.note.object = f"<span class='eha-warn'>The plant's step failed: {html.escape(message)}</span>"

        self.plant_runner.run("board: the plant's step", compute, show, fail=fail)

    # -- drawing ---------------------------------------------------------------------------------
    def build(self) -> None:
        """Build the figures (first shown) and compute what is missing."""
        if self.built:
            return
        self.built = True
        self._rebuild_list()
        self._compute_missing()
        self.update_record()

    def amplitude(self) -> float:
        """The step of r [m] the step view draws."""
        return (self.parsed()[0].get("board_step") or 10.0) * 1e-3

    def shown_view(self) -> str:
        """The key of the view whose tab is open (``fit``, ``bode``, ``step``, ``pz``)."""
        return _VIEWS[self.view_tabs.active][1]

    def show_view(self, key: str):
        """Open the view ``key``'s tab (as a click on it does) and return its figure (None if it has
        nothing to draw yet)."""
        self.view_tabs.active = [k for _, k in _VIEWS].index(key)
        return self.figures.get(key)

    def refresh(self) -> None:
        """Redraw the view in sight from the cached curves of the ticked models (no computation); the
        others are drawn when their tab is opened, and the tables kept current."""
        if not self.built:
            return
        entries = self.ticked()
        amplitude = self.amplitude()
        drawn = [e for e in entries if e.key in self.views]
        # a figure is made with its first data: an empty one makes Bokeh complain it cannot range it
        ready = {"fit": self.record is not None and any(e.key in self.fits for e in entries),
                 "bode": bool(drawn), "step": bool(drawn), "pz": bool(drawn)}
        # a view with nothing to draw shows a line instead of its figure (kept for later): Bokeh
        # cannot range a figure without data, and says so in the browser's console
        shown = self.shown_view()
        for key, cls in (("fit", board_plots.BoardFitFigure), ("bode", board_plots.BoardBodeFigure),
                         ("step", board_plots.BoardStepFigure), ("pz", board_plots.PoleZeroFigure)):
            if key != shown:
                continue
            if not ready[key]:
                self._slots[key].objects = [pn.pane.HTML(
                    "<p class='eha-note'>" + ("Computing…" if entries else "Tick a model to draw it.") + "</p>")]
                continue
            if key not in self.figures:
                self.figures[key] = cls()
                self._panes[key] = pn.pane.Bokeh(self.figures[key].layout, sizing_mode="stretch_width")
            fig = self.figures[key]
            if key == "fit":
                fig.update(self.record, entries, self.fits)
            elif key == "bode":
                fig.update(entries, self.views, bands=self.bands.value)
            elif key == "step":
                fig.update(entries, self.views, self.plant, amplitude)
            else:
                fig.update(entries, self.views)
            if self._slots[key].objects != [self._panes[key]]:
                self._slots[key].objects = [self._panes[key]]
        self.tables["fit"].object = self.fit_table(entries)
        self.tables["step"].object = self.step_table(entries, amplitude)

    def fit_table(self, entries) -> str:
        return fit_table(entries, self.record, self.fits, self.record_key, self.state.kp, self.state.hidden)

    def step_table(self, entries, amplitude: float) -> str:
        return step_table(entries, self.views, self.plant, amplitude)

    # -- the section's protocol -----------------------------------------------------------------
    def result_views(self) -> list:
        return [self.record_view]

    def guide_done(self) -> bool:
        return True             # no run of its own: the routes' runs fill it

    def snapshot(self) -> SectionSnapshot:
        entries = tuple(dataclasses.replace(e) for e in self.ticked())
        noise_x, _ = self._measured()
        content = BoardSnapshot(entries, dict(self.views), dict(self.fits), self.record, self.record_key, self.plant,
                                self.amplitude(), bool(self.bands.value), self.state.kp,
                                self.state.params if self.state.valid else None, noise_x)
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(), content=content)

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        b = snapshot.content
        if b is None or not b.entries:
            return None
        b = b.complete()
        parts = {"board_fit": board_plots.BoardFitFigure(), "board_bode": board_plots.BoardBodeFigure(),
                 "board_step": board_plots.BoardStepFigure(), "board_pz": board_plots.PoleZeroFigure()}
        parts["board_fit"].update(b.record, list(b.entries), b.fits)
        parts["board_bode"].update(list(b.entries), b.views, bands=b.bands)
        parts["board_step"].update(list(b.entries), b.views, b.plant, b.amplitude)
        parts["board_pz"].update(list(b.entries), b.views)
        return ReportPart("Model board (the models ticked)", stale_note(snapshot)
                          + fit_table(b.entries, b.record, b.fits, b.record_key, b.kp, hidden)
                          + "{{board_fit}}{{board_bode}}"
                          + step_table(b.entries, b.views, b.plant, b.amplitude) + "{{board_step}}{{board_pz}}",
                          {k: f.layout for k, f in parts.items()})

    def __panel__(self):
        controls = pn.Column(self.form, self.bands, self.note, self.list, width=290)
        results = pn.Column(self.record_view.banner, self.area, sizing_mode="stretch_width", min_width=440)
        return side_by_side(controls, results)


def _with_kp(description: str, kp: float) -> str:
    """A plant model's description with its loop's new gain (``Kp = … V/m`` replaced)."""
    import re

    text = re.sub(r"Kp = [^ ]+ V/m", f"Kp = {kp:g} V/m", description)
    return text if text != description or "Kp =" in description else f"{description}, Kp = {kp:g} V/m"


@dataclass(frozen=True)
class BoardSnapshot:
    """What the board shows at one moment (its ticked models, copied), for the session report."""

    entries: tuple
    views: dict
    fits: dict
    record: object
    record_key: object
    plant: object
    amplitude: float
    bands: bool
    kp: float
    params: object = None       # tab 1's actuator (None when not valid), for the plant's step
    noise_x: float = 0.0

    def complete(self) -> BoardSnapshot:
        """The snapshot with the views a page computes only when their tab is opened (the Bode diagram,
        the steps, the poles; the nonlinear plant's step): the report draws every view. In the
        report's worker."""
        views, plant = dict(self.views), self.plant
        for e in self.entries:
            if e.key not in views:
                try:
                    views[e.key] = model_views(e.model, amplitude_m=self.amplitude)
                except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                    continue                # its row says it could not be drawn, as on the page
        if plant is None and self.params is not None:
            try:
                plant = nonlinear_step(self.params, self.kp, self.amplitude, noise_x=self.noise_x)
            except (ValueError, ArithmeticError, ComputationError):
                plant = None
        return dataclasses.replace(self, views=views, plant=plant)


def fit_table(entries, record, fits, record_key, kp: float, hidden=()) -> str:
    """The fits of ``entries`` on the validation record, with the residual tests' verdicts; a model
    estimated on another actuator than the record's (tab 1 changed since) is marked and the change named."""
    if record is None:
        return ""
    record_params = record_key[0] if record_key else None
    moved = 0
    rows = []
    for e in entries:
        fit = fits.get(e.key)
        if fit is None:
            continue
        verdicts = ""
        if fit.assessment is not None:
            verdicts = "".join(f"<div>{'✓' if v.passed else '✗'} {html.escape(v.sentence)}</div>"
                               for v in fit.assessment.verdicts)
        made_on = getattr(e.model, "params", None)
        if made_on is not None and record_params is not None and made_on != record_params:
            moved += 1
            change = param_changes(made_on, record_params, hidden=hidden) or "hidden values"
            verdicts = (f"<div class='eha-stale-note eha-board-other-actuator'>Estimated on another actuator "
                        f"({html.escape(change)}): this record is tab 1's "
                        "current one, so its fit compares the model with a plant it was not made from.</div>"
                        + verdicts)
        if e.model.kp is not None and e.model.kp != kp:
            verdicts += (f"<div class='eha-warn'>Built for Kp = {e.model.kp:g} V/m; the record's loop has "
                         f"Kp = {kp:g} V/m (tab 1): a low fit says so, not that the model is "
                         "wrong.</div>")
        fit_text = f"{fit.fit_percent:.2f} %" if np.isfinite(fit.fit_percent) else "—"
        rows.append(f"<tr><td><span style='color:{e.color}'>■</span> {html.escape(e.name)}</td>"
                    f"<td>{fit_text}</td><td style='font-size:12px'>{verdicts}</td></tr>")
    seed = record_key[2] if record_key else ""
    return ("<div style='overflow-x:auto'><table class='eha-table eha-board-fits'><tr><th>model</th>"
            "<th>fit</th><th>residual tests on the "
            "validation record</th></tr>" + "".join(rows) + "</table></div>"
            f"<p class='eha-note'>Validation record: a closed-loop experiment on tab 1's actuator (idinput "
            f"sine, seed {seed}, N = 1000, Ts = 0.01 s). Each transfer function's initial state and input "
            "offset are fitted to it (MATLAB's compare); a grey-box model is the nonlinear model simulated in "
            "the record's loop from its own initial state, without the record's load (it does not know it); "
            "fit = 100 (1 − ‖x − x̂‖ / ‖x − mean x‖).</p>"
            + (f"<p class='eha-stale-note eha-board-moved'>Tab 1's actuator changed after {moved} of these models "
               f"{'was' if moved == 1 else 'were'} estimated: the record follows tab 1, so "
               f"{'its fit is' if moved == 1 else 'their fits are'} against another plant (marked in the table)."
               "</p>" if moved else ""))


def step_table(entries, views, plant, amplitude: float) -> str:
    """The step responses' figures of ``entries`` (and the nonlinear plant's)."""
    rows = []
    items = [(e.name, e.color, views[e.key].step) for e in entries if e.key in views]
    if plant is not None:
        items.append(("nonlinear plant", "#333333", plant))

    def cell(v, fmt="{:.3g}"):
        return fmt.format(v) if v is not None and np.isfinite(v) else "—"

    for name, color, s in items:
        i = s.info
        rows.append(f"<tr><td><span style='color:{color}'>■</span> {html.escape(name)}</td>"
                    f"<td>{cell(i.rise_time_s)}</td><td>{cell(i.overshoot_percent, '{:.2f}')}</td>"
                    f"<td>{cell(i.settling_time_s)}</td><td>{cell(i.steady_state * amplitude * 1e3)}</td>"
                    f"<td>{html.escape('' if s.message == 'ok' else s.message)}</td></tr>")
    return ("<div style='overflow-x:auto'><table class='eha-table eha-board-steps'><tr><th>model</th>"
            "<th>rise time 10-90 % [s]</th>"
            "<th>overshoot [%]</th><th>settling time 2 % [s]</th><th>final x [mm]</th><th></th></tr>"
            + "".join(rows) + "</table></div><p class='eha-note'>Rise, overshoot and settling as python-control's "
            "step_info; a transfer function's figures are taken against its DC gain; the plant's, and "
            "a grey-box model's (the nonlinear loop simulated at this step), against their last sample (60 s).</p>")
