"""A student's work in an exercise survives a reload and a restart: settings, results, uploads."""

import logging
import os

import numpy as np
import pytest

from eha_app.app import create_app
from eha_app.runtime.handins import HandIns, handins_path
from eha_app.runtime.work_store import WorkStore
from eha_app.session.state import AppState
from eha_core.exercise import Exercise

HIDE = ("M", "B", "Af", "beta_e")


@pytest.fixture
def exercise(tmp_path, monkeypatch):
    ex = Exercise.new(hide=HIDE, roster=[("s1", "Ada"), ("s2", "Alan")], title="Lab 3", secret="5a" * 32)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    return ex, path


def join(student: str):
    """A new page (a reload, or a server started again: nothing but the database is shared), joined
    as ``student`` through the exercise's gate."""
    page = create_app(AppState())
    page.gate.student_id.value = Exercise.load(os.environ["EHA_EXERCISE"]).join_code(student)   # their slip's code
    page.gate.start()
    assert page.session.student == student
    return page


def _settings(page) -> dict:
    return {k: v for k, v in page.session.settings().items() if k != "tab"}


def test_settings_and_results_come_back_for_the_same_student_only(exercise):
    ex, path = exercise
    page = join("s1")
    session = page.session
    session.state.set_text("kp", "12")
    session.state.set_text("Dc", "125")
    lse = page.show("least_squares")
    lse.form.set_values(lse_seed="7", lse_noise_p="0.05", lse_model="harmonic")
    lse.run()
    freq = page.show("frequency")
    freq.form.set_values(freq_seed="3", n_samples="2000")
    freq.run()
    assert lse.view.is_current and freq.views["summary"].is_current
    estimates = dict(lse.result.estimates)
    num, den = freq.result.estimate.num, freq.result.estimate.den
    kept = WorkStore(HandIns(path)).load("s1")
    assert set(kept.runs) == {"least_squares", "frequency"} and kept.files == ()
    settings, board = _settings(page), [m.name for m in session.mail("board")]

    again = join("s1")              # a fresh page: only the database remembers
    assert page.stopped and not again.stopped      # one id, one live page: the first gave way
    lse2, freq2 = again.session.section("least_squares"), again.session.section("frequency")
    assert _settings(again) == settings
    assert again.session.state.params == session.state.params
    assert lse2.view.is_current and freq2.views["summary"].is_current
    assert dict(lse2.result.estimates) == estimates                  # to the last digit
    assert np.array_equal(freq2.result.estimate.num, num) and np.array_equal(freq2.result.estimate.den, den)
    note = again.settings_note.object
    assert "Your work was restored" in note and "results of Least squares, Transfer function" in note
    assert "settings of Parameters" in note and "computing again" not in note
    # the board was sent the restored estimates, as by a click (an unphysical least-squares estimate,
    # which the exercise's noise can give, is not a model: then the first page had no LS either)
    assert [m.name for m in again.session.mail("board")] == board
    assert "H" in board

    other = join("s2")              # nothing of s1's
    assert other.session.section("least_squares") is None and other.session.section("frequency") is None
    assert other.session.settings()["least_squares"]["lse_seed"] == "0"
    assert other.session.state.texts["Dc"] != "125" and other.settings_note.object == ""
    assert WorkStore(HandIns(path)).load("s2") is None


def test_settings_alone_are_kept_and_a_changed_run_is_not_run_again(exercise):
    _, path = exercise
    page = join("s1")
    lse = page.show("least_squares")
    lse.run()
    lse.form.set_values(lse_seed="5")           # the table is out of date: not a result to compute again
    assert not lse.view.is_current
    again = join("s1")
    lse2 = again.session.section("least_squares")
    assert lse2 is None or lse2.result is None
    assert again.session.settings()["least_squares"]["lse_seed"] == "5"
    assert "results of" not in again.settings_note.object


def test_an_uploaded_record_with_its_columns_comes_back(exercise):
    ex, path = exercise
    page = join("s1")
    lse = page.show("least_squares")
    lse.form.set_values(lse_seed="2")
    lse.run()
    csv = lse.data_bytes("csv").replace(b"t[s],x[m]", b"time[s],pos[m]", 1)
    lse.upload.param.update(filename="mine.csv", value=csv)
    assert lse.column_mapping.waiting
    lse.mapping_selects["t"].value, lse.mapping_selects["x"].value = "time[s]", "pos[m]"
    lse.mapping_button.clicks += 1
    assert lse.own_data is not None
    lse.window_form.set_values(own_from="1", own_to="4")
    lse.run()
    estimates = dict(lse.result.estimates)
    assert "mine.csv" in lse.table.object + lse.upload_note.object

    again = join("s1")
    lse2 = again.session.section("least_squares")
    assert lse2.own_data is not None and lse2.windowed().t.size == lse.windowed().t.size
    assert lse2.window_form.values["own_from"] == "1" and lse2.window_form.values["own_to"] == "4"
    assert dict(lse2.result.estimates) == estimates and lse2.view.is_current
    kept = WorkStore(HandIns(path)).load("s1").files
    assert [(f.slot, f.name, f.data == csv) for f in kept] == [("least_squares", "mine.csv", True)]
    assert kept[0].mapping["t"] == "time[s]"


def test_a_damaged_database_is_said_and_the_page_goes_on(exercise, caplog):
    _, path = exercise
    join("s1").show("least_squares").run()
    handins_path(path).write_bytes(b"this is not a database" * 100)
    caplog.set_level(logging.WARNING, logger="eha_app")
    page = join("s1")
    assert "Your earlier work could not be read" in page.settings_note.object
    assert "move it away to start an empty one" in page.settings_note.object
    lse = page.show("least_squares")
    lse.form.set_values(lse_seed="3")
    lse.run()                                   # the page works; the save says it could not be made
    assert lse.result is not None and lse.view.is_current
    assert "could not be saved" in caplog.text and "could not be read" in caplog.text


def test_outside_an_exercise_nothing_is_kept(monkeypatch, tmp_path):
    monkeypatch.delenv("EHA_EXERCISE", raising=False)
    page = create_app(AppState())
    assert page.work is None
    page.show("least_squares").run()
    assert list(tmp_path.iterdir()) == []


def test_an_own_record_of_the_frequency_domain_comes_back_with_its_range(exercise):
    _, path = exercise
    page = join("s1")
    freq = page.show("frequency")
    freq.form.set_values(n_samples="2000")
    freq.run()
    rec = page.session.section("record")
    loop = freq.data_bytes("csv")
    rec.upload.param.update(filename="loop.csv", value=loop)
    assert rec.columns is not None
    rec.window_form.set_values(rec_from="0.5")
    rec.detrend.value = "mean"
    rec.run()
    assert rec.view.is_current
    num, den = rec.result.estimate.num, rec.result.estimate.den

    again = join("s1")
    rec2 = again.session.section("record")
    assert rec2.columns[3] == "loop.csv" and rec2.window_form.values["rec_from"] == "0.5"
    assert rec2.detrend.value == "mean" and rec2.view.is_current
    assert np.array_equal(rec2.result.estimate.num, num) and np.array_equal(rec2.result.estimate.den, den)
    assert "Your own record" in again.settings_note.object
    kept = WorkStore(HandIns(path)).load("s1")
    assert [(f.slot, f.name, f.data == loop, f.mapping) for f in kept.files] == [("record", "loop.csv", True, None)]


def test_a_reloaded_address_wins_over_the_kept_settings(exercise):
    """A reload keeps every field that differs from its default in the address (a missing one is the
    default); the kept settings may lag the last change by a couple of seconds: the address wins, and
    a kept result is run again only where its fields are the page's."""
    _, path = exercise
    page = join("s1")
    page.session.state.set_text("Dc", "125")
    lse = page.show("least_squares")
    lse.form.set_values(lse_seed="4")
    lse.run()
    estimates = dict(lse.result.estimates)

    def reload(query):
        again = create_app(AppState(), query=query)
        again.gate.student_id.value = Exercise.load(os.environ["EHA_EXERCISE"]).join_code("s1")
        again.gate.start()
        return again

    same = reload({"Dc": "125", "lse_seed": "4", "tab": "3"})       # the address as the page wrote it
    lse2 = same.session.section("least_squares")
    assert lse2.result is not None and dict(lse2.result.estimates) == estimates
    moved = reload({"lse_seed": "9"})                               # Dc back at its default, seed 9
    assert moved.session.state.texts["Dc"] == "120" and moved.session.settings()["least_squares"]["lse_seed"] == "9"
    lse3 = moved.session.section("least_squares")
    assert lse3 is None or lse3.result is None                      # tab 1 differs: nothing is run again


def test_the_grey_box_result_comes_back_after_a_rejoin(exercise):
    """The grey-box is one of an exercise's hand-in routes: its result comes back like the least squares',
    and can be handed in from the page the student joined again on."""
    _, path = exercise
    page = join("s1")
    gb = page.show("greybox")
    gb.form.set_values(gb_params="M, B", gb_seed="4")
    gb.run()
    assert gb.result.success and gb.view.is_current
    estimates = dict(gb.result.estimates)
    assert WorkStore(HandIns(path)).load("s1").runs["greybox"] == {"views": ["gb"]}

    again = join("s1")
    gb2 = again.session.section("greybox")
    assert gb2 is not None and gb2.view.is_current and gb2.form.values["gb_seed"] == "4"
    assert dict(gb2.result.estimates) == estimates                     # to the last digit
    assert "results of Grey-box (nonlinear)" in again.settings_note.object
    assert not gb2.handin_button.disabled
    assert "GB" in [m.name for m in again.session.mail("board")]      # the board was sent it again


def _renamed(data: bytes, old: bytes, new: bytes) -> bytes:
    """The CSV with its header's column ``old`` called ``new`` (a file whose columns need the mapping)."""
    head, rest = data.split(b"\n", 1)
    assert old in head.split(b",")
    return b",".join(new if c == old else c for c in head.split(b",")) + b"\n" + rest


def test_every_result_comes_back_after_a_restart_of_the_server(exercise):
    """A new server process: nothing but the exercise's database is shared (a new store on the same
    file, no result computed by the old process). The simulation, the least squares, the transfer
    function, the own record with its range and the grey-box on the student's file with its columns
    come back, each with the same numbers."""
    from eha_app.runtime import exercise_file, work_store
    from eha_app.runtime.shared import shared_results

    _, path = exercise
    page = join("s1")
    sim = page.show("simulation")
    sim.set_inputs(t_end="2")
    sim.run("both")
    lse = page.show("least_squares")
    lse.form.set_values(lse_seed="3")
    lse.run()
    freq = page.show("frequency")
    freq.form.set_values(n_samples="2000")
    freq.run()
    rec = page.session.section("record")
    rec.upload.param.update(filename="loop.csv", value=freq.data_bytes("csv"))
    rec.window_form.set_values(rec_from="0.5")
    rec.run()
    gb = page.show("greybox")
    gb.form.set_values(gb_params="M, B", gb_seed="2")
    gb.run()
    record = _renamed(gb.data_bytes(), b"x[m]", b"pos[m]")
    gb.upload.param.update(filename="rig.csv", value=record)
    assert gb.column_mapping.waiting                                 # x is not found by its name
    gb.column_mapping.selects["x"].value = "pos[m]"
    gb.column_mapping.button.clicks += 1
    assert gb.own_data is not None
    gb.run()
    assert all(v.is_current for v in (sim.view, lse.view, freq.views["summary"], rec.view, gb.view))
    assert "rig.csv" in gb.table.object
    shown = {"simulation": [r.x.copy() for r in sim.results], "least_squares": dict(lse.result.estimates),
             "frequency": freq.result.estimate.den.copy(), "record": rec.result.estimate.den.copy(),
             "greybox": dict(gb.result.estimates)}
    work_store.drain()
    page.give_way()                               # the old server's page is gone

    # the restart: a new process reads the exercise and opens its database afresh, and has computed nothing
    exercise_file._exercise_at.cache_clear()
    shared_results.clear()
    again = join("s1")
    assert again.session.state.handins is not page.session.state.handins
    s = again.session
    sim2, lse2, freq2 = s.section("simulation"), s.section("least_squares"), s.section("frequency")
    rec2, gb2 = s.section("record"), s.section("greybox")
    assert all(v.is_current for v in (sim2.view, lse2.view, freq2.views["summary"], rec2.view, gb2.view))
    assert [r.x.tolist() for r in sim2.results] == [x.tolist() for x in shown["simulation"]]
    assert dict(lse2.result.estimates) == shown["least_squares"]
    assert np.array_equal(freq2.result.estimate.den, shown["frequency"])
    assert np.array_equal(rec2.result.estimate.den, shown["record"]) and rec2.window_form.values["rec_from"] == "0.5"
    assert gb2.own_data is not None and gb2.own_data_key[0] == "rig.csv" and "rig.csv" in gb2.table.object
    assert dict(gb2.result.estimates) == shown["greybox"]
    note = again.settings_note.object
    for title in ("Simulation", "Least squares", "Transfer function", "Your own record", "Grey-box (nonlinear)"):
        assert title in note, title
    kept = WorkStore(HandIns(path)).load("s1")
    assert sorted((f.slot, f.name) for f in kept.files) == [("greybox", "rig.csv"), ("record", "loop.csv")]
    assert [f.mapping["x"] for f in kept.files if f.slot == "greybox"] == ["pos[m]"]


def test_a_run_on_a_file_that_was_not_kept_is_not_run_again_on_simulated_data(tmp_path, monkeypatch):
    """A file past the class's space for kept files is not kept: its run is not computed again on the
    simulated sensors (another result under the same name); the settings still come back."""
    ex = Exercise.new(hide=HIDE, roster=[("s1", "Ada")], title="Lab 3", secret="5a" * 32, kept_uploads_mb=0)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    page = join("s1")
    gb = page.show("greybox")
    gb.form.set_values(gb_params="M, B")
    gb.run()
    gb.upload.param.update(filename="rig.csv", value=gb.data_bytes())
    gb.run()
    assert gb.own_data is not None and gb.view.is_current and "rig.csv" in gb.table.object
    assert "Your file rig.csv is used on this page but not kept for a reload" in page.settings_note.object
    kept = WorkStore(HandIns(path)).load("s1")
    assert kept.files == () and kept.runs["greybox"] == {"views": ["gb"], "file": "rig.csv"}

    again = join("s1")
    gb2 = again.session.section("greybox")
    assert gb2 is None or gb2.result is None
    assert again.session.settings()["greybox"]["gb_params"] == "M, B"
    assert "settings of" in again.settings_note.object and "results of" not in again.settings_note.object
