"""The lab page tells the student what they need: the rules always in view (deadline, hand-ins left,
tolerances, feedback), a question before an impossible estimate uses an attempt, and no hand-in button
after the last attempt."""

from __future__ import annotations

import pytest

from eha_app.app import create_app
from eha_app.runtime.handins import HandIns
from eha_app.sections.handin import impossible_estimates, lab_rules_html
from eha_app.session.state import AppState
from eha_core.exercise import Exercise


@pytest.fixture
def lab(tmp_path, monkeypatch):
    ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), tolerance=0.05, title="Lab 3", secret="5a" * 32, attempts=2,
                      deadline="2099-01-01T12:00:00+00:00", feedback="none")
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    return ex, path, page


def test_the_rules_are_in_view_from_the_start(lab):
    ex, _, page = lab
    rules = page.rules_pane.object
    assert page.rules_pane in page.layout.objects
    assert "deadline 2099-01-01 12:00 UTC (in " in rules
    assert "hand-ins: 0 of 2 used, 2 left" in rules and "3 standard errors are at most ±5 % (M, B, A" in rules
    assert "only that the hand-in was stored" in rules                    # the feedback policy, named
    assert "least squares" in rules and "refused" not in rules


def test_the_rules_say_when_hand_ins_are_refused():
    ex = Exercise.new(hide=("M",), attempts=1, deadline="2000-01-01T00:00:00+00:00")
    rules = lab_rules_html(ex, {}, 1)
    assert "deadline 2000-01-01 00:00 UTC (passed)" in rules and "1 of 1 used, 0 left" in rules
    assert "Hand-ins are refused now: the deadline" in rules
    assert "no limit" in lab_rules_html(Exercise.new(hide=("M",)), {}, 3)


def test_impossible_estimates_are_named_in_display_units():
    said = impossible_estimates({"M": 4000.0, "B": -1626.0, "beta_e": 0.0, "Af": float("nan")})
    assert len(said) == 3
    assert "B = -1626 N s/m: must be ≥ 0" in said[0] and "must be > 0" in said[1]


def test_an_impossible_estimate_is_asked_about_and_the_last_attempt_turns_the_button_off(lab):
    ex, path, page = lab
    lse = page.session.build("least_squares")
    lse.run()
    box = lse.handin
    good = dict(lse.result.estimates)
    bad = {**{n: good[n] for n in ex.hide}, "B": -1626.0}
    box.estimates = lambda: (dict(bad), {})
    box.hand_in()
    assert box.confirm.visible and "Physically impossible" in box.confirm[0].object
    assert "It would use hand-in 1 of 2" in box.confirm[0].object
    assert HandIns(path).all() == []                                     # nothing used yet
    no = next(b for b in box.confirm.select(lambda m: hasattr(m, "clicks")) if b.label == "Keep it")
    no.clicks += 1
    assert not box.confirm.visible and HandIns(path).all() == []
    box.hand_in()
    yes = next(b for b in box.confirm.select(lambda m: hasattr(m, "clicks")) if b.label == "Hand in anyway")
    yes.clicks += 1
    assert [r.estimates["B"] for r in HandIns(path).all()] == [-1626.0]
    assert "1 of 2 used, 1 left" in page.rules_pane.object and not box.button.disabled
    box.estimates = lambda: ({n: good[n] for n in ex.hide}, {})
    box.hand_in()                                                        # possible: no question
    assert not box.confirm.visible and len(HandIns(path).all()) == 2
    assert "2 of 2 used, 0 left" in page.rules_pane.object
    for b in page.session.handin_boxes:                                  # every route's button is off
        assert b.button.disabled and "you have handed in 2 of 2" in b.button.description
    lse.form.values = {**lse.form.values, "lse_seed": "3"}               # the section's own say cannot turn it on
    lse.run()
    assert box.button.disabled


def test_a_verdict_writes_each_value_as_the_page_does():
    from eha_app.sections.handin import shown_value

    assert shown_value("beta_e", 8.2861e8) == "0.82861 GPa" and shown_value("M", 4012.34) == "4012.3 kg"
