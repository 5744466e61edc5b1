"""The test PostgreSQL server itself (tests/postgres.py, the `postgres` and `pg_url` fixtures): password
logins over TCP, a database per test, the database lost mid-lab and back, and nothing left behind."""

import os

import pytest

psycopg = pytest.importorskip("psycopg")


def test_the_url_logs_in_as_eha_with_its_password(postgres):
    assert postgres.url() == f"postgresql://eha:s3cret-pw@127.0.0.1:{postgres.port}/eha_test"
    with psycopg.connect(postgres.url(), connect_timeout=5) as conn:
        user, db, addr = conn.execute("SELECT current_user, current_database(), inet_server_addr()").fetchone()
        scram = conn.execute("SHOW password_encryption").fetchone()[0]
    assert (user, db, str(addr), scram) == ("eha", "eha_test", "127.0.0.1", "scram-sha-256")


def test_a_wrong_or_missing_password_is_refused(postgres):
    wrong = postgres.url().replace("s3cret-pw", "not-the-password")
    with pytest.raises(psycopg.OperationalError, match="password authentication failed"):
        psycopg.connect(wrong, connect_timeout=5)
    with pytest.raises(psycopg.OperationalError):
        psycopg.connect(postgres.url(password=False), connect_timeout=5)


def test_eha_is_no_superuser_and_owns_its_databases(postgres, pg_url):
    with psycopg.connect(pg_url, connect_timeout=5) as conn:
        superuser, createdb = conn.execute(
            "SELECT rolsuper, rolcreatedb FROM pg_roles WHERE rolname = current_user").fetchone()
        owner = conn.execute("SELECT pg_get_userbyid(datdba) FROM pg_database "
                             "WHERE datname = current_database()").fetchone()[0]
    assert (superuser, createdb, owner) == (False, True, "eha")


def test_each_created_database_is_a_fresh_empty_one(postgres):
    first, second = postgres.create_database("iso_a"), postgres.create_database("iso_b")
    assert first != second and first.endswith("/iso_a") and second.endswith("/iso_b")
    with psycopg.connect(first, autocommit=True) as conn:
        conn.execute("CREATE TABLE marks (id int)")
        conn.execute("INSERT INTO marks VALUES (1)")
    with psycopg.connect(second) as conn:
        tables = conn.execute("SELECT count(*) FROM pg_tables WHERE schemaname = 'public'").fetchone()[0]
    assert tables == 0
    with psycopg.connect(first) as conn:
        assert conn.execute("SELECT count(*) FROM marks").fetchone()[0] == 1


def test_pg_url_gives_each_test_its_own_database(pg_url, postgres):
    assert pg_url.startswith(f"postgresql://eha:s3cret-pw@127.0.0.1:{postgres.port}/t_test_pg_url_gives")
    with psycopg.connect(pg_url) as conn:
        assert conn.execute("SELECT count(*) FROM pg_tables WHERE schemaname = 'public'").fetchone()[0] == 0


@pytest.fixture
def own_server(postgres):
    """A server of the test's own (these stop or kill it), not the session's; `postgres` for the skip."""
    from tests.postgres import PostgresServer

    server = PostgresServer().start()
    yield server
    server.stop()


def test_kill_loses_the_database_and_restart_brings_it_back(own_server):
    url = own_server.create_database("lab")
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("CREATE TABLE marks (v int)")
        conn.execute("INSERT INTO marks VALUES (42)")
    held = psycopg.connect(url, autocommit=True)  # a connection open when the database goes away
    port, old_pid = own_server.port, own_server.pid

    own_server.kill()
    with pytest.raises(ProcessLookupError):
        os.kill(old_pid, 0)
    with pytest.raises(psycopg.OperationalError):
        held.execute("SELECT 1")
    held.close()
    with pytest.raises(psycopg.OperationalError):
        psycopg.connect(url, connect_timeout=3)

    own_server.restart()
    assert own_server.port == port and own_server.pid != old_pid
    with psycopg.connect(url, connect_timeout=5) as conn:
        assert conn.execute("SELECT v FROM marks").fetchone()[0] == 42


def test_stop_leaves_no_process_and_no_directory(own_server):
    pid, tmp_dir, url = own_server.pid, own_server.tmp_dir, own_server.url()
    assert tmp_dir.is_dir() and (tmp_dir / "data" / "postmaster.pid").is_file()
    os.kill(pid, 0)  # it runs

    own_server.stop()
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    assert not tmp_dir.exists()
    with pytest.raises(psycopg.OperationalError):
        psycopg.connect(url, connect_timeout=3)
    own_server.stop()  # a second stop is harmless
