"""The exercise's scoring rules against a student who sprays guesses instead of identifying.

A sprayer hands in B at 0.84, 1.00 and 1.17 times the paper's value without any identification; each
student's B is within ±25 % of the paper's; a hand-in counts when B is within 5 %. One guess at the
paper's value is right for about 21 % of students."""

from __future__ import annotations

import numpy as np
import pytest

from eha_core.exercise import SCORE_RULES, Exercise

GUESSES = np.array([0.84, 1.00, 1.17])


@pytest.fixture(scope="module")
def hits():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.75, 1.25, 4000)                      # each student's B over the paper's
    return np.abs(GUESSES[None, :] / truth[:, None] - 1) <= 0.05


def _mean_score(exercise: Exercise, hits) -> float:
    return float(np.mean([exercise.score([{"B": bool(h)} for h in row]) for row in hits]))


def test_the_default_rules_give_a_sprayer_no_more_than_one_guess(hits):
    one_guess = max(hits[:, k].mean() for k in range(3))          # the luckiest single guess
    assert 0.15 < hits[:, 1].mean() < 0.25
    ex = Exercise.new(hide=("B",), tolerance=0.05, attempts=3)
    assert ex.score_rule == "last" == SCORE_RULES[0]           # the default is not the best of several
    for rule in ("last", "mean"):
        assert _mean_score(ex.replace(score_rule=rule), hits) <= one_guess + 0.01, rule
    # plain best of three rewards it: almost three times one guess
    assert _mean_score(ex.replace(score_rule="best"), hits) > 2.5 * hits[:, 1].mean()


def test_a_penalty_per_attempt_pays_off_spraying_only_when_it_is_large(hits):
    """The best hand-in less a penalty per attempt before it: spraying three guesses beats one guess
    unless the penalty is about 85 points (the first guess is never penalised: 0.60 at 0, 0.43 at 25,
    0.27 at 50, 0.20 at 85 against 0.20 for one guess; --score's help says so)."""
    ex = Exercise.new(hide=("B",), tolerance=0.05, attempts=3, score_rule="best-penalty")
    one_guess = hits[:, 1].mean()
    sprayed = {p: _mean_score(ex.replace(attempt_penalty=p), hits) for p in (0.0, 0.25, 0.5, 0.75, 0.9, 1.0)}
    values = list(sprayed.values())
    assert all(a > b for a, b in zip(values, values[1:], strict=False))                       # falls with p
    assert sprayed[0.5] > one_guess and sprayed[0.75] > one_guess and sprayed[0.9] < one_guess
    assert sprayed[0.0] == pytest.approx(_mean_score(ex.replace(score_rule="best"), hits))


def test_an_exercise_file_from_before_keeps_scoring_the_best():
    ex = Exercise.new(hide=("M",))
    text = ex.to_json().replace('"score_rule": "last",', "").replace('"attempt_penalty": 0.25,', "")
    assert '"score_rule"' not in text
    assert Exercise.from_json(text).score_rule == "best"


def test_bad_rules_are_refused_with_their_names():
    with pytest.raises(ValueError, match="score = sprinkle is not allowed"):
        Exercise.new(hide=("M",), score_rule="sprinkle")
    with pytest.raises(ValueError, match="attempt penalty = 1.5 is not allowed"):
        Exercise.new(hide=("M",), attempt_penalty=1.5)
