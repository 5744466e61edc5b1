"""Work for a view no one is looking at waits until someone does: tab 1 typed into recomputes neither
tab 2's simulation nor the model board while they are out of sight; each says it is out of date and
computes again once shown. Without a page (a script, a test of one section) everything is in sight."""

from eha_app.app import create_app
from eha_app.session import Session
from eha_app.session.state import AppState


def test_tab_1_typed_into_recomputes_only_what_is_in_sight():
    page = create_app(AppState())
    session = page.session
    sim = page.show("simulation")
    sim.run("nonlinear")
    board = page.show("board")
    assert session.in_sight("board") and not session.in_sight("simulation")
    record_key, views = board.record_key, dict(board.views)
    page.tabs.tabs.active = 0                                       # back to tab 1, and type
    assert not session.in_sight("board") and not session.in_sight("least_squares")
    session.state.set_text("M", "7000")
    assert board.record_key == record_key and board.record_view.status == "stale"
    assert sim.view.status == "stale" and sim.results[0].params.M != 7000
    session.state.set_text("M", "7100")                             # typed again: still one catch-up each
    assert len(session._out_of_sight["board"]) == 1 and len(session._out_of_sight["simulation"]) == 1
    page.show("simulation")                                         # shown: computed with what tab 1 says
    assert sim.view.status == "current" and sim.results[0].params.M == 7100
    assert board.record_view.status == "stale"                      # the board is still not on show
    page.show("board")
    assert board.record_key != record_key and board.record_key[0].M == 7100
    assert board.record_view.status == "current" and set(board.views) == set(views)
    assert session._out_of_sight == {}


def test_without_a_page_every_section_is_in_sight():
    session = Session(AppState())
    board = session.build("board")
    key = board.record_key
    session.state.set_text("M", "7000")
    assert session.in_sight("board") and board.record_key != key and board.record_key[0].M == 7000


def test_the_board_computes_each_view_when_its_tab_is_first_opened_and_the_report_has_them_all():
    page = create_app(AppState())
    page.show("least_squares").run()
    page.show("frequency").run()
    board = page.show("board")                                      # opens on the fit on the validation record
    models = list(board.entries)
    assert all(e.key in board.fits for e in models) and board.record is not None
    assert board.views == {} and board.plant is None and set(board.figures) == {"fit"}
    assert board.record_view.status == "current"
    bode = board.show_view("bode")
    assert set(board.views) == {e.key for e in models} and board.plant is None
    assert len(bode.curves.data["xs"]) == len(board.ticked())
    board.show_view("step")
    assert board.plant is not None and "nonlinear plant" in board.tables["step"].object
    assert board.record_view.status == "current"
    # a page that never opened them: the report draws every view all the same
    other = create_app(AppState())
    other.show("least_squares").run()
    fresh = other.show("board")
    assert fresh.views == {} and fresh.plant is None
    part = type(fresh).report(fresh.snapshot())
    assert {"board_fit", "board_bode", "board_step", "board_pz"} <= set(part.figures)
    assert "nonlinear plant" in part.html
    complete = fresh.snapshot().content.complete()
    assert set(complete.views) == {e.key for e in complete.entries} and complete.plant is not None
