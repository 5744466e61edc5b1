"""``eha exercise extend`` grants one student a later deadline (``--clear`` takes it away), kept in the class's
database; ``eha exercise new --release-truth-at`` writes the release date into the exercise file."""

from __future__ import annotations

from eha_app.cli import main
from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise


def test_extend_and_clear_a_students_deadline(tmp_path, capsys):
    path = tmp_path / "class.json"
    Exercise.new(hide=("M",), roster=[("s1", "Ada Lovelace"), ("s2", "Alan Turing")], deadline="2099-01-01T00:00",
                 release_at="2099-02-01T00:00").save(path)
    assert main(["exercise", "extend", str(path), "--student", " S1 ", "--until", "2099-01-08T17:00"]) == 0
    assert capsys.readouterr().out == ("Ada Lovelace (s1) may hand in until 2099-01-08T17:00 (the class's deadline: "
                                       "2099-01-01T00:00)\n")
    assert HandIns(path).extensions()["s1"][0] == "2099-01-08T17:00"
    # after the release no hand-in is taken: an extension past it is refused
    assert main(["exercise", "extend", str(path), "--student", "s2", "--until", "2099-03-01T00:00"]) == 2
    assert capsys.readouterr().err == ("eha: error: --until = 2099-03-01T00:00 is not allowed: it is after the true "
                                       "values are released (2099-02-01T00:00): no hand-in is taken from then on; "
                                       "give one at or before it\n")
    assert main(["exercise", "extend", str(path), "--student", "s1", "--clear"]) == 0
    assert "no extension now" in capsys.readouterr().out and HandIns(path).extensions() == {}
    assert main(["exercise", "extend", str(path), "--student", "s1", "--clear", "--until", "2099-01-08T17:00"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_new_writes_the_release_date(tmp_path, capsys):
    path = tmp_path / "class.json"
    assert main(["exercise", "new", "--hide", "M", "--deadline", "2099-01-01T00:00", "--release-truth-at",
                 "2099-01-02T08:00", "--out", str(path)]) == 0
    assert "every student sees their true values from 2099-01-02T08:00" in capsys.readouterr().out
    assert Exercise.load(path).release_at == "2099-01-02T08:00"
