"""Tab 3's grey-box sub-tab tells the truth about an estimate: one that failed its own checks shows no
interval, says what each check found and what to try, is not handed in and goes to no board; one that
passed says so and how it was fitted. The run shows the core's stage under its button and can be
cancelled, keeping the previous result."""

import html
import json
import math

import numpy as np
import pytest

from eha_app.render.formatting import display_unit, estimate_texts, num_html
from eha_app.render.greybox import correlation_html, greybox_table_html, routes_html
from eha_app.runtime.handins import HandIns
from eha_app.session import Session
from eha_app.session.state import AppState

#: A start far from the paper's actuator (M x3, B x0.1, Af x0.2, βe x0.3) from x alone, over the whole record
#: at once: the fit ends in a local minimum with B at the bound of its range.
BAD_START = {"gb_measured": "x", "gb_shooting": "single", "gb_guess_M": "12000", "gb_guess_B": "150",
             "gb_guess_Af": "600", "gb_guess_beta_e": "0.33"}


def type_into(form, **texts):
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


@pytest.fixture(scope="module")
def micrometres():
    """A failed estimate, cheaply: a record whose x is in µm instead of m."""
    from eha_core.experiments import LSE_INPUT
    from eha_core.identify.greybox import GreyBoxData, greybox_data, identify_greybox
    from eha_core.params import ActuatorParams

    rec = greybox_data(ActuatorParams(), LSE_INPUT, t_end=3.0, noise={"x": 1e-5}, seed=1, measured=("x",))
    bad = GreyBoxData(t=rec.t, u=rec.u, signals={"x": rec.signals["x"] * 1e6})
    res = identify_greybox(bad, ("M", "B", "Af", "beta_e"), measured=("x",))
    assert not res.success and res.failed_checks and res.advice
    return res


@pytest.fixture(scope="module")
def failed():
    """The section run from a bad start: its checks fail."""
    session = Session(AppState())
    gb = session.build("greybox")
    type_into(gb.form, **BAD_START)
    assert gb.run().state == "done"
    assert not gb.result.success
    return session, gb


def _unchecked_intervals(res) -> list[str]:
    """The fit's own interval ends, as the table would write them (they must appear nowhere)."""
    return [text for n, (lo, hi) in res.extras["ci95_unchecked"].items()
            if n not in res.held and math.isfinite(lo) and math.isfinite(hi)
            for text in (f"[{num_html(lo, 5)}, {num_html(hi, 5)}]",
                         estimate_texts(res.estimates[n], lo, hi, display_unit(n)[1])[1])]


def test_a_failed_estimate_has_no_interval_and_says_what_failed_and_what_to_try(micrometres):
    res = micrometres
    table = greybox_table_html(res, AppState().params)
    assert "This estimate may be wrong" in table and "eha-gb-failed" in table and "What to try" in table
    for c in res.failed_checks:
        assert f"<li>{html.escape(c.says)}</li>" in table, c.name
    for a in res.advice:
        assert f"<li>{html.escape(a)}</li>" in table
    assert "Checks passed" not in table and "covers ✓" not in table
    # no interval and no standard error in any row: each cell of the columns is a dash or says why
    for interval in _unchecked_intervals(res):
        assert interval not in table
    rows = table.split("<tbody>")[1].split("<tr>")[1:]
    assert len(rows) == len(res.names)
    for row in rows:
        assert sum(mark in row for mark in ("eha-gb-no-interval", "eha-gb-held-row", "eha-gb-at-bound")) == 1, row
    assert f"How it was fitted: {html.escape(res.strategy)}." in table
    # the correlations are not shown, and a sentence says why
    corr = correlation_html(res)
    assert "Not shown: the estimate failed its checks" in corr and "eha-gb-corr" not in corr.replace(
        "eha-gb-corr-hidden", "")
    # side by side: "may be wrong", no interval
    routes = routes_html(AppState().params, greybox=res)
    assert routes.count("may be wrong") == 5                # M, B, Af, βe and the damping row
    for interval in _unchecked_intervals(res):
        assert interval.replace("[", "<small>[") not in routes


def test_a_failed_run_on_the_page(failed):
    session, gb = failed
    res = gb.result
    table = gb.table.object
    assert "This estimate may be wrong" in table and "Checks passed" not in table
    # the parameter the fit pushed to a bound is marked in its row, distinct from a held one
    (at_bound,) = next(c.about for c in res.failed_checks if c.name == "bounds")
    assert at_bound == "B" and "at the bound of its range" in table and "eha-gb-held-row" not in table
    assert "B ended at a bound of its range" in gb.details.object
    assert "Not shown: the estimate failed its checks" in gb.details.object
    assert "may be wrong" in gb.routes.object
    # the residual verdicts are the core's: no transfer-function advice on a grey-box model
    assert "poles" not in gb.details.object and "a delay" not in gb.details.object
    # the board takes only an estimate that passed its checks
    assert session.mail("board") == []
    # the estimates' JSON: a value not given is null (never NaN, which is no JSON)
    text = gb.estimates_bytes().decode()
    out = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert out["ci95"]["M"] == [None, None] and out["std_errors"]["M"] is None and not out["success"]
    assert {c["name"] for c in out["checks"] if not c["passed"]} >= {"noise", "bounds"} and out["advice"]


def test_a_passed_estimate_shows_its_intervals_the_checks_and_how_it_was_fitted():
    session = Session(AppState())
    gb = session.build("greybox")
    assert gb.form.values["gb_shooting"] == "auto"
    assert gb.run().state == "done"
    res, table = gb.result, gb.table.object
    assert res.success and "This estimate may be wrong" not in table
    assert "Checks passed ✓" in table
    for c in res.checks:
        assert html.escape(c.says) in table
    assert f"How it was fitted: {html.escape(res.strategy)}." in table and "single shooting over the first" in table
    for n in res.names:
        lo, hi = res.ci95[n]
        assert estimate_texts(res.estimates[n], lo, hi, display_unit(n)[1])[1] in table
    assert table.count("covers ✓") == 4
    assert "eha-gb-corr" in gb.details.object and "Not shown" not in gb.details.object
    assert "may be wrong" not in gb.routes.object
    (model,) = session.mail("board")
    assert model.name == "GB"


def test_a_held_parameter_names_the_bias_it_can_cause():
    gb = Session(AppState()).build("greybox")
    type_into(gb.form, gb_excitation="custom", gb_u="sine:0.01:2", gb_t_end="5")
    assert gb.run().state == "done"
    res = gb.result
    assert "B" in res.held and res.held_bias.get("B")
    row = next(r for r in gb.table.object.split("<tr>") if r.startswith("<td>B [N s/m]"))
    assert f"held at the initial value, {num_html(res.estimates['B'], 5)} N s/m; if it is 10 % off, " in row
    first, change = next(iter(res.held_bias["B"].items()))
    from eha_app.render.formatting import pct_short
    from eha_app.render.tables import SYMBOLS_HTML

    assert f"{SYMBOLS_HTML[first]} moves by {pct_short(change)}" in row
    assert "at the bound" not in row


def test_the_shooting_select_offers_auto_first_and_prices_it():
    from eha_app.sections.greybox import GB_DEFAULTS, SHOOTING_OPTIONS, parse_greybox
    from eha_core.identify.greybox import SHOOTING

    assert [k for k, _ in SHOOTING_OPTIONS] == ["auto", "single", "multiple"] and set(SHOOTING) == {"auto", "single",
                                                                                                    "multiple"}
    assert GB_DEFAULTS["gb_shooting"] == "auto"
    gb = Session(AppState()).build("greybox")
    costs = {}
    for how in ("single", "auto", "multiple"):
        type_into(gb.form, gb_shooting=how)
        assert gb.request()[0].shooting == how and gb.form.errors == {}
        costs[how] = gb.run_cost().steps
    assert costs["single"] < costs["auto"] < costs["multiple"] == 3 * costs["single"]
    # settings saved with the old default still load
    req, errors = parse_greybox({**GB_DEFAULTS, "gb_shooting": "single"})
    assert errors == {} and req.shooting == "single"
    _, errors = parse_greybox({**GB_DEFAULTS, "gb_shooting": "sideways"})
    assert "gb_shooting" in errors


def test_the_run_shows_the_cores_stages_under_its_button_and_ends_idle():
    gb = Session(AppState()).build("greybox")
    seen = []
    gb.progress_text.param.watch(lambda e: seen.append(e.new), "object")
    running = []
    gb.progress_text.param.watch(lambda e: running.append((gb.progress.visible, gb.cancel_button.disabled)), "object")
    assert gb.cancel_button.disabled and not gb.progress.visible
    assert gb.run().state == "done"
    text = " ".join(seen)
    for stage in ("Which parameters the record determines at the initial guess", "Single shooting over the first 1 s",
                  "Single shooting over the whole record", "The estimate&#x27;s statistics"):
        assert stage in text, (stage, seen)
    assert all(visible and not disabled for visible, disabled in running)   # Cancel enabled while it runs
    assert gb.cancel_button.disabled and not gb.progress.visible and not gb.progress_text.visible


def test_cancel_stops_a_run_and_keeps_the_previous_result():
    gb = Session(AppState()).build("greybox")
    assert gb.run().state == "done"
    before, table = gb.result, gb.table.object
    type_into(gb.form, gb_seed="5")
    calls = []

    def press_cancel(event):
        if "shooting" in event.new and not calls:       # the core is fitting: the student presses Cancel
            calls.append(event.new)
            gb.cancel_button.clicks += 1

    gb.progress_text.param.watch(press_cancel, "object")
    job = gb.run()
    assert calls and job.state == "cancelled"
    assert gb.result is before and gb.table.object == table
    assert "cancelled" in gb.progress_text.object and "previous result" in gb.progress_text.object
    assert gb.progress_text.visible and gb.cancel_button.disabled and not gb.progress.visible
    assert gb.view.status == "stale"                    # the table is the previous settings'
    # the next run is not cancelled by the last one's press
    assert gb.run().state == "done" and gb.result is not before


def test_an_estimate_that_failed_its_checks_is_not_handed_in(lab_exercise):
    from eha_app.app import create_app

    ex, path = lab_exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    gb = page.session.build("greybox")
    type_into(gb.form, **BAD_START)
    assert gb.run().state == "done" and not gb.result.success
    # refused beside the button, before any press: what failed and what to try
    assert gb.handin_button.disabled and gb.verdict.visible
    says = gb.result.failed_checks[0].says
    assert "Cannot be handed in: this estimate failed its checks" in gb.verdict.object
    assert html.escape(says) in gb.verdict.object and "run it again, e.g." in gb.verdict.object
    assert "failed its checks" in gb.handin_button.description
    assert gb.hand_in() is None and HandIns(path).all() == []
    # a run that passes its checks takes the refusal away and can be handed in
    type_into(gb.form, gb_measured="x, p1, p2", gb_shooting="auto")
    assert gb.run().state == "done" and gb.result.success
    assert not gb.handin_button.disabled and not gb.verdict.visible
    gb.hand_in()
    (row,) = HandIns(path).all()
    assert row.method == "greybox" and set(row.estimates) == {"M", "B", "Af", "beta_e"}
    assert np.isfinite(list(row.estimates.values())).all()
