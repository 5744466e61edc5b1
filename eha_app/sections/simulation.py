"""Tab 2: open-loop simulation of the nonlinear and linearised models (Figs. 2-7, 16)."""

from __future__ import annotations

import html
import io
import math
from dataclasses import dataclass, replace
from dataclasses import fields as dc_fields
from functools import lru_cache

import panel as pn
from bokeh.models import Div

from eha_core.experiments import PAPER_CASES, run_paper_cases
from eha_core.signals import ZERO, Chirp, Sine, Square, Step, WhiteNoise
from eha_core.simulate import runs_to_pandas, simulate_many, simulation_cost

from ..render.layout import BUTTON_CONTRAST, side_by_side
from ..render.plots import TimeSeriesGrid
from ..runtime.limits import RunCost
from ..runtime.shared import shared_results
from ..runtime.tasks import apply_locked, on_click, watch
from ..session import GuideStep, KeptWork, ReportPart, RestoreStep, Section, SectionSnapshot, stale_note
from ..session.form import (
    Field,
    Form,
    Group,
    InputError,
    parse_fields,
    raised_to_bounds,
    regrouped,
    with_lower_bounds,
)
from ..session.freshness import ResultView

__all__ = ["SimulationTab", "SimulationRequest", "SIMULATION_FORM", "build_inputs", "parse_t_end", "compute_runs"]

MODEL_CHOICES = {"nonlinear": ("nonlinear",), "linear": ("linear",), "both": ("nonlinear", "linear")}
MAX_T_END = 60.0
DT = 1e-3
#: Runs up to this many simulated seconds in all (runs x horizon) are re-run as the
#: student types: the four paper cases with both models (40 s) take about 9 ms, two
#: 20 s runs about 10 ms. Longer ones wait for the Run button; their plots are
#: marked out of date meanwhile.
AUTO_RUN_MAX_SECONDS = 40.0


@dataclass(frozen=True)
class SimulationRequest:
    """What to simulate: a paper case, all four, or a custom input and disturbance."""

    preset: object = "custom"
    u_kind: str = "sine"
    u_amplitude: float = 6.0
    u_freq: float = 2.0
    u_freq_end: float = 10.0
    u_t0: float = 0.5
    d_kind: str = "sine"
    d_amplitude: float = 5000.0
    d_freq: float = 1.0
    d_sigma: float = 1000.0
    d_seed: int = 0
    t_end: float = 5.0
    sensor_x: float = 0.0       # σ of the sensors' white noise: x [mm], v [mm/s], p1 and p2 [MPa]
    sensor_v: float = 0.0
    sensor_p: float = 0.0
    sensor_seed: int = 0

    @property
    def sensor_noise(self) -> tuple[float, float, float]:
        return self.sensor_x, self.sensor_v, self.sensor_p


_U = Field("u_kind", "input u(t)", "select", options=(("sine", "sine"), ("step", "step"), ("square", "square"),
                                                     ("chirp", "chirp")))
_D = Field("d_kind", "disturbance d(t)", "select", options=(("none", "none"), ("sine", "sine"),
                                                            ("white noise", "white noise")))
SIMULATION_FORM = (
    Group("Input and disturbance", (
        _U,
        Field("u_amplitude", "amplitude", "slider", unit="V", lo=0.0, hi=10.0, step=0.1, short="u amplitude",
              tip="valve command amplitude (the valve saturates the flow, not the command)"),
        Field("u_freq", "frequency", "slider", unit="Hz", lo=0.05, hi=20.0, step=0.05, short="u frequency"),
        Field("u_freq_end", "chirp end frequency", "slider", unit="Hz", lo=0.05, hi=40.0, step=0.05,
              short="chirp end frequency"),
        Field("u_t0", "step time", "slider", unit="s", lo=0.0, hi=MAX_T_END, step=0.1, short="step time"),
        _D,
        Field("d_amplitude", "amplitude", "slider", unit="N", lo=0.0, hi=50000.0, step=100.0, short="d amplitude"),
        Field("d_freq", "frequency", "slider", unit="Hz", lo=0.05, hi=20.0, step=0.05, short="d frequency"),
        Field("d_sigma", "σ", "slider", unit="N", lo=0.0, hi=20000.0, step=100.0, short="d σ",
              tip="standard deviation of the white force noise, held over each 1 ms sample"),
        Field("d_seed", "noise seed", "integer", lo=0, hi=10**6, short="noise seed"),
        Field("t_end", "horizon", "number", unit="s", lo=0.0, hi=MAX_T_END, lo_open=True, short="horizon",
              tip="simulated time, a whole number of milliseconds"),
    )),
    Group("Sensor noise (what the sensors would read)", (
        Field("sensor_x", "σ of x", "number", unit="mm", lo=0.0, hi=10.0, short="sensor σ x",
              tip="white Gaussian noise added to the drawn x, as a position sensor would add it"),
        Field("sensor_v", "σ of v", "number", unit="mm/s", lo=0.0, hi=1000.0, short="sensor σ v"),
        Field("sensor_p", "σ of p1, p2", "number", unit="MPa", lo=0.0, hi=10.0, short="sensor σ p"),
        Field("sensor_seed", "sensor noise seed", "integer", lo=0, hi=10**6, short="sensor noise seed"),
    ), collapsible=True, collapsed=True),
)
_FIELDS = {f.name: f for g in SIMULATION_FORM for f in g.fields}
DEFAULT_TEXTS = {name: f.text(getattr(SimulationRequest(), name)) for name, f in _FIELDS.items()}
#: which fields each choice shows
_SHOWN = {"u_freq": ("sine", "square", "chirp"), "u_freq_end": ("chirp",), "u_t0": ("step",),
          "d_amplitude": ("sine",), "d_freq": ("sine",), "d_sigma": ("white noise",), "d_seed": ("white noise",)}


def parse_t_end(text: str, dt: float = DT) -> float:
    """The horizon typed by the user; InputError with a message when not allowed."""
    value = _FIELDS["t_end"].parse(text)
    n = round(value / dt)
    if abs(n * dt - value) > 1e-9:
        raise InputError("t_end", "horizon", str(text).strip(), "use a whole number of milliseconds")
    return n * dt


def hidden_fields(u_kind: str, d_kind: str) -> list[str]:
    kinds = {"u": u_kind, "d": d_kind}
    return [name for name, shown in _SHOWN.items() if kinds[name[0]] not in shown]


#: The sensor-noise fields, the signals whose σ each sets and the display scale (value_SI / scale).
_SENSOR_FIELDS = {"sensor_x": (("x",), 1e-3), "sensor_v": (("v",), 1e-3), "sensor_p": (("p1", "p2"), 1e6)}


def exercise_fields(conditions) -> dict:
    """The form's fields under an exercise's conditions: the sensors' σ at least the exercise's floors
    (every record of the student's actuator that reaches the page is measured, as in the lab)."""
    if conditions is None:
        return dict(_FIELDS)
    lows = {name: max(conditions.noise_floor(sig) for sig in signals) / scale
            for name, (signals, scale) in _SENSOR_FIELDS.items()}
    return with_lower_bounds(_FIELDS, lows, "this exercise's sensor noise")


def parse_request(texts: dict, preset, fields: dict | None = None) -> tuple[SimulationRequest, dict]:
    """The request the form's texts describe, and a message per invalid field (``fields``: as an
    exercise bounds them, see :func:`exercise_fields`).

    Fields hidden by the chosen kinds are not checked: they take no part in the run.
    """
    kinds, _ = parse_fields([_U, _D], texts)
    hidden = set(hidden_fields(kinds.get("u_kind", "sine"), kinds.get("d_kind", "sine")))
    values, errors = parse_fields([f for f in (fields or _FIELDS).values() if f.name != "t_end"], texts, skip=hidden)
    if preset != "all":
        try:
            values["t_end"] = parse_t_end(texts.get("t_end", ""))
        except InputError as exc:
            errors["t_end"] = str(exc)
    known = {f.name for f in dc_fields(SimulationRequest)}
    return replace(SimulationRequest(), preset=preset, **{k: v for k, v in values.items() if k in known}), errors


def build_inputs(req: SimulationRequest):
    """(labels, us, ds, t_end) for a request: one run per case, or the custom one."""
    if req.preset == "all":
        cases = [PAPER_CASES[k] for k in (1, 2, 3, 4)]
        return [c.label for c in cases], [c.u for c in cases], [c.d for c in cases], 5.0
    t_end = req.t_end
    if req.u_kind == "sine":
        u = Sine(req.u_amplitude, req.u_freq)
    elif req.u_kind == "step":
        u = Step(req.u_amplitude, t0=req.u_t0)
    elif req.u_kind == "square":
        u = Square(req.u_amplitude, req.u_freq)
    else:
        u = Chirp(req.u_amplitude, req.u_freq, req.u_freq_end, t1=t_end)
    if req.d_kind == "none":
        d = ZERO
    elif req.d_kind == "sine":
        d = Sine(req.d_amplitude, req.d_freq)
    else:
        d = WhiteNoise(req.d_sigma, seed=req.d_seed, hold_s=DT)
    label = f"Case {req.preset}" if req.preset in (1, 2, 3, 4) else f"u = {u.label}, d = {d.label}"
    return [label], [u], [d], t_end


def compute_runs(params, req: SimulationRequest, model: str, cancel=None, measured=None):
    """The runs for a request (in a worker thread in the app), with the sensors' noise if asked, as the
    ``measured`` signals give them (an exercise's; None: all four)."""
    labels, us, ds, t_end = build_inputs(req)
    results = []
    for m in MODEL_CHOICES[model]:
        results += simulate_many(params, us, ds, t_end=t_end, dt=DT, model=m, labels=labels, cancel=cancel)
    return as_measured(with_sensor_noise(results, req) if any(req.sensor_noise) else results, measured)


def as_measured(results, measured):
    """The runs as an exercise's sensors give them: without a velocity sensor v is dx/dt of the
    measured x (central differences), an unmeasured pressure is not a number (no curve, "nan" in
    the downloads)."""
    import numpy as np

    if measured is None or set(measured) >= {"x", "v", "p1", "p2"}:
        return results
    out = []
    for r in results:
        changes = {} if "v" in measured else {"v": np.gradient(r.x, r.t)}
        changes.update({p: np.full(r.t.size, np.nan) for p in ("p1", "p2") if p not in measured})
        out.append(replace(r, label=f"{r.label} ({', '.join(measured)} measured)", **changes))
    return out


def with_sensor_noise(results, req: SimulationRequest):
    """The runs as noisy sensors would read them: white Gaussian noise on x, v, p1, p2 (σ in the
    form's units), drawn from the sensor seed (each run its own stream); the labels say so."""
    import numpy as np

    sx, sv, sp = req.sensor_x * 1e-3, req.sensor_v * 1e-3, req.sensor_p * 1e6
    out = []
    for k, r in enumerate(results):
        rng = np.random.default_rng([req.sensor_seed, k])
        noisy = {name: getattr(r, name) + sigma * rng.standard_normal(r.t.size)
                 for name, sigma in (("x", sx), ("v", sv), ("p1", sp), ("p2", sp)) if sigma > 0}
        out.append(replace(r, label=f"{r.label} + sensor noise", **noisy))
    return out


@lru_cache(maxsize=8)
def _paper_figure_2(params):
    # what every student sees when first opening the tab: computed once per
    # parameter set and server process (results are never modified; 0.8 MB each)
    return tuple(run_paper_cases(params, "nonlinear"))


_STATE_WORDS = {"x": ("x", "mm", 1e3), "p1": ("p<sub>1</sub>", "MPa", 1e-6), "p2": ("p<sub>2</sub>", "MPa", 1e-6)}
_BOUND_WORDS = {("x", "above"): "the end stop", ("x", "below"): "the end stop",
                ("p1", "below"): "the tank pressure", ("p2", "below"): "the tank pressure",
                ("p1", "above"): "the supply pressure", ("p2", "above"): "the supply pressure"}


def beyond_range_html(results) -> str:
    """A warning for each run that leaves the actuator's physical range (the linearised model can)."""
    lines = []
    for r in results:
        parts = []
        for e in r.beyond_physical_range():
            name, unit, scale = _STATE_WORDS[e.state]
            parts.append(f"{name} reaches {e.extreme * scale:.4g} {unit}, {e.side} {_BOUND_WORDS[(e.state, e.side)]} "
                         f"({e.bound * scale:.4g} {unit})")
        if parts:
            lines.append(f"{r.label} ({r.model}): " + "; ".join(parts))
    if not lines:
        return ""
    return ("<div class='eha-warn eha-beyond-range'>Beyond the physical range — these results mean nothing "
            "physically: " + " · ".join(lines) + ". The linearised model holds only near its operating point "
            "(eq. 10); the real actuator stops at the end stops and its pressures stay between tank and "
            "supply.</div>")


def results_mat(results) -> bytes:
    """All runs as a MATLAB .mat file: t (N x 1) and x, v, p1, p2, u, d (N x runs, SI), with the runs'
    labels and models (cell arrays): ``load eha_simulation.mat; plot(t, x)``."""
    import numpy as np
    import scipy.io

    t = results[0].t
    data = {"t": t[:, None], "labels": np.array([r.label for r in results], dtype=object),
            "models": np.array([r.model for r in results], dtype=object)}
    for name in ("x", "v", "p1", "p2", "u", "d"):
        data[name] = np.column_stack([getattr(r, name) for r in results])
    buf = io.BytesIO()
    scipy.io.savemat(buf, data)
    return buf.getvalue()


def results_csv(results) -> str:
    """All runs in one table: run, model, t[s], x[m], v[m/s], p1[Pa], p2[Pa], u[V], d[N] (SI units, named in
    the header as the uploads read them)."""
    from eha_core.data import signal_units

    df = runs_to_pandas(results)
    units = signal_units(df.columns)
    return df.rename(columns={c: f"{c}[{u}]" for c, u in units.items()}).to_csv(index=False, float_format="%.10g")


class SimulationTab(Section):
    """Step 2 of the paper: define u(t) and d(t), run the models, compare (Fig. 16)."""

    key = "simulation"
    title = "Simulation"
    defaults = DEFAULT_TEXTS
    guide_step = GuideStep(
        "2. Simulation", "Step 2: drive the nonlinear and the linearised model with the paper's four cases (Figs. 2-7) "
        "and compare them.", "2. Simulation", "Press <b>Compare both</b> (after a paper case, if you like).")
    form_css = "eha-sim-form"
    #: its plots' status line, made once the plots are drawn (the form comes before them)
    content_css = "eha-sim-info"
    run_buttons = ("Case 1", "Case 2", "Case 3", "Case 4", "All four cases", "Run nonlinear", "Run linearised",
                   "Compare both")

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state = self.state
        self.preset = "all"
        self.results: list = []
        self._last_job_wait = 0.0
        self.last_model = "nonlinear"
        self.last_elapsed_s = float("nan")
        self.run_count = 0
        self._pending_key = None            # the inputs of the run on its way, if any
        # The plots are built in a second step (their half of the tab's cost), so
        # that a server building thirty tabs serves other messages in between.
        self.grid: TimeSeriesGrid | None = None
        self.info: Div | None = None
        # the loading indicator goes on a Panel layout: setting it on the Bokeh pane
        # would touch the raw Bokeh model outside the document lock
        self.plot_area = pn.Column(pn.pane.HTML("<p class='eha-note'>Drawing the paper's Fig. 2…</p>"),
                                   sizing_mode="stretch_width", css_classes=["eha-sim-plots"], min_height=580)
        self.view = ResultView("simulation", self.plot_area, updating_marker=self._mark_updating,
                               run_hint="Press a Run button: runs this long are not re-run on every change.")
        self.notice = pn.pane.HTML("", visible=False, sizing_mode="stretch_width", css_classes=["eha-sim-notice"])
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-sim-alert"])
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        ex = state.exercise if state.hidden else None
        self.fields = exercise_fields(ex.conditions if ex is not None else None)
        self.measured = ex.conditions.measured if ex is not None else None
        texts = self.initial_texts()
        restored = {k: v for k, v in texts.items() if v != DEFAULT_TEXTS.get(k)}
        texts = raised_to_bounds(texts, self.fields, _SENSOR_FIELDS)
        self.form = Form(spec=[g.to_spec() for g in regrouped(SIMULATION_FORM, self.fields)], values=texts,
                         url_defaults=DEFAULT_TEXTS,
                         width=270, css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, self._typed, "values")

        # with several cases and both models (8 traces), one case at a time is legible: the selector
        # shows when a run has several cases and both models
        self.case_select = pn.widgets.RadioButtonGroup(options=["all"], value="all", visible=False,
                                                       css_classes=["eha-sim-case-select"], margin=(2, 10))
        watch(self.case_select, lambda _e: self._draw(), "value")
        # what the form describes: a paper case, the four cases (whose inputs are not the form's), or its own
        self.form_note = pn.pane.HTML("", width=270, css_classes=["eha-sim-form-note"],
                                      styles={"font-size": "12px", "color": "#444"})
        self.preset_buttons = []
        for k in (1, 2, 3, 4):
            b = pn.widgets.Button(label=f"Case {k}", width=62, margin=(2, 2), description=PAPER_CASES[k].title)
            on_click(b, self._preset_handler(k))
            self.preset_buttons.append(b)
        b = pn.widgets.Button(label="All four cases", width=130, margin=(2, 2),
                              description="the four cases of Figs. 2 and 3, overlaid")
        on_click(b, self._preset_handler("all"))
        self.preset_buttons.append(b)
        self.run_buttons = {
            "nonlinear": pn.widgets.Button(label="Run nonlinear", color="primary", width=130,
                                           css_classes=["eha-run-nonlinear"]),
            "linear": pn.widgets.Button(label="Run linearised", color="primary", width=130,
                                        css_classes=["eha-run-linear"]),
            "both": pn.widgets.Button(label="Compare both", color="success", width=130, css_classes=["eha-run-both"],
                                      stylesheets=[BUTTON_CONTRAST]),
        }
        for model, button in self.run_buttons.items():
            on_click(button, self._run_handler(model))
        self.download = pn.widgets.FileDownload(callback=self._csv, filename="eha_simulation.csv",
                                                color="default", label="Download CSV", disabled=True, width=134)
        self.download_mat = pn.widgets.FileDownload(callback=lambda: io.BytesIO(results_mat(self.results)),
                                                    filename="eha_simulation.mat", color="default",
                                                    label="Download .mat", disabled=True, width=134)
        if restored:
            self.preset = "custom"       # the student had been editing inputs
        state.param.watch(self._update_enabled, "valid")
        state.param.watch(self._inputs_changed, ["params", "valid"])
        self._update_enabled()
        self._describe_form()
        apply_locked(self._build_plots)

    def _build_plots(self) -> None:
        """The four state plots, opening on the paper's Fig. 2 (four cases, nonlinear)."""
        if self.grid is not None:
            return
        self.grid = TimeSeriesGrid()
        # The status line is a Bokeh Div changed after the data in the same locked
        # callback (one message): the browser never shows a status ahead of its plots.
        # It is a root of its own, not in the grid's layout: a new text would make the
        # browser lay the four figures out again (about 50 ms a run, which halved the
        # updates per second of a dragged slider).
        self.info = Div(text="Choose a case or an input, then run a model.", sizing_mode="stretch_width",
                        css_classes=["eha-sim-info"])
        req, _ = self.request()
        runs = list(_paper_figure_2(self.state.params))
        if self.state.hidden and self.preset == "all" and any(req.sensor_noise):
            # an exercise: the student's actuator is seen through its noisy sensors from the first draw
            # (noise-free curves of it would reach the browser's data, and the hidden values with them)
            self._show(as_measured(with_sensor_noise(runs, req), self.measured), None)
            # what it was drawn from, as run_key says it for valid inputs (run_key is None while tab 1 is
            # not: a view shown from None would stay current whatever the inputs)
            self.view.shown((self.state.params, "all", "nonlinear", req.sensor_noise, req.sensor_seed))
        else:
            self._show(runs, None)
            # the paper's Fig. 2 as computed: the four cases, nonlinear, no sensor noise
            self.view.shown((self.state.params, "all", "nonlinear", (0.0, 0.0, 0.0), req.sensor_seed))
        if self.preset == "custom" or (any(req.sensor_noise) and not self.state.hidden) or not self.state.valid:
            # opened from a link (or a reload) with inputs of its own: run those, as typed; or
            # opened while tab 1 is not valid: Fig. 2 of its last valid parameters, marked so
            self._inputs_changed()
        self.plot_area.objects = [pn.pane.Bokeh(self.info, sizing_mode="stretch_width"),
                                  pn.pane.Bokeh(self.grid.layout, sizing_mode="stretch_width", min_height=540)]

    # -- inputs ------------------------------------------------------------------------
    def request(self) -> tuple[SimulationRequest, dict]:
        return parse_request(self.form.values, self.preset, self.fields)

    def set_inputs(self, **texts) -> None:
        """Type into the form (tests, presets): values as text or numbers."""
        self.form.set_values(**texts)

    def run_key(self, model: str, preset=None):
        """What a run of ``model`` with the current inputs is computed from (None if they are not valid)."""
        preset = self.preset if preset is None else preset
        req, errors = parse_request(self.form.values, preset, self.fields)
        if errors or not self.state.valid:
            return None
        if preset == "all":             # the four cases ignore the form's inputs, not the sensors
            return self.state.params, "all", model, req.sensor_noise, req.sensor_seed
        return self.state.params, req, model

    def _typed(self, event) -> None:
        if getattr(self, "_applying_preset", False):
            return                        # the preset's own run follows
        old, new = event.old or {}, event.new or {}
        changed = {k for k in set(old) | set(new) if old.get(k) != new.get(k)}
        if self.preset != "custom" and not all(k.startswith("sensor_") for k in changed):
            self.preset = "custom"        # editing an input leaves the preset (the sensors do not)
            self._describe_form()
        self._update_enabled()
        self._inputs_changed()

    def _inputs_changed(self, *_events) -> None:
        """Re-run what is on screen with the new inputs when that is quick, else mark it out of date."""
        key = self.run_key(self.last_model)
        if key is not None and key == self._pending_key:
            return                          # a run with these inputs is on its way
        if key is None or key == self.view.computed_from:
            why = ("a parameter on tab 1 is not valid" if not self.state.valid else
                   "an input is not valid")
            self.view.inputs_changed(key, why=why)
            return
        req, _ = self.request()
        labels, _, _, t_end = build_inputs(req)
        quick = len(labels) * len(MODEL_CHOICES[self.last_model]) * t_end <= AUTO_RUN_MAX_SECONDS
        if quick and not self.session.in_sight(self.key):
            # not on show (tab 1 is being typed into): marked out of date, and run again once shown
            self.view.inputs_changed(key)
            self.session.when_in_sight(self.key, self._inputs_changed)
            return
        job = self.run(self.last_model, auto=True) if quick else None
        self.view.inputs_changed(key, updating=job is not None)

    def _apply_preset(self, preset) -> None:
        """Show a paper case in the form (or mark 'all four')."""
        self._applying_preset = True
        try:
            if preset in (1, 2, 3, 4):
                c = PAPER_CASES[preset]
                texts = dict(u_kind="sine", u_amplitude=f"{c.u.amplitude:g}", u_freq=f"{c.u.freq_hz:g}",
                             d_kind="sine" if c.d != ZERO else "none", t_end="5")
                if c.d != ZERO:
                    texts.update(d_amplitude=f"{c.d.amplitude:g}", d_freq=f"{c.d.freq_hz:g}")
                self.form.set_values(**texts)
            else:
                self.form.set_values(t_end="5")
            self.preset = preset
        finally:
            self._applying_preset = False
        self._update_enabled()
        self._describe_form()

    def _describe_form(self) -> None:
        """Say which case the form holds (the four cases' inputs are their own, not the form's)."""
        preset = self.preset
        if preset in (1, 2, 3, 4):
            text = f"The form holds the paper's {PAPER_CASES[preset].title}."
        elif preset == "all":
            cases = "; ".join(f"{c.label}: u = {c.u.label}, d = {c.d.label}" for c in PAPER_CASES.values())
            text = (f"All four cases of Figs. 2-7, each with its own input ({cases}): the form's u and d are not "
                    "used for them.")
        else:
            text = "Your own inputs (the form's)."
        text = f"<span class='eha-form-says'>{html.escape(text)}</span>"
        if self.form_note.object != text:
            self.form_note.object = text

    def _update_enabled(self, *_events) -> None:
        req, errors = self.request()
        self.form.errors = errors
        self.form.hidden = hidden_fields(self.form.values.get("u_kind", "sine"), self.form.values.get("d_kind", "sine"))
        ok = self.state.valid and not errors
        for b in list(self.run_buttons.values()) + self.preset_buttons:
            b.disabled = not ok
        if not self.state.valid:
            self.notice.object = ('<span class="eha-warn">A parameter on the first tab is not valid: '
                                  'fix it to run the models.</span>')
        elif errors:
            first = next(iter(errors.values()))
            self.notice.object = f'<span class="eha-warn">Fix the input to run the models: {first}</span>'
        self.notice.visible = not ok

    # -- events ------------------------------------------------------------------------
    def _preset_handler(self, preset):
        def handler(_event):
            self._apply_preset(preset)
            self.run(self.last_model)
        return handler

    def _run_handler(self, model):
        def handler(_event):
            self.run(model)
        return handler

    # -- running -----------------------------------------------------------------------
    def compute(self, model: str, cancel=None):
        """The runs for the current request (also used without a browser)."""
        req, errors = self.request()
        if errors:
            raise ValueError(next(iter(errors.values())))         # the form's message, as rendered
        return compute_runs(self.state.params, req, model, cancel, self.measured)

    def run(self, model: str, *, auto: bool = False):
        """Queue a run of ``model`` ('nonlinear', 'linear' or 'both'); returns the job.

        ``auto``: started by a change of the inputs, not a click: no loading
        indicator or queue note (the view's outline says it is updating).
        """
        req, errors = self.request()
        if not self.state.valid or errors:
            return None
        key = self.run_key(model)
        self.last_model = model
        self.alert.visible = False
        try:
            self.check_cost(model=model)
        except ValueError as exc:
            self.alert.object = str(exc)
            self.alert.visible = True
            return None
        params, measured = self.state.params, self.measured

        def fail(message):
            self._pending_key = None
            self.alert.object = f"The simulation failed: {message}"
            self.alert.visible = True
            self.view.inputs_changed(self.run_key(self.last_model), why="the last run failed")

        def show(results, job):
            self._pending_key = None
            self._show(results, job)
            self.view.shown(key)
            self._inputs_changed_since(key)

        if not auto:
            self.view.inputs_changed(key, updating=True)
        self._pending_key = key
        def compute(token):
            # a function of these alone: students with the same inputs share it
            key = ("simulation", params, req, model, None if measured is None else tuple(measured))
            return shared_results.get(key, lambda tok: compute_runs(params, req, model, tok, measured), token)

        return self.runner.run(f"simulation ({model})", compute, show, fail=fail, busy=[] if auto else [self.plot_area],
                               note=(lambda _text: None) if auto else self._note)

    _UPDATING = "<span class='eha-sim-updating' style='color:#1a56c4'>⟳ updating to the new inputs… </span>"

    def _mark_updating(self, on: bool) -> None:
        """The status line says the plots are being re-run (see ResultView)."""
        if self.info is None:
            return
        text = self.info.text.replace(self._UPDATING, "")
        self.info.text = self._UPDATING + text if on else text

    def _inputs_changed_since(self, key) -> None:
        # inputs typed while the run computed: mark (or re-run) again
        if self.run_key(self.last_model) != key:
            self._inputs_changed()

    def _draw(self) -> None:
        """The grid and the status line for the case chosen (all of them unless the selector shows)."""
        results = self.results
        if self.grid is None or not results:
            return
        chosen = self.case_select.value
        shown = [r for r in results if chosen == "all" or r.label == chosen] or results
        self.grid.update(shown)
        labels = list(dict.fromkeys(r.label for r in results))
        models = " and ".join(dict.fromkeys(r.model for r in results))
        elapsed = self.last_elapsed_s
        timing = "" if math.isnan(elapsed) else f", computed in {elapsed * 1e3:.0f} ms"
        if self._last_job_wait > 0.05:
            timing += f" (of which {self._last_job_wait:.1f} s waiting for the server)"
        what = ", ".join(labels)
        if chosen != "all" and len(labels) > 1:
            what = f"{chosen} of {what} (choose the case above the plots)"
        self.info.text = (f"<b>{what}</b> — {models} model, {results[0].t[-1]:g} s{timing}. "
                          f"<span class='eha-run-count' style='color:#666'>run {self.run_count}</span>"
                          + beyond_range_html(results))

    def _show(self, results, job) -> None:
        """Show a run: the plots' data, then the status line, then the download."""
        if self.grid is None:
            self._build_plots()
        elapsed = float("nan") if job is None else job.elapsed_s
        self.run_count += 1
        self.results = list(results)
        self.last_elapsed_s = elapsed
        self._last_job_wait = 0.0 if job is None else job.wait_s
        labels = list(dict.fromkeys(r.label for r in results))
        models = list(dict.fromkeys(r.model for r in results))
        several = len(labels) > 1 and len(models) > 1
        options = ["all", *labels] if several else ["all"]
        if self.case_select.options != options:
            self.case_select.options = options
        # one case at first; later runs keep the student's choice ("all" included)
        chosen = self.case_select.value
        if several and (not self.case_select.visible or chosen not in options):
            chosen = labels[0]
        elif not several:
            chosen = "all"
        self.case_select.visible = several
        if chosen != self.case_select.value:
            self.case_select.value = chosen         # its watcher draws
        else:
            self._draw()
        failed = [r for r in results if not r.success]
        if failed:
            self.alert.object = "; ".join(f"{r.label} ({r.model}): {r.message}" for r in failed)
            self.alert.visible = True
        self.download.disabled = False
        self.download_mat.disabled = False

    def _csv(self):
        return io.BytesIO(results_csv(self.results).encode())

    # -- the section's protocol -----------------------------------------------------------
    def result_views(self) -> list:
        return [self.view]

    def guide_done(self) -> bool:
        """The step is a comparison: done once both models' run is on the page (the paper's Fig. 2, drawn
        when the tab opens, is the nonlinear model's)."""
        key = self.view.computed_from
        return isinstance(key, tuple) and len(key) > 2 and key[2] == "both"

    def run_cost(self, *, model: str = "both") -> RunCost | None:
        """Open-loop runs: every case of the request, with each model of ``model``."""
        req, errors = self.request()
        if errors:
            return None
        labels, _, _, t_end = build_inputs(req)
        n_runs = len(labels) * len(MODEL_CHOICES[model])
        cost = simulation_cost(t_end, DT, n_runs=n_runs)
        return RunCost("runs × horizon", f"{n_runs} × {t_end:g} s", cost.steps, cost.peak_bytes, n_runs * t_end,
                       "shorten the horizon")

    def kept_work(self) -> KeptWork | None:
        # the paper's Fig. 2 is drawn when the tab opens: only a run of the student's own is kept
        if self.run_count > 1 and self.view.is_current:
            return KeptWork({"views": ["simulation"], "model": self.last_model, "preset": self.preset})
        return None

    @classmethod
    def restore_work(cls, kept: KeptWork, texts) -> list[RestoreStep]:
        run = kept.run or {}
        model, preset = run.get("model"), run.get("preset")
        if model not in MODEL_CHOICES:
            return []

        def simulate(section):
            # the case the form held: the four cases' inputs are their own, not the form's
            section.preset = preset if preset in ("all", "custom", 1, 2, 3, 4) else "custom"
            section._describe_form()
            return section.run(model)
        return [RestoreStep(cls.title, simulate)]

    def snapshot(self) -> SectionSnapshot:
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(),
                               content=tuple(self.results))

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        results = snapshot.content
        if not results:
            return None
        runs = ", ".join(html.escape(f"{r.label} ({r.model})") for r in results)
        return ReportPart("Simulation (tab 2)", stale_note(snapshot) + f"<p>Runs: {runs}.</p>{{{{sim}}}}",
                          {"sim": TimeSeriesGrid(list(results)).layout})

    # -- layout --------------------------------------------------------------------------
    def __panel__(self):
        presets = pn.Column(pn.pane.HTML("<b>Paper cases</b> (one click runs)", margin=(0, 10)),
                            pn.FlexBox(*self.preset_buttons), width=280)
        runs = pn.Column(*self.run_buttons.values(), pn.Row(self.download, self.download_mat), self.queue_note,
                         width=280)
        side = pn.Column(presets, runs, self.form_note, self.form, width=290)
        main = pn.Column(self.notice, self.alert, self.view.banner, self.case_select, self.plot_area,
                         sizing_mode="stretch_width", min_width=440)
        return side_by_side(side, main)
