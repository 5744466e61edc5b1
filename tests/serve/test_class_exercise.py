"""The graded lab served to a class: bench_classroom.py --exercise's path, every step, no error."""

from __future__ import annotations

from benchmarks.bench_classroom import make_exercise
from benchmarks.classroom_client import (
    EXERCISE_OBSERVER_VALUES,
    EXERCISE_PARAM,
    EXERCISE_STEPS,
    exercise_texts,
    run_students,
)


def test_a_class_joins_an_exercise_with_codes_and_hands_in(serve, tmp_path):
    path, codes = make_exercise(tmp_path / "lab", 2)
    server = serve("--exercise", str(path))
    result = run_students(server.url, 2, EXERCISE_STEPS, observer=True, spread=0.3, timeout=120, codes=codes,
                          param=EXERCISE_PARAM, texts=exercise_texts, observer_values=EXERCISE_OBSERVER_VALUES)
    for step in EXERCISE_STEPS:
        assert result.ok(step) == 2, (step, result.errors(step)[:3])
    assert result.error_count() == 0
    assert all(o.error is None for o in result.observer) and result.observer
    for gb, board, handin in zip(result.steps["gb"], result.steps["board"], result.steps["handin"], strict=True):
        # an estimate that failed its checks is done, noted; its hand-in is refused and the least squares' go
        assert gb.detail["checks"] in ("passed", "failed"), gb.detail
        assert handin.detail["route"] == ("greybox" if gb.detail["checks"] == "passed" else "lse"), handin.detail
        assert handin.detail["handed_in"] and handin.detail["within"].endswith("/4"), handin.detail
        models = {m.rstrip("*") for m in board.detail["models"].split(",")}       # "*": ticked (stable)
        assert {"LS1", "H1"} <= models and ("GB1" in models) == (gb.detail["checks"] == "passed"), board.detail
    log = server.log_text()
    assert "Traceback" not in log and "ERROR" not in log, log[-3000:]
