"""Tab 3's grey-box sub-tab without a browser: the run, what the data cannot determine, refused fields,
the own record, the three routes side by side, the report and settings, the exercise's hand-in."""

import numpy as np
import pytest

from eha_app.render.formatting import display_unit, estimate_texts, num_html
from eha_app.runtime.handins import HandIns
from eha_app.session import Session
from eha_app.session.state import AppState


def type_into(form, **texts):
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


@pytest.fixture(scope="module")
def ran():
    """One session with the grey-box run on the paper's experiment (the defaults: M, B, Af, βe from x, p1, p2)."""
    session = Session(AppState())
    gb = session.build("greybox")
    type_into(gb.form, gb_guess_M="5000", gb_guess_B="2500", gb_guess_Af="2000", gb_guess_beta_e="0.8")
    job = gb.run()
    assert job.state == "done", job
    return session, gb


def test_the_run_recovers_tab_1s_values_within_the_intervals(ran):
    session, gb = ran
    res, truth = gb.result, session.state.params
    assert res.success and res.held == () and res.names == ("M", "B", "Af", "beta_e")
    for n in res.names:
        lo, hi = res.ci95[n]
        assert lo <= getattr(truth, n) <= hi, n
        # written as everywhere: in tab 1's unit, the digits following the interval
        shown, interval = estimate_texts(res.estimates[n], lo, hi, display_unit(n)[1])
        assert f"<td>{shown}</td><td>{interval}</td>" in gb.table.object
    assert gb.table.object.count("covers ✓") == 4
    assert all(f > 95 for f in res.fit.values()) and set(res.fit) == {"x", "p1", "p2"}
    assert f"x {res.fit['x']:.2f} %" in gb.table.object
    assert "Table 4, d = 0" in gb.table.object                     # the paper's least-squares numbers beside
    # one plot per measured signal; the details: sentences (none here), correlations, residual verdicts
    assert len(gb.plot.objects) == 1 and len(gb.plot.objects[0].object.children) == 3
    assert "determine every estimated parameter" in gb.details.object
    assert "eha-gb-corr" in gb.details.object and "Residuals of x" in gb.details.object
    assert gb.view.status == "current"
    # the downloads: the record with the simulation beside it, the estimates as JSON
    assert not any(d.disabled for d in gb.downloads)
    head = gb.data_bytes().decode().splitlines()[0]
    assert "x_sim" in head and "p2" in head
    import json

    assert json.loads(gb.estimates_bytes())["estimates"]["M"] == pytest.approx(res.estimates["M"])
    # the board receives eq. 24's H(s) at the estimate
    (model,) = session.mail("board")
    assert model.name == "GB" and model.kind == "greybox" and model.kp == 10.0
    # the settings and the page's address: the form's fields, as typed
    assert session.settings()["greybox"]["gb_guess_M"] == "5000"
    type_into(gb.form, gb_seed="3")
    assert gb.view.status == "stale"
    type_into(gb.form, gb_seed="0")
    assert gb.view.status == "current"


def test_a_small_excitation_says_b_is_undetermined():
    gb = Session(AppState()).build("greybox")
    type_into(gb.form, gb_excitation="custom", gb_u="sine:0.01:2", gb_t_end="5")
    assert gb.form.errors == {} and "gb_u" not in gb.form.hidden
    gb.run()
    res = gb.result
    assert "B" in res.held
    assert "the data do not determine B" in gb.details.object and "B + 2 kf Af / π" in gb.details.object
    assert "Held at the initial guess" in gb.details.object and "held at the initial value" in gb.table.object


def test_bad_fields_are_refused_beside_the_field():
    gb = Session(AppState()).build("greybox")
    type_into(gb.form, gb_params="M, Q")
    assert "Q is not one of" in gb.form.errors["gb_params"] and gb.button.disabled
    type_into(gb.form, gb_params="M, B", gb_measured="x, z", gb_noise_x="-1")
    assert "z is not one of" in gb.form.errors["gb_measured"]
    assert "σ x = -1 is not allowed" in gb.form.errors["gb_noise_x"]
    type_into(gb.form, gb_measured="x", gb_noise_x="0.01", gb_guess_M="0")
    assert "gb_guess_M" in gb.form.errors and gb.button.disabled and gb.run() is None
    type_into(gb.form, gb_guess_M="4000", gb_scenario="custom", gb_custom="sine:abc")
    assert "gb_custom" in gb.form.errors
    type_into(gb.form, gb_scenario="none")
    assert gb.form.errors == {} and not gb.button.disabled


def test_the_students_own_record_with_the_column_mapping():
    from eha_core.data import write_data
    from eha_core.experiments import LSE_INPUT
    from eha_core.identify.greybox import greybox_data

    truth = AppState().params
    rec = greybox_data(truth, LSE_INPUT, t_end=3.0, noise={"x": 1e-5, "p1": 5e4, "p2": 5e4}, seed=2,
                       measured=("x", "p1", "p2"))
    raw = write_data({"time": rec.t, "u": rec.u, "pos": rec.signals["x"], "p1": rec.signals["p1"],
                      "p2": rec.signals["p2"]}, "csv", units="si")
    gb = Session(AppState()).build("greybox")
    gb.upload.filename, gb.upload.value = "rig.csv", raw
    assert gb.column_mapping.waiting and gb.button.disabled
    gb.column_mapping.selects["t"].value = next(o for o in gb.column_mapping.selects["t"].options if "time" in o)
    gb.column_mapping.selects["x"].value = next(o for o in gb.column_mapping.selects["x"].options if "pos" in o)
    gb.column_mapping.button.clicks += 1
    assert gb.own_data is not None and not gb.button.disabled, gb.upload_note.object
    gb.run()
    assert gb.result.success and "rig.csv" in gb.table.object and "nominal" not in gb.table.object
    assert abs(gb.result.estimates["M"] / truth.M - 1) < 0.01
    # the file does not say how u moved between its samples: the page says what was read and why
    assert "u between samples: linear (the samples of u cannot tell" in gb.table.object
    gb.use_simulated()
    assert gb.own_data is None


def test_the_three_routes_side_by_side_and_in_the_report():
    session = Session(AppState())
    gb = session.build("greybox")
    assert gb.routes.object.count("not run") >= 3
    session.build("least_squares").run()
    session.build("frequency").run()
    assert "not run" in gb.routes.object          # grey-box itself not yet
    gb.run()
    routes = gb.routes.object
    assert "not run" not in routes and "taken as measured" in routes and "from the gain" in routes
    lse = session.section("least_squares").result
    assert estimate_texts(lse.estimates["M"], *lse.ci95["M"])[0] in routes
    assert estimate_texts(gb.result.estimates["M"], *gb.result.ci95["M"])[0] in routes
    part = type(gb).report(gb.snapshot())
    assert "three routes side by side" in part.html and "{{greybox}}" in part.html and "greybox" in part.figures
    from eha_app.render.report import session_report

    text = session_report(session, session.snapshot()).decode()
    assert "Grey-box identification (the nonlinear model)" in text and "gb_params" in text
    assert estimate_texts(gb.result.estimates["Af"], *gb.result.ci95["Af"])[0] in text


def test_the_hand_in_in_an_exercise_stores_method_greybox(lab_exercise):
    from eha_app.app import create_app

    ex, path = lab_exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    truth = ex.student_params("ada")
    gb = page.session.build("greybox")
    # the exercise's noise floors bound the σ fields, as the least squares'
    assert gb.form.values["gb_noise_v"] == "1"
    type_into(gb.form, gb_noise_x="0.001")
    assert "must lie in [0.01, 10] mm" in gb.form.errors["gb_noise_x"]
    type_into(gb.form, gb_noise_x="0.01")
    assert gb.handin_button.visible and gb.handin_button.disabled
    gb.run()
    assert gb.result.success and not gb.handin_button.disabled
    shown = gb.table.object + gb.routes.object
    assert "hidden" in gb.table.object and "nominal (tab 1)" not in gb.table.object
    for n in ("M", "B", "Af", "beta_e"):
        assert f"{getattr(truth, n):.5g}" not in shown
    gb.hand_in()
    row = HandIns(path).all()[-1]
    assert row.method == "greybox" and set(row.estimates) == {"M", "B", "Af", "beta_e"}
    assert row.conditions["noise"]["x"] == pytest.approx(1e-5) and row.settings["gb_seed"] == "0"
    assert row.estimates["M"] == pytest.approx(truth.M, rel=0.02)
    assert "from the grey-box identification" in gb.verdict.object
    from eha_app.render.report import session_report

    text = session_report(page.session, page.session.snapshot()).decode()
    assert "Grey-box identification" in text
    for n in ("M", "B", "Af", "beta_e"):
        scale = display_unit(n)[1]
        assert num_html(getattr(truth, n), 5) not in text and num_html(getattr(truth, n) / scale, 5) not in text


def test_multiple_shooting_from_the_form_ends_where_output_error_does(ran):
    session, gb = ran
    single = dict(gb.result.estimates)
    type_into(gb.form, gb_shooting="multiple")
    assert gb.view.status == "stale"
    job = gb.run()
    assert job.state == "done" and gb.result.success
    for n, v in single.items():
        assert gb.result.estimates[n] == pytest.approx(v, rel=2e-3 if n != "B" else 5e-2), n
    type_into(gb.form, gb_shooting="single")


def test_a_second_run_updates_the_same_figures(ran):
    """A run shown again changes the figures' data, not their models (no new Bokeh models to build,
    send and lay out)."""
    session, gb = ran
    figure, pane = gb.figure, gb.plot.objects[0]
    before = {s: np.array(src.data["s"]) for s, src in figure.sources.items()}
    type_into(gb.form, gb_seed="7")
    assert gb.run().state == "done"
    assert gb.figure is figure and gb.plot.objects[0] is pane
    after = {s: np.array(src.data["s"]) for s, src in figure.sources.items()}
    assert any(not np.allclose(before[s], after[s]) for s in before)
    type_into(gb.form, gb_seed="0")


def test_a_run_too_large_for_a_shared_server_is_refused_before_it_is_queued():
    session = Session(AppState())
    gb = session.build("greybox")
    type_into(gb.form, gb_excitation="custom", gb_t_end="60",
              gb_params="M, B, Af, beta_e, Kq1, Kq2, L0, k_f, d0, p1_0")
    assert gb.run() is None and gb.alert.visible
    assert "record length × (1 + parameters) = 60 s × 11 is not allowed here" in gb.alert.object
    assert "estimate fewer parameters at once, or use a shorter record" in gb.alert.object


def test_the_board_takes_the_estimate_as_a_nonlinear_model_closed_with_tab_1s_controller():
    from eha_core.board import nonlinear_step

    session = Session(AppState())
    board = session.build("board")
    gb = session.build("greybox")
    assert gb.run().state == "done"
    entry = next(e for e in board.entries if e.name == "GB1")
    eq24 = board.entries[0]
    assert entry.model.plant.actuator == gb.result.params and entry.ticked
    assert entry.model.plant.names == ("M", "B", "Af", "beta_e") and "the nonlinear model" in entry.model.description
    # simulated on the validation record it fits as the plant does; eq. 24's linearisation misses the friction
    assert board.fits[entry.key].fit_percent > 99 > 95 > board.fits[eq24.key].fit_percent
    assert board.views[entry.key].band is not None and len(board.views[entry.key].pz.poles) == 3
    # its step is the nonlinear loop's at the board's height (10 mm, then 20 mm), beside the plant's
    np.testing.assert_allclose(board.views[entry.key].step.y * 0.01,
                               nonlinear_step(gb.result.params, 10.0, 0.01).y, atol=1e-12)
    board.form.values = {**board.form.values, "board_step": "20"}
    np.testing.assert_allclose(board.views[entry.key].step.y * 0.02,
                               nonlinear_step(gb.result.params, 10.0, 0.02).y, atol=1e-12)
    assert "GB1" in board.tables["step"].object and "grey-box model" in board.tables["step"].object
    # a new Kp on tab 1: the model of the plant is closed with it (a transfer function would stay)
    session.state.set_text("kp", "25")
    assert entry.model.kp == 25.0 and "Kp = 25 V/m" in entry.model.description
    assert board.fits[entry.key].fit_percent > 99 and "Built for Kp" not in board.tables["fit"].object
    np.testing.assert_allclose(entry.model.den, eq24.model.den / eq24.model.den[0], rtol=2e-3)
