"""A hand-in while the lab's PostgreSQL is down waits to be saved: the page says so, the server keeps it
(in memory and in its spool file, without the database's password) and saves it once when the
database is back; a server that stopped meanwhile saves it at its next start."""

from __future__ import annotations

import json
import time

import pytest

from eha_app.app import create_app
from eha_app.runtime import outbox as outbox_module
from eha_app.runtime.extensions import lab_rules
from eha_app.runtime.handins import HandIns
from eha_app.runtime.outbox import Outbox, replay
from eha_app.session.state import AppState
from eha_core.exercise import Exercise


@pytest.fixture
def own_postgres():
    """A PostgreSQL of the test's own (it is killed and started again)."""
    from tests.postgres import PostgresServer, find_pg_bin

    if find_pg_bin() is None:
        pytest.skip("PostgreSQL not found (no initdb): apt-get install -y postgresql (the README's test command "
                    "installs it)")
    server = PostgresServer().start()
    yield server
    server.stop()


@pytest.fixture
def lab(tmp_path, monkeypatch, own_postgres):
    ex = Exercise.new(hide=("M",), roster=[("s1", "Ada"), ("s2", "Alan")], attempts=2, secret="6b" * 32)
    path = tmp_path / "class.json"
    ex.save(path)
    url = own_postgres.url()
    HandIns(path, store=url).check()
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    monkeypatch.setenv("EHA_STORE", url)
    spool = tmp_path / "spool.jsonl"
    monkeypatch.setattr(outbox_module, "_outbox", Outbox(spool, retry_s=0.2))
    monkeypatch.setattr("eha_app.runtime.extensions.HANDIN_PATIENCE_S", 0.5)
    monkeypatch.setattr("eha_app.sections.handin.HANDIN_PATIENCE_S", 0.5)
    return ex, path, url, spool


def _wait(cond, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return False


def test_a_hand_in_while_the_database_is_down_waits_and_is_saved_once(lab, own_postgres):
    ex, path, url, spool = lab
    page = create_app(AppState())
    page.gate.student_id.value = ex.join_code("s1")
    page.gate.start()
    lse = page.session.build("least_squares")
    lse.run()
    lse.hand_in()
    assert "hand-in 1 of 2 allowed" in lse.verdict.object
    own_postgres.kill()                                   # the database goes away mid-lab
    lse.hand_in()
    box = lse.verdict.object
    assert "Your hand-in is waiting to be saved" in box and "Not handed in" not in box
    assert outbox_module.outbox().waiting("s1") == 1
    lse.hand_in()                                         # clicked again meanwhile: not a second attempt
    assert "still waiting to be saved" in lse.verdict.object and outbox_module.outbox().waiting("s1") == 1
    kept = [json.loads(line) for line in spool.read_text().splitlines()]
    assert [k["kwargs"]["student"] for k in kept] == ["s1"] and "s3cret-pw" not in spool.read_text()
    assert oct(spool.stat().st_mode & 0o777) == "0o600"
    time.sleep(1.0)                                       # tried a few times while it is down
    own_postgres.restart()
    assert outbox_module.outbox().wait_empty(30.0)
    assert _wait(lambda: "hand-in 2 of 2 allowed" in lse.verdict.object), lse.verdict.object
    store = HandIns(path, store=url)
    assert [h.student for h in store.all()] == ["s1", "s1"] and not spool.exists()
    # the attempt it took counts: a third is refused
    lse.hand_in()
    assert "Not handed in: you have handed in 2 of 2 times allowed" in lse.verdict.object


def test_a_server_stopped_while_a_hand_in_waited_saves_it_at_its_next_start(lab, own_postgres, tmp_path):
    ex, path, url, spool = lab
    store = HandIns(path, store=url)
    own_postgres.kill()
    first_run = Outbox(spool, retry_s=0.2)
    handin = dict(student="s2", estimates={"M": 4000.0}, verdicts={"M": False}, method="lse", key="page-9-1",
                  refusal=lab_rules(ex, {"method": "lse", "at": time.time()}))
    first_run.put(store, handin, refusal_spec={"method": "lse", "at": time.time()})
    time.sleep(0.5)
    assert first_run.waiting() == 1 and spool.exists()    # the server dies here: its thread is gone with it
    first_run.spool = None                                # (this one writes no more)
    own_postgres.restart()
    # the next start of the server (its own outbox, the same spool file) puts it back
    assert replay(ex, HandIns(path, store=url), lambda rules: lab_rules(ex, rules)) == 1
    assert outbox_module.outbox().wait_empty(30.0)
    assert [(h.student, h.estimates) for h in store.all()] == [("s2", {"M": 4000.0})]
    assert not spool.exists()


def _join(ex, student):
    page = create_app(AppState())
    page.gate.student_id.value = ex.join_code(student)
    page.gate.start()
    return page


def test_a_page_opened_while_the_database_is_down_waits_for_the_work_and_keeps_it(lab, own_postgres, monkeypatch):
    ex, path, url, spool = lab
    monkeypatch.setattr("eha_app.sections.work.RETRY_UNAVAILABLE_S", 0.3)
    page = _join(ex, "s1")
    page.session.state.set_text("kp", "12")
    page.session.state.set_text("Dc", "125")
    page.work.save()
    from eha_app.runtime.work_store import WorkStore

    assert WorkStore(HandIns(path, store=url)).load("s1") is not None
    own_postgres.kill()
    again = _join(ex, "s1")                                # a reload (or another server) while it is down
    assert again.work.restoring and "Your earlier work is on its way" in again.settings_note.object
    again.session.state.set_text("Dc", "999")              # typed meanwhile: not saved over the kept work
    again.work.changed()
    own_postgres.restart()
    assert _wait(lambda: not again.work.restoring, 30.0)
    assert again.session.state.texts["kp"] == "12"
    kept = WorkStore(HandIns(path, store=url)).load("s1")
    assert kept is not None and json.loads(kept.settings)["parameters"]["kp"] == "12"
