"""Tab 3: identification, in the time domain (least squares) and the frequency domain."""

from __future__ import annotations

import csv
import html
import io
import json
import math
from dataclasses import dataclass

import numpy as np
import panel as pn

from eha_core.experiments import (
    LSE_INPUT,
    LSE_INPUT_RICH,
    LSE_INPUT_RICH_T_END,
    LSE_SCENARIOS,
    FrequencyExperiment,
    lse_data,
    lse_resimulation,
    run_frequency_identification,
    run_lse_table,
)
from eha_core.identify.disturbance import MAX_FREQ_HZ
from eha_core.identify.lse import identify_lse
from eha_core.params import ParameterError
from eha_core.signals import SignalSpecError, parse_signal

from .. import plots
from ..form import Field, Form, Group, parse_fields
from ..formatting import tf_html
from ..freshness import ResultView
from ..glossary import GLOSSARY, term
from ..layout import side_by_side
from ..limits import check_frequency, check_lse
from ..state import AppState
from ..tables import (
    SCENARIOS,
    backout_html,
    estimate_alert,
    estimation_sentences,
    freq_summary_html,
    lse_table_html,
    table4_html,
)
from ..tasks import SessionRunner, apply_locked, frozen_models

__all__ = ["IdentificationTab", "LseRequest", "LSE_FORM", "FREQ_FORM", "parse_lse", "parse_freq"]

#: The columns the least squares need from a data file (eqs. 15-18).
LSE_COLUMNS = ("t", "x", "v", "p1", "p2", "u")
#: An upload larger than this is refused (a 10 minute record at 1 kHz is about 2 MB of CSV).
MAX_UPLOAD_BYTES = 20e6


_NAMES_HTML = {"M": "M", "B": "B", "Af": "A<sub>f</sub>", "beta_e": "β<sub>e</sub>"}
EXCITATIONS = {"paper": "u = 6 sin(4πt), 5 s (default)",
               "rich": "u = 8 sin(4πt) + 4 sin(10πt), 20 s (narrows B)"}

# -- the least-squares request ---------------------------------------------------------------

LSE_FORM = (Group("Least squares", (
    Field("lse_scenario", "disturbance", "select", options=tuple(SCENARIOS.items()), short="disturbance"),
    Field("lse_custom", "custom d(t)", "text", short="custom d(t)",
          tip="none, sine:AMP[:FREQ_HZ], white:SIGMA, or any signal of the simulation, e.g. sine:500:2+noise:100:1"),
    Field("lse_model", "disturbance model", "select", options=(("constant", "constant d0 (the paper's)"),
                                                               ("harmonic", "d0 + a sinusoid")),
          short="disturbance model"),
    Field("lse_freq", "harmonic frequency", "text", unit="Hz", placeholder="blank: estimate it",
          short="harmonic frequency"),
    Field("lse_seed", "noise seed", "integer", lo=0, hi=10**6, short="noise seed"),
    Field("lse_excitation", "excitation", "select", options=tuple(EXCITATIONS.items()), short="excitation"),
)), Group("Sensor noise (simulated measurements)", (
    Field("lse_noise_x", "σ of x", "number", unit="mm", lo=0.0, hi=10.0, short="σ x",
          tip="white Gaussian noise added to the position sensor, drawn from the noise seed"),
    Field("lse_noise_v", "σ of v", "number", unit="mm/s", lo=0.0, hi=1000.0, short="σ v",
          tip="white Gaussian noise added to the velocity sensor"),
    Field("lse_noise_p", "σ of p1, p2", "number", unit="MPa", lo=0.0, hi=10.0, short="σ p",
          tip="white Gaussian noise added to each pressure sensor"),
), collapsible=True, collapsed=True),)
LSE_DEFAULTS = {"lse_scenario": "none", "lse_custom": "sine:1000:3", "lse_model": "constant", "lse_freq": "",
                "lse_seed": "0", "lse_excitation": "paper", "lse_noise_x": "0", "lse_noise_v": "0",
                "lse_noise_p": "0"}
_LSE_FIELDS = {f.name: f for g in LSE_FORM for f in g.fields}


@dataclass(frozen=True)
class LseRequest:
    """A parsed least-squares request."""

    scenario: str = "none"
    custom: str = "sine:1000:3"
    model: str = "constant"
    frequency_hz: float | None = None
    seed: int = 0
    excitation: str = "paper"
    noise: tuple[float, float, float] = (0.0, 0.0, 0.0)     # σ of x [mm], v [mm/s], p1 and p2 [MPa]

    def measurement_noise(self) -> dict[str, float] | None:
        """The sensors' noise in SI, for :func:`eha_core.experiments.lse_data` (None: noise-free)."""
        sx, sv, sp = self.noise
        if not any(self.noise):
            return None
        return {"x": sx * 1e-3, "v": sv * 1e-3, "p1": sp * 1e6, "p2": sp * 1e6}

    def disturbance(self):
        """d(t): a scenario of Table 4, or the custom text in the signal grammar."""
        spec = self.custom if self.scenario == "custom" else LSE_SCENARIOS[self.scenario]
        return parse_signal(spec, name="custom d(t)", seed=self.seed, hold_s=1e-3)

    def input_signal(self):
        return (LSE_INPUT, 5.0) if self.excitation == "paper" else (LSE_INPUT_RICH, LSE_INPUT_RICH_T_END)


def lse_hidden(texts: dict) -> list[str]:
    hidden = []
    if texts.get("lse_scenario") != "custom":
        hidden.append("lse_custom")
    if texts.get("lse_model") != "harmonic":
        hidden.append("lse_freq")
    return hidden


def parse_lse(texts: dict) -> tuple[LseRequest, dict]:
    """The least-squares request the form describes, and a message per invalid field."""
    hidden = set(lse_hidden(texts))
    values, errors = parse_fields(_LSE_FIELDS.values(), texts, skip=hidden)
    freq = None
    text = str(texts.get("lse_freq", "")).strip()
    if "lse_freq" not in hidden and text:
        try:
            freq = float(text.replace(",", "."))
            if not (math.isfinite(freq) and 0 < freq < MAX_FREQ_HZ):
                raise ValueError
        except ValueError:
            errors["lse_freq"] = (f"harmonic frequency = {text} is not allowed: a number in (0, {MAX_FREQ_HZ:g}) "
                                  f"Hz, or blank to estimate it")
            freq = None
    req = LseRequest(scenario=values.get("lse_scenario", "none"), custom=texts.get("lse_custom", ""),
                     model=values.get("lse_model", "constant"), frequency_hz=freq,
                     seed=values.get("lse_seed", 0), excitation=values.get("lse_excitation", "paper"),
                     noise=tuple(float(values.get(k, 0.0)) for k in ("lse_noise_x", "lse_noise_v", "lse_noise_p")))
    if "lse_custom" not in hidden and not errors.get("lse_custom"):
        try:
            req.disturbance()
        except (ValueError, SignalSpecError) as exc:
            errors["lse_custom"] = " ".join(str(exc).split())
    return req, errors


# -- the frequency-domain request --------------------------------------------------------------

FREQ_FORM = (
    Group("Excitation (idinput)", (
        Field("signal_type", "idinput type", "select",
              options=(("sine", "sine"), ("rgs", "rgs"), ("rbs", "rbs"), ("prbs", "prbs")), short="idinput type",
              tip=GLOSSARY["idinput"]),
        Field("n_samples", "samples N", "integer", lo=20, hi=20000, short="N"),
        Field("freq_seed", "seed", "integer", lo=0, hi=10**6, short="seed"),
        Field("band_lo", "band low", "number", unit="× Nyquist", lo=0.0, hi=1.0, short="band low"),
        Field("band_hi", "band high", "number", unit="× Nyquist", lo=0.0, hi=1.0, short="band high"),
        Field("range_lo", "range min", "number", unit="m", short="range min"),
        Field("range_hi", "range max", "number", unit="m", short="range max"),
        Field("n_sines", "sinusoids", "integer", lo=1, hi=5000, short="sinusoids"),
        Field("n_trials", "trials", "integer", lo=1, hi=500, short="trials"),
        Field("grid_skip", "grid skip", "integer", lo=1, hi=100, short="grid skip"),
        Field("ts", "Ts", "number", unit="s", lo=1e-4, hi=1.0, short="Ts",
              tip="sample time of the controller; its output is held between samples (ZOH: " + GLOSSARY["ZOH"] + ")"),
    )),
    Group("Loop and model", (
        Field("model", "model in the loop", "select", options=(("nonlinear", "nonlinear"), ("linear", "linearised")),
              short="model", tip="the actuator's model the closed loop is simulated with"),
        Field("n_poles", "poles", "integer", lo=1, hi=6, short="poles", tip="poles: " + GLOSSARY["poles"]),
        Field("n_zeros", "zeros", "integer", lo=0, hi=5, short="zeros", tip="zeros: " + GLOSSARY["zeros"]),
        Field("initial_condition", "initial condition", "select", options=(("estimate", "estimate"), ("zero", "zero")),
              short="initial condition", tip=GLOSSARY["initial condition"]),
        Field("input_offset", "input offset", "select", options=(("estimate", "estimate"), ("zero", "zero")),
              short="input offset", tip=GLOSSARY["input offset"]),
    )),
)
_FREQ_FIELDS = {f.name: f for g in FREQ_FORM for f in g.fields}
_CONFIG_NAME = {"signal_type": "signal_type", "n_samples": "n_samples", "freq_seed": "seed", "ts": "ts",
                "model": "model", "n_poles": "n_poles", "n_zeros": "n_zeros",
                "initial_condition": "initial_condition", "input_offset": "input_offset"}
_DEFAULT_CONFIG = FrequencyExperiment()
FREQ_DEFAULTS = {
    "signal_type": _DEFAULT_CONFIG.signal_type, "n_samples": str(_DEFAULT_CONFIG.n_samples),
    "freq_seed": str(_DEFAULT_CONFIG.seed), "band_lo": f"{_DEFAULT_CONFIG.band[0]:g}",
    "band_hi": f"{_DEFAULT_CONFIG.band[1]:g}", "range_lo": f"{_DEFAULT_CONFIG.range[0]:g}",
    "range_hi": f"{_DEFAULT_CONFIG.range[1]:g}", "n_sines": str(_DEFAULT_CONFIG.sinedata[0]),
    "n_trials": str(_DEFAULT_CONFIG.sinedata[1]), "grid_skip": str(_DEFAULT_CONFIG.sinedata[2]),
    "ts": f"{_DEFAULT_CONFIG.ts:g}", "model": _DEFAULT_CONFIG.model,
    "n_poles": str(_DEFAULT_CONFIG.n_poles), "n_zeros": str(_DEFAULT_CONFIG.n_zeros),
    "initial_condition": _DEFAULT_CONFIG.initial_condition, "input_offset": _DEFAULT_CONFIG.input_offset,
}


def freq_hidden(texts: dict) -> list[str]:
    return [] if texts.get("signal_type", "sine") == "sine" else ["n_sines", "n_trials", "grid_skip"]


def _field_of_message(message: str) -> str | None:
    """The form field a core message (``NAME = VALUE is not allowed: ...``) is about."""
    head = message.split(" = ", 1)[0].strip()
    for form_name, config_name in _CONFIG_NAME.items():
        if head == config_name:
            return form_name
    return {"band": "band_lo", "range": "range_lo", "sinedata": "n_sines"}.get(head)


def parse_freq(texts: dict, kp: float = _DEFAULT_CONFIG.kp) -> tuple[FrequencyExperiment | None, dict]:
    """The experiment the form describes (None if invalid), and a message per invalid field ("" for the rest).

    ``kp`` is the controller gain: tab 1's, the one H(s) is shown with everywhere.
    """
    hidden = set(freq_hidden(texts))
    values, errors = parse_fields(_FREQ_FIELDS.values(), texts, skip=hidden)
    if errors:
        return None, errors
    d = _DEFAULT_CONFIG
    try:
        cfg = FrequencyExperiment(
            n_samples=values["n_samples"], ts=values["ts"], signal_type=values["signal_type"],
            band=(values["band_lo"], values["band_hi"]), range=(values["range_lo"], values["range_hi"]),
            sinedata=(values.get("n_sines", d.sinedata[0]), values.get("n_trials", d.sinedata[1]),
                      values.get("grid_skip", d.sinedata[2])),
            seed=values["freq_seed"], kp=kp, model=values["model"], n_poles=values["n_poles"],
            n_zeros=values["n_zeros"], initial_condition=values["initial_condition"],
            input_offset=values["input_offset"])
    except (ValueError, TypeError) as exc:
        message = " ".join(str(exc).split())
        return None, {_field_of_message(message) or "": message}
    return cfg, {}


# -- the tab -------------------------------------------------------------------------------------

class LeastSquaresPanel(pn.viewable.Viewer):
    """Time domain: least squares on eqs. 15-18, one scenario or Table 4."""

    def __init__(self, state: AppState, runner: SessionRunner, query: dict | None = None, **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.runner = runner
        self.result = None
        self.all_results = None
        texts = dict(LSE_DEFAULTS)
        texts.update({k: v for k, v in (query or {}).items() if k in _LSE_FIELDS})
        self.form = Form(spec=[g.to_spec() for g in LSE_FORM], values=texts, url_defaults=LSE_DEFAULTS, width=270,
                         css_classes=["eha-lse-form"], margin=(5, 10))
        self.form.param.watch(self._update_enabled, "values")
        self.table = pn.pane.HTML("<p>Choose a disturbance and run the least squares.</p>",
                                  sizing_mode="stretch_width", css_classes=["eha-lse-table"])
        # the figure is built with the first result: an empty figure is no use to
        # anyone and makes Bokeh complain that it cannot range it
        self.figure: plots.LseFitFigure | None = None
        self.plot = pn.Column(sizing_mode="stretch_width", css_classes=["eha-lse-plot"])
        self.area = pn.Column(self.table, self.plot, sizing_mode="stretch_width")
        self.table4 = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-table4-pane"])
        self.table4_area = pn.Column(self.table4, sizing_mode="stretch_width")
        self.view = ResultView("lse", self.area, run_hint="Press “Run least squares” to update it.")
        self.table4_view = ResultView("table4", self.table4_area,
                                      run_hint="Press “Run all four scenarios” to update it.")
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-lse-alert"])
        self.notice = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-lse-notice"])
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        self.button = pn.widgets.Button(label="Run least squares", color="primary", width=260,
                                        css_classes=["eha-run-lse"])
        self.all_button = pn.widgets.Button(label="Run all four scenarios (Table 4)", color="success", width=260,
                                            css_classes=["eha-run-table4"])
        self.button.on_click(lambda _e: self.run())
        self.all_button.on_click(lambda _e: self.run_all())
        # an exercise: hand in the hidden parameters' estimates (Table 4 would show the truth)
        self.all_button.visible = not state.hidden
        self.handin_button = pn.widgets.Button(label="Hand in these estimates", color="warning", width=260,
                                               css_classes=["eha-handin"], visible=bool(state.hidden), disabled=True,
                                               description="run the least squares first")
        self.handin_button.on_click(lambda _e: self.hand_in())
        self.verdict = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-verdict"])
        # the student's own data (CSV or .mat), instead of the simulated sensors
        self.own_data = None                # MeasuredData of an upload, when one is in use
        self.own_data_key = None
        self.last_data = None               # the data behind the table and the plot (for downloads)
        self._upload = None
        self.upload = pn.widgets.FileInput(accept=".csv,.mat", width=260, css_classes=["eha-lse-upload"],
                                           multiple=False)
        self.upload.param.watch(self._uploaded, "value")
        self.upload_note = pn.pane.HTML(
            "<span class='eha-note'>Or use your own measurements: a CSV or MATLAB .mat file with columns "
            "t, x, v, p1, p2, u (SI, or units in the header such as <code>p1[MPa]</code>).</span>",
            width=270, css_classes=["eha-lse-upload-note"])
        self.mapping = pn.Column(visible=False, width=270, css_classes=["eha-lse-mapping"])
        # the part of the student's record to use (preprocessing: a time range)
        self.window_form = Form(spec=[Group("Part of your record to use", (
            Field("own_from", "from t", "text", unit="s", placeholder="its start", short="from t"),
            Field("own_to", "to t", "text", unit="s", placeholder="its end", short="to t"),
        )).to_spec()], values={"own_from": "", "own_to": ""}, width=270, visible=False,
            css_classes=["eha-lse-window"], margin=(5, 10))
        self.window_form.param.watch(lambda _e: self._update_enabled(), "values")
        self.simulated_button = pn.widgets.Button(label="Back to simulated data", width=260, visible=False,
                                                  css_classes=["eha-lse-simulated"])
        self.simulated_button.on_click(lambda _e: self.use_simulated())
        self.downloads = [
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.data_bytes("csv")), filename="eha_lse_data.csv",
                                    label="Data (CSV)", disabled=True, width=128, css_classes=["eha-dl-data-csv"]),
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.data_bytes("mat")), filename="eha_lse_data.mat",
                                    label="Data (.mat)", disabled=True, width=128, css_classes=["eha-dl-data-mat"]),
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.estimates_bytes("csv")),
                                    filename="eha_lse_estimates.csv", label="Estimates (CSV)", disabled=True,
                                    width=128, css_classes=["eha-dl-est-csv"]),
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.estimates_bytes("json")),
                                    filename="eha_lse_estimates.json", label="Estimates (JSON)", disabled=True,
                                    width=128, css_classes=["eha-dl-est-json"]),
        ]
        state.param.watch(self._update_enabled, "valid")
        state.param.watch(self._inputs_changed, ["params", "valid"])
        self._update_enabled()

    def request(self) -> tuple[LseRequest, dict]:
        return parse_lse(self.form.values)

    def key(self):
        """What a least-squares run with the current inputs is computed from (None if they are not valid)."""
        req, errors = self.request()
        if errors or not self.state.valid or self.window_errors():
            return None
        return self.state.params, req, self.own_data_key, self.window() if self.own_data is not None else None

    def window(self) -> tuple[float | None, float | None]:
        """The time range of the student's record to use (None: its start or end)."""
        out = []
        for name in ("own_from", "own_to"):
            text = str(self.window_form.values.get(name, "")).strip().replace(",", ".")
            out.append(float(text) if text else None)
        return out[0], out[1]

    def window_errors(self) -> dict:
        """Messages of the time-range fields (in seconds, within the record, at least 50 samples)."""
        if self.own_data is None:
            return {}
        t = self.own_data.t
        errors, values = {}, {}
        for name, label in (("own_from", "from t"), ("own_to", "to t")):
            text = str(self.window_form.values.get(name, "")).strip()
            if not text:
                continue
            try:
                v = float(text.replace(",", "."))
                if not math.isfinite(v):
                    raise ValueError
            except ValueError:
                errors[name] = f"{label} = {text} is not allowed: enter a time in s, or leave it blank"
                continue
            if not t[0] <= v <= t[-1]:
                errors[name] = f"{label} = {text} s is not allowed: your record runs from {t[0]:g} to {t[-1]:g} s"
            values[name] = v
        if not errors:
            lo, hi = values.get("own_from", t[0]), values.get("own_to", t[-1])
            n = int(np.count_nonzero((t >= lo) & (t <= hi)))
            if n < 50:
                target = "own_to" if "own_to" in values else "own_from"
                errors[target] = (f"{'to t' if target == 'own_to' else 'from t'} = "
                                  f"{self.window_form.values[target]} s is not allowed: the range [{lo:g}, {hi:g}] s "
                                  f"holds {n} samples; need at least 50")
        return errors

    def windowed(self):
        """The student's record cut to the chosen time range."""
        from eha_core.identify.lse import MeasuredData

        d = self.own_data
        lo, hi = self.window()
        keep = (d.t >= (d.t[0] if lo is None else lo)) & (d.t <= (d.t[-1] if hi is None else hi))
        if keep.all():
            return d
        return MeasuredData(d.t[keep], d.x[keep], d.v[keep], d.p1[keep], d.p2[keep], d.u[keep],
                            source=f"{d.source}, t in [{d.t[keep][0]:g}, {d.t[keep][-1]:g}] s")

    # -- the student's own data ---------------------------------------------------------
    def _uploaded(self, _event) -> None:
        if self.upload.value is None:
            return
        self._upload = (bytes(self.upload.value), self.upload.filename or "upload")
        self.read_upload()

    def read_upload(self, mapping: dict | None = None):
        """Read the uploaded file (in a worker): use it, or ask which columns are which."""
        from eha_core.data import DataError, file_columns, read_data, sample_time
        from eha_core.identify.lse import MeasuredData

        if self._upload is None:
            return None
        data, filename = self._upload
        if len(data) > MAX_UPLOAD_BYTES:
            self._upload_problem(f"your file = {filename!r} is not allowed: it has {len(data) / 1e6:.1f} MB; "
                                 f"at most {MAX_UPLOAD_BYTES / 1e6:g} MB")
            return None

        def compute(_token):
            try:
                cols = read_data(data, LSE_COLUMNS, name="your file", filename=filename, mapping=mapping,
                                 min_rows=50)
            except DataError as exc:
                if exc.what.startswith("no column"):
                    return "map", file_columns(data, filename, name="your file"), str(exc)
                raise
            ts = sample_time(cols["t"], name="your file", path=filename)
            return "ok", MeasuredData(**cols, source=filename), ts

        def show(out, _job):
            if out[0] == "map":
                self._ask_mapping(out[1], out[2])
                return
            _, measured, ts = out
            self.own_data = measured
            self.own_data_key = (filename, len(data), tuple(sorted((mapping or {}).items())))
            self.mapping.visible = False
            self.window_form.visible = True
            self.simulated_button.visible = True
            self.upload_note.object = (f"<span class='eha-ok'>Using your data: {html.escape(filename)}, "
                                       f"{measured.t.size} samples every {ts * 1e3:.4g} ms. "
                                       "Run the least squares on it.</span>")
            self._inputs_changed()

        return self.runner.run("reading your data", compute, show, fail=self._upload_problem, note=self._note)

    def _upload_problem(self, message: str) -> None:
        self.upload_note.object = f"<span class='eha-warn'>{html.escape(message)}</span>"

    def _ask_mapping(self, available: list, message: str) -> None:
        """Which of the file's columns is t, x, v, p1, p2, u?"""
        options = ["(none)", *available]
        selects = {}
        for c in LSE_COLUMNS:
            guess = next((a for a in available if a.split("[")[0].strip().lower() == c), "(none)")
            selects[c] = pn.widgets.Select(label=f"{c} is", options=options, value=guess, width=250,
                                           css_classes=[f"eha-map-{c}"])
        go = pn.widgets.Button(label="Use these columns", color="primary", width=250, css_classes=["eha-map-go"])

        def use(_e):
            chosen = {c: s.value for c, s in selects.items() if s.value != "(none)"}
            self.read_upload(mapping=chosen)

        go.on_click(use)
        self.mapping.objects = [pn.pane.HTML(f"<span class='eha-warn'>{html.escape(message)}</span>"),
                                *selects.values(), go]
        self.mapping.visible = True
        self.mapping_selects = selects
        self.mapping_button = go

    def use_simulated(self) -> None:
        self.own_data, self.own_data_key, self._upload = None, None, None
        self.simulated_button.visible = False
        self.window_form.visible = False
        self.mapping.visible = False
        self.upload_note.object = "<span class='eha-note'>Using the simulated sensors again.</span>"
        self._inputs_changed()

    # -- downloads ---------------------------------------------------------------------
    def data_bytes(self, kind: str) -> bytes:
        """The measurements behind the table and the plot, as CSV or .mat (read back by the upload)."""
        from eha_core.data import write_data

        d = self.last_data
        cols = {"t": d.t, "x": d.x, "v": d.v, "p1": d.p1, "p2": d.p2, "u": d.u}
        return write_data(cols, kind)

    def estimates_bytes(self, kind: str) -> bytes:
        """The estimates with their standard errors and 95 % intervals (no hidden nominal value)."""
        res = self.result
        rows = []
        for k, v in res.estimates.items():
            lo, hi = res.ci95[k]
            nominal = None if k in self.state.hidden else res.nominal.get(k)
            rows.append({"parameter": k, "estimate": float(v), "std_error": float(res.std_errors[k]),
                         "ci95_low": float(lo), "ci95_high": float(hi),
                         "nominal": None if nominal is None else float(nominal)})
        if kind == "json":
            source = self.last_data.source if self.last_data is not None else ""
            return json.dumps({"disturbance_model": res.disturbance_model, "data": source,
                               "estimates": rows}, indent=1).encode()
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        return buf.getvalue().encode()

    def table4_key(self):
        _, errors = self.request()
        return None if "lse_seed" in errors or not self.state.valid else (self.state.params,
                                                                          self.form.values.get("lse_seed"))

    def _inputs_changed(self, *_events) -> None:
        why = "a parameter on tab 1 is not valid" if not self.state.valid else ""
        self.view.inputs_changed(self.key(), why=why)
        self.table4_view.inputs_changed(self.table4_key(), why=why)

    def _update_enabled(self, *_events) -> None:
        _, errors = self.request()
        self.form.errors = errors
        self.form.hidden = lse_hidden(self.form.values)
        window_errors = self.window_errors()
        self.window_form.errors = window_errors
        errors = {**errors, **window_errors}
        ok = self.state.valid
        self.button.disabled = not ok or bool(errors)
        self.all_button.disabled = not ok or "lse_seed" in errors
        if not ok:
            self.notice.object = ('<span class="eha-warn">The buttons are off: a parameter on tab 1 is not valid; '
                                  'fix it to run the identification.</span>')
        elif errors:
            self.notice.object = ('<span class="eha-warn">“Run least squares” is off until this input is fixed: '
                                  f'{next(iter(errors.values()))}</span>')
        self.notice.visible = not ok or bool(errors)
        self._inputs_changed()

    def _fail(self, message: str) -> None:
        self.alert.object = f"The identification failed: {message}"
        self.alert.visible = True

    def _note(self, text: str) -> None:
        self.queue_note.object = text
        self.queue_note.visible = bool(text)

    def run(self):
        req, errors = self.request()
        if errors or not self.state.valid:
            return None
        u, t_end = req.input_signal()
        self.alert.visible = False
        try:
            check_lse(t_end)
        except ValueError as exc:
            self._fail(str(exc))
            return None
        params = self.state.params
        key = self.key()
        scenario = req.scenario if req.excitation == "paper" else None

        own = self.windowed() if self.own_data is not None else None

        def compute(token):
            if own is not None:     # the student's measurements: nothing to simulate
                res = identify_lse(own, params, disturbance_model=req.model, disturbance_freq_hz=req.frequency_hz,
                                   cancel=token)
                return res, plots.lse_view(own, None), (f"Your data ({html.escape(own.source)}, {own.t.size} "
                                                        "samples): the model is not re-simulated (the input is "
                                                        "known only at its samples)."), own
            d = req.disturbance()
            data = lse_data(params, d, u=u, t_end=t_end, seed=req.seed, measurement_noise=req.measurement_noise(),
                            cancel=token)
            res = identify_lse(data, params, disturbance_model=req.model, disturbance_freq_hz=req.frequency_hz,
                               cancel=token)
            try:
                resim = lse_resimulation(res, params, data, u=u, cancel=token)
                resim_error = ""
            except ParameterError as exc:
                resim, resim_error = None, f"No re-simulation: the estimate is not physical ({exc})."
            return res, plots.lse_view(data, resim), resim_error, data

        def show(out, job):
            res, view, resim_error, data = out
            self.result = res
            self.last_data = data
            for d in self.downloads:
                d.disabled = False
            note = (f"<p class='eha-note'>Simulated, identified and re-simulated in {job.run_s * 1e3:.0f} ms"
                    + (f" (and {job.wait_s:.1f} s waiting for the server)" if job.wait_s > 0.05 else "")
                    + f". {resim_error}</p>")
            warn = "" if res.success else f"<div class='eha-warn'>{res.message}</div>"
            self.table.object = warn + lse_table_html(res, scenario if scenario != "custom" else None,
                                                      hidden=self.state.hidden) + note
            self.handin_button.disabled = not self.state.hidden
            if self.figure is None:
                self.figure = plots.LseFitFigure()
                self.figure.update(view)
                self.plot.objects = [pn.pane.Bokeh(self.figure.layout, sizing_mode="stretch_width")]
            else:
                self.figure.update(view)
            self.view.shown(key)
            self._inputs_changed()          # typed while it computed

        return self.runner.run("least squares", compute, show, fail=self._fail, busy=[self.area], note=self._note)

    def run_all(self):
        _, errors = self.request()
        if not self.state.valid or "lse_seed" in errors:
            return None
        self.alert.visible = False
        params = self.state.params
        seed = int(self.form.values.get("lse_seed", "0"))
        key = self.table4_key()

        def compute(token):
            return {m: run_lse_table(params, disturbance_model=m, seed=seed, cancel=token)
                    for m in ("constant", "harmonic")}

        def show(results, job):
            self.all_results = results
            self.table4.object = (f"<h4>Table 4: four scenarios, both disturbance models, beside the paper "
                                  f"({job.run_s * 1e3:.0f} ms)</h4>" + table4_html(results))
            self.table4_view.shown(key)
            self._inputs_changed()

        return self.runner.run("Table 4", compute, show, fail=self._fail, busy=[self.table4_area], note=self._note)

    def hand_in(self):
        """Hand in the last estimates of the exercise's hidden parameters; show the verdicts (never the truth)."""
        s = self.state
        if self.result is None or not s.hidden:
            return None
        estimates = {n: float(self.result.estimates[n]) for n in s.hidden}
        exercise, student, store = s.exercise, s.student, s.handins

        def compute(_token):
            verdicts = exercise.verdicts(student, estimates)
            store.add(student, estimates, verdicts)
            return verdicts, len([h for h in store.all() if h.student == student])

        def show(out, _job):
            verdicts, count = out
            tol = f"±{100 * exercise.tolerance:g} %"
            items = "".join(f"<li>{_NAMES_HTML.get(n, n)} = {estimates[n]:.5g}: "
                            + (f"<span class='eha-ok'>within {tol} ✓</span>" if ok else
                               f"<span class='eha-warn'>not within {tol} ✗</span>") + "</li>"
                            for n, ok in verdicts.items())
            score = sum(verdicts.values())
            self.verdict.object = (f"<div class='eha-verdict-box'><b>Handed in</b> (hand-in {count} of "
                                   f"{html.escape(student)}): {score} of {len(verdicts)} within tolerance."
                                   f"<ul>{items}</ul></div>")
            self.verdict.visible = True

        return self.runner.run("hand-in", compute, show, fail=self._fail, note=self._note)

    def __panel__(self):
        controls = pn.Column(self.form, self.upload_note, self.upload, self.mapping, self.window_form,
                             self.simulated_button,
                             self.notice, self.button, self.all_button, self.handin_button, self.verdict,
                             pn.FlexBox(*self.downloads, width=270, sizing_mode="fixed"), self.queue_note, width=280)
        explain = pn.pane.HTML(
            "<p class='eha-note'>Least squares on eq. 15 filtered by H(s) = 1/(0.01 s + 1) (eqs. 16-18): "
            "y<sub>1</sub> = A<sub>1</sub>p<sub>1</sub> − A<sub>2</sub>p<sub>2</sub> = M dv/dt + B v + "
            "A<sub>f</sub> S(v) + d<sub>0</sub>, and dp<sub>1</sub>/dt = β<sub>e</sub> φ<sub>2</sub>: each "
            f"unknown multiplies a {term('regressor')} formed from the measurements. "
            "D<sub>c</sub>, d<sub>c</sub>, L<sub>0</sub>, K<sub>q</sub> are measured; 1 kHz sensors.</p>",
            sizing_mode="stretch_width")
        results = pn.Column(explain, self.alert, self.view.banner, self.area, self.table4_view.banner,
                            self.table4_area, sizing_mode="stretch_width", min_width=440)
        return side_by_side(controls, results)


_FIGURES = (("Fig. 8 excitation", "excitation", plots.ExcitationFigure),
            ("Fig. 9 closed-loop data", "data", plots.ClosedLoopFigure),
            ("Fig. 11 fit", "fit", plots.FitFigure),
            ("Fig. 12 Bode", "bode", plots.BodeFigure),
            ("Fig. 13 validation", "validation", plots.ValidationFigure),
            ("Residuals", "residuals", plots.ResidualFigure))


class FrequencyPanel(pn.viewable.Viewer):
    """Frequency domain: the closed-loop experiment, tfest, validation, back-out (Figs. 8-13)."""

    def __init__(self, state: AppState, runner: SessionRunner, query: dict | None = None, **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.runner = runner
        # the excitation preview is a job of its own: typing N must not wait behind an experiment
        self.preview_runner = SessionRunner((runner.owner, "preview"), runner._queue)
        self.result = None
        self.view: plots.FrequencyView | None = None
        self.preview = None
        texts = dict(FREQ_DEFAULTS)
        texts.update({k: v for k, v in (query or {}).items() if k in _FREQ_FIELDS})
        self.form = Form(spec=[g.to_spec() for g in FREQ_FORM], values=texts, url_defaults=FREQ_DEFAULTS, width=270,
                         css_classes=["eha-freq-form"], margin=(5, 10))
        self.form.param.watch(self._on_config, "values")
        self.error = pn.pane.HTML("", visible=False, width=260, css_classes=["eha-error", "eha-error-freq"],
                                  styles={"color": "#b00020", "font-size": "12px"})
        self.button = pn.widgets.Button(label="Run experiment and estimate", color="primary", width=260,
                                        css_classes=["eha-run-freq"])
        self.button.on_click(lambda _e: self.run())
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        self.summary = pn.pane.HTML("<p>Configure the excitation (Fig. 8) and run the closed-loop experiment.</p>",
                                    sizing_mode="stretch_width", css_classes=["eha-freq-summary"])
        self.backout = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-backout"])
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-freq-alert"])
        self.unstable = pn.pane.Alert("", alert_type="warning", visible=False, sizing_mode="stretch_width",
                                      css_classes=["eha-freq-unstable"])
        self.downloads = [
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.data_bytes("csv")), filename="eha_closed_loop.csv",
                                    label="Data (CSV)", disabled=True, width=128, css_classes=["eha-dl-freq-csv"]),
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.data_bytes("mat")), filename="eha_closed_loop.mat",
                                    label="Data (.mat)", disabled=True, width=128, css_classes=["eha-dl-freq-mat"]),
            pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.estimate_bytes()),
                                    filename="eha_transfer_function.json", label="Estimate (JSON)", disabled=True,
                                    width=260, css_classes=["eha-dl-freq-json"]),
        ]
        self.area = pn.Column(self.unstable, self.summary, self.backout, sizing_mode="stretch_width")
        self.kp_note = pn.pane.HTML("", width=260, css_classes=["eha-freq-kp"], margin=(0, 10))
        self.config_errors: dict = {}
        self.excitation_errors: dict = {}
        self.figures: dict[str, object] = {}
        self._slots = {key: pn.Column(pn.pane.HTML(
            "<p class='eha-note'>" + ("Computing the excitation…" if key == "excitation" else
                                      "Run the experiment to see this figure.") + "</p>"),
            min_height=260, sizing_mode="stretch_width") for _, key, _ in _FIGURES}
        hint = "Press “Run experiment and estimate” to update it."
        # Fig. 8 follows the settings by itself (a preview); the others come from the experiment
        self.views = {key: ResultView(f"freq-{key}", self._slots[key], run_hint=hint) for _, key, _ in _FIGURES}
        self.views["summary"] = ResultView("freq-summary", self.area, run_hint=hint)
        self.figure_tabs = pn.Tabs(*((title, pn.Column(self.views[key].banner, self._slots[key],
                                                       sizing_mode="stretch_width"))
                                     for title, key, _ in _FIGURES), dynamic=False,
                                   sizing_mode="stretch_width", css_classes=["eha-freq-figures"])
        self._shown = {"excitation"}
        self.figure_tabs.param.watch(self._on_figure_tab, "active")
        self._record_widgets()
        state.param.watch(self._update_enabled, "valid")
        state.param.watch(self._on_config, ["params", "kp", "valid"])
        self._on_config()

    def config(self):
        """The experiment the form and tab 1's Kp describe (None if invalid), and the messages."""
        return parse_freq(self.form.values, self.state.kp)

    def key(self, cfg=None):
        """What the experiment's results are computed from (None if the inputs are not valid)."""
        cfg = cfg if cfg is not None else self.config()[0]
        return None if cfg is None or not self.state.valid else (self.state.params, cfg)

    @staticmethod
    def excitation_key(cfg):
        return None if cfg is None else (cfg.signal_type, cfg.n_samples, cfg.seed, cfg.band, cfg.range,
                                         cfg.sinedata, cfg.ts)

    def _mark(self, cfg, *, preview_queued: bool) -> None:
        """Mark every view of this panel against the current inputs."""
        why = "a parameter on tab 1 is not valid" if not self.state.valid else ""
        key = self.key(cfg)
        for name, view in self.views.items():
            if name == "excitation":
                view.inputs_changed(self.excitation_key(cfg), updating=preview_queued, why=why)
            else:
                view.inputs_changed(key, why=why)

    # A figure is built when it is first shown with data to draw; afterwards
    # only its data change.
    def _on_figure_tab(self, event) -> None:
        key = _FIGURES[event.new][1]
        self._shown.add(key)
        apply_locked(lambda: self._draw(key))

    def _has_data(self, key: str) -> bool:
        return self.preview is not None if key == "excitation" else self.view is not None

    def _draw(self, key: str) -> None:
        if key not in self._shown or not self._has_data(key):
            return
        fig = self.figures.get(key)
        built = fig is None
        if built:
            fig = self.figures[key] = next(c for _, k, c in _FIGURES if k == key)()
        if key == "excitation":
            fig.update(*self.preview)
        elif key == "fit":
            fig.update(self.view, self.result.config.model if self.result is not None else "nonlinear")
        else:
            fig.update(self.view)
        if built:
            self._slots[key].objects = [pn.pane.Bokeh(fig.layout, sizing_mode="stretch_width")]

    def _update_enabled(self, *_events) -> None:
        errors = {**self.config_errors, **self.excitation_errors}
        self.form.errors = {k: v for k, v in errors.items() if k}
        ok = self.state.valid and not errors
        self.button.disabled = not ok
        if not self.state.valid:
            self.error.object = "A parameter on the first tab is not valid: fix it to run the experiment."
        else:
            self.error.object = errors.get("", "") or (f"Fix the input to run: {next(iter(errors.values()))}"
                                                       if errors else "")
        self.error.visible = bool(self.error.object)

    def _on_config(self, *_events) -> None:
        cfg, errors = self.config()
        self.config_errors = errors
        self.form.hidden = freq_hidden(self.form.values)
        self.kp_note.object = (f"<span class='eha-note'>Controller gain K<sub>p</sub> = {self.state.kp:g} V/m, "
                               "set on tab 1 (the same K<sub>p</sub> as tab 1's H(s)).</span>")
        if cfg is None:
            self._mark(None, preview_queued=False)
            self._update_enabled()
            return
        ts = cfg.ts
        exc_key = self.excitation_key(cfg)
        if exc_key == self.views["excitation"].computed_from:
            self._mark(cfg, preview_queued=False)
            self._update_enabled()
            return

        def show(out, _job):
            self.excitation_errors = {}
            self.preview = out
            self._draw("excitation")
            self.views["excitation"].shown(exc_key)
            self._update_enabled()

        def fail(message):
            # idinput checks the band, range and sinusoid settings against N
            self.excitation_errors = {_field_of_message(message) or "": message}
            self._update_enabled()

        self._update_enabled()
        self._mark(cfg, preview_queued=True)
        self.preview_runner.run("excitation preview", lambda token: plots.excitation_view(cfg.excitation(), ts),
                                show, fail=fail)

    def data_bytes(self, kind: str) -> bytes:
        """The closed-loop record the estimate was made from: t, r, x, u (SI), as CSV or .mat."""
        from eha_core.data import write_data

        d = self.result.data
        return write_data({"t": d.t, "r": d.r, "x": d.x, "u": d.u}, kind)

    def estimate_bytes(self) -> bytes:
        """The estimated transfer function with its fit, validation and settings (JSON)."""
        fi = self.result
        out = {"estimate": fi.estimate.to_dict(), "settings": {k: getattr(fi.config, k) for k in (
            "signal_type", "n_samples", "seed", "ts", "kp", "model", "n_poles", "n_zeros", "initial_condition",
            "input_offset")},
            "validation_fit_percent": None if fi.validation is None else float(fi.validation.fit_percent)}
        return json.dumps(out, indent=1, default=float).encode()

    def _fail(self, message: str) -> None:
        self.alert.object = f"The experiment failed: {message}"
        self.alert.visible = True

    def _note(self, text: str) -> None:
        self.queue_note.object = text
        self.queue_note.visible = bool(text)

    def run(self):
        cfg, errors = self.config()
        if cfg is None or not self.state.valid or self.excitation_errors:
            return None
        self.alert.visible = False
        try:
            check_frequency(cfg)
        except ValueError as exc:
            self._fail(str(exc))
            return None
        params = self.state.params
        run_key = (params, cfg)

        hidden = self.state.hidden

        def compute(token):
            fi = run_frequency_identification(params, cfg, cancel=token)
            return fi, plots.frequency_view(fi, hidden)

        def show(out, job):
            fi, view = out
            self.result = fi
            self.view = view
            self.preview = (view.excitation_t, view.excitation_r, view.excitation_title)
            timing = (f"<p class='eha-note'>Experiment, estimation and validation in {job.run_s:.2f} s "
                      f"(estimation alone {fi.timings.get('tfest', float('nan')):.2f} s)"
                      + (f", after {job.wait_s:.1f} s waiting for the server" if job.wait_s > 0.05 else "")
                      + ".</p>")
            self.summary.object = freq_summary_html(fi, hidden) + timing
            self.backout.object = "<h4>Backed-out parameters (eq. 27)</h4>" + backout_html(fi, hidden)
            for d in self.downloads:
                d.disabled = False
            alert = estimate_alert(fi.estimate)
            self.unstable.object = alert
            self.unstable.visible = bool(alert)
            for _, key, _ in _FIGURES:
                self._draw(key)
            for name, view in self.views.items():
                view.shown(self.excitation_key(cfg) if name == "excitation" else run_key)
            self._mark(self.config()[0], preview_queued=False)      # typed while it computed

        return self.runner.run("frequency experiment", compute, show, fail=self._fail, busy=[self.area],
                               note=self._note)

    # -- the student's own record ---------------------------------------------------------
    def _record_widgets(self) -> None:
        self.record = None                  # (t, u, y, filename) of an upload
        self.record_result = None
        self.record_note = pn.pane.HTML(
            "<span class='eha-note'>Or estimate H(s) from your own record: a CSV or .mat file with t, u, y "
            "(or t, r, x), in SI or with units in the header. Its first two thirds estimate, the rest "
            "validates.</span>", width=270, css_classes=["eha-freq-record-note"])
        self.record_upload = pn.widgets.FileInput(accept=".csv,.mat", width=260, css_classes=["eha-freq-upload"])
        self.record_upload.param.watch(self._record_uploaded, "value")
        self.record_detrend = pn.widgets.Select(label="remove from u and y", value="none", width=260,
                                                options={"nothing": "none", "the mean": "mean",
                                                         "a linear trend": "linear"})
        self.record_button = pn.widgets.Button(label="Estimate from your record", disabled=True, width=260,
                                               css_classes=["eha-freq-record-run"])
        self.record_button.on_click(lambda _e: self.run_record())
        self.record_summary = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-freq-record-summary"])
        self.record_bode: plots.BodeFigure | None = None
        self.record_area = pn.Column(self.record_summary, sizing_mode="stretch_width", visible=False)
        self.record_view = ResultView("freq-record", self.record_area,
                                      run_hint="Press “Estimate from your record” to update it.")
        self.record_detrend.param.watch(lambda _e: self.record_view.inputs_changed(self.record_key()), "value")
        self.form.param.watch(lambda _e: self.record_view.inputs_changed(self.record_key()), "values")

    def record_key(self):
        cfg, _ = self.config()
        if self.record is None or cfg is None:
            return None
        return (self.record[3], self.record[0].size, self.record_detrend.value, cfg.n_poles, cfg.n_zeros,
                cfg.initial_condition, cfg.input_offset)

    def _record_uploaded(self, _event) -> None:
        from eha_core.data import DataError, read_data, sample_time

        if self.record_upload.value is None:
            return
        data, filename = bytes(self.record_upload.value), self.record_upload.filename or "upload"

        def compute(_token):
            if len(data) > MAX_UPLOAD_BYTES:
                raise ValueError(f"your file = {filename!r} is not allowed: it has {len(data) / 1e6:.1f} MB; at "
                                 f"most {MAX_UPLOAD_BYTES / 1e6:g} MB")
            try:
                cols = read_data(data, ("t", "u", "y"), name="your file", filename=filename, min_rows=20)
                u, y = cols["u"], cols["y"]
            except DataError as exc:
                if not exc.what.startswith("no column"):
                    raise
                try:
                    cols = read_data(data, ("t", "r", "x"), name="your file", filename=filename, min_rows=20)
                except DataError as second:
                    if not second.what.startswith("no column"):
                        raise
                    have = exc.what.split("the file has ", 1)[-1].split(";")[0]
                    raise DataError("your file", filename, f"it needs columns t, u, y (or t, r, x); the file has "
                                                           f"{have}") from None
                u, y = cols["r"], cols["x"]
            return cols["t"], u, y, filename, sample_time(cols["t"], name="your file", path=filename)

        def show(out, _job):
            t, u, y, name, ts = out
            self.record = (t, u, y, name)
            self.record_button.disabled = False
            self.record_note.object = (f"<span class='eha-ok'>Your record: {html.escape(name)}, {t.size} samples "
                                       f"every {ts * 1e3:.4g} ms.</span>")
            self.record_view.inputs_changed(self.record_key())

        def fail(message):
            self.record_note.object = f"<span class='eha-warn'>{html.escape(message)}</span>"

        self.runner.run("reading your record", compute, show, fail=fail, note=self._note)

    def run_record(self):
        """H(s) from the student's record (a worker), shown with its validation and Bode diagram."""
        from eha_core.identify.record import identify_record

        cfg, _ = self.config()
        if self.record is None or cfg is None:
            return None
        t, u, y, name = self.record
        detrend, key = self.record_detrend.value, self.record_key()

        def compute(token):
            rec = identify_record(t, u, y, n_poles=cfg.n_poles, n_zeros=cfg.n_zeros,
                                  initial_condition=cfg.initial_condition, input_offset=cfg.input_offset,
                                  detrend=detrend, cancel=token)
            return rec, plots.record_view(rec)

        def show(out, _job):
            rec, view = out
            self.record_result = rec
            e = rec.estimate
            alert = estimate_alert(e)
            parts = [f"<h4>Your record: {html.escape(name)}</h4>"]
            if alert:
                parts.append(f"<div class='eha-warn'>{alert}</div>")
            if e.success and np.all(np.isfinite(e.den)):
                parts.append(tf_html("Ĥ(s)", e.num, e.den, f"from the first {rec.n_estimation} samples; "
                                     f"{term('fit', f'fit {e.fit_percent:.2f} %')}"))
                if rec.validation is not None:
                    parts.append(f"<p>Validated on the last {t.size - rec.n_estimation} samples: fit "
                                 f"<b>{rec.validation.fit_percent:.2f} %</b>.</p>")
                parts.append(estimation_sentences(e))
            if detrend != "none":
                parts.append(f"<p class='eha-note'>{'The mean' if detrend == 'mean' else 'A linear trend'} was "
                             "removed from u and y first.</p>")
            self.record_summary.object = "".join(parts)
            if self.record_bode is None:
                self.record_bode = plots.BodeFigure()
                self.record_bode.update(view)
                self.record_area.objects = [self.record_summary,
                                            pn.pane.Bokeh(self.record_bode.layout, sizing_mode="stretch_width")]
            else:
                self.record_bode.update(view)
            self.record_area.visible = True
            self.record_view.shown(key)
            self.record_view.inputs_changed(self.record_key())

        return self.runner.run("estimate from your record", compute, show, fail=self._fail, note=self._note)

    def __panel__(self):
        config = pn.Column(self.kp_note, self.form, self.error, self.button,
                           pn.FlexBox(*self.downloads, width=270, sizing_mode="fixed"), self.record_note,
                           self.record_upload, self.record_detrend, self.record_button, self.queue_note, width=280)
        results = pn.Column(self.alert, self.figure_tabs, self.views["summary"].banner, self.area,
                            self.record_view.banner, self.record_area, sizing_mode="stretch_width", min_width=440)
        return side_by_side(config, results)


class IdentificationTab(pn.viewable.Viewer):
    """Step 3 of the paper: identification (Fig. 17), time and frequency domain.

    The frequency-domain panel is built when first shown.
    """

    def __init__(self, state: AppState, *, runner: SessionRunner | None = None, query: dict | None = None,
                 **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.runner = runner if runner is not None else SessionRunner(state)
        self._query = query
        self.lse = LeastSquaresPanel(state, self.runner, query)
        self.freq: FrequencyPanel | None = None
        self._freq_slot = pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing the frequency domain…</p>"),
                                    sizing_mode="stretch_width")
        self.tabs = pn.Tabs(("Time domain: least squares", self.lse),
                            ("Frequency domain: transfer function", self._freq_slot),
                            dynamic=False, sizing_mode="stretch_width", css_classes=["eha-ident-tabs"])
        self.tabs.param.watch(lambda e: apply_locked(self.frequency_panel) if e.new == 1 else None, "active")

    def frequency_panel(self) -> FrequencyPanel:
        """The frequency-domain panel, built now if never shown."""
        if self.freq is None:
            with frozen_models():
                self.freq = FrequencyPanel(self.state, self.runner, self._query)
                self._freq_slot.objects = [self.freq]
        return self.freq

    def __panel__(self):
        return self.tabs
