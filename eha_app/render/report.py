"""`eha reproduce`'s report: the core's :class:`~eha_core.reproduction.Reproduction`, rendered.

:func:`build_report` has the core compute everything
(:func:`eha_core.reproduction.reproduce`), then writes ``report.html`` (one
self-contained file: Bokeh's JavaScript is inlined, so it opens offline and
its plots stay interactive), the data behind it as CSV in ``data/``, and
``data/results.json`` with every number (:meth:`Reproduction.numbers`).
Figures and tables come from the app's own builders (:mod:`eha_app.render.plots`,
:mod:`eha_app.render.tables`); nothing here computes physics, and every sentence is
filled in from the computed numbers and the parameters they were computed for.
"""

from __future__ import annotations

import datetime as _dt
import html
import json
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np

from eha_core.experiments import (
    PAPER_BETA_E_HAT,
    PAPER_CASES,
    PAPER_EQ25,
    PAPER_EQ26,
    PAPER_FIT_PERCENT,
    PAPER_TABLE3_BETA_E,
    PAPER_TABLE4,
)
from eha_core.params import FIELD_INFO, ActuatorParams
from eha_core.reproduction import REPRODUCTION_STEPS, STATES, Reproduction, reproduce
from eha_core.simulate import runs_to_pandas

from . import plots
from .formatting import json_default, json_safe, num_html, table_html
from .tables import CSS, SYMBOLS_HTML, backout_html, derived_html, freq_summary_html, lse_table_html, table4_html

__all__ = ["ReportResult", "build_report", "differences_from_paper", "SECTIONS"]

#: The paper's own values (Tables 1 and 3), which its printed errors refer to.
PAPER_PARAMS = ActuatorParams()
#: Section ids, in the paper's order (the test checks each is present).
SECTIONS = ("parameters", "fig2", "fig3", "figs4-7", "tables3-4", "figs8-13", "routes", "differences", "versions")
PACKAGES = ("eha", "numpy", "scipy", "control", "numba", "pandas", "bokeh", "panel")


@dataclass
class ReportResult:
    path: Path
    seconds: float
    numbers: dict = field(default_factory=dict)
    reproduction: Reproduction | None = None


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


class _Progress:
    """One line per step on the terminal: [k/n] what ... seconds."""

    def __init__(self, steps: int, stream=None, started: float | None = None):
        self.steps, self.k, self.stream = steps, 0, stream if stream is not None else sys.stderr
        self.t_step = time.perf_counter()
        self.t0 = started if started is not None else self.t_step

    def __call__(self, what: str) -> None:
        now = time.perf_counter()
        if self.k:
            self.stream.write(f" {now - self.t_step:.1f} s\n")
        self.k += 1
        self.t_step = now
        self.stream.write(f"[{self.k}/{self.steps}] {what} ...")
        self.stream.flush()

    def done(self) -> float:
        now = time.perf_counter()
        self.stream.write(f" {now - self.t_step:.1f} s\nreport written in {now - self.t0:.1f} s\n")
        self.stream.flush()
        return now - self.t0


# -- pieces ---------------------------------------------------------------------------

def _params_section(r: Reproduction) -> tuple[str, list[dict]]:
    p = r.params
    source = {"M": "Table 3", "B": "Table 3", "Af": "Table 3", "beta_e": "Table 3", "Dc": "Table 3",
              "dc": "Table 3", "ps": "Table 1", "pr": "Table 1", "k_f": "eq. 2 (900 s/m)",
              "L0": "inferred from eq. 23 (see below)", "Kq1": "inferred from eq. 23", "Kq2": "inferred from eq. 23",
              "d0": "our default (no slow load)", "x0": "section II-A", "v0": "section II-A", "p1_0": "section II-A",
              "p2_0": "force balance (A1/A2) p1(0), section II-A"}
    rows, data = [], []
    for name, info in FIELD_INFO.items():
        value = getattr(p, name) if name != "p2_0" else p.p2_init
        rows.append([name, num_html(value), info.unit, info.description, source.get(name, "")])
        data.append({"name": name, "value": value, "unit": info.unit, "source": source.get(name, "")})
    # how L0 and Kq were inferred: eq. 23's s coefficient (A1 + A2) beta_e / (M L0) fixes L0 alone
    s_paper, gain_paper = 1.721e4, 243.7
    lin_rows = [[f"{row.L0:g}", num_html(row.s_coefficient), num_html(row.gain)] for row in r.l0_inference]
    best = min(r.l0_inference, key=lambda row: abs(row.s_coefficient / s_paper - 1))
    inference = table_html(["L<sub>0</sub> [m]", f"s coefficient (eq. 23: {num_html(s_paper)})",
                            f"gain with K<sub>q</sub> = {num_html(p.Kq1)} (eq. 23: {gain_paper:g})"], lin_rows)
    text = (
        "<p>The paper's Tables 1 and 3 give M, B, A<sub>f</sub>, β<sub>e</sub>, D<sub>c</sub>, d<sub>c</sub>, "
        "p<sub>s</sub>, p<sub>r</sub>; L<sub>0</sub> and the valve gains K<sub>q1</sub> = K<sub>q2</sub> are not "
        "printed. eq. 23's s coefficient (A<sub>1</sub> + A<sub>2</sub>) β<sub>e</sub> / (M L<sub>0</sub>) depends on "
        f"L<sub>0</sub> alone among the unknowns: with these parameters L<sub>0</sub> = {best.L0:g} m gives "
        f"{num_html(best.s_coefficient)} ({100 * (best.s_coefficient / s_paper - 1):+.2f} % from the paper's "
        f"{num_html(s_paper)}); the gain {gain_paper:g} then fixes K<sub>q</sub>, here {num_html(p.Kq1)} "
        f"m<sup>3</sup>/(s V √Pa), which gives {num_html(best.gain)} (table below, computed by the core's "
        "linearisation).</p>")
    html_ = (text + table_html(["symbol", "value (SI)", "unit", "meaning", "source"], rows)
             + "<h3>Inferring L<sub>0</sub> and K<sub>q</sub></h3>" + inference
             + "<h3>Derived values (Tables 1-2, eqs. 21-24)</h3>" + derived_html(p, 10.0))
    return html_, data


def _differences_html(rows) -> str:
    by_case: dict[str, dict] = {}
    for r in rows:
        by_case.setdefault(r.case, {})[r.state] = {"rms": r.rms, "max": r.max}
    header = ["case"] + [f"{n} RMS | max [{u}]" for n, u, _ in STATES]
    body = [[case] + [f"{c[n]['rms']:.3g} | {c[n]['max']:.3g}" for n, _, _ in STATES] for case, c in by_case.items()]
    return table_html(header, body)


def _pct(x: float) -> str:
    return f"{100 * x:+.2f} %"


def differences_from_paper(n: dict) -> list[str]:
    """'Where we differ from the paper and why', every claim computed from ``n``
    (:meth:`Reproduction.numbers`): ours relative to the parameters used, the
    paper's relative to the paper's own values (Tables 1 and 3)."""
    items = []
    ours = n["params"]
    paper = PAPER_PARAMS
    be = n["table3_beta_e_rel_error"]
    paper_be = PAPER_TABLE3_BETA_E / paper.beta_e - 1
    items.append(
        f"<b>Table 3, β<sub>e</sub> without disturbance.</b> The paper: {num_html(PAPER_TABLE3_BETA_E)} Pa "
        f"({_pct(paper_be)}); ours: {num_html(n['table3_beta_e'])} Pa ({_pct(be)}), "
        f"{'closer to' if abs(be) < abs(paper_be) else 'further from'} the nominal value. "
        f"Our regressors are formed on a cubic-spline grid 16 times finer than the samples and filtered there; "
        f"filtering the samples as if linear in between (the classical discretisation) gives B "
        f"{_pct(n['b_linear_interpolation_rel_error'])} and β<sub>e</sub> "
        f"{_pct(n['beta_e_linear_interpolation_rel_error'])} on the same data, ours B {_pct(n['b_none_rel_error'])}.")
    bc, bh = n["b_5000_constant"], n["b_5000_harmonic"]
    covers = n["b_5000_constant_covers"]
    b5 = PAPER_TABLE4["5000 sin"]["B"]
    items.append(
        f"<b>Table 4, B under d = 5000 sin(2πt).</b> The paper: {b5:g} N s/m ({_pct(b5 / paper.B - 1)}). Ours with "
        f"the paper's constant d<sub>0</sub>: {num_html(bc['estimate'])} ({_pct(bc['rel_error'])}), 95 % interval "
        f"[{num_html(bc['ci95'][0])}, {num_html(bc['ci95'][1])}], which {'covers' if covers else 'misses'} the "
        f"nominal value: the unmodelled sinusoid leaves B undetermined and the interval says so. With the harmonic "
        f"model (frequency estimated: {n['harmonic_freq_hz']:.6g} Hz): {num_html(bh['estimate'])} "
        f"({_pct(bh['rel_error'])}).")
    w = n["b_white_constant"]
    bw = PAPER_TABLE4["white noise"]["B"]
    items.append(
        f"<b>Table 4, B under white force noise (σ = 1000 N).</b> The paper: {bw:g} ({_pct(bw / paper.B - 1)}), "
        f"no uncertainty given. Ours: {num_html(w['estimate'])} ({_pct(w['rel_error'])}) "
        f"± {num_html(1.96 * w['std_error'])} (95 %): B v reaches only {n['b_times_vmax_lse']:.0f} N against 1000 N "
        f"of noise, so B is weakly determined. Our richer excitation (8 sin(4πt) + 4 sin(10πt) over 20 s) narrows "
        f"its standard error from {100 * n['b_se_default'] / ours['B']:.0f} % to "
        f"{100 * n['b_se_rich'] / ours['B']:.0f} % of nominal.")
    a1 = n["hhat_den"][1]
    items.append(
        f"<b>eq. 25, the s<sup>2</sup> coefficient of Ĥ(s).</b> The paper: 11.12; ours: {a1:.4g}; both far below "
        f"the linearised {n['theoretical_den'][1]:.4g}. The linearisation takes the friction's slope at v = 0, "
        f"2k<sub>f</sub>A<sub>f</sub>/π; in the experiment |v| reaches {n['vmax_mm_s']:.0f} mm/s ≫ 1/k<sub>f</sub> = "
        f"{n['inv_kf_mm_s']:.2g} mm/s, where the friction is saturated. On the linearised plant the same estimator "
        f"gives {n['linear_plant_a1']:.4g}.")
    items.append(
        f"<b>eq. 25, fit.</b> The paper: {PAPER_FIT_PERCENT} % (initial condition handling not stated). Ours: "
        f"{n['fit_percent']:.2f} % on the estimation data and {n['validation_fit_percent']:.2f} % on a fresh "
        f"excitation, estimating the initial state and a constant input offset. The offset is physical: the valve's "
        f"flows differ with the sign of u, which in the loop acts as a constant offset of r (we found "
        f"{n['input_offset']:.4g}). With the paper's plain structure (zero initial state, no offset) our estimate fits "
        f"{n['fit_percent_plain']:.2f} %.")
    c0, k0 = n["hhat_den"][3], n["hhat_num"][-1]
    pc0, pk0 = PAPER_EQ25[1][3], PAPER_EQ25[0][-1]
    pp_num, pp_den = n["paper_eq26_from_eq25"]
    items.append(
        f"<b>eq. 25, the constant term.</b> The paper: {num_html(pc0)}, so its Ĥ(0) = {num_html(pk0 / pc0, 2)}; ours: "
        f"{num_html(c0)}, Ĥ(0) = {k0 / c0:.3g}. A proportional loop around an integrating plant has a static gain "
        f"of 1. eq. 26 applied to the paper's Ĥ(s) gives P̂(s) = {num_html(pp_num[0])} / (s³ + {num_html(pp_den[1])} s² "
        f"+ {num_html(pp_den[2])} s {'−' if pp_den[3] < 0 else '+'} {num_html(abs(pp_den[3]))}), not its printed "
        f"{num_html(PAPER_EQ26[0][0])} / (s³ + {num_html(PAPER_EQ26[1][1])} s² + {num_html(PAPER_EQ26[1][2])} s + "
        f"{num_html(PAPER_EQ26[1][3])}).")
    items.append(
        f"<b>eq. 27, β<sub>e</sub> backed out.</b> The paper: {num_html(PAPER_BETA_E_HAT)} Pa "
        f"({_pct(PAPER_BETA_E_HAT / paper.beta_e - 1)}). Ours from the s coefficient: "
        f"{num_html(n['beta_e_stiffness'])} ({_pct(n['beta_e_stiffness'] / ours['beta_e'] - 1)}); "
        f"from the gain: {num_html(n['beta_e_gain'])} ({_pct(n['beta_e_gain'] / ours['beta_e'] - 1)}), "
        f"low because eq. 27 uses the u ≥ 0 valve branch (gain {n['gain_positive']:.4g}) while the loop "
        f"switches to the u < 0 branch (gain {n['gain_negative']:.4g}) half of the time.")
    items.append(
        f"<b>Fig. 3, linearised model.</b> Without physical bounds the linearised p<sub>2</sub> reaches "
        f"{n['linear_p2_max_mpa']:.1f} MPa (supply: {n['ps_mpa']:g} MPa) in case 3, as the paper's Fig. 3 axes (up to "
        f"35 MPa) suggest; "
        f"the nonlinear model stays within [{n['nonlinear_p2_range_mpa'][0]:.1f}, "
        f"{n['nonlinear_p2_range_mpa'][1]:.1f}] MPa.")
    return items


# -- the report ---------------------------------------------------------------------------

def build_report(out_dir: str | Path, *, seed: int = 0,
                 params: ActuatorParams | None = None, progress: Callable | None = None,
                 stream=None, started: float | None = None) -> ReportResult:
    """Have the core compute everything, then write ``out_dir/report.html`` and ``out_dir/data/``.

    ``started`` (a ``time.perf_counter()`` value) is when the command began:
    the wall time it reports then includes the imports.
    """

    out = Path(out_dir)
    data_dir = out / "data"
    data_dir.mkdir(parents=True, exist_ok=True)
    step = progress if progress is not None else _Progress(len(REPRODUCTION_STEPS) + 3, stream, started)
    r = reproduce(params, seed=seed, progress=step)
    numbers = {**r.numbers(), "versions": versions(), "generated": _dt.datetime.now().isoformat(timespec="seconds")}

    step("figures and tables")
    params_html, params_rows = _params_section(r)
    _write_csv(data_dir / "parameters.csv", params_rows)
    for name, runs in (("fig2_nonlinear", r.cases_nonlinear), ("fig3_linear", r.cases_linear)):
        _write_runs(data_dir / f"{name}.csv", runs)
    _write_csv(data_dir / "figs4-7_differences.csv", numbers["differences"])
    _write_csv(data_dir / "tables3-4_least_squares.csv", numbers["least_squares"])
    figures: dict[str, object] = {"fig2": plots.TimeSeriesGrid(r.cases_nonlinear).layout,
                                  "fig3": plots.TimeSeriesGrid(r.cases_linear).layout}
    for a, b in zip(r.cases_nonlinear, r.cases_linear, strict=True):
        figures[f"fig{3 + int(a.label[-1])}"] = plots.TimeSeriesGrid([a, b]).layout
    lse_html = ("<h3>Table 3: no disturbance, the paper's constant d<sub>0</sub></h3>"
                + lse_table_html(r.lse["constant"]["none"], "none")
                + "<h3>Table 4: four scenarios, both disturbance models</h3>" + table4_html(r.lse))
    fi = r.frequency
    _write_freq_data(data_dir, fi)
    view = plots.frequency_view(fi)
    fig8 = plots.ExcitationFigure()
    fig8.update(view.excitation_t, view.excitation_r, view.excitation_title)
    figures["fig8"] = fig8.layout
    for key, cls in (("fig9", plots.ClosedLoopFigure), ("fig11", plots.FitFigure), ("fig12", plots.BodeFigure),
                     ("fig13", plots.ValidationFigure), ("residuals", plots.ResidualFigure)):
        fig = cls()
        fig.update(view)
        figures[key] = fig.layout
    freq_html = freq_summary_html(fi) + "<h3>Backed-out parameters (eq. 27)</h3>" + backout_html(fi)
    from .greybox import routes_html

    routes = routes_html(r.params, lse=r.lse["constant"]["none"], backout=fi.backout, greybox=r.greybox)

    step("where we differ from the paper")
    diff_items = differences_from_paper(numbers)
    numbers["differences_from_paper"] = diff_items

    step("writing report.html")
    script, divs = components_alone(figures)
    page = _page(r, numbers, params_html, lse_html, freq_html, _differences_html(r.case_differences), diff_items,
                 divs, script, _bokeh_js(), routes)
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    # (a failed estimate's missing numbers are NaN: JSON has null for them, not the NaN it does not know)
    (data_dir / "results.json").write_text(json.dumps(json_safe(numbers), indent=2, default=json_default,
                                                      allow_nan=False), encoding="utf-8")
    seconds = step.done() if isinstance(step, _Progress) else float("nan")
    return ReportResult(path=path, seconds=seconds, numbers=numbers, reproduction=r)


def _bokeh_js() -> str:
    """Bokeh's JavaScript, inlined: the figures need the core and the widgets (the legend
    Div) only. The tags are written here from the raw code because, once Panel is
    imported, Bokeh's rendered resources also reference
    Panel's module shim, a file a saved page cannot load."""
    from bokeh.resources import Resources

    res = Resources(mode="inline", components=["bokeh", "bokeh-widgets"])
    css = "".join(f"<style>{c}</style>" for c in res.css_raw)
    return css + "".join(f'<script type="text/javascript">{js}</script>' for js in res.js_raw)


def _write_csv(path: Path, rows: list[dict]) -> None:
    import pandas as pd

    pd.DataFrame(rows).to_csv(path, index=False, float_format="%.10g")


def _write_runs(path: Path, runs) -> None:
    runs_to_pandas(runs).to_csv(path, index=False, float_format="%.10g")


def _write_freq_data(data_dir: Path, fi) -> None:
    import pandas as pd

    ts = fi.config.ts
    pd.DataFrame({"k": np.arange(fi.excitation.u.size), "t": np.arange(fi.excitation.u.size) * ts,
                  "r": fi.excitation.u}).to_csv(data_dir / "fig8_excitation.csv", index=False, float_format="%.10g")
    pd.DataFrame({"freq_rad_per_sample": np.ravel(fi.excitation.freqs)}).to_csv(
        data_dir / "fig8_frequencies.csv", index=False, float_format="%.10g")
    fi.data.to_csv(data_dir / "fig9_closed_loop.csv")
    dr = fi.data_response
    data_cols = {"w_rad_s": dr.w, "magnitude_db": dr.magnitude_db, "phase_deg": dr.phase_deg}
    if dr.lower_db is not None:
        data_cols.update(band_lower_db=dr.lower_db, band_upper_db=dr.upper_db)
    pd.DataFrame(data_cols).to_csv(data_dir / f"fig12_data_{dr.method}.csv", index=False, float_format="%.10g")
    if fi.bode is not None:
        b = fi.bode
        pd.DataFrame({"w_rad_s": b.w, "estimate_db": b.estimate.magnitude_db, "estimate_deg": b.estimate.phase_deg,
                      "eq24_db": b.theoretical.magnitude_db, "eq24_deg": b.theoretical.phase_deg}).to_csv(
            data_dir / "fig12_bode.csv", index=False, float_format="%.10g")
    if fi.validation is not None:
        d = fi.validation_data
        pd.DataFrame({"t": d.t, "r": d.r, "x": d.x, "x_model": fi.validation.y_hat}).to_csv(
            data_dir / "fig13_validation.csv", index=False, float_format="%.10g")
        pd.DataFrame({"t": fi.data.t, "r": fi.data.r, "x": fi.data.x, "x_model": fi.estimate_output}).to_csv(
            data_dir / "fig11_fit.csv", index=False, float_format="%.10g")


_INTRO = {
    "parameters": "The physical parameters as the code uses them, where each comes from, and the values derived "
                  "from them: areas, the operating point, λ<sub>1</sub>…λ<sub>6</sub>, a<sub>1</sub>…a<sub>10</sub>, "
                  "and the transfer functions P(s) and H(s) of eqs. 23 and 24, which they reproduce.",
    "fig2": "The nonlinear model (eqs. 1-4, with its physical bounds) under the four cases of section II-A, from "
            "rest at p<sub>1</sub> = 12 MPa. The piston drifts towards +x because the valve's flows differ with the "
            "sign of u; the load disturbance barely changes the response (d/M is small).",
    "fig3": "The linearised model (eqs. 11-14) under the same inputs, with λ<sub>5</sub>, λ<sub>6</sub> switching "
            "with the sign of u; states are absolute (operating point added back, eq. 14). It has no physical "
            "bounds, so the pressures swing wider than the nonlinear model's.",
    "figs4-7": "Nonlinear (solid) against linearised (dashed), one case per figure, and the differences: root mean "
               "square and largest absolute difference per state over the horizon.",
    "tables3-4": "Least-squares estimates of M, B, A<sub>f</sub>, d<sub>0</sub>, β<sub>e</sub> (eqs. 15-18) from "
                 "5 s of 1 kHz sensor data under u = 6 sin(4πt), beside the paper's, with relative errors and 95 % "
                 "intervals (Newey-West: the prefilter colours the residual). Both disturbance models: the paper's "
                 "constant d<sub>0</sub>, and d<sub>0</sub> plus a sinusoid of estimated frequency.",
    "figs8-13": "The closed-loop experiment of section III-B: an idinput sum-of-sines reference (Fig. 8), Kp = 10 "
                "sampled at 0.01 s around the nonlinear plant (Fig. 9), a 3-pole transfer function estimated like "
                "MATLAB's tfest (Fig. 11), its Bode diagram against eq. 24 and the data's empirical transfer "
                "function (Fig. 12), validation on a fresh excitation (Fig. 13), residual checks, and eqs. 25-27.",
    "routes": "Not in the paper: what each route gives for each physical parameter. The least squares (Table 3's "
              "record, d = 0), the transfer function with its back-out (eq. 27: only the damping B + 2 kf Af/π "
              "and βe), and grey-box identification (output error on the nonlinear model, from x, p1 and p2 of "
              "Table 3's record, started from the paper's values).",
    "differences": "Every statement below is filled in from the numbers computed above.",
    "versions": "What produced this report; with the same versions and seed the numbers are the same.",
}


def _section(sid: str, title: str, body: str) -> str:
    return f'<section id="{sid}"><h2>{title}</h2><p class="intro">{_INTRO[sid]}</p>{body}</section>'


def _page(r, numbers, params_html, lse_html, freq_html, diff_table, diff_items, divs, script, resources,
          routes_html: str = "") -> str:
    settings = r.settings

    def figs(*names):
        return "".join(f'<div class="fig"><div class="cap">{cap}</div>{divs[n]}</div>' for n, cap in names)

    per_case = figs(*((f"fig{3 + k}", f"Fig. {3 + k}: {html.escape(PAPER_CASES[k].title)}") for k in (1, 2, 3, 4)))
    xvp = "x, v, p<sub>1</sub>, p<sub>2</sub> against t"
    vers = numbers["versions"]
    version_rows = [[k, html.escape(v)] for k, v in vers.items()]
    toc = "".join(f'<a href="#{sid}">{t}</a>' for sid, t in (
        ("parameters", "Parameters"), ("fig2", "Fig. 2"), ("fig3", "Fig. 3"), ("figs4-7", "Figs. 4-7"),
        ("tables3-4", "Tables 3-4"), ("figs8-13", "Figs. 8-13"), ("routes", "Three routes"),
        ("differences", "Differences"),
        ("versions", "Versions")))
    body = "".join([
        _section("parameters", "Parameters (Tables 1-2)", params_html),
        _section("fig2", "Fig. 2: nonlinear model, four cases", figs(("fig2", xvp))),
        _section("fig3", "Fig. 3: linearised model, four cases", figs(("fig3", xvp))),
        _section("figs4-7", "Figs. 4-7: nonlinear against linearised", per_case + "<h3>Differences</h3>" + diff_table),
        _section("tables3-4", "Tables 3 and 4: least squares", lse_html),
        _section("figs8-13", "Figs. 8-13: transfer-function identification", figs(
            ("fig8", "Fig. 8: excitation"), ("fig9", "Fig. 9: closed-loop data"),
            ("fig11", "Fig. 11: measured and simulated output"), ("fig12", "Fig. 12: Bode diagram"),
            ("fig13", "Fig. 13: validation on a fresh excitation"), ("residuals", "Residual checks (99 % bands)"))
            + "<h3>eqs. 24-27: ours beside the paper's</h3>" + freq_html),
        _section("routes", "Three routes to the physical parameters, side by side", routes_html),
        _section("differences", "Where we differ from the paper, and why",
                 "<ol>" + "".join(f"<li>{item}</li>" for item in diff_items) + "</ol>"),
        _section("versions", "Software versions and settings",
                 table_html(["", "version"], version_rows)
                 + f"<p>Seed {settings.seed}. Generated {numbers['generated']} by "
                   f"<code>eha reproduce --seed {settings.seed}</code>. "
                   "The data behind every figure and table: <code>data/*.csv</code>; "
                   "every number: <code>data/results.json</code>.</p>"),
    ])
    header = f"""<h1>Modeling and identification of an electro-hydraulic actuator: the paper's results, reproduced</h1>
<p>Every figure and table of <i>Modeling and System Identification of Hydraulic-electric Actuator: a GUI
application for illustration</i>, regenerated with this project and set beside the paper's printed numbers.
Seed {settings.seed}; eha {html.escape(vers.get('eha', '?'))}.</p>
<nav>{toc}</nav>"""
    return html_document("EHA: the paper's results, reproduced", header, body, script, resources)


def html_document(title: str, header: str, body: str, script: str, resources: str) -> str:
    """One self-contained page (Bokeh inlined): the report's and a session report's frame."""
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{html.escape(title)}</title>
{resources}
<style>
body {{ font-family: Helvetica, Arial, sans-serif; margin: 0 auto; max-width: 1100px; padding: 0 20px 60px;
       color: #222; }}
header {{ border-bottom: 2px solid #1f77b4; margin-bottom: 10px; }}
nav a {{ margin-right: 14px; font-size: 14px; }}
section {{ margin-top: 28px; }}
h2 {{ border-bottom: 1px solid #ddd; padding-bottom: 4px; }}
.intro {{ color: #444; max-width: 900px; }}
.fig {{ margin: 14px 0 22px; }}
.cap {{ font-weight: 600; margin-bottom: 4px; }}
li {{ margin-bottom: 8px; }}
{CSS}
</style></head>
<body>
<header>{header}</header>
{body}
{script}
</body></html>
"""


# -- the report of one session (the lab report a student hands in) ------------------------

def components_alone(figures: dict):
    """Bokeh's ``components`` of ``figures`` without touching any other document.

    Given models of no document, Bokeh makes one and copies the JavaScript
    callbacks of ``curdoc()`` into it, and takes ``curdoc()``'s theme: in a
    server's worker thread that is whatever page the event loop happens to be
    serving (or one already closed: "'DocumentCallbackManager' object has no
    attribute '_js_event_callbacks'"). The figures are put in a document of
    their own first, and no theme is asked of ``curdoc()``.
    """
    from bokeh.document import Document
    from bokeh.embed import components

    doc = Document()
    for fig in figures.values():
        doc.add_root(fig)
    return components(figures, theme=None)


def session_report(session, snapshot, author: str = "") -> bytes:
    """What this student ran, as one self-contained HTML file: every section's part, in page order
    (its settings, plots, estimates with intervals...), drawn from ``snapshot`` (taken under the
    page's lock; this runs in a worker) by the same code as ``eha reproduce``; an exercise's hidden
    values are left out as on the page. ``author``: the name the student typed (in an exercise the
    report names the student's checked id instead)."""
    figures, parts = {}, []
    intro = f"<p>Student: <b>{html.escape(author)}</b>.</p>" if author else ""
    if snapshot.hidden:
        names = ", ".join(SYMBOLS_HTML.get(n, html.escape(n)) for n in snapshot.hidden)
        intro = (f"<p>Exercise <b>{html.escape(snapshot.exercise_title)}</b>, student "
                 f"<b>{html.escape(snapshot.student)}</b>; hidden: {names}.</p>")
    for section, part in session.report_sections(snapshot):
        if part is None:
            continue
        names = {name: f"{section.key}_{name}" for name in part.figures}
        content = part.html
        for name, unique in names.items():
            content = content.replace("{{" + name + "}}", "{{" + unique + "}}")
            figures[unique] = part.figures[name]
        parts.append((section.key, part.title, content))
    parts.append(("settings", "Settings of this session (load them with “Load settings”)",
                  f"<pre>{html.escape(json.dumps(snapshot.settings, indent=1, ensure_ascii=False))}</pre>"))
    script, divs = components_alone(figures) if figures else ("", {})
    body = intro
    for sid, title, content in parts:
        for key, div in divs.items():
            content = content.replace("{{" + key + "}}", f'<div class="fig">{div}</div>')
        body += f'<section id="{sid}"><h2>{html.escape(title)}</h2>{content}</section>'
    when = _dt.datetime.now().isoformat(timespec="seconds")
    header = (f"<h1>Electro-hydraulic actuator: report of a session</h1><p>Generated {when} by the EHA app "
              f"(eha {html.escape(versions().get('eha', '?'))}).</p>")
    return html_document("EHA: report of a session", header, body, script, _bokeh_js()).encode()
