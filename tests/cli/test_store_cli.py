"""``--store URL`` on the teacher's commands and ``eha serve``, and ``eha exercise copy-store``: a lab moved
from its SQLite file to a real PostgreSQL (tests/postgres.py) reads the same; a database that cannot be
used is one line on stderr, exit code 2, naming the URL without its password."""

from __future__ import annotations

import subprocess
import sys

from eha_app.cli import main
from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise
from tests.serve.conftest import free_port


def _lab(tmp_path):
    path = tmp_path / "class.json"
    ex = Exercise.new(hide=("M",), roster=[("s1", "Ada Lovelace"), ("s2", "Alan Turing")], secret="3c" * 32,
                      deadline="2098-12-01T00:00")
    ex.save(path)
    store = HandIns(path).check()
    store.add("s1", {"M": 4100.0}, ex.verdicts("s1", {"M": 4100.0}), errors=ex.errors("s1", {"M": 4100.0}))
    store.add("s2", {"M": 9000.0}, ex.verdicts("s2", {"M": 9000.0}), errors=ex.errors("s2", {"M": 9000.0}))
    store.set_extension("s2", "2099-01-01T00:00")
    return path


def test_copy_store_moves_the_lab_and_the_commands_read_it_there(tmp_path, pg_url, capsys):
    path = _lab(tmp_path)
    assert main(["exercise", "results", str(path)]) == 0
    from_sqlite = capsys.readouterr().out
    assert main(["exercise", "copy-store", str(path), "--to", pg_url]) == 0
    out = capsys.readouterr().out
    assert "2 handins" in out and "1 extensions" in out and "s3cret-pw" not in out
    assert main(["exercise", "results", str(path), "--store", pg_url]) == 0
    assert capsys.readouterr().out == from_sqlite
    # the commands write there too: an extension granted on PostgreSQL is not in the SQLite file
    assert main(["exercise", "extend", str(path), "--student", "s1", "--until", "2099-01-08T17:00",
                 "--store", pg_url]) == 0
    assert "s1" in HandIns(path, store=pg_url).extensions() and "s1" not in HandIns(path).extensions()
    # a second copy would mix two labs: refused
    capsys.readouterr()
    assert main(["exercise", "copy-store", str(path), "--to", pg_url]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not empty" in err and "s3cret-pw" not in err


def test_an_unreachable_store_is_one_line_without_the_password(tmp_path, capsys, monkeypatch):
    path = _lab(tmp_path)
    url = f"postgresql://teacher:hunter2@127.0.0.1:{free_port()}/lab"
    for argv in (["exercise", "results", str(path), "--store", url],
                 ["exercise", "extend", str(path), "--student", "s1", "--clear", "--store", url]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "hunter2" not in err, err
        assert f"--store: the lab's database postgresql://teacher@127.0.0.1:{url.rsplit(':', 1)[1]} cannot be " \
               "reached" in err
    monkeypatch.setenv("EHA_STORE", url)            # the same from the environment (no password in ps)
    assert main(["exercise", "results", str(path)]) == 2
    assert "cannot be reached" in capsys.readouterr().err
    # the join codes come from the exercise file alone: no database is needed for them
    assert main(["exercise", "codes", str(path), "--store", url]) == 0
    assert "Ada Lovelace" in capsys.readouterr().out


def test_serve_refuses_a_store_it_cannot_use_before_it_starts(tmp_path, postgres):
    path = _lab(tmp_path)
    wrong = postgres.url().replace("s3cret-pw", "guessed")
    run = subprocess.run([sys.executable, "-m", "eha_app.cli", "serve", "--exercise", str(path), "--store", wrong,
                          "--port", str(free_port())], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "guessed" not in run.stderr
    assert "refused the user name or password" in run.stderr and f"postgresql://eha@127.0.0.1:{postgres.port}" \
        in run.stderr


def test_a_store_that_is_no_database_url_is_one_line(tmp_path, capsys):
    path = _lab(tmp_path)
    assert main(["exercise", "results", str(path), "--store", "mysql://root:pw@db/lab"]) == 2
    err = capsys.readouterr().err
    assert err == ("eha: error: --store: 'mysql://root@db/lab' is not a database URL: give postgresql://USER@HOST:"
                   "PORT/DATABASE (the password from ~/.pgpass or PGPASSWORD), or sqlite:///PATH (relative; "
                   "sqlite:////PATH absolute; the default is a SQLite file beside the exercise)\n")
