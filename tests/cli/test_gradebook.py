"""``eha exercise results --format moodle|canvas|csv --out FILE``: the grades as the teacher's gradebook imports them.

The files are read back with the csv module: the header rows are the documented ones (Moodle's CSV grade
import takes the columns of Moodle's own export, ``First name``, ``Last name``, ``ID number``, ``Email
address``, ``ITEM (Real)``; Canvas's gradebook import takes ``Student``, ``ID``, ``SIS User ID``, ``SIS Login
ID``, ``Section``, the assignment and a ``Points Possible`` row), one row per roster student in the roster's
order, each grade the exercise's counted score of the hand-ins in the store times ``--points``, 0 for a
student who handed nothing in; a name with a comma is quoted, the text is UTF-8 without a byte-order mark.
"""

from __future__ import annotations

import csv
import io
import os

import pytest

from eha_app.cli import main
from eha_app.runtime.gradebook import CANVAS_HEADER, MOODLE_HEADER
from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise

ROSTER = [("s1", "Ada King Lovelace"), ("s2", "Turing, Alan"), ("s3", "Émilie du Châtelet"), ("s4", "Hypatia")]
#: The verdicts of each student's hand-ins, oldest first (s4 hands nothing in).
HANDED = {"s1": [{"M": True, "B": False}, {"M": True, "B": True}],
          "s2": [{"M": False, "B": False}],
          "s3": [{"M": True, "B": True}, {"M": False, "B": False}, {"M": True, "B": False}]}


@pytest.fixture
def lab(tmp_path):
    ex = Exercise.new(hide=("M", "B"), title="Lab 3: the actuator", roster=ROSTER, secret="4d" * 32,
                      score_rule="mean")
    path = tmp_path / "class.json"
    ex.save(path)
    store = HandIns(path).check()
    for sid, handins in HANDED.items():
        for verdicts in handins:
            store.add(sid, {"M": 4000.0, "B": 1000.0}, verdicts)
    return ex, str(path), tmp_path


def expected(ex, sid, points=100.0) -> str:
    """The grade the file must hold: the exercise's rule over the store's hand-ins, times the points."""
    return f"{ex.score(HANDED.get(sid, [])) * points:.2f}"


def written(capsys, tmp_path, argv, name) -> tuple[bytes, list[list[str]]]:
    out = tmp_path / name
    assert main([*argv, "--out", str(out)]) == 0, capsys.readouterr().err
    assert f"wrote {out}" in capsys.readouterr().err
    raw = out.read_bytes()
    return raw, list(csv.reader(io.StringIO(raw.decode("utf-8"), newline="")))


def test_the_moodle_file_is_moodles_import_format_with_each_counted_score(lab, capsys):
    ex, path, tmp = lab
    raw, rows = written(capsys, tmp, ["exercise", "results", path, "--format", "moodle"], "moodle.csv")
    assert rows[0] == ["First name", "Last name", "ID number", "Email address", "Lab 3: the actuator (Real)"]
    assert tuple(rows[0][:4]) == MOODLE_HEADER
    body = rows[1:]
    assert [r[2] for r in body] == [sid for sid, _ in ROSTER]                 # one row each, the roster's order
    assert all(len(r) == 5 and r[3] == "" for r in body)
    assert {r[2]: r[4] for r in body} == {sid: expected(ex, sid) for sid, _ in ROSTER}
    assert body[0][4] == "75.00" and body[3][4] == "0.00"                    # mean of 0.5 and 1; nothing handed in
    # the names split the simple way: the last word is the last name; "Last, First" at its comma
    assert [r[:2] for r in body] == [["Ada King", "Lovelace"], ["Alan", "Turing"], ["Émilie du", "Châtelet"],
                                     ["", "Hypatia"]]
    assert not raw.startswith(b"\xef\xbb\xbf") and "Châtelet".encode() in raw        # UTF-8, no byte-order mark
    assert os.stat(tmp / "moodle.csv").st_mode & 0o777 == 0o600                     # every student's grade


def test_the_canvas_file_is_canvass_import_format_with_points_possible(lab, capsys):
    ex, path, tmp = lab
    raw, rows = written(capsys, tmp, ["exercise", "results", path, "--format", "canvas", "--points", "20",
                                      "--item", "Lab 3"], "canvas.csv")
    assert rows[0] == ["Student", "ID", "SIS User ID", "SIS Login ID", "Section", "Lab 3"]
    assert tuple(rows[0][:5]) == CANVAS_HEADER
    assert rows[1] == ["Points Possible", "", "", "", "", "20.00"]
    body = rows[2:]
    assert [r[0] for r in body] == [name for _, name in ROSTER]
    assert [r[2] for r in body] == [sid for sid, _ in ROSTER]                 # the roster's id as SIS User ID
    assert all(r[1] == "" and r[3] == "" and r[4] == "" for r in body)       # Canvas's own ids are not ours
    assert {r[2]: r[5] for r in body} == {sid: expected(ex, sid, 20.0) for sid, _ in ROSTER}
    assert body[2][5] == "10.00" and body[3][5] == "0.00"                    # s3: mean of 1, 0, 0.5, times 20
    assert b'"Turing, Alan"' in raw                                          # a name with a comma, quoted
    assert not raw.startswith(b"\xef\xbb\xbf") and raw.startswith(b"Student,ID,")
    assert "Émilie du Châtelet".encode() in raw


def test_format_csv_is_the_results_table_as_csv_and_the_text_table_stays(lab, capsys):
    _, path, tmp = lab
    assert main(["exercise", "results", path, "--csv", str(tmp / "old.csv")]) == 0
    table = capsys.readouterr().out
    assert "s1" in table and "Ada King Lovelace" in table
    written(capsys, tmp, ["exercise", "results", path, "--format", "csv"], "new.csv")
    assert (tmp / "new.csv").read_bytes() == (tmp / "old.csv").read_bytes()
    written(capsys, tmp, ["exercise", "results", path], "default.csv")        # --out alone: the table as CSV
    assert (tmp / "default.csv").read_bytes() == (tmp / "old.csv").read_bytes()


def test_a_formula_in_a_name_is_neutralised_and_an_open_exercise_lists_who_joined(tmp_path, capsys):
    ex = Exercise.new(hide=("M",), title="Lab", secret="5e" * 32)
    path = tmp_path / "open.json"
    ex.save(path)
    store = HandIns(path).check()
    store.seen("ada")
    store.add("bob", {"M": 1.0}, {"M": True})
    _, rows = written(capsys, tmp_path, ["exercise", "results", str(path), "--format", "canvas"], "c.csv")
    assert [(r[2], r[5]) for r in rows[2:]] == [("ada", "0.00"), ("bob", "100.00")]
    ex = Exercise.new(hide=("M",), title="Lab", secret="5e" * 32, roster=[("s1", '=HYPERLINK("http://x","y")')])
    path = tmp_path / "formula.json"
    ex.save(path)
    _, rows = written(capsys, tmp_path, ["exercise", "results", str(path), "--format", "canvas"], "f.csv")
    assert rows[2][0] == '\'=HYPERLINK("http://x","y")'


@pytest.mark.parametrize("argv, says", [
    (["--format", "moodle"], "--format = moodle is not allowed: give --out FILE"),
    (["--format", "canvas", "--out", "{out}", "--points", "-5"], "--points = -5 is not allowed: a number of points"),
    (["--format", "canvas", "--out", "{out}", "--points", "lots"], "--points = lots is not allowed"),
    (["--format", "canvas", "--out", "{out}", "--item", "Lab (3)"], "--item = Lab (3) is not allowed: Canvas reads"),
    (["--format", "canvas", "--out", "{out}", "--item", "Final Grade"], "--item = Final Grade is not allowed"),
    (["--format", "pdf", "--out", "{out}"], "argument --format: invalid choice: 'pdf'"),
])
def test_bad_gradebook_options_are_one_line(lab, capsys, argv, says):
    _, path, tmp = lab
    code = main(["exercise", "results", path, *[a.format(out=tmp / "g.csv") for a in argv]])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.startswith(f"eha: error: {says}") and err.count("\n") == 1, err
    assert not (tmp / "g.csv").exists()
