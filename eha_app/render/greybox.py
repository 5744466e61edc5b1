"""What the grey-box sub-tab and the report show: the estimates' table, the correlation matrix, the
identifiability sentences, the residual verdicts, the three routes side by side and the figure of
measured against simulated signals (numbers from the core, never copied)."""

from __future__ import annotations

import html
import math

import numpy as np
from bokeh.layouts import gridplot
from bokeh.models import ColumnDataSource, LegendItem

from eha_core.experiments import PAPER_TABLE4

from .figure_text import Described
from .formatting import display_unit, estimate_texts, num_html, pct_short, pct_text, table_html
from .plots import CASE_COLORS, FIGURE_WIDTH, _f32, _figure, _lean, _legend_above, decimate
from .tables import SCENARIOS, SYMBOLS_HTML, UNITS

__all__ = ["greybox_table_html", "checks_html", "held_text", "at_bound", "correlation_html", "identifiability_html",
           "verdicts_html", "routes_html", "GreyBoxFigure", "SIGNAL_DISPLAY", "ROUTE_PARAMS"]

#: How each measured signal is drawn: its title, axis label and the factor from SI.
SIGNAL_DISPLAY = {"x": ("Position", "x [mm]", 1e3), "v": ("Velocity", "v [mm/s]", 1e3),
                  "p1": ("Piston-chamber pressure", "p₁ [MPa]", 1e-6), "p2": ("Rod-chamber pressure", "p₂ [MPa]", 1e-6)}
_STATE_COLUMN = {"x": 0, "v": 1, "p1": 2, "p2": 3}
#: The physical parameters every route speaks of (the side-by-side table's rows).
ROUTE_PARAMS = ("M", "B", "Af", "beta_e")


def _num(v: float) -> str:
    return num_html(v, 5) if v != 0 else "0"


def _unit(name: str) -> str:
    """The unit a parameter is written in, as on tab 1 (βe in GPa)."""
    return display_unit(name, UNITS.get(name, ""))[0]


def _scale(name: str) -> float:
    """The factor from SI to :func:`_unit`."""
    return display_unit(name)[1]


def _name(name: str) -> str:
    return SYMBOLS_HTML.get(name, html.escape(name))


def at_bound(res) -> tuple[str, ...]:
    """The parameters whose estimate ended at a bound of its range (the core's bounds check)."""
    return tuple(n for c in res.failed_checks if c.name == "bounds" for n in c.about)


def held_text(res, name: str) -> str:
    """A held parameter's row: its value and how it moves the estimates if it is 10 % off (the core's
    ``held_bias``), e.g. "held at the initial value, 1500 N s/m; if it is 10 % off, M moves by +4.1 %, Af by
    -2.0 %"."""
    text = f"held at the initial value, {_num(res.estimates[name] / _scale(name))} {_unit(name)}"
    moves = [(m, v) for m, v in (res.held_bias.get(name) or {}).items() if math.isfinite(v)]
    if moves:
        parts = [f"{_name(m)} {'moves ' if k == 0 else ''}by {pct_short(v)}" for k, (m, v) in enumerate(moves)]
        text += "; if it is 10 % off, " + ", ".join(parts)
    return text


def checks_html(res) -> str:
    """Whether the estimate holds, from its own checks (the core's ``checks``): an alert with each failed
    check and what to try, or one line of the checks passed; and how it was fitted (``strategy``)."""
    how = (f"<p class='eha-note eha-gb-strategy'>How it was fitted: {html.escape(res.strategy)}.</p>"
           if res.strategy else "")
    if res.success:
        passed = "; ".join(html.escape(c.says) for c in res.checks)
        return (f"<p class='eha-gb-checks eha-gb-passed'><span class='eha-ok'>Checks passed ✓</span> {passed}.</p>"
                + how) if passed else how
    failed = res.failed_checks
    found = "".join(f"<li>{html.escape(c.says)}</li>" for c in failed) or f"<li>{html.escape(res.message)}</li>"
    tries = "".join(f"<li>{html.escape(a)}</li>" for a in res.advice)
    return ("<div class='eha-gb-checks eha-gb-failed' role='alert'><b>This estimate may be wrong</b>: it failed "
            f"{'its check' if len(failed) == 1 else 'its checks'}, so no interval, standard error or correlation is "
            f"given.<ul class='eha-gb-found'>{found}</ul>"
            + (f"<b>What to try</b><ul class='eha-gb-advice'>{tries}</ul>" if tries else "") + "</div>" + how)


def greybox_table_html(res, nominal, *, hidden=(), scenario: str | None = None, own_record: bool = False) -> str:
    """Each estimated parameter: estimate, 95 % interval, standard error, the nominal (tab 1) value and
    the difference, and the paper's least-squares number of the same case (Table 4) where it gives one;
    above them, whether the estimate passed its checks (:func:`checks_html`). An estimate that failed
    them has no interval or standard error (the core gives none); a parameter at a bound of its range
    and one held at its initial value say so in their row, the held one with the bias it can cause.

    ``nominal``: tab 1's :class:`~eha_core.params.ActuatorParams` (the plant the record came from);
    ``hidden``: an exercise's hidden parameters (no nominal value, difference or paper column);
    ``own_record``: the student's file (nothing is known to compare with)."""
    known = not own_record
    paper = PAPER_TABLE4.get(scenario) if known and not hidden and scenario in PAPER_TABLE4 else None
    bound = at_bound(res)
    rows = []
    for n in res.names:
        v, lo_hi, se = res.estimates[n], res.ci95[n], res.std_errors[n]
        scale = _scale(n)
        given = n not in res.held and res.success and all(math.isfinite(c) for c in lo_hi)
        shown, interval = estimate_texts(v, *lo_hi, scale) if given else (_num(v / scale), "")
        row = [f"{_name(n)} [{_unit(n)}]", shown]
        if n in res.held:
            row += [f"<span class='eha-gb-held-row'>{held_text(res, n)}</span>", ""]
        elif n in bound:
            row += ["<span class='eha-warn eha-gb-at-bound'>at the bound of its range</span>", "—"]
        elif given:
            row += [interval, num_html(se / scale, 2)]
        else:
            row += ["<span class='eha-gb-no-interval'>—</span>", "—"]
        if known:
            if n in hidden:
                row += ["hidden", ""]
            else:
                nom = _nominal(nominal, n)
                inside = given and lo_hi[0] <= nom <= lo_hi[1]
                diff = "" if nom == 0 else pct_text(v / nom - 1, 3)
                mark = " <span class='eha-ok'>covers ✓</span>" if inside else ""
                row += [_num(nom / scale), diff + mark]
        if paper is not None:
            p = paper.get(n)
            row.append("" if p is None else f"{_num(p / scale)}<br><small class='eha-cite'>Table 4, "
                                             f"{SCENARIOS[scenario]}</small>")
        rows.append(row)
    header = (["parameter", "estimate", "95 % interval", "std. error"]
              + (["nominal (tab 1)" if not hidden else "known value", "difference"] if known else [])
              + (["paper (least squares)"] if paper is not None else []))
    fits = ", ".join(f"{SIGNAL_DISPLAY[s][1].split(' ')[0]} {f:.2f} %" for s, f in res.fit.items())
    note = (f"<p class='eha-note eha-gb-fit'>Fit of the simulated signals to the measured ones (NRMSE, as MATLAB's "
            f"compare): {fits}. {res.nfev} simulations with sensitivities, {res.time_s:.2f} s.</p>")
    return (checks_html(res) + "<div class='eha-table-scroll'>" + table_html(header, rows, cls="eha-table eha-gb-table")
            + "</div>" + note)


def _nominal(params, name: str) -> float:
    if name == "p2_0":
        return float(params.initial_state[3])
    return float(getattr(params, name))


def correlation_html(res) -> str:
    """The estimates' correlation matrix; |r| > 0.9 (the data hardly separate the two) highlighted. Only
    when it means something: an estimate that failed its checks, or one whose estimated parameters'
    correlations are not all finite, gets a sentence saying why there is none."""
    names = [n for n in res.names]
    c = np.asarray(res.correlation, dtype=float)
    free = [i for i, n in enumerate(names) if n not in res.held]
    if not res.success:
        return ("<p class='eha-note eha-gb-corr-hidden'>Not shown: the estimate failed its checks, so the "
                "correlations of its estimates describe a minimum that may not be the answer.</p>")
    if c.shape != (len(names), len(names)) or not np.all(np.isfinite(c[np.ix_(free, free)])):
        return ("<p class='eha-note eha-gb-corr-hidden'>Not shown: the data do not bound every estimate, so their "
                "correlations are not defined.</p>")
    rows = []
    for i, a in enumerate(names):
        cells = [f"<b>{_name(a)}</b>"]
        for j in range(len(names)):
            r = c[i, j] if i < c.shape[0] and j < c.shape[1] else math.nan
            if i == j:
                cells.append("1")
            elif not math.isfinite(r):
                cells.append("–")
            elif abs(r) > 0.9:
                cells.append(f"<span class='eha-warn eha-gb-high'>{r:+.3f}</span>")
            else:
                cells.append(f"{r:+.3f}")
        rows.append(cells)
    header = [""] + [_name(n) for n in names]
    return ("<div class='eha-table-scroll'>" + table_html(header, rows, cls="eha-table eha-gb-corr") + "</div>"
            "<p class='eha-note'>|r| &gt; 0.9 in red: the data hardly tell those two apart (a change of one is "
            "nearly made up by the other).</p>")


def identifiability_html(res) -> str:
    """What the data cannot determine, in words, and which parameters were held at their initial value."""
    items = "".join(f"<li>{html.escape(s)}</li>" for _, s in res.identifiability)
    held = ""
    if res.held:
        held = (f"<p class='eha-gb-held'>Held at the initial guess (the data do not determine them): "
                f"{', '.join(_name(n) for n in res.held)}.</p>")
    if not items:
        return ("<p class='eha-ok eha-gb-identifiable'>The data determine every estimated parameter (no singular "
                "direction of the scaled Jacobian has a standard error above 1).</p>" + held)
    return f"<ul class='eha-readings eha-gb-sentences'>{items}</ul>" + held


def verdicts_html(res) -> str:
    """The residual tests on the first measured signal's output error, as the model board shows them."""
    a = res.assessment
    if a is None:
        return ""
    lines = "".join(f"<div>{'✓' if v.passed else '✗'} {html.escape(v.sentence)}</div>" for v in a.verdicts)
    first = res.measured[0] if res.measured else "x"
    return (f"<div class='eha-gb-verdicts' style='font-size:13px'><b>Residuals of {html.escape(first)}</b> "
            f"(measured − simulated):{lines}</div>")


# -- the three routes ----------------------------------------------------------------------------------

def _cell(v: float, ci: tuple[float, float] | None, truth: float | None, scale: float = 1.0) -> str:
    if ci is not None and all(math.isfinite(c) for c in ci):
        shown, interval = estimate_texts(v, *ci, scale)
        out = f"{shown}<br><small>{interval}</small>"
    else:
        out = _num(v / scale)
    if truth:
        out += f"<br><small>{pct_text(v / truth - 1, 2)}</small>"
    return out


def _lse_cell(lse, n, truth):
    if lse is None:
        return "<i>not run</i>"
    return _cell(lse.estimates[n], lse.ci95.get(n), truth, _scale(n)) if n in lse.estimates else "–"


def _tf_cell(backout, n, truth):
    """The transfer function's: M is taken as measured by eq. 27, B and Af only as their sum (the last row)."""
    if backout is None:
        return "<i>not run</i>"
    if n == "beta_e":
        ci = backout.ci95().get("beta_e_from_gain")
        return _cell(backout.beta_e_from_gain, ci, truth, _scale(n)) + "<br><small>from the gain</small>"
    if n == "M":
        m = backout.known.get("M")
        return "taken as measured" + (f" ({_num(m)})" if m is not None else "")
    return "only B + 2k<sub>f</sub>A<sub>f</sub>/π (below)"


#: What a grey-box estimate that failed its checks says beside its value in the side-by-side table.
_MAY_BE_WRONG = "<br><small class='eha-warn eha-gb-may-be-wrong'>may be wrong (failed its checks)</small>"


def _gb_cell(gb, n, truth):
    if gb is None:
        return "<i>not run</i>"
    if n not in gb.estimates:
        return "not estimated"
    held = n in gb.held
    ci = None if held or not gb.success else gb.ci95[n]
    return (_cell(gb.estimates[n], ci, truth, _scale(n)) + ("<br><small>held</small>" if held else "")
            + ("" if gb.success or held else _MAY_BE_WRONG))


def _damping_row(params, lse, backout, gb, hidden) -> list:
    """B + 2 kf Af / π, the one combination of B and Af the frequency domain determines, from every route."""
    kf = params.k_f if params is not None and "k_f" not in hidden else None
    comb_hidden = bool({"B", "Af", "k_f"} & set(hidden)) or params is None
    truth = None if comb_hidden else params.B + 2 * params.k_f * params.Af / math.pi
    row = ["B + 2k<sub>f</sub>A<sub>f</sub>/π [N s/m]", "hidden" if comb_hidden else _num(truth)]
    if lse is None:
        row.append("<i>not run</i>")
    elif kf is not None and {"B", "Af"} <= set(lse.estimates):
        row.append(_cell(lse.estimates["B"] + 2 * kf * lse.estimates["Af"] / math.pi, None, truth))
    else:
        row.append("–")
    row.append("<i>not run</i>" if backout is None else _cell(backout.damping, backout.ci95().get("damping"), truth))
    if gb is None:
        row.append("<i>not run</i>")
    elif set(hidden) & ({"B", "Af", "k_f"} - set(gb.estimates)):
        row.append("–")         # a hidden value the run held, not estimated: never shown
    else:
        p = gb.params
        row.append(_cell(p.B + 2 * p.k_f * p.Af / math.pi, None, truth) + ("" if gb.success else _MAY_BE_WRONG))
    return row


def routes_html(params, lse=None, backout=None, greybox=None, *, hidden=()) -> str:
    """What least squares, the transfer function with its back-out (eq. 27) and grey-box estimation give
    for each physical parameter, with 95 % intervals and the difference from tab 1's value (``params``);
    a route not run says so. ``hidden``: an exercise's hidden parameters (no truth, no differences)."""
    def truth(n):
        return None if n in hidden or params is None else _nominal(params, n)

    rows = [[f"{_name(n)} [{_unit(n)}]", "hidden" if n in hidden else _num(truth(n) / _scale(n)),
             _lse_cell(lse, n, truth(n)), _tf_cell(backout, n, truth(n)), _gb_cell(greybox, n, truth(n))]
            for n in ROUTE_PARAMS]
    rows.append(_damping_row(params, lse, backout, greybox, hidden))
    header = ["parameter", "tab 1", "least squares (eqs. 15-18)", "transfer function → eq. 27",
              "grey-box (nonlinear model)"]
    return ("<div class='eha-table-scroll'>" + table_html(header, rows, cls="eha-table eha-routes") + "</div>"
            "<p class='eha-note'>Each route's last run in this session: the estimate, its 95 % interval and its "
            "difference from tab 1's value. The transfer function sees the linearised model only: it takes M as "
            "measured and determines B and A<sub>f</sub> only as the damping B + 2k<sub>f</sub>A<sub>f</sub>/π; "
            "least squares need both pressures and the velocity (or dx/dt) measured; grey-box estimation "
            "simulates the nonlinear model and needs only what is measured, at the price of an iterative fit "
            "from an initial guess.</p>")


# -- the figure ------------------------------------------------------------------------------------------

class GreyBoxFigure(Described):
    """One plot per measured signal: the record (grey) against the model simulated with the estimates
    (the legend says only "simulated": a longer label overflowed a plot's width at 800 px)."""

    def __init__(self, t, measured: dict, simulated, *, height: int = 220, width: int = FIGURE_WIDTH):
        figs = []
        x_range = None
        names = list(measured)
        self.names = tuple(names)
        self.sources = {}
        share = width // 2 if len(names) > 1 else width
        for k, s in enumerate(names):
            title, label, scale = SIGNAL_DISPLAY[s]
            src = self.sources[s] = ColumnDataSource(data=self._columns(t, measured, simulated, s))
            kw = {"x_range": x_range} if x_range is not None else {}
            fig = _figure(width=share, height=height, x_axis_label="t [s]", y_axis_label=label, title=title, **kw)
            x_range = fig.x_range
            m = fig.line("t", "m", source=src, color="#888888", line_width=1.5, name="measured")
            r = fig.line("t", "s", source=src, color=CASE_COLORS[1], line_dash="dashed", line_width=2, name="simulated")
            if k == 0:
                _legend_above(fig, [LegendItem(label="measured", renderers=[m]),
                                    LegendItem(label="simulated", renderers=[r])], ncols=2)
            _lean(fig)
            figs.append(fig)
        self.figures = figs
        self.layout = gridplot(figs, ncols=2 if len(figs) > 1 else 1, sizing_mode="stretch_width",
                               toolbar_location="right", merge_tools=True)

    @staticmethod
    def _columns(t, measured: dict, simulated, s: str) -> dict:
        scale = SIGNAL_DISPLAY[s][2]
        td, ym, ys = decimate(np.asarray(t), np.asarray(measured[s]) * scale,
                              np.asarray(simulated[:, _STATE_COLUMN[s]]) * scale)
        return {"t": _f32(td), "m": _f32(ym), "s": _f32(ys)}

    def update(self, t, measured: dict, simulated) -> bool:
        """Show another run in the same figures (new column data, no new models); False when its
        signals are not the ones these figures plot (then make a new figure)."""
        if tuple(measured) != self.names:
            return False
        for s, src in self.sources.items():
            src.data = self._columns(t, measured, simulated, s)
        return True
