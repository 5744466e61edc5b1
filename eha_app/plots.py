"""HoloViews figures built from :mod:`eha_core` result objects.

One builder per figure of the paper; the app and ``eha reproduce`` both use
them. Display units: mm, mm/s, MPa, kN; the data stay SI in the core.
"""

from __future__ import annotations

import numpy as np
import holoviews as hv
import holoviews.plotting.bokeh  # noqa: F401 - registers the Bokeh renderer for to_bokeh()

__all__ = [
    "to_bokeh", "bokeh_rows", "TimeSeriesGrid", "STATE_PANELS", "CASE_COLORS", "style_for", "legend_html", "FIGURE_WIDTH",
    "excitation_plot", "closed_loop_plot", "fit_plot", "validation_plot", "bode_plots",
    "residual_plots", "lse_fit_plot", "decimate",
]

#: (field, axis label, scale from SI to the display unit)
STATE_PANELS = (
    ("x", "x [mm]", 1e3),
    ("v", "v [mm/s]", 1e3),
    ("p1", "p₁ [MPa]", 1e-6),
    ("p2", "p₂ [MPa]", 1e-6),
)
CASE_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
_MODEL_DASH = {"nonlinear": "solid", "linear": "dashed", "linear-positive": "dotted", "linear-negative": "dotdash"}
#: Points drawn per curve at most: a 5 s run at 1 kHz is shown every 2 ms, plenty for
#: the paper's 2 Hz inputs and it halves what the browser receives.
MAX_POINTS = 2500


def bokeh_rows(obj) -> list[list]:
    """Render a HoloViews object to rows of Bokeh figures (a Layout: panel by panel).

    Shared x axes are linked by giving the figures one range model. The app puts
    each figure in its own Panel pane (a GridPlot swapped into a Panel pane
    collapses to zero width); :func:`to_bokeh` joins them for standalone pages.
    """
    if not isinstance(obj, hv.Layout):
        return [[hv.render(obj, backend="bokeh")]]
    figures = [hv.render(item, backend="bokeh") for item in obj]
    if hv.Store.lookup_options("bokeh", obj, "plot").kwargs.get("shared_axes", True):
        for fig in figures[1:]:
            fig.x_range = figures[0].x_range
    ncols = obj._max_cols or len(figures)
    return [figures[i:i + ncols] for i in range(0, len(figures), ncols)]


def to_bokeh(obj):
    """One Bokeh model for a HoloViews object (for standalone HTML, e.g. the report)."""
    rows = bokeh_rows(obj)
    if len(rows) == 1 and len(rows[0]) == 1:
        return rows[0][0]
    from bokeh.layouts import gridplot

    return gridplot(rows, merge_tools=True, toolbar_location="right")


def decimate(t: np.ndarray, *ys: np.ndarray, max_points: int = MAX_POINTS):
    """Every k-th sample so that at most ``max_points`` remain (the last one kept)."""
    n = t.size
    if n <= max_points:
        return (t, *ys)
    k = int(np.ceil(n / max_points))
    idx = np.r_[np.arange(0, n, k), n - 1] if (n - 1) % k else np.arange(0, n, k)
    return (t[idx], *(y[idx] for y in ys))


def style_for(index: int, model: str) -> dict:
    return {"color": CASE_COLORS[index % len(CASE_COLORS)], "line_dash": _MODEL_DASH.get(model, "solid")}


def _legend_label(res) -> str:
    label = res.label or "run"
    return f"{label} ({res.model})"


class TimeSeriesGrid:
    """x, v, p1, p2 against t: a 2 x 2 grid of Bokeh figures with a shared time axis.

    Built once and updated in place (:meth:`update`), which takes a few
    milliseconds where re-rendering HoloViews overlays of eight curves takes
    about a second. All lines read one ColumnDataSource (columns t, x_0..x_7,
    v_0..v_7, ...), so an update is a single change for the browser to apply
    rather than 32. Bokeh stops auto-ranging an axis once the user zooms, so a
    zoom survives new data; a different set of curves or horizon resets the view.
    """

    def __init__(self, results=(), *, max_lines: int = 8, height: int = 250):
        from bokeh.models import ColumnDataSource, DataRange1d, Div, HoverTool
        from bokeh.plotting import figure

        self.max_lines = max_lines
        self._signature = None
        self.legend = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px"})
        self.source = ColumnDataSource(data=self._empty_columns())
        self.x_range = DataRange1d(range_padding=0.01)
        self.figures, self.renderers = [], []
        for field, ylabel, _ in STATE_PANELS:
            fig = figure(height=height, sizing_mode="stretch_width", x_range=self.x_range,
                         y_range=DataRange1d(), tools="pan,box_zoom,wheel_zoom,reset,save",
                         active_scroll=None, x_axis_label="t [s]", y_axis_label=ylabel,
                         output_backend="canvas")
            fig.toolbar.logo = None
            fig.add_tools(HoverTool(tooltips=[("run", "$name"), ("t", "@t{0.000} s"), (ylabel, "$y{0.000}")]))
            rends = []
            for i in range(max_lines):
                r = fig.line("t", f"{field}_{i}", source=self.source, line_width=1.6,
                             color=CASE_COLORS[i % len(CASE_COLORS)], visible=False, name=f"slot {i}")
                rends.append(r)
            self.figures.append(fig)
            self.renderers.append(rends)
        if len(results):
            self.update(results)

    def _empty_columns(self, n: int = 0) -> dict:
        cols = {"t": np.zeros(n)}
        for field, _, _ in STATE_PANELS:
            for i in range(self.max_lines):
                cols[f"{field}_{i}"] = np.full(n, np.nan)
        return cols

    @property
    def grid(self):
        """The four figures as a Bokeh grid (shared toolbar)."""
        from bokeh.layouts import gridplot

        return gridplot([self.figures[:2], self.figures[2:]], sizing_mode="stretch_width", merge_tools=True,
                        toolbar_location="right")

    @property
    def layout(self):
        """Legend strip and grid, for embedding in a page."""
        from bokeh.layouts import column

        return column(self.legend, self.grid, sizing_mode="stretch_width")

    def update(self, results) -> None:
        """Show ``results`` (at most ``max_lines``, on one time grid), colour per label, dash per model."""
        from bokeh.models import DataRange1d

        results = list(results)[: self.max_lines]
        keys: dict[str, int] = {}
        for res in results:
            keys.setdefault(res.label, len(keys))
        signature = tuple((r.label, r.model, float(r.t[-1])) for r in results)
        if self._signature is not None and signature != self._signature:
            # a different set of curves: fresh auto-ranges (the user's zoom no longer applies)
            self.x_range = DataRange1d(range_padding=0.01)
            for fig in self.figures:
                fig.x_range = self.x_range
                fig.y_range = DataRange1d()
        self._signature = signature
        if results:
            t = decimate(results[0].t)[0]
            cols = self._empty_columns(t.size)
            cols["t"] = t
            for i, res in enumerate(results):
                if res.t.size != results[0].t.size:
                    raise ValueError("TimeSeriesGrid: all runs shown together must share one time grid")
                for field, _, scale in STATE_PANELS:
                    cols[f"{field}_{i}"] = decimate(res.t, getattr(res, field))[1] * scale
        else:
            cols = self._empty_columns()
        self.source.data = cols
        for k in range(len(STATE_PANELS)):
            for i, r in enumerate(self.renderers[k]):
                if i < len(results):
                    style = style_for(keys[results[i].label], results[i].model)
                    r.glyph.line_color = style["color"]
                    r.glyph.line_dash = style["line_dash"]
                    r.name = _legend_label(results[i])
                r.visible = i < len(results)
        self.legend.text = legend_html(results)


def legend_html(results) -> str:
    """A one-line legend: a swatch per run label, solid = nonlinear, dashed = linearised."""
    keys: dict[str, int] = {}
    for res in results:
        keys.setdefault(res.label, len(keys))
    models = []
    for res in results:
        if res.model not in models:
            models.append(res.model)
    parts = []
    for label, i in keys.items():
        color = CASE_COLORS[i % len(CASE_COLORS)]
        parts.append(f'<span style="white-space:nowrap;margin-right:14px"><span style="display:inline-block;'
                     f'width:22px;height:0;border-top:3px solid {color};vertical-align:middle;margin-right:5px">'
                     f'</span>{_escape(label or "run")}</span>')
    names = {"nonlinear": "nonlinear", "linear": "linearised (switching)",
             "linear-positive": "linearised (u ≥ 0 branch)", "linear-negative": "linearised (u < 0 branch)"}
    css_dash = {"solid": "solid", "dashed": "dashed", "dotted": "dotted", "dotdash": "dashed"}
    for m in models:
        dash = css_dash[_MODEL_DASH.get(m, "solid")]
        parts.append(f'<span style="white-space:nowrap;margin-right:14px"><span style="display:inline-block;'
                     f'width:22px;height:0;border-top:2px {dash} #444;vertical-align:middle;margin-right:5px">'
                     f'</span>{names.get(m, m)}</span>')
    return "".join(parts)


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


# -- frequency-domain identification (Figs. 8-13) ------------------------------------

#: Width in pixels of the identification figures: fits the app's main column at
#: 1366 px and a report page. (Responsive HoloViews layouts collapse to zero width
#: when filled while hidden, so sizes are explicit.)
FIGURE_WIDTH = 1000


def excitation_plot(excitation, ts: float, *, height: int = 240, width: int = FIGURE_WIDTH):
    """The idinput reference signal against t (Fig. 8)."""
    t = np.arange(excitation.u.size) * ts
    return hv.Curve((t, excitation.u), "t", "r").opts(
        xlabel="t [s]", ylabel="r [m]", color=CASE_COLORS[0], width=width, height=height,
        title=f"Excitation: idinput {excitation.type}, {excitation.u.size} samples, seed {excitation.seed}",
        show_grid=True, tools=["hover"], interpolation="steps-post")


def closed_loop_plot(data, *, height: int = 240, width: int = FIGURE_WIDTH):
    """Reference r [m], position x [mm] and valve command u [V] of the closed-loop run (Fig. 9).

    Three panels: r swings over +-1 m while x moves by centimetres (the slow
    closed loop filters most of the excitation), so one axis would hide x.
    """
    common = dict(width=width // 3, height=height, xlabel="t [s]", show_grid=True)
    r = hv.Curve((data.t, data.r), "t", "r").opts(color="#777777", interpolation="steps-post",
                                                   ylabel="r [m]", title="Reference r", **common)
    x = hv.Curve((data.t, data.x * 1e3), "t", "x").opts(color=CASE_COLORS[0], ylabel="x [mm]",
                                                         title="Position x", **common)
    u = hv.Curve((data.t, data.u), "t", "u").opts(color=CASE_COLORS[1], alpha=0.7, interpolation="steps-post",
                                                  ylabel="u [V]", title="Command u = Kp (r − x)", **common)
    return hv.Layout([r, x, u]).cols(3).opts(shared_axes=True)


def fit_plot(fi, *, height: int = 300, width: int = FIGURE_WIDTH):
    """Measured x against the estimated model's output on the estimation data (Fig. 11)."""
    e = fi.estimate
    d = fi.data
    y_hat = e.simulate(d.r, x0=e.x0, input_offset=e.input_offset)
    num_t, den_t = fi.theoretical
    from eha_core.identify.validate import compare

    theo = compare(num_t, den_t, d.r, d.x, d.t[1] - d.t[0], initial_condition="estimate")
    return (hv.Curve((d.t, d.x * 1e3), "t", "x", label="measured (nonlinear plant)").opts(color="#333333", line_width=2)
            * hv.Curve((d.t, y_hat * 1e3), "t", "x", label=f"estimated H(s): fit {e.fit_percent:.1f} %").opts(
                color=CASE_COLORS[1], line_dash="dashed")
            * hv.Curve((d.t, theo.y_hat * 1e3), "t", "x", label=f"linearised H(s), eq. 24: fit {theo.fit_percent:.1f} %").opts(
                color=CASE_COLORS[2], line_dash="dotted")
            ).opts(width=width, height=height, xlabel="t [s]", ylabel="x [mm]", show_grid=True,
                   legend_position="top_left", title="Measured and simulated output (estimation data)")


def validation_plot(fi, *, height: int = 300, width: int = FIGURE_WIDTH):
    """The model on a fresh excitation (Fig. 13)."""
    d = fi.validation_data
    v = fi.validation
    return (hv.Curve((d.t, d.x * 1e3), "t", "x", label="measured (fresh excitation)").opts(color="#333333", line_width=2)
            * hv.Curve((d.t, v.y_hat * 1e3), "t", "x", label=f"estimated H(s): fit {v.fit_percent:.1f} %").opts(
                color=CASE_COLORS[1], line_dash="dashed")
            ).opts(width=width, height=height, xlabel="t [s]", ylabel="x [mm]", show_grid=True,
                   legend_position="top_left",
                   title=f"Validation on a new excitation (seed {fi.validation_excitation.seed})")


def bode_plots(fi, *, height: int = 240, width: int = FIGURE_WIDTH):
    """Bode diagram: estimate, theoretical H(s) of eq. 24, ETFE points (Fig. 12)."""
    from eha_core.identify.validate import frequency_response

    ts = fi.config.ts
    w = np.logspace(-2, np.log10(np.pi / ts), 400)
    est = fi.estimate.frequency_response(w)
    theo = frequency_response(*fi.theoretical, w)
    et = fi.etfe
    # the ETFE's phase is known modulo 360 deg: draw each point on the branch
    # nearest the estimate's phase there, not on an unwrapped path through noise
    model_phase = fi.estimate.frequency_response(et.w).phase_deg
    etfe_phase = model_phase + (np.asarray(et.phase_deg) - model_phase + 180.0) % 360.0 - 180.0
    mag = (hv.Curve((w, est.magnitude_db), "w", "dB", label="estimated H(s)").opts(color=CASE_COLORS[1], line_width=2)
           * hv.Curve((w, theo.magnitude_db), "w", "dB", label="linearised H(s), eq. 24").opts(color=CASE_COLORS[2], line_dash="dashed")
           * hv.Scatter((et.w, et.magnitude_db), "w", "dB", label="ETFE of the data (ZOH)").opts(color="#333333", size=4))
    phase = (hv.Curve((w, est.phase_deg), "w", "deg").opts(color=CASE_COLORS[1], line_width=2)
             * hv.Curve((w, theo.phase_deg), "w", "deg").opts(color=CASE_COLORS[2], line_dash="dashed")
             * hv.Scatter((et.w, etfe_phase), "w", "deg").opts(color="#333333", size=4))
    common = dict(logx=True, width=width, height=height, show_grid=True, xlabel="ω [rad/s]")
    return hv.Layout([
        mag.opts(ylabel="magnitude [dB]", title="Bode diagram", legend_position="bottom_left", **common),
        phase.opts(ylabel="phase [deg]", show_legend=False, **common),
    ]).cols(1).opts(shared_axes=True)


def residual_plots(fi, *, height: int = 260, width: int = FIGURE_WIDTH):
    """Residual autocorrelation and input cross-correlation with 99 % bands."""
    ra = fi.residuals
    band = ra.confidence_bound

    def stem(lags, values, title, color):
        spikes = hv.Spikes((lags, values), "lag", "corr").opts(color=color, line_width=2)
        pts = hv.Scatter((lags, values), "lag", "corr").opts(color=color, size=4)
        bounds = hv.HSpan(-band, band).opts(color="#cccccc", alpha=0.35)
        return (bounds * spikes * pts).opts(width=width // 2, height=height, title=title, show_grid=True,
                                            xlabel="lag [samples]", ylabel="correlation", ylim=(-1.05, 1.05))

    ok_w = "inside" if ra.whiteness_ok else "outside"
    ok_i = "inside" if ra.independence_ok else "outside"
    return hv.Layout([
        stem(ra.lags, ra.autocorrelation, f"Residual autocorrelation ({ok_w} the 99 % band)", CASE_COLORS[0]),
        stem(ra.cross_lags, ra.cross_correlation, f"Cross-correlation r → residual ({ok_i} the 99 % band)", CASE_COLORS[3]),
    ]).cols(2).opts(shared_axes=False)


# -- time-domain identification -------------------------------------------------------

def lse_fit_plot(measured, resimulated, *, height: int = 280, width: int = FIGURE_WIDTH):
    """Measured response against the model re-simulated with the estimates (x and p1)."""
    t, xm, p1m = decimate(measured.t, measured.x, measured.p1)
    tr, xr, p1r = decimate(resimulated.t, resimulated.x, resimulated.p1)
    left = (hv.Curve((t, xm * 1e3), "t", "x", label="measured").opts(color="#333333", line_width=2)
            * hv.Curve((tr, xr * 1e3), "t", "x", label="re-simulated with the estimates").opts(
                color=CASE_COLORS[1], line_dash="dashed")
            ).opts(width=width // 2, height=height, xlabel="t [s]", ylabel="x [mm]", show_grid=True,
                   legend_position="top_left", title="Position")
    right = (hv.Curve((t, p1m * 1e-6), "t", "p1").opts(color="#333333", line_width=2)
             * hv.Curve((tr, p1r * 1e-6), "t", "p1").opts(color=CASE_COLORS[1], line_dash="dashed")
             ).opts(width=width // 2, height=height, xlabel="t [s]", ylabel="p₁ [MPa]", show_grid=True,
                    title="Piston-chamber pressure")
    return hv.Layout([left, right]).cols(2).opts(shared_axes=True)
