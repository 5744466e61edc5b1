"""Tab 2: open-loop simulation of the nonlinear and linearised models (Figs. 2-7, 16)."""

from __future__ import annotations

import io
import math

import panel as pn
import param
from bokeh.layouts import column as bokeh_column
from bokeh.models import Div

from eha_core.experiments import PAPER_CASES
from eha_core.signals import ZERO, Chirp, Sine, Square, Step, WhiteNoise
from eha_core.simulate import runs_to_pandas, simulate_many

from ..plots import TimeSeriesGrid
from ..state import AppState
from ..tasks import run_task

__all__ = ["SimulationTab", "SimulationRequest", "build_inputs"]

INPUT_KINDS = ("sine", "step", "square", "chirp")
DISTURBANCE_KINDS = ("none", "sine", "white noise")
MODEL_CHOICES = {"nonlinear": ("nonlinear",), "linear": ("linear",), "both": ("nonlinear", "linear")}
MAX_T_END = 60.0


class SimulationRequest(param.Parameterized):
    """What to simulate: a paper case, all four, or a custom input and disturbance."""

    preset = param.Selector(default="custom", objects=["custom", 1, 2, 3, 4, "all"])
    u_kind = param.Selector(default="sine", objects=list(INPUT_KINDS), label="input u(t)")
    u_amplitude = param.Number(default=6.0, bounds=(0.0, 10.0), step=0.1, label="amplitude [V]")
    u_freq = param.Number(default=2.0, bounds=(0.05, 20.0), step=0.05, label="frequency [Hz]")
    u_freq_end = param.Number(default=10.0, bounds=(0.05, 40.0), step=0.05, label="chirp end frequency [Hz]")
    u_t0 = param.Number(default=0.5, bounds=(0.0, MAX_T_END), step=0.1, label="step time [s]")
    d_kind = param.Selector(default="sine", objects=list(DISTURBANCE_KINDS), label="disturbance d(t)")
    d_amplitude = param.Number(default=5000.0, bounds=(0.0, 50000.0), step=100.0, label="amplitude [N]")
    d_freq = param.Number(default=1.0, bounds=(0.05, 20.0), step=0.05, label="frequency [Hz]")
    d_sigma = param.Number(default=1000.0, bounds=(0.0, 20000.0), step=100.0, label="σ [N]")
    d_seed = param.Integer(default=0, bounds=(0, 10**6), label="noise seed")
    t_end_text = param.String(default="5", label="horizon [s]")


def parse_t_end(text: str, dt: float = 1e-3) -> float:
    """The horizon typed by the user; ValueError with a message when not allowed."""
    try:
        value = float((text or "").strip().replace(",", "."))
    except ValueError:
        raise ValueError(f"horizon = {text!r} is not allowed: enter a number of seconds in (0, {MAX_T_END:g}]") from None
    if not math.isfinite(value) or value <= 0 or value > MAX_T_END:
        raise ValueError(f"horizon = {text.strip()} is not allowed: must lie in (0, {MAX_T_END:g}] s")
    n = round(value / dt)
    if abs(n * dt - value) > 1e-9:
        raise ValueError(f"horizon = {text.strip()} is not allowed: use a whole number of milliseconds")
    return n * dt


def build_inputs(req: SimulationRequest):
    """(labels, us, ds, t_end) for a request: one run per case, or the custom one."""
    if req.preset == "all":
        cases = [PAPER_CASES[k] for k in (1, 2, 3, 4)]
        return [c.label for c in cases], [c.u for c in cases], [c.d for c in cases], 5.0
    t_end = parse_t_end(req.t_end_text)
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
        d = WhiteNoise(req.d_sigma, seed=req.d_seed, hold_s=1e-3)
    label = f"Case {req.preset}" if req.preset in (1, 2, 3, 4) else f"u = {u.label}, d = {d.label}"
    return [label], [u], [d], t_end


def results_csv(results) -> str:
    """All runs in one table: run, model, t, x, v, p1, p2, u, d (SI units)."""
    return runs_to_pandas(results).to_csv(index=False, float_format="%.10g")


class SimulationTab(pn.viewable.Viewer):
    """Step 2 of the paper: define u(t) and d(t), run the models, compare (Fig. 16)."""

    def __init__(self, state: AppState, **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.request = SimulationRequest()
        self.results: list = []
        self.last_model = "nonlinear"
        self.last_elapsed_s = float("nan")
        self.run_count = 0
        self.grid = TimeSeriesGrid()
        # the status line is a Bokeh Div in the grid's layout, changed after the data
        # in the same locked callback: the browser never shows a status ahead of its plots
        self.info = Div(text="Choose a case or an input, then run a model.", sizing_mode="stretch_width",
                        css_classes=["eha-sim-info"])
        self.plot_pane = pn.pane.Bokeh(bokeh_column(self.info, self.grid.layout, sizing_mode="stretch_width"),
                                       sizing_mode="stretch_width", min_height=580)
        # the loading indicator goes on a Panel layout: setting it on the Bokeh pane
        # would touch the raw Bokeh model outside the document lock
        self.plot_area = pn.Column(self.plot_pane, sizing_mode="stretch_width", css_classes=["eha-sim-plots"])
        self.notice = pn.pane.HTML("", visible=False, sizing_mode="stretch_width")
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width")
        self.t_end_error = pn.pane.HTML("", visible=False, styles={"color": "#b00020", "font-size": "12px"},
                                        css_classes=["eha-error", "eha-error-t_end"])

        self.preset_buttons = []
        for k in (1, 2, 3, 4):
            b = pn.widgets.Button(label=f"Case {k}", width=68, margin=(2, 2), description=PAPER_CASES[k].title)
            b.on_click(self._preset_handler(k))
            self.preset_buttons.append(b)
        b = pn.widgets.Button(label="All four cases", width=140, margin=(2, 2),
                              description="the four cases of Figs. 2 and 3, overlaid")
        b.on_click(self._preset_handler("all"))
        self.preset_buttons.append(b)

        self.run_buttons = {
            "nonlinear": pn.widgets.Button(label="Run nonlinear", color="primary", width=130, css_classes=["eha-run-nonlinear"]),
            "linear": pn.widgets.Button(label="Run linearised", color="primary", width=130, css_classes=["eha-run-linear"]),
            "both": pn.widgets.Button(label="Compare both", color="success", width=130, css_classes=["eha-run-both"]),
        }
        for model, button in self.run_buttons.items():
            button.on_click(self._run_handler(model))
        self.download = pn.widgets.FileDownload(callback=self._csv, filename="eha_simulation.csv",
                                                color="default", label="Download CSV", disabled=True, width=270)
        self.t_end_input = pn.widgets.TextInput.from_param(self.request.param.t_end_text, width=120)
        self.t_end_input.param.watch(lambda e: setattr(self.request, "t_end_text", e.new), "value_input")
        self.request.param.watch(self._on_request_change, [p for p in self.request.param if p not in ("name", "preset")])
        self.request.param.watch(self._update_enabled, "t_end_text")
        state.param.watch(self._update_enabled, "valid")
        self._update_enabled()
        # open on the paper's Fig. 2 (four cases, nonlinear) rather than on empty axes
        self.request.preset = "all"
        first = self.compute("nonlinear")
        self._draw(first, float("nan"))
        self._show(first, float("nan"))

    # -- events ------------------------------------------------------------------
    def _preset_handler(self, preset):
        async def handler(_event):
            self._apply_preset(preset)
            await self.run(self.last_model)
        return handler

    def _run_handler(self, model):
        async def handler(_event):
            await self.run(model)
        return handler

    def _apply_preset(self, preset) -> None:
        """Show a paper case in the input widgets (or mark 'all four')."""
        with param.parameterized.discard_events(self.request):
            if preset in (1, 2, 3, 4):
                c = PAPER_CASES[preset]
                self.request.param.update(u_kind="sine", u_amplitude=c.u.amplitude, u_freq=c.u.freq_hz,
                                          d_kind="sine" if c.d != ZERO else "none", t_end_text="5")
                if c.d != ZERO:
                    self.request.param.update(d_amplitude=c.d.amplitude, d_freq=c.d.freq_hz)
            else:
                self.request.t_end_text = "5"
        self.request.preset = preset
        self.t_end_input.value = self.request.t_end_text
        self._update_enabled()

    def _on_request_change(self, *_events) -> None:
        # editing an input leaves the preset
        if self.request.preset != "custom":
            self.request.preset = "custom"

    def _update_enabled(self, *_events) -> None:
        message = ""
        if self.request.preset != "all":
            try:
                parse_t_end(self.request.t_end_text)
            except ValueError as exc:
                message = str(exc)
        self.t_end_error.object = message
        self.t_end_error.visible = bool(message)
        ok = self.state.valid and not message
        for b in list(self.run_buttons.values()) + self.preset_buttons:
            b.disabled = not ok
        self.notice.object = ('<span class="eha-warn">A parameter on the first tab is not valid: '
                              'fix it to run the models.</span>')
        self.notice.visible = not self.state.valid

    # -- running -------------------------------------------------------------------
    def compute(self, model: str):
        """The runs for the current request (also used without a browser)."""
        labels, us, ds, t_end = build_inputs(self.request)
        params = self.state.params
        results = []
        for m in MODEL_CHOICES[model]:
            results += simulate_many(params, us, ds, t_end=t_end, dt=1e-3, model=m, labels=labels)
        return results

    async def run(self, model: str) -> None:
        if not self.state.valid:
            return
        self.last_model = model
        self.alert.visible = False

        def fail(message):
            self.alert.object = f"The simulation failed: {message}"
            self.alert.visible = True

        await run_task(lambda: self.compute(model), self._show, fail, busy=[self.plot_area],
                       apply_bokeh=self._draw)

    def _draw(self, results, elapsed: float) -> None:
        """Bokeh side of showing a run: the plots' data, then the status line."""
        self.run_count += 1
        self.grid.update(results)
        what = ", ".join(dict.fromkeys(r.label for r in results))
        models = " and ".join(dict.fromkeys(r.model for r in results))
        timing = "" if math.isnan(elapsed) else f", computed in {elapsed * 1e3:.0f} ms"
        self.info.text = (f"<b>{what}</b> — {models} model, {results[0].t[-1]:g} s{timing}. "
                          f"<span class='eha-run-count' style='color:#999'>run {self.run_count}</span>")

    def _show(self, results, elapsed: float) -> None:
        """Panel side of showing a run: results for the download, failures."""
        self.results = results
        self.last_elapsed_s = elapsed
        failed = [r for r in results if not r.success]
        if failed:
            self.alert.object = "; ".join(f"{r.label} ({r.model}): {r.message}" for r in failed)
            self.alert.visible = True
        self.download.disabled = False

    def _csv(self):
        return io.BytesIO(results_csv(self.results).encode())

    # -- layout ----------------------------------------------------------------------
    def _input_widgets(self):
        r = self.request
        kind = pn.widgets.Select.from_param(r.param.u_kind, width=250)
        amp = pn.widgets.FloatSlider.from_param(r.param.u_amplitude, width=250)
        freq = pn.widgets.FloatSlider.from_param(r.param.u_freq, width=250)
        freq_end = pn.widgets.FloatSlider.from_param(r.param.u_freq_end, width=250)
        t0 = pn.widgets.FloatSlider.from_param(r.param.u_t0, width=250)
        freq.visible = pn.bind(lambda k: k in ("sine", "square", "chirp"), r.param.u_kind)
        freq_end.visible = pn.bind(lambda k: k == "chirp", r.param.u_kind)
        t0.visible = pn.bind(lambda k: k == "step", r.param.u_kind)
        d_kind = pn.widgets.Select.from_param(r.param.d_kind, width=250)
        d_amp = pn.widgets.FloatSlider.from_param(r.param.d_amplitude, width=250)
        d_freq = pn.widgets.FloatSlider.from_param(r.param.d_freq, width=250)
        d_sigma = pn.widgets.FloatSlider.from_param(r.param.d_sigma, width=250)
        d_seed = pn.widgets.IntInput.from_param(r.param.d_seed, width=120)
        d_amp.visible = pn.bind(lambda k: k == "sine", r.param.d_kind)
        d_freq.visible = pn.bind(lambda k: k == "sine", r.param.d_kind)
        d_sigma.visible = pn.bind(lambda k: k == "white noise", r.param.d_kind)
        d_seed.visible = pn.bind(lambda k: k == "white noise", r.param.d_kind)
        return [kind, amp, freq, freq_end, t0, d_kind, d_amp, d_freq, d_sigma, d_seed]

    def __panel__(self):
        presets = pn.Column("**Paper cases** (one click runs)", pn.FlexBox(*self.preset_buttons), width=280)
        note = pn.pane.HTML("<span class='eha-note'>The plots show the paper's four cases; changing an input "
                            "below makes a custom run.</span>", width=250,
                            visible=self.request.param.preset.rx() == "all")
        custom = pn.Card(note, *self._input_widgets(), pn.Column(self.t_end_input, self.t_end_error),
                         title="Input and disturbance", collapsed=False, width=280)
        runs = pn.Column(*self.run_buttons.values(), self.download, width=280)
        side = pn.Column(presets, runs, custom, width=290)
        main = pn.Column(self.notice, self.alert, self.plot_area, sizing_mode="stretch_width")
        return pn.Row(side, main, sizing_mode="stretch_width")
