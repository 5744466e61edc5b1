"""An exercise's release date: from ``release_at`` on, every student is as after the teacher's reveal.

The date is checked where the exercise is made (ISO-8601, not before the deadline, refused naming the
field and the value as typed), kept in the exercise file (a file from before reads as none), and from it
on hand-ins are refused and verdicts shown whatever the feedback rule.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone

import pytest

from eha_core.errors import FieldError
from eha_core.exercise import Exercise

SECRET = "6b" * 32
DEADLINE = "2030-01-01T12:00:00+00:00"
RELEASE = "2030-01-02T12:00:00+00:00"
T_RELEASE = datetime(2030, 1, 2, 12, tzinfo=timezone.utc).timestamp()


def lab(**kw) -> Exercise:
    return Exercise.new(hide=("M", "B"), secret=SECRET, deadline=DEADLINE, **kw)


def test_the_truth_is_released_at_its_date_and_not_before():
    ex = lab(release_at=RELEASE)
    assert not ex.released(now=T_RELEASE - 1) and ex.released(now=T_RELEASE) and ex.released(now=T_RELEASE + 1e6)
    assert not lab().released(now=T_RELEASE + 1e9)                       # no date: only the teacher's reveal
    assert Exercise.new(hide=("M",), secret=SECRET, release_at=f"  {RELEASE} ").release_at == RELEASE


def test_after_the_release_no_hand_in_is_taken_and_the_verdicts_are_shown():
    ex = lab(release_at=RELEASE, feedback="none")
    assert ex.refusal(0, now=T_RELEASE - 1, deadline="2031-01-01T00:00:00+00:00") is None
    why = ex.refusal(0, now=T_RELEASE, deadline="2031-01-01T00:00:00+00:00", open_=True)
    assert why == f"the true values were released at {RELEASE}: hand-ins are closed for good"
    assert ex.refusal(0, now=T_RELEASE, revealed=True).startswith("your teacher has revealed")  # the reveal first
    assert not ex.shows_verdicts(now=T_RELEASE - 1) and ex.shows_verdicts(now=T_RELEASE)


@pytest.mark.parametrize("release, what", [
    ("2030-01-01T11:59:00+00:00", "it is before the deadline (2030-01-01T12:00:00+00:00): students could hand in "
                                  "after seeing their true values; give a date and time at or after the deadline"),
    ("soon", "give an ISO-8601 date and time"),
])
def test_a_bad_release_date_is_refused_naming_the_field_and_the_value_as_typed(release, what):
    with pytest.raises(FieldError) as refusal:
        lab(release_at=release)
    assert refusal.value.field == "release truth at"
    assert str(refusal.value).startswith(f"release truth at = {release} is not allowed: {what}")


def test_a_release_at_the_deadline_or_without_one_is_allowed():
    assert lab(release_at=DEADLINE).release_at == DEADLINE
    assert Exercise.new(hide=("M",), secret=SECRET, release_at=RELEASE).released(now=T_RELEASE)


def test_the_release_date_is_kept_in_the_file_and_an_older_file_has_none(tmp_path):
    ex = lab(release_at=RELEASE)
    path = tmp_path / "class.json"
    ex.save(path)
    assert Exercise.load(path).release_at == RELEASE
    data = json.loads(ex.to_json())
    del data["release_at"]                              # a file written before the release date existed
    older = Exercise.from_json(json.dumps(data))
    assert older.release_at == "" and not older.released(now=T_RELEASE + 1e9)
