"""The lab's store on both backends: SQLite beside the exercise (the default) and a real PostgreSQL
(tests/postgres.py starts Debian's). The same calls give the same lab; a hand-in sent twice is stored
once; two "servers" (processes) handing in at once never pass the attempt limit; migrations bring an
older database up; a newer one, a wrong password, an unreachable or lost database each get a message
that names the URL without its password."""

from __future__ import annotations

import json
import multiprocessing
import sqlite3
import threading

import pytest

from eha_app.runtime.handins import HandIns, Refused, StoreError, StoreUnavailable
from eha_app.runtime.store_backend import (
    _POSTGRES_V1,
    _SQLITE_V1,
    SCHEMA_VERSION,
    _statements,
    copy_lab,
    shown_url,
)
from eha_app.runtime.work_store import StoredFile, Work, WorkStore


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request, tmp_path):
    """None (SQLite beside the exercise) or a fresh PostgreSQL database's URL."""
    if request.param == "sqlite":
        return None
    return request.getfixturevalue("pg_url")


def _store(tmp_path, url):
    return HandIns(tmp_path / "class.json", store=url).check()


def _lab(store: HandIns) -> dict:
    """Everything a lab holds, as the store's own calls read it."""
    ws = WorkStore(store)
    return {
        "handins": [(h.id, h.student, h.estimates, h.verdicts, h.score, h.count, h.method, h.source)
                    for h in store.latest()],
        "all": [(h.id, h.student, h.estimates) for h in store.all()],
        "refusals": [r[1:] for r in store.refusals()],
        "control": store.control(),
        "extensions": {k: v[0] for k, v in store.extensions().items()},
        "presence": {k: (p.page, p.pages, p.overlaps) for k, p in store.presences().items()},
        "work": {s: (w.settings, w.runs, [(f.slot, f.name, f.data, f.mapping) for f in w.files])
                 for s in ("ada", "bob") if (w := ws.load(s)) is not None},
    }


def _play(store: HandIns) -> None:
    """A short lab: hand-ins (one refused), switches, an extension, presences, kept work with an upload."""
    store.add("ada", {"M": 4100.0}, {"M": True}, method="lse", source={"kind": "file", "name": "r.csv", "sha256": "0"})
    store.add("ada", {"M": 4200.0}, {"M": False}, method="greybox", key="page-a-1")
    store.add("bob", {"B": 1500.0}, {"B": True}, refusal=lambda count, control: "")
    with pytest.raises(Refused):
        store.add("bob", {"B": 1.0}, {"B": False}, refusal=lambda count, control: "too many hand-ins")
    store.set_controls({"open": "1", "deadline": "2030-01-01T00:00"})
    store.set_extension("bob", "2031-01-01T00:00")
    store.seen("ada", "p1")
    store.seen("ada", "p2")             # a second page of ada's: an overlap
    store.left("ada", "p2")
    store.seen("bob", "q1")
    assert store.new_id_from("10.0.0.1", "cy", limit=1) is None
    ws = WorkStore(store, quota_bytes=10_000)
    assert ws.save(Work("ada", b'{"format": "eha-settings/1"}', {"lse": {"views": ["lse"]}},
                        (StoredFile("lse", "run.csv", b"t,x\n0,0\n1,2\n", {"x": "pos"}),))) == []
    assert ws.save(Work("bob", b"{}", {}, ())) == []


def test_the_same_calls_give_the_same_lab_on_both_backends(tmp_path, pg_url):
    (tmp_path / "a").mkdir()
    sqlite_store, pg_store = _store(tmp_path / "a", None), _store(tmp_path, pg_url)
    for store in (sqlite_store, pg_store):
        _play(store)
    a, b = _lab(sqlite_store), _lab(pg_store)
    assert a == b
    assert [h[1] for h in a["handins"]] == ["ada", "bob"] and a["handins"][0][5] == 2
    assert a["presence"]["ada"] == ("", 2, 1) and a["refusals"] == [("bob", "lse", "too many hand-ins")]
    assert a["work"]["ada"][2] == [("lse", "run.csv", b"t,x\n0,0\n1,2\n", {"x": "pos"})]
    # what a live page polls changes with every kind of change, on both
    for store in (sqlite_store, pg_store):
        before = store.version()
        store.touch("bob", "q1")
        store.set_control("revealed", "1")
        assert store.version() != before


def test_a_hand_in_sent_again_under_its_key_is_stored_once(tmp_path, store_url):
    store = _store(tmp_path, store_url)
    first = store.add("ada", {"M": 1.0}, {"M": True}, key="k-1")
    again = store.add("ada", {"M": 1.0}, {"M": True}, key="k-1",
                      refusal=lambda count, control: "too many" if count >= 1 else "")
    other = store.add("bob", {"M": 2.0}, {"M": True}, key="k-1")     # a key is the student's own
    assert again == first and other != first
    assert [h.student for h in store.all()] == ["ada", "bob"] and store.refusals() == []


def _hand_in_many(url, folder, student, n, limit, out):
    """One "server": n threads each handing in for ``student`` under an attempt limit."""
    store = HandIns(folder / "class.json", store=url)
    got = []

    def one(i):
        try:
            got.append(store.add(student, {"M": float(i)}, {"M": True},
                                 refusal=lambda count, control: "no attempts left" if count >= limit else ""))
        except Refused:
            got.append(None)
    threads = [threading.Thread(target=one, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    out.put(got)


def test_two_servers_handing_in_at_once_never_pass_the_attempt_limit(tmp_path, store_url):
    store = _store(tmp_path, store_url)
    ctx = multiprocessing.get_context("spawn")
    out = ctx.Queue()
    servers = [ctx.Process(target=_hand_in_many, args=(store_url, tmp_path, "ada", 8, 3, out)) for _ in range(2)]
    for p in servers:
        p.start()
    got = [out.get(timeout=120) for _ in servers]
    for p in servers:
        p.join(timeout=60)
    stored = [i for g in got for i in g if i is not None]
    assert len(stored) == 3 and len(set(stored)) == 3
    assert len(store.of("ada")) == 3 and len(store.refusals()) == 13


def test_an_older_postgresql_database_is_brought_up_to_date(pg_url, tmp_path):
    import psycopg

    with psycopg.connect(pg_url, autocommit=True) as conn:         # a lab made by version 1
        for statement in _statements(_POSTGRES_V1):
            conn.execute(statement)
        conn.execute("CREATE TABLE eha_schema (version INTEGER NOT NULL, written_by TEXT NOT NULL)")
        conn.execute("INSERT INTO eha_schema VALUES (1, 'eha 0.9')")
        conn.execute("INSERT INTO handins (time, student, estimates, verdicts, score) VALUES "
                     "('2026-11-01 10:00:00', 'ada', '{\"M\": 1.0}', '{\"M\": true}', 1.0)")
    store = _store(tmp_path, pg_url)
    assert store.backend.schema_version() == SCHEMA_VERSION
    assert [(h.id, h.student, h.estimates) for h in store.all()] == [(1, "ada", {"M": 1.0})]
    assert store.add("ada", {"M": 2.0}, {"M": True}, key="k") == 2 == store.add("ada", {"M": 2.0}, {}, key="k")


def test_an_older_sqlite_file_is_brought_up_to_date(tmp_path):
    path = tmp_path / "class.handins.sqlite"
    with sqlite3.connect(path) as db:                       # made before versions were kept
        for statement in _statements(_SQLITE_V1):
            db.execute(statement)
        db.execute("INSERT INTO handins (time, student, estimates, verdicts, score) VALUES "
                   "('2026-11-01 10:00:00', 'ada', '{\"M\": 1.0}', '{\"M\": true}', 1.0)")
    store = _store(tmp_path, None)
    assert store.backend.schema_version() == SCHEMA_VERSION
    assert [(h.student, h.method, h.source) for h in store.all()] == [("ada", "lse", {"kind": "simulated"})]
    assert store.add("ada", {"M": 2.0}, {"M": True}, key="k") == store.add("ada", {"M": 2.0}, {}, key="k")


def test_a_database_of_a_newer_version_is_refused_saying_so(tmp_path, store_url):
    store = _store(tmp_path, store_url)
    store._write(lambda db: db.execute("INSERT INTO eha_schema (version, written_by) VALUES (?, ?)",
                                       (SCHEMA_VERSION + 1, "eha 9.0")))
    with pytest.raises(StoreError) as err:
        HandIns(tmp_path / "class.json", store=store_url).check() if store_url is None else \
            HandIns(tmp_path / "class.json", store=store_url + "?application_name=x").check()
    text = str(err.value)
    assert "newer version of eha (eha 9.0" in text and f"version {SCHEMA_VERSION + 1}" in text
    assert "pip install -U eha" in text
    if store_url:
        assert "s3cret-pw" not in text and shown_url(store_url) in text


def test_wrong_credentials_and_an_unknown_database_name_the_url_without_its_password(postgres, tmp_path):
    wrong = postgres.url().replace("s3cret-pw", "not-the-password")
    with pytest.raises(StoreError) as err:
        HandIns(tmp_path / "class.json", store=wrong).check()
    assert not isinstance(err.value, StoreUnavailable)
    assert "refused the user name or password" in str(err.value) and "not-the-password" not in str(err.value)
    assert f"postgresql://eha@127.0.0.1:{postgres.port}/eha_test" in str(err.value)
    with pytest.raises(StoreError) as err:
        HandIns(tmp_path / "class.json", store=postgres.url("no_such_lab")).check()
    assert "does not exist" in str(err.value) and "s3cret-pw" not in str(err.value)


def test_an_unreachable_database_is_unavailable_not_damaged(tmp_path):
    from tests.serve.conftest import free_port

    url = f"postgresql://eha:hidden-pw@127.0.0.1:{free_port()}/lab"
    with pytest.raises(StoreUnavailable) as err:
        HandIns(tmp_path / "class.json", store=url).check()
    text = str(err.value)
    assert "cannot be reached" in text and "hidden-pw" not in text and "postgresql://eha@127.0.0.1:" in text


def test_a_database_lost_mid_lab_is_unavailable_then_works_again(tmp_path):
    from tests.postgres import PostgresServer, find_pg_bin

    if find_pg_bin() is None:
        pytest.skip("PostgreSQL not found (no initdb): apt-get install -y postgresql")
    server = PostgresServer().start()
    try:
        store = _store(tmp_path, server.url())
        store.add("ada", {"M": 1.0}, {"M": True}, key="a1")
        server.kill()
        with pytest.raises(StoreUnavailable) as err:
            store.backend.write(lambda db: db.execute("SELECT 1"), 0.5)
        assert "cannot be reached" in str(err.value) and "s3cret-pw" not in str(err.value)
        server.restart()
        # (PostgreSQL's ids may skip after a crash: its sequences are logged ahead)
        second = store.add("ada", {"M": 2.0}, {"M": True}, key="a2")
        assert [(h.id, h.estimates) for h in store.all()] == [(1, {"M": 1.0}), (second, {"M": 2.0})]
    finally:
        server.stop()


def test_a_lab_copied_from_sqlite_to_postgresql_is_the_same_lab(tmp_path, pg_url):
    source = _store(tmp_path, None)
    _play(source)
    target = HandIns(tmp_path / "class.json", store=pg_url)
    counts = copy_lab(source.backend, target.backend)
    assert counts["handins"] == 3 and counts["refusals"] == 1 and counts["work_files"] == 1
    assert _lab(target) == _lab(source)
    # ids go on after the copied ones; a copy into a lab that holds something is refused
    assert target.add("cy", {"M": 1.0}, {"M": True}) == 4
    with pytest.raises(StoreError, match="is not empty"):
        copy_lab(source.backend, target.backend)
    # and back, as a backup: the same again
    backup = HandIns(tmp_path / "backup" / "class.json", store=f"sqlite:///{tmp_path / 'backup.sqlite'}")
    copy_lab(target.backend, backup.backend)
    assert _lab(backup) == _lab(target)
    assert json.loads(json.dumps(_lab(backup)["control"])) == {"open": "1", "deadline": "2030-01-01T00:00"}


def test_servers_started_together_issue_one_dashboard_link(tmp_path, store_url):
    from eha_app.runtime.teacher_access import ensure_token
    from eha_core.exercise import Exercise

    ex = Exercise.new(hide=("M",), secret="4d" * 32)
    _store(tmp_path, store_url)
    barrier, got = threading.Barrier(4), []

    def server():
        store = HandIns(tmp_path / "class.json", store=store_url)     # each its own, as each process has
        barrier.wait()
        got.append(ensure_token(ex, store))
    threads = [threading.Thread(target=server) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len({issued.token for issued, _ in got}) == 1 and sum(made for _, made in got) == 1
