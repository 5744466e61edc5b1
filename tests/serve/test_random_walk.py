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


# -- the walker's own parts (no server) ----------------------------------------------------------------

def test_an_upload_is_sent_as_bokeh_reads_bytes():
    """A file's bytes go as a binary buffer, as BokehJS sends an ArrayBuffer; Bokeh's deserializer gets
    them back whole."""
    import json

    from bokeh.core.serialization import Buffer, Deserializer

    from benchmarks.classroom_client import _encode, _with_buffers

    data = bytes(range(256)) * 3
    content = {"events": [{"kind": "ModelChanged", "model": {"id": "p1"}, "attr": "value", "new": _encode(data)}]}
    text, buffers = _with_buffers(content)
    sent = json.loads(text)["events"][0]["new"]
    assert sent == {"type": "bytes", "data": {"id": "0"}} and buffers[0][0] == {"id": "0"}
    assert bytes(Deserializer().decode(sent, [Buffer(ref["id"], raw) for ref, raw in buffers])) == data


def test_the_log_reader_finds_problems_and_leaves_notes(tmp_path):
    log = tmp_path / "eha.log"
    log.write_text(
        "2026-11-25 04:20:17,536 INFO job 'x' ended without a result: your file is not allowed\n"
        "2026-11-25 04:20:18,131 INFO /a/experiments.py:347: UserWarning: idinput: the PRBS signal\n"
        "  return idinput([self.n_samples, 1, 1])\n"
        " ** On entry to DLASCL parameter number  4 had an illegal value\n"
        "2026-11-25 04:20:19,000 WARNING job 'Table 4' failed: bad\n"
        "Traceback (most recent call last):\n"
        '  File "a.py", line 1, in f\n'
        "ValueError: bad\n"
        "ERROR: panel.reactive - Callback failed for object named 'Form1'\n"
        "2026-11-25 04:20:20,000 INFO fine\n")
    monitor = LogMonitor(str(log))
    monitor._read()
    monitor._close()
    assert [p.head for p in monitor.problems] == [
        "** On entry to DLASCL parameter number  4 had an illegal value", "ValueError: bad",
        "ERROR: panel.reactive - Callback failed for object named 'Form1'"]


def test_texts_compare_as_the_app_compares_them():
    from benchmarks.walker import normalized

    assert normalized("t_end", " 5,0 ") == normalized("t_end", "5") == 5.0
    assert normalized("input_delay", "") == normalized("input_delay", "none") == 0.0
    assert normalized("input_delay", "EST") == "estimate"
    assert normalized("n_samples", "nan") == "nan" and normalized("u_kind", " sine ") == "sine"
