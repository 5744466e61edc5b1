"""Tab 3, study: one experiment repeated over many noise seeds.

The least squares under a chosen disturbance, the transfer-function
estimate or the grey-box estimate (its spread against the Cramér-Rao bound),
run for N seeds (:func:`eha_core.study.run_study`) in the server's child
process for long work, at the lowest priority (the others' clicks go first),
with a progress bar and a cancel button; the page stays live. It shows each
estimate's distribution against the nominal value, the mean, the spread and
how often the 95 % interval covered the truth: one run's 10 % error in B under
white noise (the paper's Table 4) is one draw from a wide distribution.

Not offered in an exercise: every figure is drawn against the true values.
"""

from __future__ import annotations

import dataclasses
import html
from functools import partial

import numpy as np
import panel as pn
from bokeh.models import ColumnDataSource, Span

from eha_core.experiments import FrequencyExperiment

from ..render import plots
from ..render.figure_text import Described
from ..render.formatting import display_unit, num_html
from ..render.layout import side_by_side
from ..render.tables import SYMBOLS_HTML, UNITS
from ..runtime.background import background_process
from ..runtime.tasks import PageProgress, apply_locked, on_click, pages_busy, served_document, watch
from ..session import GuideStep, ReportPart, Section, SectionSnapshot
from ..session.form import Field, Form, Group, parse_fields
from ..session.freshness import ResultView
from ..session.state import FIELD_LABELS

__all__ = ["StudyPanel", "STUDY_FORM", "STUDY_DEFAULTS", "MAX_APP_SEEDS"]

#: Seeds a study in the app runs at most (the command line allows 1000).
MAX_APP_SEEDS = 500
STUDY_FORM = (Group("Study over noise seeds", (
    Field("study_kind", "experiment", "select", options=(("lse", "least squares (eqs. 15-18)"),
                                                         ("tf", "transfer function (eqs. 19-25)"),
                                                         ("greybox", "grey-box (the nonlinear model)")),
          short="experiment"),
    Field("study_seeds", "seeds N", "integer", lo=2, hi=MAX_APP_SEEDS, short="seeds N"),
    Field("study_first", "first seed", "integer", lo=0, hi=10**6, short="first seed"),
    Field("study_white", "white force noise σ", "number", unit="N", lo=0.0, hi=1e5, short="white force noise σ",
          tip="least squares: the load disturbance d(t) is white noise of this σ (Table 4's 'white noise')"),
    Field("study_estimator", "estimator", "select", options=(("ls", "least squares (the paper's)"),
                                                             ("iv", "instrumental variables")),
          short="estimator", tip="which estimator the study repeats: see which one is biased"),
    Field("study_dmodel", "disturbance model", "select", options=(("constant", "constant d0 (the paper's)"),
                                                                   ("harmonic", "d0 + a sinusoid")),
          short="disturbance model"),
    Field("study_model", "model in the loop", "select", options=(("linear", "linearised (H(s) is the truth)"),
                                                                  ("nonlinear", "nonlinear (H(s) a reference)")),
          short="model in the loop"),
    Field("study_noise", "position noise σ", "number", unit="mm", lo=0.0, hi=10.0, short="position noise σ",
          tip="transfer function: white noise added to the recorded x"),
    Field("study_gb_params", "parameters to estimate", "text", short="parameters",
          tip="grey-box: comma-separated, e.g. M, B, Af, βe (the rest held at tab 1's values)"),
    Field("study_gb_measured", "signals measured", "text", short="measured",
          tip="grey-box: comma-separated, of x, v, p1, p2 (x alone works)"),
    Field("study_snr", "signal-to-noise ratio", "number", unit="dB", lo=0.0, hi=80.0, short="SNR",
          tip="grey-box: white noise on each measured signal, its σ the clean signal's spread / 10^(SNR/20); "
              "the paper's u = 6 sin(4πt) and a load 5000 sin(2πt) N the model knows, 5 s at 1 ms"),
)),)
STUDY_DEFAULTS = {"study_kind": "lse", "study_seeds": "100", "study_first": "0", "study_white": "1000",
                  "study_dmodel": "constant", "study_model": "linear", "study_noise": "0.1", "study_estimator": "ls",
                  "study_gb_params": "M, B, Af, βe", "study_gb_measured": "x, p1, p2", "study_snr": "30"}
_FIELDS = {f.name: f for g in STUDY_FORM for f in g.fields}
_ONLY = {"lse": ("study_white", "study_dmodel", "study_estimator"), "tf": ("study_model", "study_noise"),
         "greybox": ("study_gb_params", "study_gb_measured", "study_snr")}
#: At most this many progress updates a second reach the page.
_PROGRESS_HZ = 4.0


def plain_name(name: str) -> str:
    """A parameter as the figures' plain text names it: tab 1's label (βe), else its own name."""
    return FIELD_LABELS.get(name, name)


def study_hidden(texts: dict) -> list[str]:
    kind = texts.get("study_kind", "lse")
    return [f for k, fields in _ONLY.items() if k != kind for f in fields]


#: A histogram without seeds (yet): one bar of height 0, so that BokehJS has finite data to set the
#: figure's ranges from (with none it warns "could not set initial ranges" in the browser's console).
_NO_BARS = {"left": [-1.0], "right": [1.0], "top": [0]}


class StudyFigure(Described):
    """One histogram per parameter: estimates minus the nominal value (in % of it, or in its unit
    when it is zero), the nominal value (dashed) and the mean (solid)."""

    def __init__(self, names: tuple[str, ...], *, width: int = 300):
        self.names = names
        self.sources, self.means, self.figs = {}, {}, []
        for name in names:
            src = ColumnDataSource(data=dict(_NO_BARS))
            # fixed-size figures in a wrapping row: three across on a wide page, one on a narrow one
            fig = plots._figure(width=width, height=210, sizing_mode="fixed", title=plain_name(name),
                                x_axis_label="estimate − nominal [%]", y_axis_label="seeds")
            fig.title.text_font_size = "11px"
            fig.xaxis.ticker.desired_num_ticks = 4
            fig.quad(left="left", right="right", bottom=0, top="top", source=src, fill_color=plots.CASE_COLORS[0],
                     fill_alpha=0.5, line_color="white", name="estimates over the seeds")
            fig.add_layout(Span(location=0.0, dimension="height", line_color="#333333", line_dash="dashed",
                                line_width=2))
            mean = Span(location=0.0, dimension="height", line_color=plots.CASE_COLORS[1], line_width=2)
            fig.add_layout(mean)
            self.sources[name], self.means[name] = src, mean
            self.figs.append(fig)
        plots._lean(*self.figs)
        self.width = width
        self._layout = None

    @property
    def layout(self):
        """The page's wrapping row of the histograms (made on first use: the session report, drawn
        in a worker, uses the Bokeh figures alone and makes no Panel object)."""
        if self._layout is None:
            self._layout = pn.FlexBox(*(pn.pane.Bokeh(f, width=self.width + 10) for f in self.figs),
                                      sizing_mode="stretch_width", css_classes=["eha-study-histograms"])
        return self._layout

    def update(self, result) -> None:
        for name, fig in zip(self.names, self.figs, strict=True):
            values = result.values(name)
            values = values[np.isfinite(values)]
            nominal = result.nominal.get(name, np.nan)
            relative = np.isfinite(nominal) and nominal != 0
            with np.errstate(all="ignore"):
                shown = (values / nominal - 1) * 100 if relative else values
                # an estimate of 1e308 against a nominal value of 1e-3 overflows, and so does the span of
                # values near the largest float: np.histogram would refuse the figure (long random walk)
                shown = shown[np.isfinite(shown)]
                span_ok = shown.size and np.isfinite(float(np.max(shown)) - float(np.min(shown)))
                mean = float(np.mean(shown)) if shown.size else np.nan
                std = float(np.std(shown, ddof=1)) if shown.size > 1 else np.nan
            if span_ok and np.isfinite(mean):
                counts, edges = np.histogram(shown, bins=min(30, max(5, shown.size // 4)))
                self.sources[name].data = {"left": edges[:-1].tolist(), "right": edges[1:].tolist(),
                                           "top": counts.tolist()}
                self.means[name].location = mean
            else:
                self.sources[name].data = dict(_NO_BARS)
            fig.xaxis.axis_label = ("estimate − nominal [%]" if relative
                                    else f"estimate − nominal [{UNITS.get(name, '-')}]")
            cov = result.coverage.get(name, np.nan)
            unit = " %" if relative else f" {UNITS.get(name, '')}".rstrip()
            label = plain_name(name)
            fig.title.text = (f"{label}: mean {mean:+.3g}{unit}, spread {std:.3g}{unit}, covered "
                              f"{cov * 100:.0f} %" if shown.size else label)


class StudyPanel(Section):
    """A study of one session (see the module docstring)."""

    key = "study"
    title = "Study over seeds"
    defaults = STUDY_DEFAULTS
    guide_step = GuideStep(
        "3. Study", "Beyond the paper: repeat an estimation over many seeds to see bias and how honest the intervals "
        "are.", "the study over seeds", "Press <b>Run the study</b>.")
    form_css = "eha-study-form"
    run_buttons = ("Run the study",)
    # No kept work (Section.kept_work): a study is closed in an exercise, the only place work is kept.

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state = self.state
        # a study's parts are background work: they take no worker and no turn of the session's
        self.study_runner = self.runner.sub("study", background=True)
        self.result = None
        self._token = None
        self._busy = False                  # a study is waiting or running: one at a time
        self._parts: list = []              # the results of its jobs so far
        self._stopped = False
        self._study = None                  # (config, parameters) of the study running
        self.figure: StudyFigure | None = None
        texts = self.initial_texts()
        self.form = Form(spec=[g.to_spec() for g in STUDY_FORM], values=texts, url_defaults=STUDY_DEFAULTS,
                         width=270, css_classes=[self.form_css], margin=(5, 10))
        # one parse of the form per change: the run button's state and the results' out-of-date mark
        watch(self.form, lambda _e: self._update_enabled(), "values")
        self.button = pn.widgets.Button(label="Run the study", color="primary", width=260,
                                        css_classes=["eha-run-study"])
        on_click(self.button, lambda _e: self.run())
        self.cancel_button = pn.widgets.Button(label="Cancel", width=260, disabled=True,
                                               css_classes=["eha-cancel-study"])
        on_click(self.cancel_button, lambda _e: self.cancel())
        self.progress = pn.indicators.Progress(value=0, max=100, width=260, visible=False,
                                               css_classes=["eha-study-progress"])
        self.status = pn.pane.HTML("", width=270, css_classes=["eha-study-status"])
        self.summary = pn.pane.HTML(
            "<p>Run one experiment over many noise seeds to see how much a single estimate can be trusted: the "
            "spread of each estimate, and how often its 95 % interval covers the truth.</p>",
            sizing_mode="stretch_width", css_classes=["eha-study-summary"])
        self.plot = pn.Column(sizing_mode="stretch_width", css_classes=["eha-study-plot"])
        # its table and histograms are marked out of date when tab 1 or the form changes, as every result is
        self.results = pn.Column(self.summary, self.plot, sizing_mode="stretch_width", min_width=440)
        self.view = ResultView("study", self.results, run_hint="Run the study again to update.")
        self._run_key = None                # what the study running (or last run) was computed from
        self.exercise_note = pn.pane.HTML(
            "<p class='eha-warn'>Not in an exercise: a study draws every estimate against the true values.</p>",
            visible=bool(state.hidden), width=270)
        state.param.watch(self._update_enabled, ["params", "valid"])
        self._update_enabled()

    def run_key(self, cfg=None):
        """What a study run now would be computed from: tab 1's parameters and the form as typed (None
        while either is not valid); ``cfg``: :meth:`config`'s study, when it was just parsed."""
        cfg = self.config()[0] if cfg is None else cfg
        if cfg is None or not self.state.valid:
            return None
        return (self.state.params, tuple(sorted(self.form.values.items())))

    def result_views(self) -> list:
        return [self.view]

    def config(self):
        """The study the form describes (None if invalid), and a message per invalid field."""
        from eha_core.study import StudyConfig

        texts = self.form.values
        values, errors = parse_fields(_FIELDS.values(), texts, skip=set(study_hidden(texts)))
        if errors:
            return None, errors
        if values["study_kind"] == "greybox":
            return self._greybox_config(values, texts)
        if values["study_kind"] == "lse":
            sigma = values["study_white"]
            cfg = StudyConfig("lse", n_seeds=values["study_seeds"], first_seed=values["study_first"],
                              disturbance=f"white:{sigma:g}" if sigma > 0 else "none",
                              disturbance_model=values["study_dmodel"], estimator=values["study_estimator"])
        else:
            cfg = StudyConfig("tf", n_seeds=values["study_seeds"], first_seed=values["study_first"],
                              experiment=FrequencyExperiment(model=values["study_model"], kp=self.state.kp),
                              noise_m=values["study_noise"] * 1e-3)
        return cfg, {}

    def _greybox_config(self, values: dict, texts: dict):
        from eha_core.identify.greybox_study import GreyBoxStudyConfig
        from eha_core.study import StudyConfig

        from .greybox import listed_params, listed_signals

        names, msg_p = listed_params(texts.get("study_gb_params", ""))
        measured, msg_m = listed_signals(texts.get("study_gb_measured", ""))
        errors = {k: m for k, m in (("study_gb_params", msg_p), ("study_gb_measured", msg_m)) if m}
        if errors:
            return None, errors
        g = GreyBoxStudyConfig(params=names, measured=measured, snr_db=float(values["study_snr"]))
        return StudyConfig("greybox", n_seeds=values["study_seeds"], first_seed=values["study_first"],
                           greybox=g), {}

    def _update_enabled(self, *_events) -> None:
        cfg, errors = self.config()
        self.form.errors = errors
        self.form.hidden = study_hidden(self.form.values)
        self.button.disabled = self._busy or cfg is None or not self.state.valid or bool(self.state.hidden)
        self.view.inputs_changed(self.run_key(cfg) if cfg is not None else None)

    #: Seeds per part (about 0.7 s of one core): two students' studies take turns part by part, and a
    #: part's end is a change of the page (fewer parts, less of the event loop's time for one study).
    CHUNK_SEEDS = {"lse": 50, "tf": 10, "greybox": 8}

    def run(self):
        """Run the study in short jobs on the server's pool; the page shows the progress and the
        result (a cancel keeps the seeds done)."""
        cfg, _ = self.config()
        if self._busy or cfg is None or not self.state.valid or self.state.hidden:
            return None
        from eha_core.study import estimated_parameters

        self._parts, self._stopped = [], False
        self._study = (cfg, self.state.params)
        self._run_key = self.run_key()
        self._running(True)
        self._show_progress(0, cfg.n_seeds)
        # the histograms are made now, in turn with the other pages' big changes, and only filled in
        # later: made at the study's end, they held every student's next answer for 0.1-0.3 s (the
        # others' frequency experiment 0.11 -> 0.31 s at the median when a study ended in that step)
        apply_locked(partial(self._figure_for, estimated_parameters(cfg)))
        # the table of an earlier study would stand beside the histograms of this one's first seeds
        self.summary.object = ("<p class='eha-note'>The study runs: the histograms show the seeds done so far; "
                               "the table comes when it ends.</p>")
        return self._run_part(cfg, self.state.params, cfg.first_seed)

    def _figure_for(self, names: tuple[str, ...]) -> StudyFigure:
        if self.figure is None or self.figure.names != names:
            self.figure = StudyFigure(names)
            self.plot.objects = [self.figure.layout]
        return self.figure

    def _run_part(self, cfg, params, first: int):
        from eha_core.study import combine_studies, run_study

        total, done_before = cfg.n_seeds, first - cfg.first_seed
        part = dataclasses.replace(cfg, first_seed=first,
                                   n_seeds=min(self.CHUNK_SEEDS[cfg.kind], total - done_before))
        doc = served_document()
        queue = self.study_runner.queue

        def class_at_work() -> bool:
            # the child waits (mid-seed, at its next check) while a student's run computes or a page
            # change is made: at the idle priority it still took the cores' caches and a share of
            # their time from the event loop (the others' least squares 1.26x, Compare both 1.75x at
            # p95 with a study running beside, 4 classes of 30 pooled)
            return queue.requests_pending() or pages_busy()

        # the seeds done, from the worker: a few updates a second reach the page
        shown = PageProgress(lambda done: self._show_progress(done_before + done, total), hz=_PROGRESS_HZ, doc=doc)

        def progress(done, _part_total):
            shown(done)

        def compute(token):
            self._token = token         # the cancel button's way to the running part
            # in the server's child process for long work, at the lowest priority: the other
            # students' clicks never wait for a seed in flight (eha_app.runtime.background)
            return background_process().call(run_study, part, params, workers=1, progress=progress,
                                             total=part.n_seeds, cancel=token,
                                             give_way=class_at_work if doc is not None else None)

        def show(result, job):
            shown.close()
            self._parts.append(result)
            done = done_before + result.n_completed
            if done < total and not self._stopped and not result.cancelled:
                self._show_progress(done, total)
                # the histograms of the seeds so far: a small change of data per part
                self._figure_for(tuple(result.parameters)).update(combine_studies(cfg, self._parts, params))
                self._run_part(cfg, params, first + result.n_completed)
                return
            self.result = combine_studies(cfg, self._parts, params, cancelled=done < total)
            self._draw(self.result, job)
            self._running(False)

        def fail(message):
            shown.close()
            self.status.object = f"<span class='eha-warn'>The study failed: {html.escape(message)}</span>"
            if not self._parts:
                self._show_earlier("The study failed before its first seeds were done.")
            else:
                self.result = combine_studies(cfg, self._parts, params, cancelled=True)
                self._figure_for(tuple(self.result.parameters)).update(self.result)
                self.summary.object = study_summary_html(self.result)
            self._running(False)

        return self.study_runner.run("study", compute, show, fail=fail, note=self._note, cancelled=self._cancelled)

    def cancel(self) -> None:
        """Stop the study: a running one returns the seeds done, a waiting one never starts."""
        self._stopped = True
        if self._token is not None:
            self._token.cancel("the study was cancelled")
        self.study_runner.cancel("the study was cancelled")

    def _note(self, text: str) -> None:
        if text:
            self.status.object = f"<span class='eha-note'>{html.escape(text)}</span>"

    def _cancelled(self, job) -> None:
        """A part cancelled before it ran: keep what was done."""
        if self._parts:
            from eha_core.study import combine_studies

            cfg, params = self._study
            self.result = combine_studies(cfg, self._parts, params, cancelled=True)
            self._draw(self.result, None)
        else:
            self._show_earlier("The study was cancelled before its first seeds were done.")
        self._running(False)

    def _show_earlier(self, why: str) -> None:
        """A study that ended without a seed: the page shows the earlier study again, if any."""
        earlier = self.result
        if earlier is not None:
            self._figure_for(tuple(earlier.parameters)).update(earlier)
            self.summary.object = study_summary_html(earlier)
        else:
            self.summary.object = f"<p class='eha-note'>{html.escape(why)}</p>"

    def _running(self, on: bool) -> None:
        self._busy = on
        self._update_enabled()          # the study's own rule: also tab 1 valid, no hidden values
        self.cancel_button.disabled = not on
        self.progress.visible = on

    def _show_progress(self, done: int, total: int) -> None:
        self.progress.max = total
        self.progress.value = done
        self.status.object = f"<span class='eha-note'>{done} of {total} seeds…</span>"

    def _draw(self, result, job) -> None:
        self._figure_for(tuple(result.parameters)).update(result)
        if self._run_key is not None:
            self.view.shown(self._run_key)
            self._update_enabled()          # tab 1 or the form may have changed while it ran

        self.summary.object = study_summary_html(result)
        done = (f"{result.n_completed} of {result.n_requested} seeds" + (" (cancelled)" if result.cancelled else "")
                + f" in {result.elapsed_s:.1f} s")
        self.status.object = f"<span class='eha-ok'>{done}.</span>"

    # -- the section's protocol ---------------------------------------------------------------
    def snapshot(self) -> SectionSnapshot:
        return SectionSnapshot(self.key, self.title, self.settings(), content=self.result)

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        result = snapshot.content
        if result is None:
            return None
        from bokeh.layouts import gridplot

        figure = StudyFigure(tuple(result.parameters))
        figure.update(result)
        return ReportPart("Study over seeds", study_summary_html(result) + "{{study}}",
                          {"study": gridplot(figure.figs, ncols=3)})

    def __panel__(self):
        controls = pn.Column(self.exercise_note, self.form, self.button, self.cancel_button, self.progress,
                             self.status, width=290)
        return side_by_side(controls, pn.Column(self.view.banner, self.results, sizing_mode="stretch_width",
                                                min_width=440))


def _n(v: float, digits: int = 4) -> str:
    return num_html(float(v), digits) if np.isfinite(v) else "—"


def study_summary_html(result) -> str:
    """The study's table: per parameter the nominal value, mean, spread, mean reported standard error
    and how often the 95 % interval covered the truth, against the binomial range of an honest one."""
    from eha_core.study import coverage_band

    names = tuple(result.parameters)
    lo, hi = result.coverage_band()
    bounded = bool(result.bound)
    rows = []
    for n in names:
        nom = result.nominal.get(n, np.nan)
        cov = result.coverage.get(n, np.nan)
        # the band of the seeds this parameter's coverage was counted over
        n_used = result.values(n).size
        p_lo, p_hi = coverage_band(max(n_used, 1))
        honest = p_lo <= cov <= p_hi
        # the bias against its own (Monte Carlo) standard error, the core's test at 99 %: beyond it the
        # estimator is biased, not unlucky
        bias, err = result.bias.get(n, np.nan), result.bias_std_error.get(n, np.nan)
        t = bias / err if np.isfinite(err) and err > 0 else np.nan
        if np.isfinite(t):
            verdict = (f"<span class='eha-warn'>{t:+.1f} biased</span>" if result.biased(n)
                       else f"<span class='eha-ok'>{t:+.1f}</span>")
        else:
            verdict = "—"
        # in the unit tab 1 writes it in (βe in GPa), as everywhere on the page
        unit, scale = display_unit(n, UNITS.get(n, ""))
        crb = ""
        if bounded:
            b = result.bound.get(n, np.nan)
            ratio = result.std[n] / b if np.isfinite(b) and b > 0 else np.nan
            crb = f"<td>{_n(b / scale, 3)}</td><td>{_n(ratio, 3)}</td>"
        rows.append(f"<tr><td>{SYMBOLS_HTML.get(n, html.escape(n))}{f' [{unit}]' if unit else ''}</td>"
                    f"<td>{_n(nom / scale)}</td><td>{_n(result.mean[n] / scale)}</td><td>{_n(bias / scale)}</td>"
                    f"<td>{verdict}</td><td>{_n(result.std[n] / scale, 3)}</td>"
                    f"<td>{_n(result.mean_std_error[n] / scale, 3)}</td>{crb}"
                    f"<td>{cov * 100:.1f} % {'✓' if honest else '✗'}</td></tr>")
    done = (f"{result.n_completed} of {result.n_requested} seeds" + (" (cancelled)" if result.cancelled else "")
            + f" in {result.elapsed_s:.1f} s")
    swatches = (plots._swatch("estimates over the seeds", plots.CASE_COLORS[0], width=8)
                + plots._swatch("nominal", "#333333", "dashed", width=2)
                + plots._swatch("mean", plots.CASE_COLORS[1], width=2))
    out = (f"<p>Nominal values: {html.escape(result.reference)}.</p>"
           "<div class='eha-table-scroll'><table class='eha-table eha-study-table'>"
           "<tr><th>parameter</th><th>nominal</th><th>mean</th>"
           "<th>bias (mean − nominal)</th><th>bias / its std error</th>"
           "<th>spread (std)</th><th>mean reported std error</th>"
           + ("<th>Cramér-Rao bound</th><th>spread / bound</th>" if bounded else "")
           + "<th>95 % interval covered the truth</th></tr>"
           + "".join(rows) + "</table></div>"
           f"<p class='eha-note'>{done}. An honest 95 % interval covers the truth in {lo * 100:.1f}-"
           f"{hi * 100:.1f} % of {result.n_successful} seeds (binomial, 99 %): ✓ inside that range, ✗ outside. "
           "Where the spread is larger than the reported standard error, a single run's interval is too "
           "narrow. The bias is measured against its own standard error (spread / √seeds): beyond ±2.58 (99 %) "
           "the estimator is biased, not unlucky."
           + (" The Cramér-Rao bound is the smallest spread an unbiased estimate can have on this experiment "
              "(from the Fisher information at the truth): a spread / bound near 1 wastes nothing of the data."
              if bounded else "") + "</p>"
           f"<p class='eha-note eha-study-legend'>Histograms: {swatches}</p>")
    if result.message and result.message != "ok":
        out += f"<p class='eha-note'>{html.escape(result.message)}</p>"
    return out
