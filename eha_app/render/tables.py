"""HTML tables shared by the app and the report (numbers from the core, never copied)."""

from __future__ import annotations

import html
import math

import numpy as np

from eha_core.experiments import PAPER_EQ25, PAPER_EQ26, PAPER_FIT_PERCENT, PAPER_TABLE3_BETA_E, PAPER_TABLE4
from eha_core.identify.backout import open_loop_instability
from eha_core.identify.lse_reading import read_all
from eha_core.linear import linearize
from eha_core.param_table import FIELD_INFO
from eha_core.params import ActuatorParams

from .formatting import display_unit, estimate_texts, num_html, pct_text, poles_html, table_html, tf_html
from .glossary import term

__all__ = ["CSS", "SCENARIOS", "derived_html", "lse_table_html", "table4_html", "freq_summary_html", "backout_html",
           "estimate_alert", "estimation_sentences", "SYMBOLS_HTML", "UNITS",
           "reading_mark", "readings_html", "paper_gaps", "open_loop_note", "assumed_model_html"]

#: Styles of the formulas and tables (the app's page and the report).
CSS = """
.eha-tf { display: flex; align-items: center; gap: 8px; margin: 4px 0; font-size: 15px; }
.eha-frac { display: inline-flex; flex-direction: column; text-align: center; white-space: nowrap; }
.eha-tf { overflow-x: auto; }
/* a wide table scrolls in its own box: "width: 0; min-width: 100%" keeps it from widening the boxes around it */
.eha-table-scroll { overflow-x: auto; width: 0; min-width: 100%; }
.eha-table4 td { white-space: nowrap; }
.eha-frac .eha-num { border-bottom: 1px solid #333; padding: 0 6px; }
.eha-frac .eha-den { padding: 0 6px; }
.eha-tf-note { color: #666; font-size: 12px; margin-left: 8px; }
.eha-table { border-collapse: collapse; font-size: 13px; margin: 4px 12px 8px 0; }
.eha-table th, .eha-table td { border-bottom: 1px solid #ddd; padding: 3px 8px; text-align: left; }
.eha-table th { background: #f3f5f8; }
.eha-two { display: flex; flex-wrap: wrap; }
.eha-ok { color: #1b5e20; }
.eha-warn { color: #b00020; font-weight: 600; }
.eha-undetermined { color: #8a5a00; font-weight: 600; }
.eha-readings { font-size: 13px; margin: 4px 0 8px 0; padding-left: 18px; }
.eha-cite { color: #666; }
.eha-warn-note { font-size: 13px; margin: 2px 0 6px 0; }
.eha-stale { color: #b00020; font-style: italic; }
.eha-invalid input { border-color: #b00020 !important; background: #fff4f4 !important; }
h4 { margin: 12px 0 4px 0; }
.eha-note { color: #555; font-size: 12px; }
.eha-table4 td { vertical-align: top; }
.eha-out-of-date { opacity: 0.4; filter: grayscale(0.7); }
.eha-updating { box-shadow: -3px 0 0 0 #8ab4f8; }
abbr.eha-term { text-decoration: underline dotted; cursor: help; }
.eha-gb-failed { background: #fdecea; border-left: 4px solid #b00020; color: #3d0008; font-size: 13px;
                 padding: 4px 10px; margin: 4px 0 8px 0; overflow-wrap: anywhere; }
.eha-gb-failed ul { margin: 2px 0 4px 0; padding-left: 18px; }
.eha-gb-passed { font-size: 13px; margin: 4px 0; }
.eha-gb-no-interval { color: #666; }
.eha-stale-note { background: #fff4e5; border-left: 4px solid #e08a00; color: #5a3b00; font-size: 13px;
                  padding: 2px 8px; }
"""

SCENARIOS = {"none": "d = 0", "200 sin": "d = 200 sin(2πt)", "5000 sin": "d = 5000 sin(2πt)",
             "white noise": "white noise, σ = 1000 N", "custom": "custom"}
#: The one spelling of every name the pages and reports show: tab 1's parameters, the estimates'
#: harmonic amplitudes, Kp, and the transfer-function coefficients of the study (HTML).
SYMBOLS_HTML = {"M": "M", "B": "B", "Af": "A<sub>f</sub>", "d0": "d<sub>0</sub>", "d_sin": "d<sub>sin</sub>",
                "d_cos": "d<sub>cos</sub>", "beta_e": "β<sub>e</sub>", "Dc": "D<sub>c</sub>", "dc": "d<sub>c</sub>",
                "L0": "L<sub>0</sub>", "Kq1": "K<sub>q1</sub>", "Kq2": "K<sub>q2</sub>", "ps": "p<sub>s</sub>",
                "pr": "p<sub>r</sub>", "k_f": "k<sub>f</sub>", "x0": "x(0)", "v0": "v(0)", "p1_0": "p<sub>1</sub>(0)",
                "p2_0": "p<sub>2</sub>(0)", "kp": "K<sub>p</sub>", "a1": "a<sub>1</sub>", "a2": "a<sub>2</sub>",
                "a3": "a<sub>3</sub>", "b0": "b<sub>0</sub>"}
#: The SI unit of each estimate the pages show (the transfer-function coefficients' too: r and x in m).
UNITS = {"M": "kg", "B": "N s/m", "Af": "N", "d0": "N", "d_sin": "N", "d_cos": "N", "beta_e": "Pa",
         "a1": "1/s", "a2": "1/s²", "a3": "1/s³", "b0": "1/s³"}
_UNITS, _NAMES = UNITS, SYMBOLS_HTML


def hidden_note(hidden) -> str:
    names = ", ".join(_NAMES.get(n, n) for n in hidden)
    return (f"<p class='eha-note eha-hidden-note'>Hidden in this exercise: {names}. Everything computed from them "
            "(λ<sub>1</sub>…λ<sub>6</sub>, a<sub>1</sub>…a<sub>10</sub>, P(s), H(s), the nominal values) is hidden "
            "too: find them by identification (tab 3) and hand them in.</p>")


def derived_html(params: ActuatorParams, kp: float = 10.0, *, stale: bool = False, hidden=()) -> str:
    """Tables 1-2 and the transfer functions of eqs. 21-24 for a parameter set.

    ``hidden``: an exercise's hidden parameters; only what does not depend on them is shown.
    """
    p = params
    lin = linearize(p)
    op = lin.op
    num, den = lin.tf_coeffs()
    cnum, cden = lin.closed_loop_coeffs(kp)
    stale = '<p class="eha-stale">Showing the last valid parameters.</p>' if stale else ""
    geometry = table_html(["quantity", "value"], [
        ["A<sub>1</sub> = π D<sub>c</sub><sup>2</sup>/4", f"{p.A1 * 1e4:.4g} cm<sup>2</sup>"],
        ["A<sub>2</sub> = π (D<sub>c</sub><sup>2</sup> − d<sub>c</sub><sup>2</sup>)/4",
         f"{p.A2 * 1e4:.4g} cm<sup>2</sup>"],
        ["end stops ±0.8 L<sub>0</sub>", f"±{p.x_max * 1e3:.4g} mm"],
        # "+ 0.0": -0.0 is written 0 (a cache keyed on the parameters treats -0.0 and 0.0 as one)
        ["operating point (eq. 10)", f"x = {op.x * 1e3 + 0.0:.3g} mm, v = 0, p<sub>1</sub> = {op.p1 / 1e6 + 0.0:.4g} "
                                      f"MPa, p<sub>2</sub> = {op.p2 / 1e6 + 0.0:.5g} MPa, u = 0"],
    ])
    if hidden:
        return f'{stale}<h4>Geometry and operating point</h4>{geometry}{hidden_note(hidden)}'
    lam_rows = []
    formulas = ["(B + 2k<sub>f</sub>A<sub>f</sub>/π)/M", "A<sub>1</sub>/M", "A<sub>2</sub>/M",
                "β<sub>e</sub>/L<sub>0</sub>",
                "β<sub>e</sub>K<sub>q1</sub>√D<sub>3</sub>/(A<sub>1</sub>L<sub>0</sub>)",
                "β<sub>e</sub>K<sub>q2</sub>√D<sub>4</sub>/(A<sub>2</sub>L<sub>0</sub>)"]
    for i, (lp, ln, f) in enumerate(zip(lin.lambdas, lin.lambdas_negative, formulas, strict=True), start=1):
        lam_rows.append([f"λ<sub>{i}</sub>", f, num_html(lp), num_html(ln) if ln != lp else "same"])
    lambdas = table_html(["", "formula (Table 2)", "u ≥ 0", "u < 0"], lam_rows)
    a = p.a
    a_rows = [[f"a<sub>{k[1:]}</sub>", num_html(v)] for k, v in a.items()]
    half = (len(a_rows) + 1) // 2
    keys = list(a)
    a_table = "".join(
        table_html(["", f"a<sub>{part[0][1:]}</sub>…a<sub>{part[-1][1:]}</sub> (Table 1)"], rows)
        for part, rows in ((keys[:half], a_rows[:half]), (keys[half:], a_rows[half:])))
    P = tf_html("P(s) = X(s)/U(s)", num, den, "eq. 21/23, u ≥ 0")
    H = tf_html(f"H(s), K<sub>p</sub> = {kp:g}", cnum, cden, "eq. 22/24")
    poles = (f"<p>Poles of P(s): {poles_html(lin.poles())} rad/s<br>"
             f"Poles of H(s): {poles_html(lin.closed_loop_poles(kp))} rad/s</p>")
    return (f'{stale}<h4>Geometry and operating point</h4>{geometry}'
            f'<h4>Transfer functions</h4>{P}{H}{poles}'
            f'<h4>Linearised model parameters λ<sub>1</sub>…λ<sub>6</sub> (eq. 12)</h4>{lambdas}'
            f'<h4>Compact model a<sub>1</sub>…a<sub>10</sub> (eqs. 6-8)</h4><div class="eha-two">{a_table}</div>')



def _num(v: float) -> str:
    return num_html(v, 5) if v != 0 else "0"


_MARKS = {"exact": ("exact ✓", "eha-ok"), "covers": ("covers ✓", "eha-ok"),
          "undetermined": ("undetermined", "eha-undetermined"), "estimated": ("", ""),
          "misses": ("misses ✗", "eha-warn"), "impossible": ("impossible ✗", "eha-warn")}


def _unit_of(name: str) -> tuple[str, float]:
    """The unit a parameter's row is written in (tab 1's: βe in GPa) and its factor from SI."""
    return display_unit(name, _UNITS.get(name, ""))


def reading_mark(reading, nominal: str = "nominal") -> str:
    """The reading of an estimate in one word and a mark, coloured (✓ only for exact and covers)."""
    text, cls = _MARKS[reading.kind]
    if reading.kind == "estimated":
        # no value to compare with (the student's file, a hidden parameter): a physical parameter it reads is
        # one whose interval is narrower than itself (else "undetermined"); a force's says nothing more
        text = "determined" if reading.name in ("M", "B", "Af", "beta_e") else "estimated"
    if not text:
        return ""
    unit, scale = _unit_of(reading.name)
    tip = _plain(reading.describe(fmt=lambda x: f"{x / scale:.5g}", unit=unit, nominal=nominal))
    return f"<span class='eha-reading eha-reading-{reading.kind} {cls}' title='{tip}'>{text}</span>"


def _plain(text: str) -> str:
    return html.escape(text, quote=True)


def _describe(reading, nominal: str = "nominal") -> str:
    unit, scale = _unit_of(reading.name)
    return reading.describe(fmt=lambda x: _num(x / scale), symbol=_NAMES.get(reading.name, reading.name),
                            unit=unit, nominal=nominal)


def readings_html(readings, prefix: str = "", nominal: str = "nominal") -> str:
    """What the readings that are not a plain "covers" mean, one line each; the exact ones in one line."""
    exact = [r for r in readings if r.kind == "exact"]
    lines = []
    if exact:
        names = ", ".join(_NAMES.get(r.name, r.name) for r in exact)
        worst = max((abs(r.value / r.nominal - 1) for r in exact if r.nominal), default=0.0)
        at_most = f"at most {100 * worst:.4f} %" if 100 * worst >= 5e-5 else "less than 0.0001 %"
        lines.append(f"{prefix}<b class='eha-ok'>Exact</b> ({names}): without noise each estimate equals its {nominal} "
                     f"value to within the regressors' numerical error ({at_most}), and its "
                     "interval collapses to that error: the ✓ says the estimate is right, not that the interval "
                     "covers.")
    for r in readings:
        if r.kind in ("impossible", "undetermined", "misses"):
            text, cls = _MARKS[r.kind]
            lines.append(f"{prefix}<b class='{cls}'>{text.rstrip(' ✗')}</b>: {_describe(r, nominal)}")
    return "".join(f"<li>{line}</li>" for line in lines)


def _paper_cell(scenario: str, name: str, nominal: float | None) -> tuple[float | None, str]:
    """The paper's value of ``name`` for one case, and its source: Table 4's column of that case
    (Table 3 prints the case d = 0 once more, with another β_e: named in the note)."""
    p = PAPER_TABLE4.get(scenario, {}).get(name)
    if p is None:
        return None, ""
    txt = _num(p / _unit_of(name)[1]) + (f" ({pct_text(p / nominal - 1)})" if nominal else "")
    return p, f"{txt}<br><small class='eha-cite'>Table 4, {SCENARIOS[scenario]}</small>"


def _printed_half_ulp(p: float) -> float:
    """Half a unit in the last printed digit of a number of the paper (4000.1 → 0.05, 1.101e9 → 5e5)."""
    if p == 0:
        return 0.0
    digits = repr(float(p)).lower().split("e")[0].replace("-", "").replace(".", "").strip("0") or "0"
    exp = math.floor(math.log10(abs(p)))
    return 0.5 * 10.0 ** (exp - len(digits) + 1)


def paper_gaps(res, scenario: str | None) -> list[str]:
    """The parameters whose paper value lies outside our interval by more than the paper's rounding."""
    if scenario not in PAPER_TABLE4:
        return []
    gaps = []
    for k, (lo, hi) in res.ci95.items():
        p = PAPER_TABLE4[scenario].get(k)
        if p is None:
            continue
        h = _printed_half_ulp(p)
        if p + h < lo or p - h > hi:
            gaps.append(k)
    return gaps


def _setup_note(scenario: str, model: str, gaps, seed: int | None, readings=None) -> str:
    """Where our number and the paper's differ by more than our interval, and what differs in the setup.

    An exact estimate of ours (no noise) that the paper's value misses is the paper's own error; the
    disturbance explains nothing of eq. 15b's β_e, which has no disturbance term."""
    if not gaps:
        return ""
    readings = readings or {}
    exact = [k for k in gaps if getattr(readings.get(k), "kind", "") == "exact"]
    other = [k for k in gaps if k not in exact]
    items = ""
    if exact:
        names = ", ".join(_NAMES.get(k, k) for k in exact)
        sinusoid = model != "constant" and scenario in ("200 sin", "5000 sin")
        why = ("the paper estimated with the constant d<sub>0</sub>, which cannot separate the sinusoid; this is "
               "the model with d<sub>0</sub> + a sinusoid" if sinusoid
               else "its own estimation error (it does not state how it discretised the filters of eqs. 16-17; the "
                    "classical discretisation biases B by about 1.5 %)")
        items += (f"<li><b>Not the paper's number</b> ({names}): ours is exact (no noise), the paper's lies outside "
                  f"our collapsed interval: {why}.</li>")
    if other:
        names = ", ".join(_NAMES.get(k, k) for k in other)
        setup = ["our regressors are formed on a cubic-spline grid 16 times finer than the 1 kHz samples and "
                 "filtered there (the paper does not state its discretisation)", "the paper gives no intervals"]
        if model != "constant":
            setup.insert(0, "the paper estimated with the constant d<sub>0</sub>; this is the model with "
                            "d<sub>0</sub> + a sinusoid")
        if scenario == "white noise":
            setup.insert(0, "the noise is another draw (the paper gives neither its seed nor how it is held between "
                            f"samples; ours: seed {seed if seed is not None else 0}, held for 1 ms)")
        if scenario in ("200 sin", "5000 sin") and model == "constant" and set(other) - {"beta_e"}:
            setup.insert(0, "under this force the constant model cannot separate the sinusoid from the regressors "
                            "of eq. 15a (see above), so any small difference in the setup moves their estimates far")
        items += (f"<li><b>Not the paper's number</b> ({names}): the paper's value lies outside our 95 % interval. "
                  f"What differs: {'; '.join(setup)}.</li>")
    return items


def lse_table_html(res, scenario: str | None, hidden=(), *, alternative=None, leak=None, seed: int | None = None,
                   own_record: bool = False) -> str:
    """Estimates against nominal values, with 95 % intervals, their readings and the paper's number.

    ``hidden``: an exercise's hidden parameters: their nominal value, error and
    reading against the truth are not shown (nor is the paper's column).
    ``alternative``: the same data with the harmonic disturbance model, shown
    beside when ``leak`` (a :class:`~eha_core.identify.lse_reading.DisturbanceLeak`)
    says the constant model left a sinusoid out. ``own_record``: a student's
    own measurements: no nominal or paper column (nothing is known to compare with).
    """
    if hidden:
        return _lse_exercise_html(res, hidden)
    known = not own_record
    paper_on = scenario in PAPER_TABLE4 and known
    readings = read_all(res, hidden=() if known else tuple(res.estimates))
    alt = leak is not None and alternative is not None
    rows = []
    for k, v in res.estimates.items():
        nom = res.nominal.get(k) if known else None
        rel = res.rel_error.get(k) if known else None
        lo, hi = res.ci95[k]
        unit, scale = _unit_of(k)
        shown, interval = estimate_texts(v, lo, hi, scale)
        row = [f"{_NAMES.get(k, k)} [{unit}]"]
        if known:
            row.append("" if nom is None else _num(nom / scale))
        row += [shown]
        if known:
            row.append("" if rel is None else pct_text(rel, 3))
        row += [interval, reading_mark(readings[k])]
        if alt:
            a = alternative.estimates.get(k)
            row.append("" if a is None else _num(a / scale) + (f" ({pct_text(a / nom - 1, 3)})" if nom else ""))
        if paper_on:
            row.append(_paper_cell(scenario, k, nom)[1])
        rows.append(row)
    if alt:     # the sinusoid's own amplitudes, which only the harmonic model has
        for k in ("d_sin", "d_cos"):
            row = [f"{_NAMES[k]} [{_UNITS[k]}]"] + [""] * (4 if known else 2) + [""]
            row.append(_num(alternative.estimates[k]))
            if paper_on:
                row.append("")
            rows.append(row)
    header = ["parameter"] + (["nominal"] if known else []) + ["estimate"] + (["rel. error"] if known else []) \
        + ["95 % interval", "reading"] + (["with d<sub>0</sub> + a sinusoid"] if alt else []) \
        + (["paper"] if paper_on else [])
    # (an exact fit has no textbook interval to compare with: every one is zero)
    narrower = max((res.std_errors[k] / res.std_errors_textbook[k]
                    for k in res.std_errors if res.std_errors_textbook[k] > 0), default=None)
    compared = "" if narrower is None else f"; textbook intervals are up to {narrower:.1f}× narrower"
    items = readings_html(readings.values())
    if leak is not None:
        items += f"<li class='eha-leak'><b>Why the constant model fails here.</b> {html.escape(leak.sentence)}</li>"
    if paper_on:
        items += _setup_note(scenario, res.disturbance_model, paper_gaps(res, scenario), seed, readings)
        if scenario == "none" and "beta_e" in res.estimates:
            items += (f"<li>The paper prints this case twice: Table 4 gives β<sub>e</sub> = "
                      f"{_num(PAPER_TABLE4['none']['beta_e'] / 1e9)} GPa, Table 3 "
                      f"{_num(PAPER_TABLE3_BETA_E / 1e9)} GPa "
                      f"({pct_text(PAPER_TABLE3_BETA_E / res.nominal['beta_e'] - 1)}).</li>")
    if own_record:
        items += ("<li>Your own record: no nominal values are known, so the readings say only whether an "
                  "estimate is physically possible and whether the data determine it.</li>")
    note = (f"<p class='eha-note'>Disturbance model: {res.disturbance_model}"
            + (f", frequency {res.disturbance_freq_hz:.6g} Hz ({'estimated' if res.freq_estimated else 'given'})"
               if res.disturbance_freq_hz else "")
            + f". {_how_estimated(res)} (the prefilter colours the residual{compared}).</p>")
    # eight columns: at 800 px the table scrolls in its own box, the page does not
    return ("<div class='eha-table-scroll'>" + table_html(header, rows, cls="eha-table eha-lse-readings") + "</div>"
            + note
            + (f"<ul class='eha-readings'>{items}</ul>" if items else ""))


def _how_estimated(res) -> str:
    """The estimator and how its intervals were made, in one sentence."""
    est = getattr(res, "estimator", "ls")
    who = ("Estimator: instrumental variables (instruments from a noise-free simulation of the model, "
           f"{getattr(res, 'iterations', 0)} passes)" if est == "iv" else "Estimator: least squares (the paper's)")
    if getattr(res, "intervals", "newey-west") == "ewc":
        how = (f"intervals: equal-weighted cosine standard errors ({res.cosine_terms} terms) with Student's t = "
               f"{res.critical_value:.3g}")
    else:
        how = f"intervals: {term('Newey-West')} over {res.hac_lags} lags"
    return f"{who}; {how}"


def _lse_exercise_html(res, hidden) -> str:
    readings = read_all(res, hidden=tuple(hidden))
    rows = []
    for k, v in res.estimates.items():
        lo, hi = res.ci95[k]
        nom = None if k in hidden else res.nominal.get(k)
        # the harmonic disturbance's amplitudes have no known value: an empty cell, as in the full table
        unit, scale = _unit_of(k)
        known = "hidden" if k in hidden else ("" if nom is None else _num(nom / scale))
        shown, interval = estimate_texts(v, lo, hi, scale)
        rows.append([f"{_NAMES.get(k, k)} [{unit}]", known, shown, interval,
                     reading_mark(readings[k], nominal="known")])
    items = readings_html(readings.values(), nominal="known")
    note = (f"<p class='eha-note'>Disturbance model: {res.disturbance_model}. {_how_estimated(res)}. Hand in the "
            "estimates of the hidden parameters below.</p>")
    return (table_html(["parameter", "known value", "estimate", "95 % interval", "reading"], rows) + note
            + (f"<ul class='eha-readings'>{items}</ul>" if items else ""))


def table4_html(by_model: dict, leaks: dict | None = None, seed: int | None = None) -> str:
    """Table 4: for every scenario, our estimates with both disturbance models and the paper's.

    ``by_model`` maps 'constant' / 'harmonic' to {scenario: LSEResult};
    ``leaks`` maps a scenario to its :class:`~eha_core.identify.lse_reading.DisturbanceLeak`.
    """
    names = ["M", "B", "Af", "d0", "beta_e"]
    models = list(by_model)
    scenarios = list(next(iter(by_model.values())))
    first = by_model[models[0]][scenarios[0]]
    header = ["parameter", "nominal"] + [SCENARIOS[s] for s in scenarios]
    short = {"constant": "const.", "harmonic": "harm."}
    # each result read once, for its cells and for the notes under the table
    readings = {(m, scen): read_all(by_model[m][scen]) for m in models for scen in scenarios}
    rows = []
    for k in names:
        nom = first.nominal[k]
        unit, scale = _unit_of(k)
        row = [f"{_NAMES[k]} [{unit}]", _num(nom / scale)]
        for scen in scenarios:
            lines = []
            for m in models:
                res = by_model[m][scen]
                v = res.estimates[k]
                rel = res.rel_error.get(k)
                lo, hi = res.ci95[k]
                mark = reading_mark(readings[m, scen][k])
                shown, interval = estimate_texts(v, lo, hi, scale)
                lines.append(f"<span class='eha-t4-{m}'>{short[m]}: <b>{shown}</b>"
                             + (f" ({pct_text(rel)})" if rel is not None else "")
                             + f"<br><small>{interval}</small> {mark}</span>")
            p = PAPER_TABLE4[scen][k]
            prel = f" ({pct_text(p / nom - 1)})" if nom else ""
            lines.append(f"<span class='eha-t4-paper'>paper: {_num(p / scale)}{prel}</span>")
            row.append("<br>".join(lines))
        rows.append(row)
    items = ""
    gap_rows = []           # where the paper's value lies outside our interval: said once, below
    for scen in scenarios:
        for m in models:
            res = by_model[m][scen]
            prefix = f"{SCENARIOS[scen]}, {short[m]} — "
            items += readings_html([r for r in readings[m, scen].values() if r.kind != "exact"], prefix=prefix)
            gaps = [g for g in paper_gaps(res, scen) if g in names]
            if gaps:
                gap_rows.append(f"{SCENARIOS[scen]}, {short[m]}: {', '.join(_NAMES.get(g, g) for g in gaps)}")
        leak = (leaks or {}).get(scen)
        if leak is not None:
            items += (f"<li class='eha-leak'>{SCENARIOS[scen]} — <b>why the constant model fails.</b> "
                      f"{html.escape(leak.sentence)}</li>")
    if gap_rows:
        items += ("<li><b>Not the paper's number</b>, the paper's value outside our 95 % interval: "
                  + "; ".join(gap_rows) + ". What differs: the paper used the constant d<sub>0</sub> only (the "
                  "harm. rows are ours); under a sinusoidal force that model cannot separate the sinusoid from the "
                  "regressors of eq. 15a, so small differences in the setup move its estimates far; our regressors "
                  "are formed on a cubic-spline grid 16 times finer than the samples (the paper does not state its "
                  "discretisation; the classical one biases B by about 1.5 %); where ours is exact (no noise) the "
                  "difference is the paper's own error; the white noise is another draw (the paper gives no "
                  "seed).</li>")
    note = ("<p class='eha-note'>const. = the paper's constant d<sub>0</sub>; harm. = d<sub>0</sub> plus a sinusoid "
            "whose frequency is estimated from the data. Every paper value is Table 4's, in the column of its case "
            f"(Table 3 prints d = 0 again with β<sub>e</sub> = {_num(PAPER_TABLE3_BETA_E / 1e9)} GPa). Readings: "
            "<b>exact</b> ✓ without noise, the estimate equals the nominal value to within the regressors' "
            "numerical error (~0.003 %) and its interval collapses to that error; <b>covers</b> ✓ / <b>misses</b> ✗ "
            "the nominal value; <b>undetermined</b>: the interval is wider than the estimate; <b>impossible</b> ✗: "
            "no actuator has that value.</p>")
    # at 800 px its cells wrapped to 6-8 lines: they keep their lines and the table scrolls in its own box
    return ("<div class='eha-table-scroll'>" + table_html(header, rows, cls="eha-table eha-table4") + "</div>" + note
            + (f"<ul class='eha-readings'>{items}</ul>" if items else ""))


def estimate_alert(e) -> str:
    """A warning when the estimate cannot describe the stable loop (empty when it can)."""
    if not e.success or not np.all(np.isfinite(e.den)):
        return ("The estimation did not converge: no estimate to show. Try the default structure "
                "(3 poles, no zero) or a longer record.")
    unstable = e.poles()[e.poles().real > 0]
    if unstable.size:
        worst = unstable[np.argmax(unstable.real)]
        return (f"This estimate is unstable: it has {unstable.size} pole{'s' if unstable.size > 1 else ''} in the "
                f"right half-plane (the largest real part is {worst.real:+.3g} rad/s), so it cannot describe the "
                f"stable closed loop even though its fit on this record is {e.fit_percent:.1f} %. "
                f"Try fewer poles or zeros.")
    return ""


def estimation_sentences(e) -> str:
    """How the estimate was obtained, in sentences (from the estimate's own fields)."""
    srivc = term("SRIVC")
    oe = term("output error")
    if e.method == "srivc+oe":
        how = (f"{srivc} gave a start ({e.nit_srivc} iterations), refined by {oe} ({e.nfev_oe} evaluations); "
               "the refined estimate is kept.")
    elif e.method == "srivc":
        how = (f"{srivc} ({e.nit_srivc} iterations); the {oe} refinement did not lower the error, "
               f"so the {srivc} estimate is kept.")
    else:
        how = f"{oe} from the given start model ({e.nfev_oe} evaluations)."
    ic = ("Its initial state was estimated with it" if e.initial_condition == "estimate"
          else "It starts from a zero initial state")
    offset = ("" if e.input_offset is None else
              f", and a constant {term('input offset', 'offset of r')} of {e.input_offset:.3g} m "
              "(it stands for the valve's different gains for u ≥ 0 and u < 0)")
    return f"<p class='eha-note'>{how} {ic}{offset}.</p>"


def freq_summary_html(fi, hidden=()) -> str:
    """Ĥ(s) beside eq. 24's H(s) and the paper's; without H(s) when an exercise hides parameters."""
    e = fi.estimate
    if not e.success or not np.all(np.isfinite(e.den)):
        return f"<div class='eha-warn'>{estimate_alert(e)}</div>"
    theo_num, theo_den = fi.theoretical
    plant = "nonlinear" if fi.config.model == "nonlinear" else "linearised"
    parts = [tf_html("Ĥ(s)", e.num, e.den, f"estimated from the {plant} model's data; "
                     f"{term('fit', f'fit {e.fit_percent:.2f} %')}")]
    delay = getattr(e, "input_delay", 0.0) or 0.0
    if delay or fi.config.input_delay == "estimate":
        how = ("estimated" + (f", standard error {e.input_delay_std * 1e3:.3g} ms"
                              if e.input_delay_std is not None and np.isfinite(e.input_delay_std) else "")
               if fi.config.input_delay == "estimate" else "fixed")
        parts.append(f"<p>with an input delay e<sup>−sτ</sup>, τ = <b>{delay * 1e3:.4g} ms</b> = "
                     f"{delay / fi.config.ts:.3g} samples ({how}).</p>")
    if not hidden:
        parts.append(tf_html("H(s)", theo_num, theo_den,
                             f"linearised at v = 0, eq. 24, K<sub>p</sub> = {fi.config.kp:g} V/m"))
    parts.append(tf_html("Ĥ<sub>paper</sub>(s)", PAPER_EQ25[0], PAPER_EQ25[1], f"eq. 25, fit {PAPER_FIT_PERCENT} %"))
    if fi.validation is not None:
        parts.append(f"<p>Validation on a fresh excitation (seed {fi.validation_excitation.seed}): "
                     f"fit <b>{fi.validation.fit_percent:.2f} %</b>.</p>")
    if fi.open_loop is not None:
        parts.append(tf_html("P̂(s)", *fi.open_loop, "eq. 26: Ĥ / (K<sub>p</sub>(1 − Ĥ))"))
        parts.append(open_loop_note(fi.open_loop[1], open_loop_instability(e.num, e.den, fi.config.kp)))
        parts.append(tf_html("P̂<sub>paper</sub>(s)", PAPER_EQ26[0], PAPER_EQ26[1], "eq. 26 of the paper"))
    parts.append(estimation_sentences(e))
    return "".join(parts)


def open_loop_note(den_p, instability) -> str:
    """Say that P̂(s) is unstable, and why, where it is shown (empty when it is stable)."""
    if instability is None:
        return ""
    pole, gain = instability
    const = f" (its constant term {num_html(float(den_p[-1]))} &lt; 0)" if den_p[-1] < 0 else ""
    slow = (f" A pole this slow (time constant {num_html(1.0 / pole, 3)} s) does not show within the record."
            if pole > 0 and 1.0 / pole > 10.0 else "")
    why = (f" because Ĥ(0) = {gain:.4g} &gt; 1{const}: the actuator's P(s) has an integrator (a pole at 0, eq. 21), "
           "so its loop has H(0) = 1 exactly, and eq. 26 divides by 1 − Ĥ(s), which turns a static-gain error of "
           f"{pct_text(gain - 1, 1)} into a pole on the wrong side of 0." if gain > 1 else ".")
    return (f"<p class='eha-warn-note eha-unstable-phat'><b class='eha-warn'>P̂(s) is unstable</b>: a pole at "
            f"+{num_html(pole, 3)} rad/s in the right half-plane{why}{slow}</p>")


def _s2_sentence(fi, b, lin) -> str:
    """Why λ̂1 is where it is, said only as far as this run backs it."""
    l1 = f"The estimated s² coefficient λ̂<sub>1</sub> = {b.l1:.4g}"
    if lin.lambdas[0] == 0 or fi.params.k_f == 0:
        # no damping at all in the linearised model (B = 0, k_f A_f = 0), or no friction slope: nothing to compare
        return (f"{l1}; the linearised model has λ<sub>1</sub> = {lin.lambdas[0]:.4g} (B = {num_html(fi.params.B)} "
                f"N s/m, k<sub>f</sub> = {num_html(fi.params.k_f)} s/m): the s² coefficient is all the data's.")
    ratio = b.l1 / lin.lambdas[0]
    where = f"{pct_text(ratio - 1, 1)} from the linearised {lin.lambdas[0]:.4g}"
    slope = (f"λ<sub>1</sub> holds the friction's slope at v = 0, 2k<sub>f</sub>A<sub>f</sub>/π = "
             f"{num_html(lin.friction_damping)} N s/m")
    if fi.config.model == "linear":
        return (f"{l1} is {where}: {slope}, and in the linearised plant the friction keeps that slope at "
                "every speed, so its data carry it and the estimate finds it.")
    saturated = fi.peak_speed * fi.params.k_f > 3.0
    if ratio < 0.5 and saturated:
        return (f"{l1} lies far below the linearised {lin.lambdas[0]:.4g} ({pct_text(ratio - 1, 0)}): {slope}, "
                f"but during this experiment the piston moved at up to {fi.peak_speed * 1e3:.0f} mm/s, far beyond "
                f"1/k<sub>f</sub> = {1e3 / fi.params.k_f:.2f} mm/s, where S(v) = (2/π) atan(k<sub>f</sub>v) "
                "saturates: the friction acts as a nearly constant force ±A<sub>f</sub>, which adds almost no "
                "damping to the oscillation. (The paper's Ĥ has 11.12.)")
    return (f"{l1} is {where}; {slope}, and the piston moved at up to {fi.peak_speed * 1e3:.0f} mm/s "
            f"(1/k<sub>f</sub> = {1e3 / fi.params.k_f:.2f} mm/s).")


def _gain_sentence(b, lin) -> str:
    g_pos, g_neg = lin.gain("positive"), lin.gain("negative")
    rel = b.rel_errors()["beta_e_from_gain"]
    text = ("β<sub>e</sub> from the s coefficient depends on the chamber stiffness only. "
            f"β<sub>e</sub> from the gain uses the u ≥ 0 valve branch of eq. 13 (gain {g_pos:.4g})")
    if abs(g_neg / g_pos - 1) > 0.01:
        text += (f", but u = K<sub>p</sub>(r − x) changes sign all the time and the u &lt; 0 branch has gain "
                 f"{g_neg:.4g} ({pct_text(g_neg / g_pos - 1, 0)}): the data see a blend")
        if rel < -0.05:
            text += f", so this route comes out low ({pct_text(rel, 1)})"
    return text + ". (The paper reported 1.1793·10<sup>9</sup>.)"


def backout_html(fi, hidden=()) -> str:
    b = fi.backout
    if b is None:
        return "<p>The back-out needs a model with 3 poles and no zero.</p>"
    ci = b.ci95()
    rel = b.rel_errors()
    if hidden:        # an exercise: the backed-out values and intervals, nothing about the truth
        rows = []
        for name, key, unit in (("B + 2k<sub>f</sub>A<sub>f</sub>/π = λ̂<sub>1</sub> M (eq. 27a)", "damping", "N s/m"),
                                ("β<sub>e</sub> from the gain (eq. 27e-f)", "beta_e_from_gain", "Pa"),
                                ("β<sub>e</sub> from the s coefficient (eq. 27b-d)", "beta_e_from_stiffness", "Pa")):
            lo, hi = ci[key]
            rows.append([name, _num(getattr(b, key)), "" if math.isnan(lo) else f"[{_num(lo)}, {_num(hi)}]", unit])
        # the back-out of an exercise is computed with the student's own values of what eq. 27 takes as
        # measured (the section replaces it): say which, with the values used
        taken = [n for n in ("M", "L0", "Kq1", "Kq2") if n in hidden and n in b.known]
        used = ""
        if taken:
            used = ("<p class='eha-note eha-backout-assumed'>Computed with your values of what eq. 27 takes as "
                    "measured, not the hidden ones: " + ", ".join(
                        f"{_NAMES.get(n, n)} = {_num(b.known[n])} {FIELD_INFO[n].unit}" for n in taken)
                    + " (a hidden M is your least-squares estimate, else the paper's value).</p>")
        return (table_html(["quantity", "backed out", "95 % interval", "unit"], rows) + used
                + hidden_note(hidden))

    def row(name, key, unit):
        v, nom = getattr(b, key), (b.damping_nominal if key == "damping" else b.beta_e_nominal)
        lo, hi = ci[key]
        interval = "" if math.isnan(lo) else f"[{_num(lo)}, {_num(hi)}]"
        return [name, _num(nom), _num(v), "" if math.isnan(rel[key]) else pct_text(rel[key]), interval, unit]

    rows = [row("B + 2k<sub>f</sub>A<sub>f</sub>/π = λ̂<sub>1</sub> M (eq. 27a)", "damping", "N s/m"),
            row("β<sub>e</sub> from the gain (eq. 27e-f)", "beta_e_from_gain", "Pa"),
            row("β<sub>e</sub> from the s coefficient (eq. 27b-d)", "beta_e_from_stiffness", "Pa")]
    table = table_html(["quantity", "nominal / linearised", "backed out", "difference", "95 % interval", "unit"], rows)
    lin = fi.linear
    return (table + f"<p class='eha-note eha-s2-explain'>{_s2_sentence(fi, b, lin)}</p>"
            f"<p class='eha-note'>{_gain_sentence(b, lin)}</p>")


def assumed_model_html(route: str) -> str:
    """What a route's model assumes of the actuator, one line under its result: every route fits the
    paper's model, and an actuator with an effect it leaves out (a lagging spool, internal leakage,
    Stribeck friction) shows in its residuals."""
    from eha_core.variants import describe_effects

    what = {"lse": "The least squares fit", "greybox": "The grey-box fits",
            "frequency": "The back-out (eq. 27) linearises"}[route]
    return (f"<p class='eha-note eha-assumes'>{what} {html.escape(describe_effects(None))}. An effect it leaves "
            "out (a lagging valve spool, leakage between the chambers, friction that falls with speed) shows in "
            "the residuals, not in the estimates' intervals.</p>")
