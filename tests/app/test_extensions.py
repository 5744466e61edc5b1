"""A later deadline for one student: kept in the class's database, read inside the hand-in's own transaction,
shown on the student's rules line, granted from the dashboard's form (a bad id or date refused beside its
field, naming the value as typed) and listed there; the reveal waits for it."""

from __future__ import annotations

import sqlite3
from datetime import datetime, timezone

import pytest

from eha_app.app import create_app
from eha_app.dashboard import Dashboard
from eha_app.runtime.handins import HandIns, Refused
from eha_app.sections.handin import lab_refusal, own_deadline
from eha_app.session.state import AppState
from eha_core.exercise import Exercise

PASSED = "2000-01-01T00:00:00+00:00"
LATER = "2099-06-01T12:00:00+00:00"


def test_an_older_database_gets_the_extensions_table(tmp_path):
    path = tmp_path / "class.json"
    store = HandIns(path).check()
    store.add("ada", {"M": 1.0}, {"M": True})
    with sqlite3.connect(store.path) as db:                   # a database made before extensions existed
        db.execute("DROP TABLE extensions")
        db.execute("DROP TABLE eha_schema")                   # (and before the schema's versions were kept)
        db.execute("DROP INDEX handins_key")
        db.execute("ALTER TABLE handins DROP COLUMN key")
    store = HandIns(path).check()
    assert store.extensions() == {} and len(store.all()) == 1
    store.set_extension("ada", LATER)
    assert store.extension("ada") == LATER and store.extensions()["ada"][0] == LATER
    assert store.control_for("ada") == {"extension": LATER} and store.control_for("bob") == {}
    before = store.version()
    store.set_extension("ada", "")                            # taken away
    assert store.extensions() == {} and store.version() != before


def test_the_hand_in_reads_the_students_extension_in_its_own_transaction(tmp_path):
    ex = Exercise.new(hide=("M",), deadline=PASSED, secret="71" * 32)
    store = HandIns(tmp_path / "class.json").check()

    def hand_in(student):
        return store.add(student, {"M": 1.0}, {"M": True},
                         refusal=lambda count, control: lab_refusal(ex, control, count))
    with pytest.raises(Refused, match=r"the deadline \(2000-01-01T00:00:00\+00:00\) has passed"):
        hand_in("ada")
    store.set_extension("ada", LATER)
    hand_in("ada")                                            # their own deadline: taken
    with pytest.raises(Refused):
        hand_in("bob")                                        # a classmate's is not
    assert [h.student for h in store.all()] == ["ada"]
    with pytest.raises(Refused, match=r"the deadline \(2099-06-01T12:00:00\+00:00\) has passed"):
        store.add("ada", {"M": 1.0}, {"M": True},
                  refusal=lambda count, control: lab_refusal(ex, control, count, now=4.1e9))


def test_an_extension_counts_only_when_it_is_later_than_the_class_deadline():
    ex = Exercise.new(hide=("M",), deadline="2030-01-01T12:00", secret="71" * 32)
    assert own_deadline(ex, {}) == "2030-01-01T12:00"
    assert own_deadline(ex, {"extension": "2030-01-08T12:00"}) == "2030-01-08T12:00"
    assert own_deadline(ex, {"extension": "2030-01-08T12:00", "deadline": "2030-02-01T00:00"}) == "2030-02-01T00:00"
    assert own_deadline(ex, {"extension": "not a date"}) == "2030-01-01T12:00"
    assert own_deadline(ex.replace(deadline=""), {"extension": "2030-01-08T12:00"}) is None   # nothing to extend


@pytest.fixture
def late(tmp_path, monkeypatch):
    ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), title="Lab 4", secret="72" * 32, deadline=PASSED,
                      feedback="none")
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))

    def page_of(student):
        page = create_app(AppState())
        page.gate.student_id.value = student
        page.gate.start()
        return page
    return ex, path, page_of


def test_the_student_with_an_extension_sees_their_deadline_and_hands_in(late):
    ex, path, page_of = late
    HandIns(path).set_extension("ada", LATER)
    ada, bob = page_of("ada"), page_of("bob")
    rules = ada.rules_pane.object
    assert "deadline extended for you 2099-06-01 12:00 UTC (in " in rules and "refused" not in rules
    assert "deadline 2000-01-01 00:00 UTC (passed)" in bob.rules_pane.object
    assert "Hand-ins are refused now: the deadline" in bob.rules_pane.object
    lse = ada.session.build("least_squares")
    lse.run()
    box = lse.handin
    assert not box.button.disabled
    box.estimates = lambda: ({n: float(lse.result.estimates[n]) for n in ex.hide}, {})
    box.hand_in()
    assert "Handed in" in box.verdict.object and [h.student for h in HandIns(path).all()] == ["ada"]
    HandIns(path).set_extension("ada", "")                    # the teacher takes it away: the class's holds
    ada.check_result()
    assert "deadline 2000-01-01 00:00 UTC (passed)" in ada.rules_pane.object and box.button.disabled


@pytest.fixture
def dash(tmp_path):
    ex = Exercise.new(hide=("M",), title="Lab 5", secret="73" * 32, deadline="2030-01-01T12:00:00+00:00",
                      roster=[("s1", "Ada Lovelace"), ("s2", "Alan Turing")])
    path = tmp_path / "class.json"
    ex.save(path)
    store = HandIns(path).check()
    now = [datetime(2029, 12, 1, tzinfo=timezone.utc).timestamp()]
    return ex, store, now, Dashboard(ex, store, clock=lambda: now[0])


def test_the_dashboard_form_extends_a_deadline_and_says_what_is_wrong_beside_its_field(dash):
    ex, store, _, board = dash
    assert "No student has a later deadline" in board.extensions_pane.object
    board.extension_student.value = "s9"
    board.extension_until.value = "2030-01-08T12:00:00+00:00"
    board.extension_button.clicks += 1
    assert board.extension_student_message.object.startswith(
        "student id = s9 is not allowed: no student with this id in the exercise&#x27;s roster")
    assert board.extension_until_message.object == "" and store.extensions() == {}
    board.extension_student.value = "S1 "
    board.extension_until.value = "next friday"
    board.extension_button.clicks += 1
    assert board.extension_until_message.object.startswith("until = next friday is not allowed: give an ISO-8601")
    assert board.extension_student_message.object == "" and store.extensions() == {}
    board.extend("s1", "2029-12-31T00:00:00+00:00")           # not later than the class's: it would change nothing
    assert "until = 2029-12-31T00:00:00+00:00 is not allowed: it is not later than the class" in \
        board.extension_until_message.object
    board.extension_until.value = "2030-01-08T12:00:00+00:00"
    board.extension_button.clicks += 1
    assert board.extension_until_message.object == "" and board.extension_student_message.object == ""
    assert store.extensions()["s1"][0] == "2030-01-08T12:00:00+00:00"
    assert "s1 (Ada Lovelace) until 2030-01-08T12:00:00+00:00" in board.extensions_pane.object
    assert "s1 may hand in until 2030-01-08T12:00:00+00:00" in board.note.object
    board.extend("s1", "")                                    # empty: taken away
    assert store.extensions() == {} and "No student has" in board.extensions_pane.object


def test_the_reveal_waits_for_every_extension(dash):
    ex, store, now, board = dash
    store.set_extension("s2", "2030-01-08T12:00:00+00:00")
    now[0] = datetime(2030, 1, 2, tzinfo=timezone.utc).timestamp()        # after the class's deadline
    board.poll()
    assert "except from 1 student with a later deadline of their own" in board.rules.object
    board.reveal()
    assert "s2's extension (2030-01-08T12:00:00+00:00) has not passed" in board.reveal_message.object
    assert "revealed" not in store.control()
    now[0] = datetime(2030, 1, 9, tzinfo=timezone.utc).timestamp()
    board.refresh()
    assert "— passed" in board.extensions_pane.object
    board.reveal()
    assert store.control()["revealed"] == "1"
