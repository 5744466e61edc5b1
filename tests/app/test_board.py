"""The model board: estimates land on it, are compared on one validation record, ticked, renamed, deleted."""

import numpy as np
import pytest

from eha_app.session import Session
from eha_app.session.state import AppState


@pytest.fixture
def tab():
    t = Session(AppState())
    t.build("board")
    return t


def _names(board):
    return [e.name for e in board.entries]


def test_the_references_are_there_and_compared_on_the_validation_record(tab):
    board = tab.section("board")
    assert _names(board) == ["H(s) eq. 24", "Ĥ paper"]
    assert [e.ticked for e in board.entries] == [True, False]
    assert board.record is not None and board.record.t.size == 1000
    fits = {e.name: board.fits[e.key].fit_percent for e in board.entries}
    assert 60 < fits["H(s) eq. 24"] < 95                       # the linearised model misses the friction
    assert board.record_view.status == "current"
    fig = board.show_view("fit")
    assert len(fig.models.data["xs"]) == 1                     # only the ticked one is drawn
    assert "H(s) eq. 24" in fig.legend.text and "Ĥ paper" not in fig.legend.text
    assert "H(s) eq. 24" in board.tables["fit"].object and "validation record" in board.tables["fit"].object
    # the nonlinear plant under the same controller, with its figures, beside the models
    assert board.plant is not None and "nonlinear plant" in board.tables["step"].object


def test_estimates_land_on_the_board_and_tick_rename_delete(tab):
    board = tab.section("board")
    tab.build("least_squares").run()
    freq = tab.build("frequency")
    source = Session(AppState()).build("frequency")
    source.run()
    record = freq.record
    record.upload.filename = "loop.csv"
    record.upload.value = source.data_bytes("csv")
    record.run()
    assert _names(board) == ["H(s) eq. 24", "Ĥ paper", "LS1", "R1"]
    ls1, r1 = board.entries[2], board.entries[3]
    assert ls1.kind == "lse" and "least squares" in ls1.model.description
    # noise-free least squares: eq. 24 with the estimates is eq. 24 itself
    np.testing.assert_allclose(ls1.model.den, board.entries[0].model.den, rtol=1e-4)
    assert board.views[r1.key].band is not None and board.views[ls1.key].band is None
    assert board.fits[r1.key].fit_percent > 85
    bode = board.show_view("bode")
    assert len(bode.curves.data["xs"]) == 3 and len(bode.mag_band.data["xs"]) == 1
    board.tick(board.entries[0], False)
    assert len(bode.curves.data["xs"]) == 2 and "H(s) eq. 24" not in bode.legend.text
    board.rename(r1, "my record")
    assert "my record" in board.show_view("step").legend.text and "my record" in board.tables["fit"].object
    board.delete(ls1)
    assert _names(board) == ["H(s) eq. 24", "Ĥ paper", "my record"]
    assert len(board.show_view("pz").poles.data["x"]) == 3        # R1's three poles only
    board.delete(board.entries[0])                             # a reference stays
    assert len(board.entries) == 3


def test_a_weakly_determined_pole_is_shown_not_hidden(tab):
    from eha_core.board import BoardModel
    from eha_core.experiments import FrequencyExperiment, run_frequency_identification

    fi = run_frequency_identification(config=FrequencyExperiment(model="linear"))
    e = fi.estimate
    entry = tab.section("board").add(BoardModel(name="H1", kind="tf", description="linear plant", num=e.num, den=e.den,
                                     estimate=e, ts=0.01))
    flagged = [r for r in tab.section("board").views[entry.key].pz.poles if r.weakly_determined]
    assert len(flagged) == 1 and -500 < flagged[0].location.real < -300     # the pole near -385 rad/s
    pz = tab.section("board").show_view("pz")
    assert len(pz.flagged.data["x"]) == 1 and "weakly determined" in pz.note.text
    assert len(pz.nyquist.data["x"]) > 0 and "π/Ts = 314 rad/s" in pz.note.text
    # three real poles: their regions are intervals of the real axis (drawn as bars), not ellipses
    assert len(pz.regions.data["xs"]) + len(pz.intervals.data["x0"]) == 3
    assert pz.intervals.data["x0"][0] < pz.intervals.data["x1"][0]


def test_step_table_figures_are_the_cores(tab):
    board = tab.section("board")
    view = board.views[board.entries[0].key]
    table = board.tables["step"].object
    assert f"{view.step.info.rise_time_s:.3g}" in table and f"{board.plant.info.rise_time_s:.3g}" in table
    board.form.values = {**board.form.values, "board_step": "20"}
    assert board.show_view("step").reference.location == pytest.approx(20.0)
    board.form.values = {**board.form.values, "board_step": "-1"}
    assert board.form.errors["board_step"] == "step of r = -1 is not allowed: must lie in [0.01, 200] mm"


def test_an_exercise_board_has_no_eq24():
    state = AppState()
    state.secret = {"M": 4000.0, "B": 1000.0}
    t = Session(state)
    t.build("board")
    assert _names(t.section("board")) == ["Ĥ paper"]


def test_the_frequency_experiment_lands_on_the_board(tab):
    freq = tab.build("frequency")
    freq.run()
    h1 = next(e for e in tab.section("board").entries if e.name == "H1")
    assert h1.kind == "tf" and "seed 0" in h1.model.description
    np.testing.assert_array_equal(h1.model.den, freq.result.estimate.den)
    view = tab.section("board").views[h1.key]
    assert view.band is not None and len(view.pz.poles) == 3
    assert tab.section("board").fits[h1.key].fit_percent > 90         # a fresh record: the estimate carries over


def test_estimates_made_before_the_board_is_opened_are_on_it():
    t = Session(AppState())
    t.build("least_squares").run()
    t.build("least_squares").run()
    assert t.section("board") is None and len(t.mail("board")) == 2     # no board for a session that never looks
    board = t.build("board")
    assert _names(board) == ["H(s) eq. 24", "Ĥ paper", "LS1", "LS2"] and not t.mail("board")
    assert all(e.key in board.views for e in board.entries)


def test_the_validation_record_is_marked_while_tab_1_is_not_valid(tab):
    """Found by the random walk: with an invalid field on tab 1 the board's views stayed 'current'
    (tab 1 keeps its last valid parameters, so the board saw no change)."""
    board, state = tab.section("board"), tab.state
    assert board.record_view.status == "current"
    state.set_text("Kq1", "1e309")
    assert not state.valid and board.record_view.status == "stale"
    assert "not valid" in board.record_view.banner.object
    state.set_text("Kq1", "3.043")
    assert state.valid and board.record_view.status == "current"
    # a change of validity and parameters at once (one batch of two events): every tab follows
    sim = tab.build("simulation")
    state.set_text("k_f", "-1")
    assert all(b.disabled for b in sim.run_buttons.values())
    state.set_text("k_f", "800")                   # valid again, and new parameters: two events at once
    assert state.valid and not any(b.disabled for b in sim.run_buttons.values())
    assert board.record_view.status == "current" and board.record_key[0].k_f == 800


def test_a_model_of_a_previous_actuator_is_marked_with_the_change(tab):
    """After M 4000 -> 6000 the record follows tab 1: the fits of models estimated on M = 4000 are against a
    plant they were not made from, and the table says so and names the change (it said nothing)."""
    board = tab.section("board")
    tab.build("frequency").run()
    h1 = board.entries[-1]
    assert h1.name == "H1" and h1.model.params.M == 4000.0
    fit_before = board.fits[h1.key].fit_percent
    assert "another actuator" not in board.tables["fit"].object
    tab.state.set_text("M", "6000")
    assert board.record_key[0].M == 6000.0 and board.record_view.status == "current"
    table = board.tables["fit"].object
    assert "Estimated on another actuator (M 4000 → 6000 kg)" in table
    assert "changed after 1 of these models was estimated" in table
    assert board.fits[h1.key].fit_percent != fit_before
    # the references follow tab 1: they are not marked
    assert table.count("eha-board-other-actuator") == 1
    tab.state.set_text("M", "4000")
    assert "another actuator" not in board.tables["fit"].object


def test_only_the_view_in_sight_is_drawn_the_others_when_opened(tab):
    """A view whose tab is not open costs nothing: its figure is made and filled when it is opened."""
    board = tab.section("board")
    assert set(board.figures) == {"fit"}
    bode = board.show_view("bode")
    assert set(board.figures) == {"fit", "bode"} and len(bode.curves.data["xs"]) == 1
    board.tick(board.entries[1], True)                          # Ĥ paper
    assert len(bode.curves.data["xs"]) == 2
    fit = board.figures["fit"]
    assert len(fit.models.data["xs"]) == 1                     # out of sight: not redrawn
    assert board.show_view("fit") is fit and len(fit.models.data["xs"]) == 2
    assert "Ĥ paper" in board.tables["fit"].object             # the tables are kept current throughout


def test_estimates_made_before_the_board_is_opened_land_together():
    session = Session(AppState())
    session.build("least_squares").run()
    session.build("frequency").run()
    session.build("greybox").run()
    board = session.build("board")
    assert _names(board) == ["H(s) eq. 24", "Ĥ paper", "LS1", "H1", "GB1"]
    assert all(e.key in board.views and e.key in board.fits for e in board.entries)
    rows = board.list.objects
    assert len(rows) == 5 and all("eha-board-name" in r.objects[0].objects[2].css_classes for r in rows)
