"""The model board's figures: every ticked model overlaid, one colour per model.

Each view is one multi-line (and one patch set for the bands or regions) whose
data are replaced when the ticks change: ticking a model is one data update per
view, never a new figure. The curves were computed by the core when the model
was added (:func:`eha_core.board.model_views`).
"""

from __future__ import annotations

import html

import numpy as np
from bokeh.layouts import column
from bokeh.models import ColumnDataSource, DataRange1d, Div, HoverTool, Span

from .figure_text import Described
from .plots import FIGURE_WIDTH, _f32, _figure, _lean, _swatch, decimate

__all__ = ["BOARD_STYLES", "BOARD_DASHES", "board_legend", "BoardFitFigure", "BoardBodeFigure", "BoardStepFigure",
           "PoleZeroFigure"]

#: Okabe and Ito's colour-blind-safe colours (Bokeh's ``Colorblind`` palette, ordered by contrast on
#: white; its yellow is too faint on white, and its black is the measured record's).
_COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9")
BOARD_DASHES = ("solid", "dashed", "dotted", "dotdash")
#: Each model's (colour, dash), in the order models arrive: no two share both, and models next to each
#: other differ in both, so that lines are told apart without telling colours apart. One per model
#: the board holds (its references and ``MAX_MODELS`` estimates).
BOARD_STYLES = tuple((_COLORS[i % len(_COLORS)], BOARD_DASHES[(i + i // len(_COLORS)) % len(BOARD_DASHES)])
                     for i in range(14))


def board_legend(entries, extra: tuple[tuple[str, str, str], ...] = ()) -> str:
    """One HTML line: a swatch and the name of each ticked model (and ``extra`` (label, colour, dash))."""
    parts = [_swatch(label, color, dash) for label, color, dash in
             [(e.name, e.color, e.dash) for e in entries] + list(extra)]
    return "".join(parts) or "<span class='eha-note'>Tick a model to draw it.</span>"


def _lines(xs, ys, entries):
    return {"xs": [_f32(x) for x in xs], "ys": [_f32(y) for y in ys], "color": [e.color for e in entries],
            "dash": [e.dash for e in entries], "name": [e.name for e in entries]}


def _empty_lines():
    return {"xs": [], "ys": [], "color": [], "dash": [], "name": []}


class BoardFitFigure(Described):
    """The validation record's x and each model's output on it (MATLAB ``compare``)."""

    def __init__(self, *, height: int = 300, width: int = FIGURE_WIDTH):
        self.measured = ColumnDataSource(data={"t": _f32([]), "x": _f32([])})
        self.models = ColumnDataSource(data=_empty_lines())
        self.fig = _figure(width=width, height=height, x_axis_label="t [s]", y_axis_label="x [mm]",
                           title="Models on the validation record")
        self.fig.line("t", "x", source=self.measured, color="#333333", line_width=2,
                      name="validation record (measured x)")
        self.fig.multi_line("xs", "ys", source=self.models, color="color", line_width=1.5, line_dash="dash")
        self.legend = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px"},
                          css_classes=["eha-board-legend"])
        _lean(self.fig)
        self.layout = column(self.legend, self.fig, sizing_mode="stretch_width")

    def update(self, record, entries, fits) -> None:
        if record is None:
            self.measured.data = {"t": _f32([]), "x": _f32([])}
            self.models.data = _empty_lines()
            return
        t, x = decimate(record.t, record.x * 1e3)
        self.measured.data = {"t": _f32(t), "x": _f32(x)}
        xs, ys, drawn = [], [], []
        for e in entries:
            fit = fits.get(e.key)
            if fit is None or not np.all(np.isfinite(fit.y_hat)):
                continue
            tt, yy = decimate(record.t, fit.y_hat * 1e3)
            xs.append(tt)
            ys.append(yy)
            drawn.append(e)
        self.models.data = _lines(xs, ys, drawn)
        self.legend.text = board_legend(entries, (("validation record (measured x)", "#333333", "solid"),))


class BoardBodeFigure(Described):
    """Magnitude and phase of each ticked model, with its 95 % band when it has one."""

    def __init__(self, *, height: int = 230, width: int = FIGURE_WIDTH):
        self.curves = ColumnDataSource(data=_empty_lines())
        self.phases = ColumnDataSource(data=_empty_lines())
        self.mag_band = ColumnDataSource(data={"xs": [], "ys": [], "color": [], "name": []})
        self.phase_band = ColumnDataSource(data={"xs": [], "ys": [], "color": [], "name": []})
        x_range = DataRange1d()
        self.mag = _figure(width=width, height=height, x_axis_type="log", x_range=x_range,
                           x_axis_label="ω [rad/s]", y_axis_label="magnitude [dB]", title="Bode diagram")
        self.phase = _figure(width=width, height=height, x_axis_type="log", x_range=x_range,
                             x_axis_label="ω [rad/s]", y_axis_label="phase [deg]", name="Bode diagram, phase")
        for fig, band, src in ((self.mag, self.mag_band, self.curves), (self.phase, self.phase_band, self.phases)):
            fig.patches("xs", "ys", source=band, fill_color="color", fill_alpha=0.15, line_alpha=0, name="95 % band")
            fig.multi_line("xs", "ys", source=src, color="color", line_width=2, line_dash="dash")
            fig.add_tools(HoverTool(tooltips=[("model", "@name")]))
        self.note = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px", "color": "#555"},
                        css_classes=["eha-board-bode-note"])
        self.legend = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px"})
        _lean(self.mag, self.phase)
        self.layout = column(self.legend, self.mag, self.phase, self.note, sizing_mode="stretch_width")

    def update(self, entries, views, *, bands: bool = True) -> None:
        mags, phases, mb, pb = ([], [], []), ([], [], []), ([], [], [], []), ([], [], [], [])
        banded = []
        for e in entries:
            v = views.get(e.key)
            if v is None:
                continue
            for out, y in ((mags, v.magnitude_db), (phases, v.phase_deg)):
                out[0].append(v.w)
                out[1].append(y)
                out[2].append(e)
            if bands and v.band is not None:
                banded.append(e.name)
                w = np.concatenate([v.band.w, v.band.w[::-1]])
                for out, lo, hi in ((mb, v.band.lower.magnitude_db, v.band.upper.magnitude_db),
                                    (pb, v.band.lower.phase_deg, v.band.upper.phase_deg)):
                    out[0].append(_f32(w))
                    out[1].append(_f32(np.concatenate([lo, hi[::-1]])))
                    out[2].append(e.color)
                    out[3].append(f"95 % band of {e.name}")
        self.curves.data = _lines(*mags)
        self.phases.data = _lines(*phases)
        self.mag_band.data = {"xs": mb[0], "ys": mb[1], "color": mb[2], "name": mb[3]}
        self.phase_band.data = {"xs": pb[0], "ys": pb[1], "color": pb[2], "name": pb[3]}
        self.legend.text = board_legend(entries)
        without = [e.name for e in entries if views.get(e.key) is not None and views[e.key].band is None]
        parts = []
        if banded:
            parts.append(f"Shaded: the 95 % band of {', '.join(html.escape(n) for n in banded)} (Monte Carlo over "
                         "each estimate's parameter covariance).")
        if without and bands:
            parts.append(f"No band for {', '.join(html.escape(n) for n in without)}: no covariance of their "
                         "transfer-function coefficients (a reference, or built from least-squares estimates).")
        self.note.text = " ".join(parts)


class BoardStepFigure(Described):
    """Step responses of the ticked models, of the nonlinear plant under the same controller, and the step."""

    def __init__(self, *, height: int = 300, width: int = FIGURE_WIDTH):
        self.models = ColumnDataSource(data=_empty_lines())
        self.plant = ColumnDataSource(data={"t": _f32([]), "x": _f32([])})
        self.fig = _figure(width=width, height=height, x_axis_label="t [s]", y_axis_label="x [mm]",
                           title="Step response")
        self.fig.multi_line("xs", "ys", source=self.models, color="color", line_width=2, line_dash="dash")
        self.fig.line("t", "x", source=self.plant, color="#333333", line_width=2, line_dash="dashed",
                      name="nonlinear plant, same controller")
        self.reference = Span(location=0.0, dimension="width", line_color="#999999", line_dash="dotted")
        self.fig.add_layout(self.reference)
        self.fig.add_tools(HoverTool(tooltips=[("model", "@name"), ("t", "$x{0.00} s"), ("x", "$y{0.000} mm")]))
        self.legend = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px"})
        _lean(self.fig)
        self.layout = column(self.legend, self.fig, sizing_mode="stretch_width")

    def update(self, entries, views, plant, amplitude_m: float) -> None:
        xs, ys, drawn = [], [], []
        scale = amplitude_m * 1e3
        for e in entries:
            v = views.get(e.key)
            if v is None or not np.all(np.isfinite(v.step.y)):
                continue
            t, y = decimate(v.step.t, v.step.y * scale)
            xs.append(t)
            ys.append(y)
            drawn.append(e)
        self.models.data = _lines(xs, ys, drawn)
        extra = ()
        if plant is not None:
            t, x = decimate(plant.t, plant.y * 1e3)
            self.plant.data = {"t": _f32(t), "x": _f32(x)}
            extra = (("nonlinear plant, same controller", "#333333", "dashed"),)
        else:
            self.plant.data = {"t": _f32([]), "x": _f32([])}
        self.reference.location = scale
        self.fig.title.text = f"Step response to r = {scale:g} mm (dotted)"
        self.legend.text = board_legend(entries, extra)


class PoleZeroFigure(Described):
    """Poles (×) and zeros (○) of the ticked models with their 95 % regions; flagged roots ringed in red.

    The dashed circle is the Nyquist frequency π/Ts of the estimation data: a pole beyond it
    decays within about a sample, and the data say little about it.
    """

    def __init__(self, *, height: int = 420, width: int = FIGURE_WIDTH):
        self.poles = ColumnDataSource(data={k: [] for k in ("x", "y", "color", "name", "what", "flag")})
        self.zeros = ColumnDataSource(data={k: [] for k in ("x", "y", "color", "name", "what", "flag")})
        self.flagged = ColumnDataSource(data={"x": [], "y": []})
        self.regions = ColumnDataSource(data={"xs": [], "ys": [], "color": []})
        # a real root's region is an interval of the real axis: drawn as a thick bar, not a flat patch
        self.intervals = ColumnDataSource(data={"x0": [], "x1": [], "y": [], "color": []})
        self.nyquist = ColumnDataSource(data={"x": [], "y": []})
        # one scale on both axes: a region's shape and the Nyquist circle are drawn true
        self.fig = _figure(width=width, height=height, x_axis_label="Re s [rad/s]", y_axis_label="Im s [rad/s]",
                           title="Poles (×) and zeros (○) with their 95 % regions", match_aspect=True)
        self.fig.patches("xs", "ys", source=self.regions, fill_color="color", fill_alpha=0.18, line_color="color",
                         line_alpha=0.6, name="95 % region")
        self.fig.segment("x0", "y", "x1", "y", source=self.intervals, color="color", line_width=8, line_alpha=0.35,
                         name="95 % interval of a real root")
        self.fig.line("x", "y", source=self.nyquist, color="#999999", line_dash="dashed",
                      name="Nyquist frequency |s| = π/Ts")
        self.fig.scatter("x", "y", source=self.flagged, marker="circle", size=18, fill_alpha=0, line_color="#b00020",
                         line_width=2, name="ringed (weakly determined)")
        r1 = self.fig.scatter("x", "y", source=self.poles, marker="x", size=12, line_width=3, color="color",
                              name="poles")
        r2 = self.fig.scatter("x", "y", source=self.zeros, marker="circle", size=10, fill_alpha=0, line_width=2,
                              color="color", name="zeros")
        self.fig.add_tools(HoverTool(renderers=[r1, r2], tooltips=[("model", "@name"), ("", "@what"),
                                                                   ("", "@flag")]))
        self.fig.add_layout(Span(location=0, dimension="height", line_color="#bbbbbb"))
        self.fig.add_layout(Span(location=0, dimension="width", line_color="#bbbbbb"))
        self.legend = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px"})
        self.note = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px", "color": "#555"},
                        css_classes=["eha-board-pz-note"])
        _lean(self.fig)
        self.layout = column(self.legend, self.fig, self.note, sizing_mode="stretch_width")

    def update(self, entries, views) -> None:
        cols = {"poles": {k: [] for k in self.poles.data}, "zeros": {k: [] for k in self.zeros.data}}
        flagged = {"x": [], "y": []}
        regions = {"xs": [], "ys": [], "color": []}
        intervals = {"x0": [], "x1": [], "y": [], "color": []}
        nyquist = None
        notes = []
        for e in entries:
            v = views.get(e.key)
            if v is None:
                continue
            if v.pz.nyquist is not None and e.kind in ("tf", "record"):
                nyquist = v.pz.nyquist if nyquist is None else max(nyquist, v.pz.nyquist)
            for part, roots in (("poles", v.pz.poles), ("zeros", v.pz.zeros)):
                for r in roots:
                    c = cols[part]
                    c["x"].append(float(r.location.real))
                    c["y"].append(float(r.location.imag))
                    c["color"].append(e.color)
                    c["name"].append(e.name)
                    loc = (f"{r.location.real:.4g}" + (f" ± {abs(r.location.imag):.4g}j" if r.location.imag else "")
                           + " rad/s")
                    if r.interval is not None:
                        intervals["x0"].append(float(r.interval[0]))
                        intervals["x1"].append(float(r.interval[1]))
                        intervals["y"].append(0.0)
                        intervals["color"].append(e.color)
                        loc += f" (95 %: {r.interval[0]:.4g} to {r.interval[1]:.4g})"
                    elif r.outline is not None:
                        regions["xs"].append(np.asarray(r.outline).real.tolist())
                        regions["ys"].append(np.asarray(r.outline).imag.tolist())
                        regions["color"].append(e.color)
                        loc += f" (95 %: ±{r.half_width:.3g} rad/s)"
                    c["what"].append(f"{r.kind} at {loc}")
                    c["flag"].append(f"weakly determined: {r.reason}" if r.weakly_determined else "")
                    if r.weakly_determined:
                        flagged["x"].append(float(r.location.real))
                        flagged["y"].append(float(r.location.imag))
                        notes.append(f"{html.escape(e.name)}: the {r.kind} at {html.escape(loc)} is weakly "
                                     f"determined ({html.escape(r.reason)}).")
        self.poles.data = cols["poles"]
        self.zeros.data = cols["zeros"]
        self.flagged.data = flagged
        self.regions.data = regions
        self.intervals.data = intervals
        if nyquist is not None:
            a = np.linspace(np.pi / 2, 3 * np.pi / 2, 121)
            self.nyquist.data = {"x": (nyquist * np.cos(a)).tolist(), "y": (nyquist * np.sin(a)).tolist()}
        else:
            self.nyquist.data = {"x": [], "y": []}
        self.legend.text = board_legend(entries)
        text = ("Ringed in red: a root the data determine weakly. " + " ".join(notes)) if notes else ""
        if any(e.kind in ("tf", "record") for e in entries):
            text += (" A region assumes the estimate's residuals are white noise: where the residual test on "
                     "the fit view fails, the regions are too small. Zoom in with the box-zoom tool to see the "
                     "small ones.")
        if nyquist is not None:
            text += (f" Dashed: |s| = π/Ts = {nyquist:.0f} rad/s (the Nyquist frequency); a pole beyond it decays "
                     "within about one sample.")
        self.note.text = text.strip()
