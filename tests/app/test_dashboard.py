"""The teacher's dashboard as an object (no server): it follows the store, its switches write the
store's control, a reveal waits for the deadline, the CSV neutralises a formula, student text is escaped."""

from __future__ import annotations

import asyncio
import csv
import io

import pytest

from eha_app.dashboard import Dashboard, join_slips_html
from eha_app.runtime.handins import HandIns, Refused
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
    """A hand-in of the truth times ``factor``, from a record with a standard error of 1 % of each value."""
    truth = ex.student_params(student)
    est = {n: getattr(truth, n) * factor for n in HIDE}
    se = {n: 0.01 * getattr(truth, n) for n in HIDE}
    return store.add(student, est, ex.verdicts(student, est, se), errors=ex.errors(student, est),
                     settings={"std_errors": se})


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
    assert s2[1] == '\'=HYPERLINK("http://evil.example","x")' and s2[rows[0].index("score (last)")] == "1.00"


def test_refused_attempts_best_and_last_and_units(lab):
    """The teacher sees the attempts the rules refused, the best and the last score apart (the rule's
    in bold), and each parameter in the unit the students' pages write it (βe in GPa)."""
    ex, store = lab
    hand_in(ex, store, "s1", 1.0)                       # all within tolerance
    hand_in(ex, store, "s1", 1.5)                       # none
    truth = ex.student_params("s1")
    est = {n: getattr(truth, n) for n in HIDE}
    with pytest.raises(Refused, match="closed"):
        store.add("s1", est, ex.verdicts("s1", est), refusal=lambda count, control: "hand-ins are closed")
    assert len(store.all()) == 2 and [r[1:] for r in store.refusals()] == [("s1", "lse", "hand-ins are closed")]
    dash = Dashboard(ex, store)
    roster = dash.roster.object
    assert "last hand-in</th>" in roster and "score (the last hand-in counts)" in roster
    row = next(r for r in roster.split("<tr>") if "<td>s1</td>" in r)
    # best 1, last 0, and the rule's (the last) in bold
    assert "<td class='num'>1.00</td><td class='num'>0.00</td><td class='num'><b>0.00</b></td>" in row
    assert "title='hand-ins are closed'>1</td>" in row                           # one refused, why on hover
    assert "Refused hand-ins (1)" in dash.history.object and "hand-ins are closed" in dash.history.object
    if "beta_e" in HIDE:
        assert "[GPa]" in roster and f"{1.5 * truth.beta_e / 1e9:.6g} " in row and "e+0" not in row


def test_last_seen_moves_while_the_page_is_open(lab):
    ex, store = lab
    store.seen("s1", "page-a")
    first = store.presence()["s1"][1]
    import time

    time.sleep(1.1)
    store.touch("s1", "page-b")                         # not the live page: nothing moves
    assert store.presence()["s1"][1] == first
    store.touch("s1", "page-a")
    assert store.presence()["s1"][1] > first


def test_bulk_modulus_is_written_in_gpa_as_on_the_students_pages():
    from eha_app.dashboard import _param_cell, _param_head

    ex = Exercise.new(hide=("beta_e",))
    assert "[GPa]" in _param_head(ex, "beta_e")
    cell = _param_cell("beta_e", 8.28606e8, 0.01, True, 1)
    assert "0.828606 " in cell and "e+08" not in cell
