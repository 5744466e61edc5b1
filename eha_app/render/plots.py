"""The app's and the report's figures: Bokeh models built once, data replaced in place.

Each figure class builds its Bokeh models when constructed (on the session's
document, under its lock, in the app) and shows new data with ``update()``,
which only replaces the contents of its ColumnDataSources and a few labels.
Nothing here renders HoloViews: building figures in worker threads was what
broke concurrent sessions (the renderer switches Bokeh's process-wide property
validation off while it works, and two overlapping renders could leave it off
for every student), and re-rendering a figure per result cost the event loop
0.1-1 s where replacing its data costs a few milliseconds.

The data a figure draws are computed beforehand, in a worker thread, by
:func:`frequency_view` and :func:`lse_view` from the core's results; the
figures only draw. Display units: mm, mm/s, MPa, kN; the core stays in SI.
Curves are sent as float32 (7 digits are plenty on a screen, and it halves
what each student's browser receives) and decimated to at most
``MAX_POINTS`` points.

Figures and their ranges are marked ``syncable=False``: by default the
browser sends the server each range it computes and each size it lays out
(13 messages after one "Compare both"), which the server never reads but has
to process, for every student, on its one event loop.
"""

from __future__ import annotations

import dataclasses
import html
from dataclasses import dataclass

import numpy as np
from bokeh.layouts import column, gridplot, row
from bokeh.models import (
    BoxAnnotation,
    ColumnDataSource,
    DataRange1d,
    Div,
    GlyphRenderer,
    HoverTool,
    Legend,
    LegendItem,
    MultiLine,
    Range1d,
    Span,
)
from bokeh.plotting import figure

from eha_core.identify.validate import FIT_DEFINITION, fit_conditions

from .figure_text import Described, set_description
from .glossary import term

__all__ = [
    "STATE_PANELS", "CASE_COLORS", "FIGURE_WIDTH", "MAX_POINTS", "decimate", "style_for", "legend_html", "line_sample",
    "TimeSeriesGrid", "ExcitationFigure", "ClosedLoopFigure", "FitFigure", "BodeFigure", "ValidationFigure",
    "ResidualFigure", "LseFitFigure", "FrequencyView", "frequency_view", "LseView", "lse_view",
]

#: (field, axis label, scale from SI to the display unit)
STATE_PANELS = (
    ("x", "x [mm]", 1e3),
    ("v", "v [mm/s]", 1e3),
    ("p1", "p₁ [MPa]", 1e-6),
    ("p2", "p₂ [MPa]", 1e-6),
)
#: Okabe and Ito's colour-blind-safe palette (Bokeh's ``Colorblind``), ordered by contrast on white: the
#: first four, which the figures use most, reach 3:1 (WCAG's contrast for graphics); its yellow, too faint
#: on white, comes last.
CASE_COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442")
_MODEL_DASH = {"nonlinear": "solid", "linear": "dashed", "linear-positive": "dotted", "linear-negative": "dotdash"}
#: The dash of each run when all runs are of one model (then the dash is free to tell the runs apart a
#: second way, beside their colours: for a reader who cannot tell the colours apart, or a grey print).
_RUN_DASH = ("solid", "dashed", "dotted", "dotdash")
#: Points drawn per curve at most: a 5 s run at 1 kHz is shown every 2 ms, plenty
#: for the paper's 2 Hz inputs, and it halves what the browser receives.
MAX_POINTS = 2500
#: Width in pixels of the identification figures: fits the app's main column at 1366 px.
FIGURE_WIDTH = 1000
_TOOLS = "pan,box_zoom,wheel_zoom,reset,save"


def decimate(t: np.ndarray, *ys: np.ndarray, max_points: int = MAX_POINTS):
    """Every k-th sample so that at most ``max_points`` remain (the last one kept)."""
    t = np.asarray(t)
    n = t.size
    if n <= max_points:
        return (t, *ys)
    k = int(np.ceil(n / max_points))
    idx = np.r_[np.arange(0, n, k), n - 1] if (n - 1) % k else np.arange(0, n, k)
    return (t[idx], *(np.asarray(y)[idx] for y in ys))


def _f32(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float32))


def _lean(*figs) -> None:
    """Drop the selection and muting copies of every glyph: no tool here selects or
    mutes, and each copy is one more model for every student's browser."""
    for fig in figs:
        for r in fig.renderers:
            if isinstance(r, GlyphRenderer):
                r.nonselection_glyph = None
                r.muted_glyph = None


def style_for(index: int, model: str, *, dash_per_run: bool = False) -> dict:
    """Run ``index``'s colour and dash: the dash says the model, or with ``dash_per_run`` (all runs of one
    model) the run, as its colour does."""
    dash = _RUN_DASH[index % len(_RUN_DASH)] if dash_per_run else _MODEL_DASH.get(model, "solid")
    return {"color": CASE_COLORS[index % len(CASE_COLORS)], "line_dash": dash}


def _dash_per_run(results) -> bool:
    """Do the dashes tell the runs apart (several runs, one model) rather than the models?"""
    return len({res.model for res in results}) == 1 and len({res.label for res in results}) > 1


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _figure(**kwargs):
    # a figure takes the width of its column (no horizontal scrolling on a narrow
    # screen); ``width`` is its share of a full row (FIGURE_WIDTH), and its minimum the
    # same share of the 480 px the results column has on an 800 px page (two side by side:
    # 200 px each, three: 133)
    width = kwargs.pop("width", None)
    if "sizing_mode" not in kwargs:
        kwargs["sizing_mode"] = "stretch_width"
        if width is not None:
            kwargs["min_width"] = min(280, int(0.4 * width))
    kwargs.setdefault("tools", _TOOLS)
    kwargs.setdefault("active_scroll", None)
    kwargs.setdefault("output_backend", "canvas")
    fig = figure(**kwargs)
    fig.toolbar.logo = None
    # the browser would echo every range it computes and size it lays out
    for model in (fig, fig.x_range, fig.y_range):
        model.syncable = False
    # its text alternative (a screen reader's): written again by each figure class's update (figure_text)
    set_description(fig)
    return fig


def _legend_above(fig, items, ncols: str | int = "auto") -> Legend:
    """A horizontal legend above the plot area: never over the data (``ncols=2``: long labels on two
    rows, so that the legend does not widen a narrow page)."""
    legend = Legend(items=items, orientation="horizontal", location="top_left", click_policy="none",
                    margin=0, padding=2, spacing=14, border_line_alpha=0, background_fill_alpha=0, ncols=ncols)
    fig.add_layout(legend, "above")
    return legend


#: Bokeh's dash patterns (on and off lengths in px), for the HTML legends' samples of a line
_DASH_ARRAY = {"solid": "", "dashed": "6", "dotted": "2 4", "dotdash": "2 4 6 4", "dashdot": "6 4 2 4"}


def line_sample(color: str, dash: str = "solid", width: int = 3) -> str:
    """A short line drawn as the figures draw it (colour, Bokeh's ``dash`` and ``width``), for an HTML
    legend: a CSS border has no dot-dash. Hidden from screen readers: its label says what it is."""
    height = max(width, 6)
    array = _DASH_ARRAY.get(dash, "")
    pattern = f' stroke-dasharray="{array}"' if array else ""
    return (f'<svg width="22" height="{height}" aria-hidden="true" style="vertical-align:middle;margin-right:5px">'
            f'<line x1="0" y1="{height / 2:g}" x2="22" y2="{height / 2:g}" stroke="{color}" stroke-width="{width}"'
            f'{pattern}/></svg>')


def _swatch(label: str, color: str, dash: str = "solid", width: int = 3) -> str:
    return (f'<span style="white-space:nowrap;margin-right:14px">{line_sample(color, dash, width)}'
            f'{_escape(label)}</span>')


def legend_html(results) -> str:
    """A one-line legend: a swatch per run label, and per model (solid = nonlinear, dashed = linearised);
    runs of one model only: each run's swatch with its own dash."""
    keys: dict[str, int] = {}
    for res in results:
        keys.setdefault(res.label, len(keys))
    models = list(dict.fromkeys(res.model for res in results))
    per_run = _dash_per_run(results)
    parts = [_swatch(label or "run", style["color"], style["line_dash"])
             for label, i in keys.items() for style in [style_for(i, models[0], dash_per_run=per_run)]]
    names = {"nonlinear": "nonlinear", "linear": "linearised (switching)",
             "linear-positive": "linearised (u ≥ 0 branch)", "linear-negative": "linearised (u < 0 branch)"}
    if per_run:
        return "".join(parts) + f"<span>{html.escape(names.get(models[0], models[0]))} model</span>"
    parts += [_swatch(names.get(m, m), "#444", _MODEL_DASH.get(m, "solid"), width=2) for m in models]
    return "".join(parts)


# -- open-loop runs (Figs. 2-7) ---------------------------------------------------------

def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and np.array_equal(a, b)
    return a == b


def nice_range(lo: float, hi: float, current: tuple[float, float] | None = None) -> tuple[float, float]:
    """An axis range holding [lo, hi], its ends on round values (multiples of 1, 2 or 5 × 10^k).

    ``current`` is kept while it holds the data and the data fill at least a third of it.

    >>> nice_range(0.3, 9.2)
    (0.0, 10.0)
    >>> nice_range(-3.1, 3.4)
    (-4.0, 4.0)
    >>> nice_range(1.0, 8.0, current=(0.0, 10.0)), nice_range(1.0, 1.5, current=(0.0, 10.0))
    ((0.0, 10.0), (0.9, 1.6))
    """
    if current is not None:
        c_lo, c_hi = current
        if c_lo <= lo and hi <= c_hi and (hi - lo) >= (c_hi - c_lo) / 3:
            return current
    span = hi - lo
    if not np.isfinite(span) or span <= 0:
        mid = lo if np.isfinite(lo) else 0.0
        half = max(abs(mid) * 0.1, 1e-3)
        lo, hi, span = mid - half, mid + half, 2 * half
    lo, hi = lo - 0.02 * span, hi + 0.02 * span        # the curves never touch the frame
    raw = span / 6
    power = 10.0 ** np.floor(np.log10(raw))
    step = next(m * power for m in (1, 2, 5, 10) if m * power >= raw)
    start, end = np.floor(lo / step) * step, np.ceil(hi / step) * step
    return float(np.round(start, 12)) + 0.0, float(np.round(end, 12)) + 0.0


class TimeSeriesGrid(Described):
    """x, v, p1, p2 against t: a 2 x 2 grid of figures with a shared time axis.

    All curves of a panel are one MultiLine glyph reading one ColumnDataSource
    shared by the four panels (columns xs, x, v, p1, p2 hold one array per run;
    color, dash and label one value per run): a page holds 4 renderers instead
    of 32, and an update is one change for the browser to apply.

    The axes' ranges are set here, snapped to round values, and kept while the
    curves stay inside and fill at least a third of them (:func:`nice_range`):
    a new range changes the tick labels, and the browser then lays the four
    figures out again, about 60 ms per update in a browser without a GPU. So a
    slider dragged across its range moves the curves at 14 updates a second
    instead of 7, and the axes do not jump at every step. A user's zoom lasts
    until the curves leave the range or a different set of curves is shown.
    """

    def __init__(self, results=(), *, max_lines: int = 8, height: int = 250):
        self.max_lines = max_lines
        self._signature = None
        self.legend = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px"})
        self.source = ColumnDataSource(data=self._columns([]))
        self.x_range = Range1d(0.0, 1.0, syncable=False)
        self.figures = []
        self.renderers = []
        for field, ylabel, _ in STATE_PANELS:
            fig = _figure(height=height, sizing_mode="stretch_width", x_range=self.x_range,
                          y_range=Range1d(-1.0, 1.0, syncable=False),
                          x_axis_label="t [s]", y_axis_label=ylabel)
            fig.add_tools(HoverTool(tooltips=[("run", "@label"), ("t", "$x{0.000} s"), (ylabel, "$y{0.000}")]))
            # built by hand: figure.multi_line would add selection and muting copies
            # of the glyph that nothing here uses, and that every page would carry
            r = GlyphRenderer(data_source=self.source, name=field, nonselection_glyph=None, muted_glyph=None,
                              glyph=MultiLine(xs="xs", ys=field, line_width=1.6, line_color="color",
                                              line_dash="dash"))
            fig.renderers.append(r)
            self.figures.append(fig)
            self.renderers.append(r)
        # the physical bounds (end stops; tank and supply pressures), drawn only when a
        # run passes them: the linearised model can, and its results there mean nothing
        self.bounds = {}
        for fig, (field, _, _) in zip(self.figures, STATE_PANELS, strict=True):
            for side in ("below", "above"):
                span = Span(location=0.0, dimension="width", line_color="#b00020", line_dash="dashed",
                            line_width=1.5, visible=False)
                fig.add_layout(span)
                self.bounds[(field, side)] = span
        self.grid = gridplot([self.figures[:2], self.figures[2:]], sizing_mode="stretch_width", merge_tools=True,
                             toolbar_location="right")
        self.layout = column(self.legend, self.grid, sizing_mode="stretch_width")
        if len(results):
            self.update(results)

    def _columns(self, results) -> dict:
        keys: dict[str, int] = {}
        for res in results:
            keys.setdefault(res.label, len(keys))
        cols = {"xs": [], "color": [], "dash": [], "label": []}
        for field, _, _ in STATE_PANELS:
            cols[field] = []
        per_run = _dash_per_run(results)
        for res in results:
            t, *states = decimate(res.t, *(getattr(res, f) for f, _, _ in STATE_PANELS))
            cols["xs"].append(_f32(t))
            for (field, _, scale), y in zip(STATE_PANELS, states, strict=True):
                cols[field].append(_f32(y * scale))
            style = style_for(keys[res.label], res.model, dash_per_run=per_run)
            cols["color"].append(style["color"])
            cols["dash"].append(style["line_dash"])
            cols["label"].append(f"{res.label or 'run'} ({res.model})")
        return cols

    @property
    def line_count(self) -> int:
        return len(self.source.data["xs"])

    def update(self, results) -> None:
        """Show ``results`` (at most ``max_lines``): colour per label, dash per model."""
        results = list(results)[: self.max_lines]
        signature = tuple((r.label, r.model, float(r.t[-1])) for r in results)
        fresh = signature != self._signature       # a different set of curves: new ranges
        self._signature = signature
        columns = self._columns(results)
        if results:
            t_end = max(float(r.t[-1]) for r in results)
            if fresh or (self.x_range.start, self.x_range.end) != (0.0, t_end):
                self.x_range.update(start=0.0, end=t_end)
        for fig, (field, _, _) in zip(self.figures, STATE_PANELS, strict=True):
            values = [a for a in columns[field] if a.size]
            lo = min((float(np.nanmin(a)) for a in values if np.isfinite(a).any()), default=-1.0)
            hi = max((float(np.nanmax(a)) for a in values if np.isfinite(a).any()), default=1.0)
            now = (fig.y_range.start, fig.y_range.end)
            new = nice_range(lo, hi, None if fresh else now)
            if new != now:
                fig.y_range.update(start=new[0], end=new[1])
        if fresh:
            self.source.data = columns
        else:   # the same curves: send only the columns that changed (the times, colours and labels did not)
            old = self.source.data
            changed = {k: v for k, v in columns.items()
                       if len(v) != len(old[k]) or any(not _same(a, b) for a, b in zip(v, old[k], strict=True))}
            if changed:
                self.source.data.update(changed)
        legend = legend_html(results)
        if legend != self.legend.text:      # a new text re-lays out the grid in the browser
            self.legend.text = legend
        passed = {}
        for r in results:
            for e in r.beyond_physical_range():
                passed[(e.state, e.side)] = e.bound
        scales = {field: scale for field, _, scale in STATE_PANELS}
        for (field, side), span in self.bounds.items():
            bound = passed.get((field, side))
            if bound is not None:
                span.location = bound * scales[field]
            span.visible = bound is not None


# -- frequency-domain identification (Figs. 8-13) ----------------------------------------

@dataclass(frozen=True)
class FrequencyView:
    """Everything the frequency-domain figures draw, in display units (computed in a worker)."""

    excitation_t: np.ndarray
    excitation_r: np.ndarray
    excitation_title: str
    t: np.ndarray
    r: np.ndarray
    x_mm: np.ndarray
    u: np.ndarray
    fit_ok: bool
    y_hat_mm: np.ndarray | None = None
    y_theory_mm: np.ndarray | None = None
    fit_label: str = ""
    theory_label: str = ""
    fit_title: str = ""                       # how the fits were computed (the note under Fig. 11)
    w: np.ndarray | None = None
    est_db: np.ndarray | None = None
    est_deg: np.ndarray | None = None
    theory_db: np.ndarray | None = None
    theory_deg: np.ndarray | None = None
    data_w: np.ndarray | None = None
    data_db: np.ndarray | None = None
    data_deg: np.ndarray | None = None
    data_lower_db: np.ndarray | None = None       # the spectral estimate's 95 % band (None for an ETFE)
    data_upper_db: np.ndarray | None = None
    data_label: str = ""
    data_description: str = ""
    validation_t: np.ndarray | None = None
    validation_x_mm: np.ndarray | None = None
    validation_y_mm: np.ndarray | None = None
    validation_label: str = ""
    validation_title: str = ""
    lags: np.ndarray | None = None
    autocorrelation: np.ndarray | None = None
    cross_lags: np.ndarray | None = None
    cross_correlation: np.ndarray | None = None
    band: float = float("nan")
    whiteness_title: str = ""
    independence_title: str = ""
    residual_sentences: tuple[str, ...] = ()      # one verdict per test, from the core's assessment


def _band_edge(edge, magnitude_db, side: int):
    """A band edge drawable on a dB axis: where the band reaches zero magnitude (−inf dB)
    the edge is drawn 40 dB below the estimate, the axis's useful depth."""
    if edge is None:
        return None
    edge = np.array(edge, dtype=float)
    bad = ~np.isfinite(edge)
    edge[bad] = np.asarray(magnitude_db, dtype=float)[bad] + side * 40.0
    return edge


def record_view(rec) -> FrequencyView:
    """What the Bode figure draws for a student's record (:mod:`eha_core.identify.record`):
    the estimate and the record's own frequency response; no eq. 24 (nothing is known of the plant)."""
    base = dict(excitation_t=rec.t, excitation_r=rec.u, excitation_title="your record", t=rec.t, r=rec.u,
                x_mm=rec.y * 1e3, u=rec.u)
    b = rec.bode
    if b is None:
        return FrequencyView(fit_ok=False, **base)
    nan = np.full_like(b.w, np.nan)
    return FrequencyView(
        **base, fit_ok=True, w=b.w, est_db=b.estimate.magnitude_db, est_deg=b.estimate.phase_deg, theory_db=nan,
        theory_deg=nan, data_w=np.asarray(b.data_w), data_db=np.asarray(b.data_magnitude_db),
        data_deg=b.data_phase_deg, data_lower_db=_band_edge(b.data_lower_db, b.data_magnitude_db, -1),
        data_upper_db=_band_edge(b.data_upper_db, b.data_magnitude_db, +1),
        data_label=("ETFE of your record" if b.data_method == "etfe"
                    else "spectral estimate of your record, 95 % band"),
        data_description=b.data_description)


def excitation_view(excitation, ts: float) -> tuple[np.ndarray, np.ndarray, str]:
    """(t, r, title) of an idinput excitation (Fig. 8)."""
    t = np.arange(excitation.u.size) * ts
    title = f"Excitation: idinput {excitation.type}, {excitation.u.size} samples, seed {excitation.seed}"
    return t, np.asarray(excitation.u), title


def frequency_view(fi, hidden=()) -> FrequencyView:
    """What Figs. 8-13 draw, in display units, from a
    :class:`~eha_core.experiments.FrequencyIdentification` (the core computed every curve).

    ``hidden``: an exercise's hidden parameters: eq. 24's curves, computed from them, are left out.
    """
    et, er, etitle = excitation_view(fi.excitation, fi.config.ts)
    d = fi.data
    base = dict(excitation_t=et, excitation_r=er, excitation_title=etitle, t=d.t, r=d.r, x_mm=d.x * 1e3, u=d.u)
    if fi.validation is None or fi.bode is None:        # tfest failed: the data, no estimate's curves
        return FrequencyView(fit_ok=False, **base)
    e, theo, bode = fi.estimate, fi.theoretical_comparison, fi.bode
    vd, v = fi.validation_data, fi.validation
    ra = fi.residuals
    verdict = fi.residual_assessment
    view = FrequencyView(
        **base, fit_ok=True, y_hat_mm=fi.estimate_output * 1e3, y_theory_mm=theo.y_hat * 1e3,
        fit_label=f"estimated H(s): fit {e.fit_percent:.1f} %"
                  + ("" if fit_conditions(fi.config.initial_condition, fi.config.input_offset) == FIT_DEFINITION else
                     f" ({fit_conditions(fi.config.initial_condition, fi.config.input_offset)})"),
        theory_label=f"linearised H(s), eq. 24: fit {theo.fit_percent:.1f} %",
        fit_title=(f"Estimated Ĥ(s): fit {e.fit_percent:.1f} %; linearised H(s) of eq. 24: fit "
                   f"{theo.fit_percent:.1f} %. Fit = 100 (1 − ‖x − x̂‖ / ‖x − mean x‖) as MATLAB's compare "
                   f"computes it, {FIT_DEFINITION} for each model (as on the model board)."),
        w=bode.w, est_db=bode.estimate.magnitude_db, est_deg=bode.estimate.phase_deg,
        theory_db=bode.theoretical.magnitude_db, theory_deg=bode.theoretical.phase_deg,
        data_w=np.asarray(bode.data_w), data_db=np.asarray(bode.data_magnitude_db), data_deg=bode.data_phase_deg,
        data_lower_db=_band_edge(bode.data_lower_db, bode.data_magnitude_db, -1),
        data_upper_db=_band_edge(bode.data_upper_db, bode.data_magnitude_db, +1),
        data_label=("ETFE of the sampled (ZOH) data" if bode.data_method == "etfe"
                    else "spectral estimate of the sampled (ZOH) data, 95 % band"),
        data_description=bode.data_description,
        validation_t=vd.t, validation_x_mm=vd.x * 1e3, validation_y_mm=v.y_hat * 1e3,
        validation_label=f"estimated H(s): fit {v.fit_percent:.1f} %",
        validation_title=f"Validation on a new excitation (seed {fi.validation_excitation.seed})",
        lags=np.asarray(ra.lags), autocorrelation=np.asarray(ra.autocorrelation),
        cross_lags=np.asarray(ra.cross_lags), cross_correlation=np.asarray(ra.cross_correlation),
        band=float(ra.confidence_bound),
        whiteness_title=f"Residual autocorrelation: {'passes' if verdict.whiteness.passed else 'fails'}",
        independence_title=f"Cross-correlation r → residual: {'passes' if verdict.independence.passed else 'fails'}",
        residual_sentences=verdict.sentences,
    )
    if hidden:
        nan = np.full_like
        view = dataclasses.replace(
            view, y_theory_mm=nan(view.y_theory_mm, np.nan), theory_db=nan(view.theory_db, np.nan),
            theory_deg=nan(view.theory_deg, np.nan), theory_label="linearised H(s), eq. 24: hidden in this exercise")
    return view


def _set_legend_label(item: LegendItem, text: str) -> None:
    item.label = {"value": text}


class ExcitationFigure(Described):
    """The idinput reference signal against t (Fig. 8), in mm as every position on the page (the paper's
    range ±1 m is ±1000 mm: a student reads it against the piston's travel, a few tens of mm)."""

    def __init__(self, *, height: int = 240, width: int = FIGURE_WIDTH):
        self.source = ColumnDataSource(data={"t": _f32([]), "r": _f32([])})
        self.fig = _figure(width=width, height=height, x_axis_label="t [s]", y_axis_label="r [mm]",
                           title="Excitation")
        self.fig.step("t", "r", source=self.source, mode="after", color=CASE_COLORS[0], name="reference r")
        self.fig.add_tools(HoverTool(tooltips=[("t", "@t{0.000} s"), ("r", "@r{0.0} mm")]))
        _lean(self.fig)
        self.layout = self.fig

    def update(self, t, r, title: str) -> None:
        t, r = decimate(t, r, max_points=4 * MAX_POINTS)
        self.source.data = {"t": _f32(t), "r": _f32(1e3 * np.asarray(r, dtype=float))}
        self.fig.title.text = title


class ClosedLoopFigure(Described):
    """Reference r and position x [mm] and valve command u [V] of the closed-loop run (Fig. 9).

    Three panels: r swings over +-1000 mm (the paper's +-1 m) while x moves by a few
    tens of mm (the slow closed loop filters most of the excitation, and u saturates),
    so one axis would hide x; both in mm, so that their axes compare.
    """

    def __init__(self, *, height: int = 240, width: int = FIGURE_WIDTH):
        self.source = ColumnDataSource(data={k: _f32([]) for k in ("t", "r", "x", "u")})
        x_range = DataRange1d()
        self.figs = []
        for key, ylabel, title, color, step in (("r", "r [mm]", "Reference r", "#777777", True),
                                                ("x", "x [mm]", "Position x", CASE_COLORS[0], False),
                                                ("u", "u [V]", "Command u = Kp (r − x)", CASE_COLORS[1], True)):
            fig = _figure(width=width // 3, height=height, x_range=x_range, x_axis_label="t [s]",
                          y_axis_label=ylabel, title=title)
            if step:
                fig.step("t", key, source=self.source, mode="after", color=color, alpha=0.8, name=title)
            else:
                fig.line("t", key, source=self.source, color=color, name=title)
            self.figs.append(fig)
        _lean(*self.figs)
        self.layout = row(*self.figs, sizing_mode="stretch_width")

    def update(self, view: FrequencyView) -> None:
        t, r, x, u = decimate(view.t, view.r, view.x_mm, view.u)
        self.source.data = {"t": _f32(t), "r": _f32(1e3 * np.asarray(r, dtype=float)), "x": _f32(x), "u": _f32(u)}


class FitFigure(Described):
    """Measured x against the estimated model's output on the estimation data (Fig. 11)."""

    def __init__(self, *, height: int = 300, width: int = FIGURE_WIDTH):
        self.source = ColumnDataSource(data={k: _f32([]) for k in ("t", "x", "est", "theory")})
        self.fig = _figure(width=width, height=height, x_axis_label="t [s]", y_axis_label="x [mm]",
                           title="Measured and simulated output (estimation data)")
        r0 = self.fig.line("t", "x", source=self.source, color="#333333", line_width=2)
        r1 = self.fig.line("t", "est", source=self.source, color=CASE_COLORS[1], line_dash="dashed")
        r2 = self.fig.line("t", "theory", source=self.source, color=CASE_COLORS[2], line_dash="dotted")
        self.items = [LegendItem(label="measured (nonlinear model in the loop)", renderers=[r0]),
                      LegendItem(label="estimated H(s)", renderers=[r1]),
                      LegendItem(label="linearised H(s), eq. 24", renderers=[r2])]
        _legend_above(self.fig, self.items, ncols=2)       # three long labels: 668 px on one row
        self.note = Div(text="", sizing_mode="stretch_width", css_classes=["eha-fit-note"],
                        styles={"font-size": "12px", "color": "#555"})
        _lean(self.fig)
        self.layout = column(self.fig, self.note, sizing_mode="stretch_width")

    def update(self, view: FrequencyView, model: str = "nonlinear") -> None:
        if not view.fit_ok:
            self.source.data = {k: _f32([]) for k in ("t", "x", "est", "theory")}
            return
        t, x, est, theo = decimate(view.t, view.x_mm, view.y_hat_mm, view.y_theory_mm)
        self.source.data = {"t": _f32(t), "x": _f32(x), "est": _f32(est), "theory": _f32(theo)}
        _set_legend_label(self.items[0], f"measured ({model} model in the loop)")
        _set_legend_label(self.items[1], view.fit_label)
        self.note.text = view.fit_title
        _set_legend_label(self.items[2], view.theory_label)


class BodeFigure(Described):
    """Bode diagram (Fig. 12): the estimate, the theoretical H(s) of eq. 24, and the data's
    frequency response as the core chose it (ETFE or spectral estimate with its band), named so."""

    def __init__(self, *, height: int = 240, width: int = FIGURE_WIDTH):
        self.curves = ColumnDataSource(data={k: _f32([]) for k in ("w", "est_db", "est_deg", "th_db", "th_deg")})
        self.points = ColumnDataSource(data={k: _f32([]) for k in ("w", "db", "deg")})
        self.band = ColumnDataSource(data={k: _f32([]) for k in ("w", "lo", "hi")})
        x_range = DataRange1d()
        self.mag = _figure(width=width, height=height, x_axis_type="log", x_range=x_range,
                           x_axis_label="ω [rad/s]", y_axis_label="magnitude [dB]", title="Bode diagram")
        self.phase = _figure(width=width, height=height, x_axis_type="log", x_range=x_range,
                             x_axis_label="ω [rad/s]", y_axis_label="phase [deg]", name="Bode diagram, phase")
        r1 = self.mag.line("w", "est_db", source=self.curves, color=CASE_COLORS[1], line_width=2)
        r2 = self.mag.line("w", "th_db", source=self.curves, color=CASE_COLORS[2], line_dash="dashed")
        r4 = self.mag.varea("w", "lo", "hi", source=self.band, fill_color="#333333", fill_alpha=0.12)
        r3 = self.mag.scatter("w", "db", source=self.points, color="#333333", size=4)
        # (named for the text alternative: the legend is the magnitude's)
        self.phase.line("w", "est_deg", source=self.curves, color=CASE_COLORS[1], line_width=2, name="estimated H(s)")
        self.phase.line("w", "th_deg", source=self.curves, color=CASE_COLORS[2], line_dash="dashed",
                        name="linearised H(s), eq. 24")
        self.phase.scatter("w", "deg", source=self.points, color="#333333", size=4, name="the data")
        self.data_item = LegendItem(label="the data", renderers=[r3, r4])
        self.theory_item = LegendItem(label="linearised H(s), eq. 24", renderers=[r2])
        _legend_above(self.mag, [LegendItem(label="estimated H(s)", renderers=[r1]), self.theory_item,
                                 self.data_item], ncols=2)          # (861 px on one row at 800 px)
        self.note = Div(text="", sizing_mode="stretch_width", css_classes=["eha-bode-note"],
                        styles={"font-size": "12px", "color": "#555"})
        _lean(self.mag, self.phase)
        self.layout = column(self.mag, self.phase, self.note, sizing_mode="stretch_width")

    def update(self, view: FrequencyView) -> None:
        if not view.fit_ok:
            self.curves.data = {k: _f32([]) for k in self.curves.data}
            self.points.data = {k: _f32([]) for k in self.points.data}
            self.band.data = {k: _f32([]) for k in self.band.data}
            self.note.text = ""
            return
        self.curves.data = {"w": _f32(view.w), "est_db": _f32(view.est_db), "est_deg": _f32(view.est_deg),
                            "th_db": _f32(view.theory_db), "th_deg": _f32(view.theory_deg)}
        self.points.data = {"w": _f32(view.data_w), "db": _f32(view.data_db), "deg": _f32(view.data_deg)}
        if view.data_lower_db is None:
            self.band.data = {k: _f32([]) for k in self.band.data}
        else:
            self.band.data = {"w": _f32(view.data_w), "lo": _f32(view.data_lower_db), "hi": _f32(view.data_upper_db)}
        _set_legend_label(self.data_item, view.data_label)
        # no eq. 24 for a student's record (nothing is known of its plant): no legend entry either;
        # in an exercise the entry says that it is hidden
        hidden = "hidden" in view.theory_label
        _set_legend_label(self.theory_item, view.theory_label if hidden else "linearised H(s), eq. 24")
        self.theory_item.visible = hidden or bool(np.isfinite(view.theory_db).any())
        description = html.escape(view.data_description)
        for word, shown in (("ETFE", "ETFE"), ("spectral estimate", "Spectral estimate")):
            if description.startswith(shown):
                description = term(word, shown) + description[len(shown):]
        self.note.text = (f"{description} The points describe the sampled loop "
                          f"(controller output held between samples: {term('ZOH')}), which lies up to a few dB "
                          "below the continuous H(jω) near the Nyquist frequency.")


class ValidationFigure(Described):
    """The model on a fresh excitation (Fig. 13)."""

    def __init__(self, *, height: int = 300, width: int = FIGURE_WIDTH):
        self.source = ColumnDataSource(data={k: _f32([]) for k in ("t", "x", "est")})
        self.fig = _figure(width=width, height=height, x_axis_label="t [s]", y_axis_label="x [mm]",
                           title="Validation on a new excitation")
        r0 = self.fig.line("t", "x", source=self.source, color="#333333", line_width=2)
        r1 = self.fig.line("t", "est", source=self.source, color=CASE_COLORS[1], line_dash="dashed")
        self.items = [LegendItem(label="measured (fresh excitation)", renderers=[r0]),
                      LegendItem(label="estimated H(s)", renderers=[r1])]
        _legend_above(self.fig, self.items)
        _lean(self.fig)
        self.layout = self.fig

    def update(self, view: FrequencyView) -> None:
        if not view.fit_ok:
            self.source.data = {k: _f32([]) for k in ("t", "x", "est")}
            return
        t, x, est = decimate(view.validation_t, view.validation_x_mm, view.validation_y_mm)
        self.source.data = {"t": _f32(t), "x": _f32(x), "est": _f32(est)}
        _set_legend_label(self.items[1], view.validation_label)
        self.fig.title.text = view.validation_title


def correlation_stems(title: str, color: str, **figure_kwargs):
    """A correlation against its lags as stems, with its band (a :class:`BoxAnnotation` set by the caller)
    and the zero line: ``(figure, source with lag, c, zero; band)``. Shared by the board's residual tests
    and the black-box sub-tab's."""
    src = ColumnDataSource(data={"lag": _f32([]), "c": _f32([]), "zero": _f32([])})
    fig = _figure(title=title, x_axis_label="lag [samples]", y_axis_label="correlation",
                  y_range=Range1d(-1.05, 1.05), **figure_kwargs)
    band = BoxAnnotation(bottom=0, top=0, fill_color="#cccccc", fill_alpha=0.35, line_alpha=0)
    fig.add_layout(band)
    fig.add_layout(Span(location=0, dimension="width", line_color="#999999", line_width=1))
    fig.segment("lag", "zero", "lag", "c", source=src, color=color, line_width=2, name="correlation")
    fig.scatter("lag", "c", source=src, color=color, size=4, name="correlation")
    return fig, src, band


class ResidualFigure(Described):
    """Residual autocorrelation and input cross-correlation with their 99 % bands."""

    def __init__(self, *, height: int = 260, width: int = FIGURE_WIDTH):
        self.sources = []
        self.bands = []
        self.figs = []
        for title, color in (("Residual autocorrelation", CASE_COLORS[0]),
                             ("Cross-correlation r → residual", CASE_COLORS[3])):
            fig, src, band = correlation_stems(title, color, width=width // 2, height=height)
            self.sources.append(src)
            self.bands.append(band)
            self.figs.append(fig)
        self.verdicts = Div(text="", sizing_mode="stretch_width", css_classes=["eha-residual-verdicts"],
                            styles={"font-size": "13px"})
        _lean(*self.figs)
        self.layout = column(row(*self.figs, sizing_mode="stretch_width"), self.verdicts, sizing_mode="stretch_width")

    def update(self, view: FrequencyView) -> None:
        if not view.fit_ok:
            for src in self.sources:
                src.data = {"lag": _f32([]), "c": _f32([]), "zero": _f32([])}
            self.verdicts.text = ""
            return
        self.verdicts.text = "".join(f"<p>{html.escape(sentence)}</p>" for sentence in view.residual_sentences)
        for src, band, fig, lags, c, title in (
                (self.sources[0], self.bands[0], self.figs[0], view.lags, view.autocorrelation, view.whiteness_title),
                (self.sources[1], self.bands[1], self.figs[1], view.cross_lags, view.cross_correlation,
                 view.independence_title)):
            src.data = {"lag": _f32(lags), "c": _f32(c), "zero": _f32(np.zeros(len(lags)))}
            band.bottom, band.top = -view.band, view.band
            fig.title.text = title


# -- time-domain identification ------------------------------------------------------------

@dataclass(frozen=True)
class LseView:
    """Measured x and p1 and, when the estimate is physical, the re-simulated ones."""

    t: np.ndarray
    x_mm: np.ndarray
    p1_mpa: np.ndarray
    resim_t: np.ndarray | None = None
    resim_x_mm: np.ndarray | None = None
    resim_p1_mpa: np.ndarray | None = None
    resim_label: str = "re-simulated with the estimates"


def lse_view(measured, resimulated, label: str = "re-simulated with the estimates") -> LseView:
    """What :class:`LseFitFigure` draws: the record ``measured`` and the model's run ``resimulated``
    (None: none), named ``label`` in the legend (the validation's plot: "simulated on the validation record")."""
    t, x, p1 = decimate(measured.t, measured.x * 1e3, measured.p1 * 1e-6)
    if resimulated is None:
        return LseView(t=t, x_mm=x, p1_mpa=p1, resim_label=label)
    tr, xr, p1r = decimate(resimulated.t, resimulated.x * 1e3, resimulated.p1 * 1e-6)
    return LseView(t=t, x_mm=x, p1_mpa=p1, resim_t=tr, resim_x_mm=xr, resim_p1_mpa=p1r, resim_label=label)


class LseFitFigure(Described):
    """Measured response against the model re-simulated with the estimates (x and p1).

    Without a re-simulation (an estimate that is not physical) only the
    measured curves are drawn and the legend says why.
    """

    def __init__(self, *, height: int = 280, width: int = FIGURE_WIDTH):
        self.measured = ColumnDataSource(data={k: _f32([]) for k in ("t", "x", "p1")})
        self.resim = ColumnDataSource(data={k: _f32([]) for k in ("t", "x", "p1")})
        x_range = DataRange1d()
        self.left = _figure(width=width // 2, height=height, x_range=x_range, x_axis_label="t [s]",
                            y_axis_label="x [mm]", title="Position")
        self.right = _figure(width=width // 2, height=height, x_range=x_range, x_axis_label="t [s]",
                             y_axis_label="p₁ [MPa]", title="Piston-chamber pressure")
        m0 = self.left.line("t", "x", source=self.measured, color="#333333", line_width=2)
        self.resim_renderers = [
            self.left.line("t", "x", source=self.resim, color=CASE_COLORS[1], line_dash="dashed"),
            self.right.line("t", "p1", source=self.resim, color=CASE_COLORS[1], line_dash="dashed",
                            name="re-simulated with the estimates"),
        ]
        self.right.line("t", "p1", source=self.measured, color="#333333", line_width=2, name="measured")
        self.resim_item = LegendItem(label="re-simulated with the estimates", renderers=[self.resim_renderers[0]])
        _legend_above(self.left, [LegendItem(label="measured", renderers=[m0]), self.resim_item])
        _lean(self.left, self.right)
        self.layout = row(self.left, self.right, sizing_mode="stretch_width")

    def update(self, view: LseView) -> None:
        self.measured.data = {"t": _f32(view.t), "x": _f32(view.x_mm), "p1": _f32(view.p1_mpa)}
        if view.resim_t is None:
            self.resim.data = {k: _f32([]) for k in ("t", "x", "p1")}
            # no curve, so no legend entry: the note under the table says why
            self.resim_item.visible = False
        else:
            self.resim.data = {"t": _f32(view.resim_t), "x": _f32(view.resim_x_mm), "p1": _f32(view.resim_p1_mpa)}
            _set_legend_label(self.resim_item, view.resim_label)
            self.resim_item.visible = True


# -- the student's own record (frequency domain) --------------------------------------------

@dataclass(frozen=True)
class RecordDataView:
    """A student's record as read, as prepared for the estimation, and the estimate's output."""

    t: np.ndarray                       # the file's whole record
    u: np.ndarray
    y: np.ndarray
    used_t: np.ndarray                  # the chosen range, trend removed
    used_u: np.ndarray
    used_y: np.ndarray
    trend_u: np.ndarray | None          # the removed trend on that range (None: nothing removed)
    trend_y: np.ndarray | None
    t_split: float
    title: str
    model_t: np.ndarray | None = None   # the estimate's output (estimation part, then validation part)
    model_y: np.ndarray | None = None
    model_label: str = ""


def record_data_view(t, u, y, prepared, rec=None) -> RecordDataView:
    """What :class:`RecordDataFigure` draws, from the file's columns and
    :class:`~eha_core.identify.record.PreparedRecord` (and the estimate, once made)."""
    p = prepared
    removed = p.detrend != "none"
    what = {"none": "", "mean": "; the mean removed", "linear": "; a linear trend removed"}[p.detrend]
    title = (f"Estimation on t ∈ [{p.t_from:g}, {p.t_split:g}] s, validation on the rest up to {p.t_to:g} s"
             f"{what}")
    model_t = model_y = None
    label = ""
    if rec is not None and rec.y_hat is not None:
        n = rec.n_estimation
        model_t, model_y = rec.t[:n], rec.y_hat
        label = f"estimated H(s): fit {rec.estimate.fit_percent:.1f} %"
        if rec.validation is not None:
            model_t = np.concatenate([model_t, rec.t[n:]])
            model_y = np.concatenate([model_y, rec.validation.y_hat])
            label += f", validation {rec.validation.fit_percent:.1f} %"
    return RecordDataView(t=np.asarray(t), u=np.asarray(u), y=np.asarray(y), used_t=p.t, used_u=p.u, used_y=p.y,
                          trend_u=p.u_removed if removed else None, trend_y=p.y_removed if removed else None,
                          t_split=p.t_split, title=title, model_t=model_t, model_y=model_y, model_label=label)


class RecordDataFigure(Described):
    """The student's record: the file's u and y (grey), the part used with its trend removed
    (colour), the removed trend (dashed), the estimation/validation split, and the estimate's output.

    The legend is one HTML line above both panels: it wraps on a narrow page, a Bokeh legend would not.
    """

    def __init__(self, *, height: int = 200, width: int = FIGURE_WIDTH):
        keys = ("t", "u", "y")
        self.raw = ColumnDataSource(data={k: _f32([]) for k in keys})
        self.used = ColumnDataSource(data={k: _f32([]) for k in keys})
        self.trend = ColumnDataSource(data={k: _f32([]) for k in keys})
        self.model = ColumnDataSource(data={"t": _f32([]), "y": _f32([])})
        x_range = DataRange1d()
        self.figs = []
        self.splits = []
        for key, label in (("u", "input u"), ("y", "output y")):
            fig = _figure(width=width // 2, height=height, x_range=x_range, x_axis_label="t [s]",
                          y_axis_label=label, title=f"Your record: {label}")
            fig.line("t", key, source=self.raw, color="#b0b0b0", line_width=1, name="as in the file")
            fig.line("t", key, source=self.used, color=CASE_COLORS[0], line_width=1.5, name="as estimated")
            fig.line("t", key, source=self.trend, color=CASE_COLORS[1], line_dash="dashed", line_width=2,
                     name="removed trend")
            split = Span(location=0.0, dimension="height", line_color="#555555", line_dash="dotted", line_width=2)
            fig.add_layout(split)
            self.splits.append(split)
            if key == "y":
                self.model_renderer = fig.line("t", "y", source=self.model, color=CASE_COLORS[2], line_dash="dashed",
                                               line_width=2, name="estimated H(s)")
            self.figs.append(fig)
        self.trend_shown = False
        self.model_label = ""
        self.legend = Div(text="", sizing_mode="stretch_width", css_classes=["eha-record-legend"],
                          styles={"font-size": "12px"})
        self.note = Div(text="", sizing_mode="stretch_width", css_classes=["eha-record-data-note"],
                        styles={"font-size": "12px", "color": "#555"})
        _lean(*self.figs)
        self.layout = column(self.legend, row(*self.figs, sizing_mode="stretch_width"), self.note,
                             sizing_mode="stretch_width")

    def update(self, view: RecordDataView) -> None:
        t, u, y = decimate(view.t, view.u, view.y)
        self.raw.data = {"t": _f32(t), "u": _f32(u), "y": _f32(y)}
        t, u, y = decimate(view.used_t, view.used_u, view.used_y)
        self.used.data = {"t": _f32(t), "u": _f32(u), "y": _f32(y)}
        if view.trend_u is None:
            self.trend.data = {k: _f32([]) for k in ("t", "u", "y")}
        else:
            t, u, y = decimate(view.used_t, view.trend_u, view.trend_y)
            self.trend.data = {"t": _f32(t), "u": _f32(u), "y": _f32(y)}
        self.trend_shown = view.trend_u is not None
        if view.model_t is None:
            self.model.data = {"t": _f32([]), "y": _f32([])}
        else:
            t, y = decimate(view.model_t, view.model_y)
            self.model.data = {"t": _f32(t), "y": _f32(y)}
        self.model_label = view.model_label if view.model_t is not None else ""
        if self.model_label and self.model_renderer.name != self.model_label:
            self.model_renderer.name = self.model_label         # its fits, in the text alternative
        parts = [_swatch("as in the file", "#b0b0b0", width=2), _swatch("as estimated", CASE_COLORS[0])]
        if self.trend_shown:
            parts.append(_swatch("removed trend", CASE_COLORS[1], "dashed"))
        if self.model_label:
            parts.append(_swatch(self.model_label, CASE_COLORS[2], "dashed"))
        self.legend.text = "".join(parts)
        for split in self.splits:
            split.location = view.t_split
        self.note.text = html.escape(view.title) + " (dotted line: where validation starts)."
