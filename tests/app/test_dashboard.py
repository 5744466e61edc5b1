"""The teacher's dashboard as an object (no server): it follows the store, its switches write the
store's control, a reveal waits for the deadline, the CSV neutralises a formula, student text is escaped."""

from __future__ import annotations

import asyncio
import csv
import io

import pytest

from eha_app.dashboard import Dashboard, join_slips_html
from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise

HIDE = ("M", "B")


@pytest.fixture
def lab(tmp_path):
    ex = Exercise.new(hide=HIDE, title="Lab <3>", secret="22" * 32, deadline="2030-01-01T12:00",
                      roster=[("s1", "Ada Lovelace"), ("s2", '=HYPERLINK("http://evil.example","x")'),
                              ("s3", "<img src=x onerror=alert(1)>")])
    path = tmp_path / "class.json"
    ex.save(path)
    return ex, HandIns(path).check()


def hand_in(ex, store, student, factor):
    truth = ex.student_params(student)
    est = {n: getattr(truth, n) * factor for n in HIDE}
    return store.add(student, est, ex.verdicts(student, est), errors=ex.errors(student, est))


def test_hand_ins_added_to_the_store_show_up_after_a_poll(lab):
    ex, store = lab
    dash = Dashboard(ex, store)
    assert "Ada Lovelace" in dash.roster.object and "Nobody" not in dash.roster.object
    assert "No hand-in yet" in dash.history.object
    assert dash.poll() is False                      # nothing changed: nothing drawn again
    store.seen("s1")
    hand_in(ex, store, "s1", 1.02)
    hand_in(ex, store, "s1", 1.5)
    assert dash.poll() is True
    roster = dash.roster.object
    assert "+2.00 %" in dash.history.object and "+50.00 %" in roster      # the last one's error, per parameter
    assert "1 joined of 3" not in dash.summary.object and "1 of 3 joined" in dash.summary.object
    assert dash.history.object.count("<tr>") == 3                          # a header and two hand-ins
    assert dash.who.options == ["(everyone)", "s1"]
    dash.who.value = "s1"
    assert dash.history.object.count("<tr>") == 3
    # the periodic callback's way: the read in a thread, the drawing after it
    hand_in(ex, store, "s3", 1.0)
    asyncio.run(dash.tick())
    assert "s3" in dash.who.options and dash.roster.object.count("✓") >= 2


def test_student_text_is_escaped(lab):
    ex, store = lab
    store.seen("<script>alert(1)</script>")           # an id typed in an open exercise would be anything
    dash = Dashboard(ex, store)
    page = dash.roster.object + dash.rules.object
    assert "<script>" not in page and "&lt;script&gt;" in page
    assert "<img src=x" not in page and "&lt;img src=x" in page
    assert "Lab &lt;3&gt;" in dash.rules.object
    slips = join_slips_html(ex, "http://host:5006/eha")
    assert "<img src=x" not in slips and ex.join_code("s1") in slips and "http://host:5006/eha" in slips


def test_the_switches_write_the_control(lab):
    ex, store = lab
    dash = Dashboard(ex, store)
    assert dash.open_button.label == "Close hand-ins"
    dash.open_button.clicks += 1
    assert store.control()["open"] == "0" and dash.open_button.label == "Open hand-ins"
    assert "closed" in dash.rules.object
    dash.toggle_open()
    assert store.control()["open"] == "1"
    # the deadline: a bad one is refused with the house message beside the field, a good one stored
    dash.deadline_input.value = "next friday"
    dash.deadline_button.clicks += 1
    assert "deadline = next friday is not allowed" in dash.deadline_message.object
    assert "deadline" not in store.control()
    dash.set_deadline("2031-06-01T17:00")
    assert store.control()["deadline"] == "2031-06-01T17:00" and dash.deadline_message.object == ""
    assert "2031-06-01T17:00" in dash.rules.object and "moved by you" in dash.rules.object
    dash.set_deadline("")
    assert store.control()["deadline"] == ""                # back to the file's


def test_a_reveal_waits_for_the_deadline(lab):
    ex, store = lab
    now = [ex.deadline_at() - 60]
    dash = Dashboard(ex, store, clock=lambda: now[0])
    dash.reveal_button.clicks += 1
    assert "has not passed" in dash.reveal_message.object and "revealed" not in store.control()
    now[0] += 120                                       # a minute after the deadline
    assert dash.poll() is True                          # the deadline's passing is drawn without a change
    assert "passed" in dash.rules.object
    dash.reveal()
    assert store.control()["revealed"] == "1" and dash.reveal_button.disabled


def test_no_deadline_no_reveal(tmp_path):
    ex = Exercise.new(hide=HIDE, secret="33" * 32)
    dash = Dashboard(ex, HandIns(tmp_path / "c.json").check())
    dash.reveal()
    assert "no deadline" in dash.reveal_message.object
    assert not dash.slips.visible                       # an open exercise has no codes to print


def test_the_csv_neutralises_a_formula_in_a_name(lab):
    ex, store = lab
    hand_in(ex, store, "s2", 1.0)
    rows = list(csv.reader(io.StringIO(Dashboard(ex, store).csv_bytes().decode())))
    s2 = next(r for r in rows if r[0] == "s2")
    assert s2[1] == '\'=HYPERLINK("http://evil.example","x")' and s2[rows[0].index("score (best)")] == "1.00"
