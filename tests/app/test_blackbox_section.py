"""Tab 3's black-box sub-tab without a browser: ARX with the default orders on the closed loop, the
selection table, orders refused beside their field, a failed estimate shown as failed, the model on the
board (and why an open-loop one is not), the report, and the out-of-date mark."""

import dataclasses
import re

import numpy as np
import pytest
import scipy.signal

from eha_app.session import Session
from eha_app.session.state import AppState


def type_into(form, **texts):
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


@pytest.fixture(scope="module")
def ran():
    """One session with ARX(2, 2, 1) run on the default closed-loop experiment (r -> x, Kp = 10 V/m)."""
    session = Session(AppState())
    bb = session.build("blackbox")
    job = bb.run()
    assert job.state == "done", job
    return session, bb


def test_arx_with_the_default_orders_fits_the_closed_loop(ran):
    session, bb = ran
    out = bb.outcome
    assert out.model.name == "ARX(na=2, nb=2, nk=1)" and out.model.success
    # the nonlinear loop through a second-order linear model, by simulation from zero initial conditions on a
    # second experiment, the means removed: 92.0 % here (the valve's asymmetry is an offset a linear
    # model would have to explain with the means kept); 90 % leaves room for another BLAS
    assert out.validation_fit.fit_percent > 90 and out.request.detrend
    assert "means removed" in bb.fits_pane.object
    assert out.validation_fit.label.endswith("(simulation, zero initial conditions)")
    # the fits are the core's words, wherever shown: the table and the figure's legend
    for cmp_ in (out.validation_fit, out.estimation_fit, out.model.fit):
        assert cmp_.label in bb.fits_pane.object
    fig = bb.figures["fit"]
    assert fig.items[1].label["value"] == f"model: {out.validation_fit.label}"
    assert fig.source.data["t"].size == out.validation.n_samples       # 1500 samples: not decimated
    # the model: polynomials, the parameters with their standard errors as the core gives them
    assert "A(q) = 1" in bb.model_pane.object and "B(q) =" in bb.model_pane.object
    assert bb.model_pane.object.count("<td>± ") == int(np.sum(out.model.param_std > 0)) == len(out.model.params)
    assert bb.model_pane.object.count("<tr>") == 1 + len(out.model.param_names)
    # residual tests: both verdicts' sentences, the correlations with the 99 % band of N = 1500
    for v in (out.residuals.whiteness, out.residuals.independence):
        assert v.sentence in bb.residual_pane.object.replace("&#x27;", "'")
    corr = bb.figures["resid"]
    assert corr.bands[0].top == pytest.approx(2.58 / np.sqrt(1500), rel=0.01)
    # poles in the z-plane: those of A, inside the unit circle (a stable model of a stable loop)
    pz = bb.figures["pz"]
    poles = np.array(pz.poles.data["x"]) + 1j * np.array(pz.poles.data["y"])
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(np.roots(out.model.A)), rtol=1e-12)
    assert np.all(np.abs(poles) < 1)
    assert bb.view.status == "current" and not bb.selection_pane.visible
    assert "estimated in" in bb.status.object and not bb.button.disabled and not bb.progress.visible


def test_the_board_takes_the_closed_loop_model_as_its_continuous_h(ran):
    session, bb = ran
    out = bb.outcome
    b = out.board
    assert b is not None and b.kind == "blackbox" and b.kp == 10.0 and b.params == session.state.params
    # the same loop: H(jw) (with its delay) equals G(e^jwTs) below the Nyquist frequency
    gb, ga = out.model.g_poly()
    w = np.array([0.05, 0.5, 5.0, 50.0])
    _, g_z = scipy.signal.freqz(gb, ga, worN=w * out.model.ts)
    h_s = np.polyval(b.num, 1j * w) / np.polyval(b.den, 1j * w) * np.exp(-1j * w * b.input_delay)
    if "Tustin" not in b.description:
        np.testing.assert_allclose(h_s, g_z, rtol=1e-6)
    else:       # the bilinear map warps the frequency: exact at 0, close well below the Nyquist frequency
        np.testing.assert_allclose(h_s[:2], g_z[:2], rtol=2e-3)
    assert not bb.board_button.disabled
    bb.to_board()
    bb.to_board()                                   # once per run
    (posted,) = session.mail("board")
    assert posted is b and bb.board_button.disabled and "is on the model board" in bb.board_note.object
    board = session.build("board")
    entry = next(e for e in board.entries if e.kind == "blackbox")
    assert entry.name == "ARX1" and entry.key in board.fits
    # a model of the board's own loop (Kp = 10 V/m): not marked as another loop's, and it fits the board's
    # validation record as the paper's routes do (85.9 % measured; H(s) of eq. 24 88.0 %)
    assert "Built for Kp" not in board.fit_table(board.ticked())
    assert board.fits[entry.key].fit_percent > 80


def test_the_selection_table_marks_the_picked_row():
    session = Session(AppState())
    bb = session.build("blackbox")
    type_into(bb.form, bb_choose="select", bb_criterion="bic")
    assert {"bb_na", "bb_nb", "bb_nk"} <= set(bb.form.hidden) and "bb_criterion" not in bb.form.hidden
    assert bb.run().state == "done"
    table = bb.outcome.table
    assert len(table.rows) == 32                       # MATLAB's struc(1:4, 1:4, 1:2)
    text = bb.selection_pane.object
    assert text.count("<tr") == 33 and text.count("eha-bb-picked") == 1
    picked = re.search(r"eha-bb-picked'><td>▶ ([^<]+)</td>", text).group(1)
    assert picked == table.best.name == bb.outcome.model.name
    assert min(r.bic for r in table.rows if r.success) == table.best.bic
    assert "validation fit<br><span class='eha-note'>(simulation, zero initial conditions)</span>" in text
    assert "Picked by BIC" in text
    sel = bb.figures["sel"]
    assert len(sel.crit.data["n"]) == sum(r.success for r in table.rows)
    assert sel.picked_crit.data["n"] == [table.best.n_params]
    # in the report: the table and its figure
    part = type(bb).report(bb.snapshot())
    assert "Selection of the orders" in part.html and "{{bb_sel}}" in part.html and "bb_sel" in part.figures


def test_bad_orders_are_refused_beside_the_field():
    bb = Session(AppState()).build("blackbox")
    type_into(bb.form, bb_na="-1")
    assert bb.form.errors == {"bb_na": "na = -1 is not allowed: must lie in [0, 10]"}
    assert bb.button.disabled and bb.run() is None and "na = -1 is not allowed" in bb.notice.object
    type_into(bb.form, bb_na="2", bb_nk="1.5")
    assert bb.form.errors["bb_nk"] == "nk = 1.5 is not allowed: enter a whole number; must lie in [0, 20]"
    # more parameters than half the estimation samples: said beside the largest order
    type_into(bb.form, bb_nk="1", bb_samples="100", bb_validation="split", bb_fraction="0.3", bb_na="10", bb_nb="9")
    assert "na = 10 is not allowed: the orders make 19 parameters" in bb.form.errors["bb_na"]
    # an order the structure does not have is not read (hidden), nor refused
    type_into(bb.form, bb_samples="2000", bb_validation="second experiment", bb_na="2", bb_nb="2", bb_nf="x")
    assert bb.form.errors == {} and "bb_nf" in bb.form.hidden
    type_into(bb.form, bb_structure="oe")
    assert "bb_nf" in bb.form.errors and "bb_na" in bb.form.hidden and bb.button.disabled
    type_into(bb.form, bb_nf="2", bb_horizon="k", bb_k="0")
    assert bb.form.errors == {"bb_k": "k = 0 is not allowed: must lie in [1, 1000]"}


def test_a_failed_estimate_is_shown_as_failed(monkeypatch):
    from eha_app.sections import blackbox as section

    real = section._estimate

    def failing(req, est):
        model = real(req, est)
        return dataclasses.replace(model, success=False, message="the optimiser stopped: try lower orders")

    monkeypatch.setattr(section, "_estimate", failing)
    bb = Session(AppState()).build("blackbox")
    bb.run()
    assert not bb.outcome.model.success
    assert "The estimate failed" in bb.model_pane.object and "try lower orders" in bb.model_pane.object
    assert "failed" in bb.status.object and "eha-warn" in bb.status.object and "estimated in" not in bb.status.object
    assert "These fits are of a failed estimate" in bb.fits_pane.object
    assert bb.board_button.disabled and "a failed estimate does not go on the board" in bb.board_note.object
    part = type(bb).report(bb.snapshot())
    assert "The estimate failed" in part.html


def test_an_open_loop_model_stays_off_the_board_and_says_why():
    bb = Session(AppState()).build("blackbox")
    type_into(bb.form, bb_loop="open", bb_structure="process", bb_kind="P1DI", bb_samples="1000")
    assert "bb_kp" in bb.form.hidden and bb.form.errors == {}
    bb.run()
    out = bb.outcome
    assert out.model.structure == "process" and out.board is None
    assert bb.board_button.disabled and "not the closed loop r → x the board compares" in bb.board_note.object
    assert "from u [V] to x [mm]" in bb.model_pane.object


def test_the_report_and_the_out_of_date_mark(ran):
    session, bb = ran
    part = type(bb).report(bb.snapshot())
    out = bb.outcome
    assert part.title == "Black-box models"
    for text in (out.model.name, out.validation_fit.label, out.estimation_fit.label, "Residual tests", "{{bb_fit}}",
                 "{{bb_resid}}", "{{bb_pz}}", "closed loop r → x, Kp = 10 V/m"):
        assert text in part.html, text
    assert set(part.figures) == {"bb_fit", "bb_resid", "bb_pz"}
    from eha_app.render.report import session_report

    assert "Black-box models" in session_report(session, session.snapshot()).decode()
    # the settings: the form's fields as typed; a change marks the results out of date, undoing it clears it
    assert session.settings()["blackbox"]["bb_structure"] == "arx"
    type_into(bb.form, bb_seed="5")
    assert bb.view.status == "stale" and "Out of date" in bb.view.banner.object
    assert "Out of date" in type(bb).report(bb.snapshot()).html
    type_into(bb.form, bb_seed="0")
    assert bb.view.status == "current"
    # a field the request does not read (an order of another structure) leaves it current
    type_into(bb.form, bb_nf="3")
    assert bb.view.status == "current"
    # tab 1 changes: out of date too
    session.state.set_text("M", "5000")
    assert bb.view.status == "stale"
    assert bb.kept_work() is None


def test_a_run_beyond_the_servers_limits_is_refused_before_it_is_queued():
    bb = Session(AppState()).build("blackbox")
    type_into(bb.form, bb_samples="20000", bb_ts="0.5")          # two records of 10000 s each
    assert bb.form.errors == {} and not bb.button.disabled
    assert bb.run() is None and bb.outcome is None
    assert bb.alert.visible and "N × Ts = 20000 × 0.5 s is not allowed" in bb.alert.object


def test_while_it_runs_the_button_is_off_and_the_progress_shows(monkeypatch):
    from eha_app.sections import blackbox as section

    seen = {}
    real = section.compute_blackbox

    def watched(req, params, cancel=None):
        seen.update(disabled=bb.button.disabled, progress=bb.progress.visible, again=bb.run())
        return real(req, params, cancel)

    monkeypatch.setattr(section, "compute_blackbox", watched)
    bb = Session(AppState()).build("blackbox")
    bb.run()
    assert seen == {"disabled": True, "progress": True, "again": None}      # one run at a time
    assert not bb.button.disabled and not bb.progress.visible and bb.outcome is not None


def test_a_failed_estimate_with_nan_coefficients_is_drawn_without_its_roots(monkeypatch):
    from eha_app.sections import blackbox as section

    real = section._estimate

    def broken(req, est):
        model = real(req, est)
        nan = np.full_like(model.A, np.nan)
        return dataclasses.replace(model, A=nan, params=np.full_like(model.params, np.nan), success=False,
                                   message="the regressors are singular: lower na or nb")

    monkeypatch.setattr(section, "_estimate", broken)
    bb = Session(AppState()).build("blackbox")
    assert bb.run().state == "done" and bb.alert.visible is False
    assert "The estimate failed" in bb.model_pane.object and "lower na or nb" in bb.model_pane.object
    assert bb.figures["pz"].poles.data["x"] == [] and bb.board_button.disabled
    assert type(bb).report(bb.snapshot()) is not None


def test_a_run_that_raises_says_so_and_frees_the_button(monkeypatch):
    from eha_app.sections import blackbox as section
    from eha_core.errors import ComputationError

    def broken(req, params, cancel=None):
        raise ComputationError("the simulation failed: the solver stopped at t = 3 s")

    monkeypatch.setattr(section, "compute_blackbox", broken)
    bb = Session(AppState()).build("blackbox")
    assert bb.run().state == "failed"
    assert bb.alert.visible and "the solver stopped at t = 3 s" in bb.alert.object
    assert "The estimation failed" in bb.status.object and not bb.button.disabled and not bb.progress.visible


def test_the_open_loop_integrator_with_an_input_offset_keeps_its_means():
    # u -> x in open loop: the position integrates the valve's flow, and the single-rod cylinder's
    # velocity differs with the valve's sign, which a zero-mean binary input turns into an input offset
    session = Session(AppState())
    bb = session.build("blackbox")
    type_into(bb.form, bb_loop="open", bb_structure="process", bb_kind="P1DI", bb_offset="estimate")
    assert "bb_offset" not in bb.form.hidden and "bb_kp" in bb.form.hidden
    assert bb.run().state == "done"
    out = bb.outcome
    assert not out.request.detrend and "means kept" in bb.fits_pane.object       # auto: kept in open loop
    assert out.model.input_offset is not None and "input_offset" in out.model.param_names
    # 98.8 % measured; without the offset the same model fits -16 %
    assert out.validation_fit.fit_percent > 90
    assert out.validation_fit.label.endswith("(simulation, zero initial conditions, input offset estimated)")
    assert out.validation_fit.label in bb.fits_pane.object
    type_into(bb.form, bb_structure="arx")
    assert "bb_offset" in bb.form.hidden                                         # process models only
