"""The exercise's release date on the pages: from it on each student's page shows their own true values, as
after the teacher's reveal, and takes no hand-in; before it, nothing; the dashboard's rules say when."""

from __future__ import annotations

from datetime import datetime, timezone

import pytest

from eha_app.app import create_app
from eha_app.dashboard import Dashboard
from eha_app.runtime.handins import HandIns
from eha_app.sections.handin import shown_value
from eha_app.session.state import AppState
from eha_core.exercise import Exercise

HIDE = ("M", "B", "Af", "beta_e")


def page_for(tmp_path, monkeypatch, student, **rules):
    ex = Exercise.new(hide=HIDE, title="Lab 6", secret="81" * 32, feedback="none", **rules)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    page = create_app(AppState())
    page.gate.student_id.value = student
    page.gate.start()
    return ex, path, page


def test_after_the_release_each_student_sees_their_own_truth_and_hands_in_nothing(tmp_path, monkeypatch):
    ex, path, page = page_for(tmp_path, monkeypatch, "ada", deadline="2000-01-01T00:00:00+00:00",
                              release_at="2000-01-02T00:00:00+00:00")
    HandIns(path).add("ada", {"M": 4000.0}, {"M": False})
    page.check_result()
    text = page.result_pane.object
    truth, other = ex.student_params("ada"), ex.student_params("bob")
    assert page.result_pane.visible and "Your actuator, released at 2000-01-02T00:00:00+00:00" in text
    assert f"M = {shown_value('M', truth.M)}" in text and shown_value("M", other.M) not in text
    assert "✗" in text                                          # the verdicts too, whatever the feedback rule
    rules = page.rules_pane.object
    assert "your true values were released at 2000-01-02 00:00 UTC" in rules
    assert "Hand-ins are refused now: the true values were released at 2000-01-02T00:00:00+00:00" in rules
    lse = page.session.build("least_squares")
    lse.run()
    box = lse.handin
    assert box.button.disabled and "the true values were released" in box.button.description
    box.estimates = lambda: ({n: float(lse.result.estimates[n]) for n in ex.hide}, {})
    box.hand_in()
    assert "Not handed in: the true values were released" in box.verdict.object
    assert len(HandIns(path).all()) == 1


def test_before_the_release_the_page_says_when_and_shows_nothing(tmp_path, monkeypatch):
    ex, path, page = page_for(tmp_path, monkeypatch, "ada", deadline="2099-01-01T00:00:00+00:00",
                              release_at="2099-01-02T00:00:00+00:00")
    page.check_result()
    assert not page.result_pane.visible and page.result_pane.object == ""
    rules = page.rules_pane.object
    assert "your true values are shown from 2099-01-02 00:00 UTC" in rules and "refused" not in rules


@pytest.fixture
def board(tmp_path):
    ex = Exercise.new(hide=("M",), title="Lab 7", secret="82" * 32, deadline="2030-01-01T12:00:00+00:00",
                      release_at="2030-01-02T12:00:00+00:00")
    store = HandIns(tmp_path / "class.json").check()
    now = [datetime(2030, 1, 2, tzinfo=timezone.utc).timestamp()]
    return ex, store, now, Dashboard(ex, store, clock=lambda: now[0])


def test_the_dashboard_says_when_the_truth_is_released(board, tmp_path):
    ex, store, now, dash = board
    rules = dash.rules.object
    assert ("<dt>Truth released</dt><dd>2030-01-02T12:00:00+00:00: every student sees their own true values from "
            "then on, and no hand-in is taken</dd>") in rules
    assert "closed for good" not in rules
    now[0] = datetime(2030, 1, 3, tzinfo=timezone.utc).timestamp()
    assert dash.poll() is True                                  # the release's coming is drawn without a change
    assert "— released" in dash.rules.object and "released at 2030-01-02T12:00:00+00:00: no hand-in" in \
        dash.rules.object
    plain = Dashboard(ex.replace(release_at=""), HandIns(tmp_path / "other.json").check())
    assert "<dt>Truth released</dt><dd>no date: only when you reveal them</dd>" in plain.rules.object


def test_the_dashboard_refuses_a_deadline_after_the_release(board):
    _, store, _, dash = board
    dash.set_deadline("2030-01-03T00:00:00+00:00")
    assert dash.deadline_message.object.startswith(
        "deadline = 2030-01-03T00:00:00+00:00 is not allowed: it is after the true values are released "
        "(2030-01-02T12:00:00+00:00)")
    assert "deadline" not in store.control()
    dash.set_deadline("2030-01-02T12:00:00+00:00")              # at the release: allowed
    assert store.control()["deadline"] == "2030-01-02T12:00:00+00:00"
