"""Students doing anything in any order: seeded random walks through the served app, checked after
every action (benchmarks/walker.py says what is checked and how).

Three sessions walk one server at once, 300 actions each; beside them, on a server running an
exercise, one more student gives an id, walks and hands in. The seeds are fixed: a failure names its
seed, its action and the ten actions before it, and replays with
``python -m benchmarks.walker --seed S --actions N [--exercise]`` (``--shrink 300`` then looks for
the fewest actions that still fail).
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
from pathlib import Path

from benchmarks.walker import LogMonitor, WalkOptions, format_failures, run_walks, shutdown_failures

SEEDS, ACTIONS = (101, 202, 303), 300
EXERCISE_SEEDS, EXERCISE_ACTIONS = (404,), 200
HIDDEN = ("M", "B", "Af", "beta_e")


def test_students_walking_at_random_break_nothing(serve, monkeypatch, tmp_path):
    monkeypatch.setenv("EHA_STRICT", "1")      # page changes outside the document lock raise
    exercise = tmp_path / "class.json"
    subprocess.run([str(Path(sys.executable).with_name("eha")), "exercise", "new", "--hide", ",".join(HIDDEN),
                    "--out", str(exercise)], check=True, capture_output=True)
    app, lab = serve(), serve("--exercise", str(exercise))
    monitors = LogMonitor(str(app.log_path)), LogMonitor(str(lab.log_path))

    async def walks():
        # the exercise's walk beside the others: the two servers share the machine's two cores
        return await asyncio.gather(
            run_walks(app.url, list(SEEDS), ACTIONS, monitor=monitors[0], timeout=60),
            run_walks(lab.url, list(EXERCISE_SEEDS), EXERCISE_ACTIONS, monitor=monitors[1], timeout=60,
                      options=WalkOptions(exercise_hidden=HIDDEN)))

    (failures, walkers), (lab_failures, lab_walkers) = asyncio.run(walks())
    for server in (app, lab):
        server.stop()               # what a server prints as it stops counts too
    failures += lab_failures + shutdown_failures(monitors[0]) + shutdown_failures(monitors[1])
    assert not failures, format_failures(failures)
    assert [w.actions_done for w in walkers + lab_walkers] == [ACTIONS] * len(SEEDS) + [EXERCISE_ACTIONS]
    assert lab_walkers[0].counts["gate-start"] >= 1
