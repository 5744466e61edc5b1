"""The graded lab against a curious student: the truth stays hidden on a file, a reveal is final, a
hand-in says where its data came from, one code has one live page, an open exercise and the kept
uploads are bounded, and the teacher's tools hold on a damaged row."""

from __future__ import annotations

import csv
import gc
import html
import io
import re
import stat
import time
import weakref

import numpy as np
import pytest

from eha_app.app import create_app
from eha_app.dashboard import Dashboard
from eha_app.runtime.classbook import class_rows
from eha_app.runtime.handins import HandIns, handins_path
from eha_app.session import Session
from eha_app.session.state import AppState
from eha_core.exercise import HIDEABLE, Exercise


@pytest.fixture(scope="module")
def paper_record() -> bytes:
    """The paper's own simulated record (tab 3's default least squares outside an exercise), as its export:
    a file whose origin every student knows."""
    lse = Session(AppState()).build("least_squares")
    lse.form.set_values(lse_noise_x="0.01", lse_noise_v="1", lse_noise_p="0.05")
    lse.run()
    return lse.data_bytes("csv")


@pytest.fixture(scope="module")
def paper_loop() -> bytes:
    """The frequency panel's own closed-loop record (t, r, x, u) outside an exercise, as its export."""
    freq = Session(AppState()).build("frequency")
    freq.run()
    return freq.data_bytes("csv")


def _lab(tmp_path, monkeypatch, **rules) -> tuple[Exercise, object]:
    ex = Exercise.new(**{"hide": ("M", "B", "Af", "beta_e"), "secret": "7c" * 32, **rules})
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    return ex, path


def _join(who: str, address: str = "10.0.0.1"):
    """A page joined as ``who`` (a roster's code, or an id in an open exercise) from ``address``."""
    page = create_app(AppState())
    page.gate.address = address
    page.gate.student_id.value = who
    page.gate.start()
    assert page.session.student, page.gate.message.object
    return page


def _upload(section, blob: bytes, name: str = "paper.csv"):
    section._upload = (blob, name)
    section.read_upload()
    assert section.own_data is not None, section.upload_note.object


_TIMING = re.compile(r"(Identified|Simulated and estimated) in [^.<]*(\.\d+)?[^.<]*|sensitivities, [\d.]+ s")


def _shown(section) -> str:
    """What the section shows of its result, but the time it took."""
    return _TIMING.sub("", section.table.object)


def _two_students_apart(ex: Exercise, name: str) -> tuple[str, str]:
    """Two ids whose hidden ``name`` differ by at least 10 %."""
    first = ex.student_params("s0")
    for k in range(1, 200):
        other = ex.student_params(f"s{k}")
        a, b = getattr(first, name), getattr(other, name)
        if abs(a - b) > 0.1 * max(abs(a), abs(b), 1e-12):
            return "s0", f"s{k}"
    raise AssertionError(f"no two students' {name} differ")


@pytest.mark.parametrize("hidden", HIDEABLE)
def test_no_route_on_a_file_changes_with_a_hidden_value(tmp_path, monkeypatch, paper_record, paper_loop, hidden):
    """Each parameter hidden in turn: two students whose hidden value differs upload the same file (the
    paper's record) and run every route that takes a file, as often as they like. Nothing they are shown
    may differ: a hidden L0 once came back from the least squares' βe to six digits."""
    ex, _ = _lab(tmp_path, monkeypatch, hide=(hidden,), vary=0.5, attempts=0)
    a, b = _two_students_apart(ex, hidden)
    shown = {}
    for who in (a, b):
        page = _join(who)
        assert getattr(page.session.state.params, hidden) == getattr(ex.student_params(who), hidden)
        lse = page.show("least_squares")
        _upload(lse, paper_record)
        lse.run()
        assert lse.result is not None and not lse.alert.visible, lse.alert.object
        gb = page.show("greybox")
        gb.form.set_values(gb_params="M, B", gb_measured="x, p1, p2")
        _upload(gb, paper_record)
        gb.run()
        assert gb.result is not None, gb.alert.object
        page.show("frequency")
        record = page.session.section("record")
        record.upload.param.update(filename="loop.csv", value=paper_loop)
        record.run()
        assert record.result is not None, record.note.object
        board = [(m.name, m.description) for m in page.session.mail("board")]
        shown[who] = (dict(lse.result.estimates), dict(lse.result.std_errors), _shown(lse), lse.estimates_bytes("json"),
                      dict(gb.result.estimates), dict(gb.result.std_errors), _shown(gb), gb.details.object,
                      list(record.result.estimate.num), list(record.result.estimate.den), board)
    for k, (x, y) in enumerate(zip(shown[a], shown[b], strict=True)):
        assert x == y, (hidden, k)
    # and the student is told which hidden values stood in for the truth (those the routes do not estimate)
    if hidden not in ("M", "B", "Af", "beta_e", "d0"):
        assert "taken at the paper's value" in shown[a][2]


def test_a_reveal_is_final_whatever_the_deadline_says(tmp_path, monkeypatch):
    ex, path = _lab(tmp_path, monkeypatch, hide=("M",), deadline="2000-01-01T00:00")
    store = HandIns(path).check()
    dash = Dashboard(ex, store)
    dash.reveal()
    assert store.control()["revealed"] == "1"
    # the dashboard says why before the teacher moves the deadline, and moving it reopens nothing
    assert dash.deadline_button.disabled and dash.open_button.disabled
    assert "closed for good" in dash.rules.object and "reopen nothing" in dash.deadline_message.object
    dash.set_deadline("2999-01-01T00:00")
    assert store.control().get("deadline", "") == ""
    store.set_control("deadline", "2999-01-01T00:00")          # even written behind the dashboard's back
    store.set_control("open", "1")
    page = _join("ada")
    lse = page.show("least_squares")
    lse.run()
    lse.hand_in()
    assert "Not handed in: your teacher has revealed the true values" in html.unescape(lse.verdict.object)
    assert store.all() == []
    assert "Your teacher has revealed your actuator" in page.result_pane.object


def test_a_hand_in_from_a_file_is_refused_unless_the_teacher_allows_it_and_then_labelled(tmp_path, monkeypatch,
                                                                                          paper_record):
    ex, path = _lab(tmp_path, monkeypatch)
    page = _join("ada")
    lse = page.show("least_squares")
    _upload(lse, paper_record)
    lse.run()
    assert lse.handin_button.disabled and "not from a file" in lse.handin_button.description
    lse.hand_in()                           # a click the page would not send: the server refuses it all the same
    refused = html.unescape(lse.verdict.object)
    assert "Not handed in: this exercise takes estimates from your actuator's experiment" in refused
    assert HandIns(path).all() == []

    ex, path = _lab(tmp_path, monkeypatch, own_files=True)
    for who in ("ada", "bob"):              # two students, one file
        page = _join(who)
        gb = page.show("greybox")
        gb.form.set_values(gb_params="M, B", gb_measured="x, p1, p2")
        _upload(gb, paper_record, "mine.csv")
        gb.run()
        assert not gb.handin_button.disabled
        gb.hand_in()
        verdict = html.unescape(gb.verdict.object)
        assert "Handed in" in verdict and "on your file mine.csv" in verdict
    page = _join("cid")
    page.show("least_squares").run()        # the simulated sensors: no file
    page.show("least_squares").hand_in()
    store = HandIns(path)
    sources = {h.student: h.source for h in store.all()}
    assert sources["ada"]["kind"] == "file" and sources["ada"]["name"] == "mine.csv"
    assert sources["ada"]["sha256"] == sources["bob"]["sha256"] and sources["cid"] == {"kind": "simulated"}
    rows = {r.id: r for r in class_rows(ex, store)}
    table = list(csv.reader(io.StringIO(Dashboard(ex, store).csv_bytes().decode())))
    data = {r[0]: r[table[0].index("data")] for r in table[1:]}
    assert data["ada"].startswith("uploaded file mine.csv (sha256 ") and data["ada"].endswith("also handed in by bob")
    assert data["cid"] == "own actuator's experiment"
    assert rows["bob"].same_file == ("ada",)
    conditions = {r[0]: r[table[0].index("conditions")] for r in table[1:]}
    assert conditions["ada"] == "an uploaded file: not the exercise's conditions" and "σ x" in conditions["cid"]
    dash = Dashboard(ex, store)
    assert "also handed in by bob" in dash.roster.object


def test_one_code_has_one_live_page_and_the_teacher_sees_it_used_twice(tmp_path, monkeypatch, paper_record):
    ex, path = _lab(tmp_path, monkeypatch, roster=[("s1", "Ada"), ("s2", "Bob")])
    code = ex.join_code("s1")
    first = _join(code)
    lse = first.show("least_squares")
    _upload(lse, paper_record)
    lse.run()
    gone = weakref.ref(lse)
    del lse
    pages = [first]
    for _ in range(11):                     # one code, twelve pages, each with an upload
        page = _join(code)
        section = page.show("least_squares")
        _upload(section, paper_record)
        pages.append(page)
        del section
    assert [p.stopped for p in pages] == [True] * 11 + [False]
    assert "Your code was opened on another page" in first.layout.objects[-1].object
    gc.collect()
    # a page that gave way lets go of its sections (their uploads and results)
    assert gone() is None
    assert sum(p.session.section("least_squares") is not None for p in pages) == 1
    store = HandIns(path)
    seen = store.presences()["s1"]
    assert (seen.pages, seen.overlaps, seen.page) == (12, 11, pages[-1].page_token)
    row = next(r for r in class_rows(ex, store) if r.id == "s1")
    assert (row.pages, row.overlaps) == (12, 11)
    assert "12 (11 while another was open)" in Dashboard(ex, store).roster.object
    _join(ex.join_code("s2"))               # another student's page is not touched
    assert not pages[-1].stopped


def test_a_page_in_another_process_gives_way_at_its_next_look(tmp_path, monkeypatch):
    ex, path = _lab(tmp_path, monkeypatch, roster=[("s1", "Ada")])
    page = _join(ex.join_code("s1"))
    HandIns(path).seen("s1", "a-page-of-another-server")         # the same code, opened through another process
    page.check_result()
    assert page.stopped and "opened on another page" in page.layout.objects[-1].object


def test_an_open_exercise_caps_the_new_ids_of_one_address(tmp_path, monkeypatch):
    ex, path = _lab(tmp_path, monkeypatch, ids_per_client=3)
    for k in range(3):
        _join(f"student {k}", address="10.0.0.9")
    page = create_app(AppState())
    page.gate.address = "10.0.0.9"
    page.gate.student_id.value = "student 3"
    page.gate.start()
    assert not page.session.student and "started 3 new ids in this exercise in the last hour" in \
        page.gate.message.object
    _join("student 1", address="10.0.0.9")          # an id that joined before comes back
    _join("student 1", address="10.0.0.10")         # from anywhere
    _join("student 3", address="10.0.0.10")         # another computer has its own share
    for k in range(4, 10):                           # this machine itself (a proxy without --behind-proxy)
        _join(f"student {k}", address="127.0.0.1")
    assert set(HandIns(path).presence()) == {f"student {k}" for k in range(10)}


def test_kept_uploads_stop_at_the_class_quota_and_the_student_is_told(tmp_path, monkeypatch, paper_record):
    ex, path = _lab(tmp_path, monkeypatch, kept_uploads_mb=0)
    page = _join("ada")
    lse = page.show("least_squares")
    _upload(lse, paper_record, "big.csv")
    lse.run()
    note = page.settings_note.object
    assert "Your file big.csv is used on this page but not kept for a reload" in note and "is full" in note
    from eha_app.runtime.work_store import WorkStore

    assert WorkStore(HandIns(path)).load("ada").files == ()
    assert lse.result is not None                  # the page goes on with the file


def test_the_teachers_results_survive_a_damaged_row(tmp_path, capsys):
    import sqlite3

    from eha_app.cli import main

    path = tmp_path / "class.json"
    ex = Exercise.new(hide=("M",), secret="44" * 32)
    ex.save(path)
    store = HandIns(path).check()
    store.add("ada", {"M": ex.student_params("ada").M}, {"M": True})
    store.add("bob", {"M": 1.0}, {"M": False})
    with sqlite3.connect(handins_path(path)) as db:                # edited by hand: not JSON any more
        db.execute("UPDATE handins SET estimates = 'M=4000' WHERE student = 'bob'")
    out_csv = tmp_path / "results.csv"
    assert main(["exercise", "results", str(path), "--csv", str(out_csv)]) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err and "1 stored hand-in could not be read" in out
    assert "ada" in out and np.isclose(float(next(r for r in csv.reader(open(out_csv)) if r[0] == "ada")[7]),
                                       ex.student_params("ada").M, rtol=1e-5)
    # every student's errors against the truth: the teacher's file only
    assert stat.S_IMODE(out_csv.stat().st_mode) == 0o600


def test_the_dashboard_token_rotates_and_expires(tmp_path, monkeypatch, capsys):
    """A leaked link is undone by a rotation (no student's actuator changes), and a link ends by itself."""
    from eha_app.cli import main
    from eha_app.runtime import teacher_access as ta

    ex, path = _lab(tmp_path, monkeypatch)
    store = HandIns(path).check()
    assert main(["exercise", "token", str(path), "--url", "http://10.1.2.3:5006"]) == 0
    first = capsys.readouterr().out
    link = re.search(r"http://10\.1\.2\.3:5006/teacher\?token=([0-9a-f]{40})", first)
    assert link and "valid until" in first and "new link" in first
    token = link.group(1)
    assert ta.decide("/teacher", token, None, ta._teacher_token().token) == "login"
    assert main(["exercise", "token", str(path)]) == 0                  # printed again: the same link
    assert token in capsys.readouterr().out
    students = {s: ex.student_params(s) for s in ("s1", "s2")}
    assert main(["exercise", "token", str(path), "--rotate", "--days", "7"]) == 0
    rotated = re.search(r"token=([0-9a-f]{40})", capsys.readouterr().out).group(1)
    now = ta._teacher_token()
    assert rotated != token and now.token == rotated and 6.99 < (now.expires - time.time()) / 86400 < 7.01
    # the old link and the old cookie no longer open anything; the new ones do
    assert ta.decide("/teacher", token, None, now.token) == "forbidden"
    assert ta.decide("/teacher/ws", None, ta.cookie_value(token), now.token) == "forbidden"
    assert ta.decide("/teacher/ws", None, ta.cookie_value(rotated), now.token) == "pass"
    assert {s: Exercise.load(path).student_params(s) for s in students} == students
    store.set_controls({"token_expires": "1000"})                      # long past
    assert ta._teacher_token().expired
    assert ta.decide("/teacher", rotated, None, rotated, expired=True) == "expired"
    assert main(["exercise", "token", str(path)]) == 0                  # expired: a new one is made
    out = capsys.readouterr().out
    assert "new link" in out and rotated not in out
    assert main(["exercise", "token", str(path), "--days", "0"]) == 2
    assert "--days = 0 is not allowed" in capsys.readouterr().err
