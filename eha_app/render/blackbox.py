"""What the black-box sub-tab and the report show: the model (its polynomials or matrices and its
parameters with standard errors), its fits in the core's own words (:attr:`Comparison.label`), the
residual tests with their verdicts, the selection table, and the figures (measured against model on
the validation data, the correlations with their bands, poles and zeros in the z-plane, the criteria
against the number of parameters). Every number is the core's; nothing here fits or simulates."""

from __future__ import annotations

import html
import math

import numpy as np
from bokeh.layouts import column, row
from bokeh.models import ColumnDataSource, Div, Range1d, Span

from eha_core.identify.blackbox import horizon_words, initial_words

from .figure_text import Described
from .formatting import num_html
from .plots import CASE_COLORS, FIGURE_WIDTH, _f32, _figure, _lean, _legend_above, correlation_stems, decimate

__all__ = ["STRUCTURE_NAMES", "qpoly_html", "model_html", "fits_html", "verdicts_html", "selection_rows",
           "selection_html", "failed_html", "BlackBoxFitFigure", "CorrelationFigure", "ZPlaneFigure",
           "SelectionFigure", "CSS"]

#: How each structure is named on the page.
STRUCTURE_NAMES = {"arx": "ARX", "armax": "ARMAX", "oe": "OE", "bj": "BJ", "ss": "state space (n4sid)",
                   "process": "process model"}

#: The sub-tab's own rules (wide tables scroll in their own box; a failure stands out as the grey-box's).
CSS = """
.eha-bb-failed { background: #fdecea; border-left: 4px solid #b00020; color: #3d0008; font-size: 13px;
                 padding: 4px 10px; margin: 4px 0 8px 0; overflow-wrap: anywhere; }
.eha-bb-poly { font-size: 14px; margin: 2px 0; overflow-wrap: anywhere; }
.eha-bb-selection td:first-child { white-space: nowrap; }
.eha-bb-matrix { display: inline-block; vertical-align: middle; border-left: 1px solid #333;
                 border-right: 1px solid #333; padding: 0 4px; margin: 0 6px; }
.eha-bb-matrix td { padding: 0 6px; text-align: right; font-size: 13px; }
.eha-bb-matrices { display: flex; flex-wrap: wrap; gap: 6px 14px; align-items: center; font-size: 14px; }
.eha-bb-picked td { background: #e8f4ea; font-weight: 600; }
"""


#: The process models' G(s), as MATLAB's procest writes them.
_PROCESS_FORMS = {"P1": "K / (1 + Tp1 s)", "P1D": "K e^(−Td s) / (1 + Tp1 s)",
                  "P2": "K / ((1 + Tp1 s)(1 + Tp2 s))", "P2D": "K e^(−Td s) / ((1 + Tp1 s)(1 + Tp2 s))",
                  "P1I": "K / (s (1 + Tp1 s))", "P1DI": "K e^(−Td s) / (s (1 + Tp1 s))",
                  "P2I": "K / (s (1 + Tp1 s)(1 + Tp2 s))", "P2DI": "K e^(−Td s) / (s (1 + Tp1 s)(1 + Tp2 s))",
                  "P2DU": "K e^(−Td s) / (1 + 2 Zeta Tw s + (Tw s)²)"}


def _num(v, digits: int = 4) -> str:
    v = float(v)
    return num_html(v, digits) if math.isfinite(v) else "—"


def qpoly_html(coeffs, var: str = "q") -> str:
    """A polynomial in ``q^-1`` from its coefficients in ascending powers: ``1 − 1.5 q⁻¹ + 0.7 q⁻²``.

    Examples
    --------
    >>> qpoly_html([1.0, -1.5, 0.7])
    '1 − 1.5&#8239;q<sup>−1</sup> + 0.7&#8239;q<sup>−2</sup>'
    >>> qpoly_html([0.0, 1.0])
    'q<sup>−1</sup>'
    """
    terms = []
    for k, c in enumerate(np.asarray(coeffs, dtype=float)):
        if c == 0:
            continue
        power = "" if k == 0 else f"{var}<sup>−{k}</sup>" if k > 1 else f"{var}<sup>−1</sup>"
        mag = abs(c)
        coef = num_html(mag) if (mag != 1 or not power) else ""
        body = f"{coef}&#8239;{power}" if coef and power else (coef or power)
        terms.append(("−" if c < 0 else "+", body))
    if not terms:
        return "0"
    sign, first = terms[0]
    return ("−" if sign == "−" else "") + first + "".join(f" {s} {b}" for s, b in terms[1:])


def _matrix_html(name: str, m) -> str:
    m = np.atleast_2d(np.asarray(m, dtype=float))
    rows = "".join("<tr>" + "".join(f"<td>{_num(v)}</td>" for v in r) + "</tr>" for r in m)
    return f"<span>{name} =<table class='eha-bb-matrix'>{rows}</table></span>"


def failed_html(model) -> str:
    """A failed estimate's warning: the core's message (why, and what to try)."""
    return (f"<div class='eha-bb-failed' role='alert'><b>The estimate failed</b> ({html.escape(model.name)}): "
            f"{html.escape(str(model.message))}. Its numbers below are not a model to trust.</div>")


def _polynomials_html(model) -> str:
    out = []
    orders = dict(getattr(model, "orders", {}) or {})
    for poly, order in (("A", "na"), ("B", "nb"), ("C", "nc"), ("D", "nd"), ("F", "nf")):
        if order in orders and hasattr(model, poly):
            out.append(f"<div class='eha-bb-poly'>{poly}(q) = {qpoly_html(getattr(model, poly))}</div>")
    return "".join(out)


def _structure_sentence(model) -> str:
    s = getattr(model, "structure", "")
    return {"arx": "A(q) y(t) = B(q) u(t) + e(t)", "armax": "A(q) y(t) = B(q) u(t) + C(q) e(t)",
            "oe": "y(t) = B(q)/F(q) u(t) + e(t)", "bj": "y(t) = B(q)/F(q) u(t) + C(q)/D(q) e(t)",
            "ss": "x(t+1) = A x(t) + B u(t) + K e(t),  y(t) = C x(t) + D u(t) + e(t)"}.get(s, "")


def model_html(model, input_name: str = "u", output_name: str = "y") -> str:
    """The model as the core estimated it: a failure's warning first, its structure, polynomials (or
    matrices), G(q) and the parameters with ± one standard error."""
    out = failed_html(model) if not model.success else ""
    out += (f"<p><b>{html.escape(model.name)}</b> from {html.escape(input_name)} to "
            f"{html.escape(output_name)}, T<sub>s</sub> = {float(model.ts):g} s"
            + (f": {html.escape(_structure_sentence(model))}" if _structure_sentence(model) else "") + "</p>")
    if getattr(model, "structure", "") == "ss" and hasattr(model, "K"):
        out += ("<div class='eha-bb-matrices'>" + "".join(_matrix_html(n, getattr(model, n))
                                                           for n in ("A", "B", "C", "D", "K")) + "</div>")
    elif getattr(model, "structure", "") == "process" and isinstance(getattr(model, "values", None), dict):
        values = ", ".join(f"{html.escape(str(k))} = {_num(v)}{'' if k == 'K' else ' s' if k != 'Zeta' else ''}"
                           for k, v in model.values.items())
        form = _PROCESS_FORMS.get(getattr(model, "kind", ""))
        out += (f"<div class='eha-bb-poly'>G(s) = {html.escape(form)}</div>" if form else "")
        out += f"<div class='eha-bb-poly'>Continuous-time values: {values}</div>"
    else:
        out += _polynomials_html(model)
    try:
        gb, ga = model.g_poly()
        out += (f"<div class='eha-bb-poly'>G(q) = ({qpoly_html(gb)}) / ({qpoly_html(ga)})</div>")
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        pass
    names = list(getattr(model, "param_names", ()))
    if names:
        values, stds = np.asarray(model.params, float), np.asarray(model.param_std, float)
        if stds.size != values.size:            # no covariance: no standard error to show
            stds = np.full(values.size, np.nan)
        rows = "".join(f"<tr><td>{html.escape(str(n))}</td><td>{_num(v, 5)}</td>"
                       f"<td>{'± ' + _num(s, 2) if s > 0 and math.isfinite(s) else '—'}</td></tr>"
                       for n, v, s in zip(names, values, stds, strict=True))
        out += ("<div class='eha-table-scroll'><table class='eha-table eha-bb-params'><tr><th>parameter</th>"
                "<th>estimate</th><th>± 1 standard error</th></tr>" + rows + "</table></div>")
    message = str(getattr(model, "message", ""))
    if model.success and message:
        out += f"<p class='eha-note'>The estimator says: {html.escape(message)}.</p>"
    return out


def fits_html(est_fit, val_fit, own_fit=None, *, failed: bool = False) -> str:
    """The fits, each in the core's words (``Comparison.label``): on the estimation data and on the
    validation data with the form's horizon and initial conditions, and the estimator's own criterion."""
    rows = []
    for what, cmp_ in (("validation data", val_fit), ("estimation data", est_fit),
                       ("estimation data, the estimator's own criterion", own_fit)):
        if cmp_ is None:
            continue
        name = html.escape(getattr(cmp_, "data_name", "") or "")
        rows.append(f"<tr><td>{what}{f'<br><span class=eha-note>{name}</span>' if name else ''}</td>"
                    f"<td class='eha-bb-fit-label'>{html.escape(cmp_.label)}</td></tr>")
    note = ("<p class='eha-warn'>These fits are of a failed estimate.</p>" if failed else "")
    return (note + "<div class='eha-table-scroll'><table class='eha-table eha-bb-fits'><tr><th>data</th><th>fit</th>"
            "</tr>" + "".join(rows) + "</table></div><p class='eha-note'>fit = 100 (1 − ‖y − ŷ‖ / ‖y − mean y‖) "
            "(MATLAB's compare); simulation is ŷ = G u, a k-step prediction also uses the measured output up to "
            "k samples back.</p>")


def _verdicts(resid):
    """The residual tests' verdicts (``whiteness``, ``independence``), wherever the result holds them."""
    for holder in (resid, getattr(resid, "assessment", None), getattr(resid, "verdicts", None)):
        if holder is not None and hasattr(holder, "whiteness"):
            return [holder.whiteness, holder.independence]
    v = getattr(resid, "verdicts", None)
    return list(v) if isinstance(v, (list, tuple)) else []


def _analysis(resid):
    """The correlations (lags, autocorrelation, cross-correlation and band), wherever the result holds them."""
    for holder in (resid, getattr(resid, "analysis", None), getattr(resid, "correlations", None)):
        if holder is not None and hasattr(holder, "autocorrelation"):
            return holder
    return None


def verdicts_html(resid) -> str:
    """The residual tests' sentences, each marked passed or failed."""
    if resid is None:
        return "<p class='eha-note'>No residual tests: the model could not be simulated on the validation data.</p>"
    items = "".join(f"<li class='{'eha-ok' if v.passed else 'eha-warn'}'>{'✓' if v.passed else '✗'} "
                    f"{html.escape(v.sentence)}</li>" for v in _verdicts(resid))
    return f"<ul class='eha-bb-verdicts eha-readings'>{items}</ul>"


def selection_rows(table) -> list[dict]:
    """The selection table's rows (:class:`~eha_core.identify.selection.SelectionRow`) as the page shows
    them: name, parameters, loss, AIC, BIC, the validation fit (its percent and its words), success and
    whether it is the one picked."""
    return [{"name": r.name, "n_params": int(r.n_params), "loss": float(r.loss), "aic": float(r.aic),
             "bic": float(r.bic), "fit": float(r.validation_fit), "fit_label": r.validation_label,
             "success": bool(r.success), "message": r.message, "picked": i == table.best_index}
            for i, r in enumerate(table.rows)]


def selection_html(table) -> str:
    """The selection table: each candidate's loss, AIC, BIC and validation fit, the picked one marked."""
    rows = selection_rows(table)
    # the fits' horizon and initial conditions, in the words of every fit's label
    words = f"({horizon_words(table.horizon)}, {initial_words(table.initial)})"
    criterion = {"bic": "BIC", "aic": "AIC",
                 "validation fit": "validation fit (the fewest parameters whose validation loss these data "
                                   "cannot tell from the best's: within two standard errors)"}.get(table.criterion,
                                                                                                 table.criterion)
    body = "".join(
        f"<tr class='{'eha-bb-picked' if r['picked'] else ''}'><td>{'▶ ' if r['picked'] else ''}"
        f"{html.escape(r['name'])}{'' if r['success'] else ' <span class=eha-warn>(failed)</span>'}</td>"
        f"<td>{r['n_params']}</td><td>{_num(r['loss'])}</td><td>{_num(r['aic'], 6)}</td><td>{_num(r['bic'], 6)}</td>"
        f"<td>{_num(r['fit'], 3)} %</td></tr>" for r in rows)
    picked = next((r["name"] for r in rows if r["picked"]), None)
    return ("<div class='eha-table-scroll'><table class='eha-table eha-bb-selection'><tr><th>candidate</th>"
            "<th>parameters</th><th>loss V</th><th>AIC</th><th>BIC</th>"
            f"<th>validation fit<br><span class='eha-note'>{html.escape(words)}</span></th></tr>" + body
            + "</table></div>"
            f"<p class='eha-note'>Picked by {html.escape(criterion)}: "
            f"{html.escape(picked) if picked else 'none'} (▶). Loss, AIC and BIC are of the one-step prediction "
            "errors on the estimation data (MATLAB's raw AIC = N log V + 2d + N(log 2π + 1)); the validation fit "
            "is on data the candidates were not estimated from. A failed candidate is never picked.</p>")


class BlackBoxFitFigure(Described):
    """The validation data's output and the model's (MATLAB ``compare``), titled with the fit's label."""

    def __init__(self, *, height: int = 280, width: int = FIGURE_WIDTH):
        self.source = ColumnDataSource(data={"t": _f32([0.0]), "y": _f32([0.0]), "yhat": _f32([0.0])})
        self.fig = _figure(width=width, height=height, x_axis_label="t [s]", y_axis_label="x [mm]",
                           title="Validation data")
        r1 = self.fig.line("t", "y", source=self.source, color="#333333", line_width=1.5, name="measured")
        r2 = self.fig.line("t", "yhat", source=self.source, color=CASE_COLORS[0], line_width=1.5,
                           line_dash="dashed", name="model")
        from bokeh.models import LegendItem

        self.items = [LegendItem(label="measured", renderers=[r1]), LegendItem(label="model", renderers=[r2])]
        # one label a row: the model's carries the fit's words, long for a narrow page
        _legend_above(self.fig, self.items, ncols=1)
        _lean(self.fig)
        self.layout = self.fig

    def update(self, comparison, output_name: str = "x [mm]") -> None:
        t = comparison.t if comparison.t is not None else np.arange(np.size(comparison.y), dtype=float)
        t, y, yhat = decimate(np.asarray(t, float), np.asarray(comparison.y, float), np.asarray(comparison.yhat, float))
        yhat = np.where(np.isfinite(yhat), yhat, np.nan)
        self.source.data = {"t": _f32(t), "y": _f32(y), "yhat": _f32(yhat)}
        self.fig.yaxis.axis_label = output_name
        self.items[1].label = {"value": f"model: {comparison.label}"}
        self.fig.title.text = "Measured and model output on the validation data"


class CorrelationFigure(Described):
    """The residuals' autocorrelation and their cross-correlation with the input, with the 99 % band."""

    def __init__(self, *, height: int = 240, width: int = 340):
        self.sources, self.bands, self.figs = [], [], []
        for title, color in (("Residual autocorrelation", CASE_COLORS[0]),
                             ("Cross-correlation input → residual", CASE_COLORS[3])):
            # fixed-size figures: the page sets them in a wrapping row (two across on a wide page, one on
            # a narrow one), the report in a row
            fig, src, band = correlation_stems(title, color, sizing_mode="fixed")
            src.data = {"lag": _f32([0.0]), "c": _f32([0.0]), "zero": _f32([0.0])}
            fig.width, fig.height = width, height
            self.sources.append(src)
            self.bands.append(band)
            self.figs.append(fig)
        _lean(*self.figs)
        self.note = Div(text="", sizing_mode="stretch_width", styles={"font-size": "12px", "color": "#555"})
        self.width = width
        self._layout = None

    @property
    def layout(self):
        """The report's row of the two figures and the band's note (made on first use: the page lays the
        figures out itself, :meth:`panes`)."""
        if self._layout is None:
            self._layout = column(row(*self.figs), self.note, sizing_mode="stretch_width")
        return self._layout

    def band_text(self) -> str:
        return self.note.text

    def update(self, resid) -> None:
        a = _analysis(resid)
        if a is None:
            for src in self.sources:
                src.data = {"lag": _f32([0.0]), "c": _f32([0.0]), "zero": _f32([0.0])}
            self.note.text = ""
            return
        band = float(getattr(a, "confidence_bound", 0.0))
        for src, b, lags, c in ((self.sources[0], self.bands[0], a.lags, a.autocorrelation),
                                (self.sources[1], self.bands[1], a.cross_lags, a.cross_correlation)):
            src.data = {"lag": _f32(lags), "c": _f32(c), "zero": _f32(np.zeros(len(lags)))}
            b.bottom, b.top = -band, band
        self.note.text = (f"Grey band: the 99 % band ±{band:.3g} (2.58/√N) of white residuals independent of the "
                          "input; positive lags of the cross-correlation: the residual after the input.")


class ZPlaneFigure(Described):
    """Poles (×) and zeros (○) of G in the z-plane with the unit circle (the stability boundary)."""

    def __init__(self, *, size: int = 320):
        theta = np.linspace(0, 2 * np.pi, 241)
        self.poles = ColumnDataSource(data={"x": [], "y": []})
        self.zeros = ColumnDataSource(data={"x": [], "y": []})
        self.fig = _figure(sizing_mode="fixed", x_axis_label="Re z", y_axis_label="Im z",
                           title="Poles (×) and zeros (○) of G", toolbar_location="below",
                           x_range=Range1d(-1.3, 1.3), y_range=Range1d(-1.3, 1.3))
        # about a square plot area (the y axis's labels left, the title and the toolbar above and below), equal
        # ranges: the unit circle drawn round; a fixed figure fits an 800 px page, and a wide one beside the model
        self.fig.width, self.fig.height = size, size + 40
        self.size = size
        self.fig.line(_f32(np.cos(theta)), _f32(np.sin(theta)), color="#999999", line_dash="dashed",
                      name="unit circle")
        self.fig.add_layout(Span(location=0, dimension="height", line_color="#bbbbbb"))
        self.fig.add_layout(Span(location=0, dimension="width", line_color="#bbbbbb"))
        self.fig.scatter("x", "y", source=self.poles, marker="x", size=12, line_width=3, color=CASE_COLORS[0],
                         name="poles")
        self.fig.scatter("x", "y", source=self.zeros, marker="circle", size=10, fill_alpha=0, line_width=2,
                         color=CASE_COLORS[1], name="zeros")
        _lean(self.fig)
        self.layout = self.fig

    def update(self, poles, zeros) -> None:
        # (None: the model's roots could not be computed, e.g. a failed estimate's NaN coefficients)
        poles, zeros = (np.atleast_1d(np.asarray(r if r is not None else [], complex)) for r in (poles, zeros))
        poles, zeros = poles[np.isfinite(poles)], zeros[np.isfinite(zeros)]
        self.poles.data = {"x": poles.real.tolist(), "y": poles.imag.tolist()}
        self.zeros.data = {"x": zeros.real.tolist(), "y": zeros.imag.tolist()}
        # the unit circle always in sight, and any root beyond it
        reach = max(1.3, 1.1 * float(np.max(np.abs(np.r_[poles, zeros]), initial=0.0)))
        reach = min(reach, 1e3)
        self.fig.x_range.start, self.fig.x_range.end = -reach, reach
        self.fig.y_range.start, self.fig.y_range.end = -reach, reach


class SelectionFigure(Described):
    """The candidates' AIC and BIC, and their validation fit, against the number of parameters; the
    picked candidate ringed."""

    def __init__(self, *, height: int = 260, width: int = FIGURE_WIDTH):
        self.crit = ColumnDataSource(data={"n": [], "aic": [], "bic": [], "name": []})
        self.fits = ColumnDataSource(data={"n": [], "fit": [], "name": []})
        self.picked_crit = ColumnDataSource(data={"n": [], "aic": []})
        self.picked_fit = ColumnDataSource(data={"n": [], "fit": []})
        self.fig_crit = _figure(width=width // 2, height=height, title="Information criteria",
                                x_axis_label="parameters", y_axis_label="AIC, BIC")
        a = self.fig_crit.scatter("n", "aic", source=self.crit, marker="circle", size=8, color=CASE_COLORS[0],
                                  name="AIC")
        b = self.fig_crit.scatter("n", "bic", source=self.crit, marker="square", size=7, color=CASE_COLORS[1],
                                  name="BIC")
        p1 = self.fig_crit.scatter("n", "aic", source=self.picked_crit, marker="circle", size=18, fill_alpha=0,
                                   line_color="#b00020", line_width=2, name="picked")
        self.fig_fit = _figure(width=width // 2, height=height, title="Validation fit",
                               x_axis_label="parameters", y_axis_label="fit [%]")
        c = self.fig_fit.scatter("n", "fit", source=self.fits, marker="circle", size=8, color=CASE_COLORS[2],
                                 name="validation fit")
        p2 = self.fig_fit.scatter("n", "fit", source=self.picked_fit, marker="circle", size=18, fill_alpha=0,
                                  line_color="#b00020", line_width=2, name="picked")
        from bokeh.models import LegendItem

        _legend_above(self.fig_crit, [LegendItem(label="AIC", renderers=[a]), LegendItem(label="BIC", renderers=[b]),
                                      LegendItem(label="picked", renderers=[p1])])
        _legend_above(self.fig_fit, [LegendItem(label="validation fit", renderers=[c]),
                                     LegendItem(label="picked", renderers=[p2])])
        _lean(self.fig_crit, self.fig_fit)
        self.layout = row(self.fig_crit, self.fig_fit, sizing_mode="stretch_width")

    def update(self, table) -> None:
        rows = [r for r in selection_rows(table) if r["success"]]
        ok = [r for r in rows if math.isfinite(r["aic"]) and math.isfinite(r["bic"])]
        fit = [r for r in rows if math.isfinite(r["fit"])]
        self.crit.data = {"n": [r["n_params"] for r in ok], "aic": [r["aic"] for r in ok],
                          "bic": [r["bic"] for r in ok], "name": [r["name"] for r in ok]}
        # a fit of -1e4 % (a candidate that diverges on the validation data) would flatten the others
        self.fits.data = {"n": [r["n_params"] for r in fit], "fit": [max(r["fit"], -100.0) for r in fit],
                          "name": [r["name"] for r in fit]}
        picked = [r for r in rows if r["picked"]]
        self.picked_crit.data = {"n": [r["n_params"] for r in picked if r in ok],
                                 "aic": [r["aic"] for r in picked if r in ok]}
        self.picked_fit.data = {"n": [r["n_params"] for r in picked if r in fit],
                                "fit": [max(r["fit"], -100.0) for r in picked if r in fit]}
