import re
import uuid

import pytest


@pytest.fixture(scope="session")
def postgres():
    """A real PostgreSQL server for the whole run (tests/postgres.py), started on first use and stopped
    at the end; skips the tests that use it when PostgreSQL or psycopg is missing."""
    from tests.postgres import PostgresServer, find_pg_bin

    if find_pg_bin() is None:
        pytest.skip("PostgreSQL not found (no initdb): apt-get install -y postgresql "
                    "(the README's test command installs it)")
    try:
        import psycopg  # noqa: F401
    except ImportError:
        pytest.skip("psycopg not installed: pip install -e '.[test]'")
    server = PostgresServer().start()
    yield server
    server.stop()


@pytest.fixture
def pg_url(postgres, request):
    """The URL of a fresh, empty database of the session's server, the test's own."""
    name = re.sub(r"[^a-z0-9_]+", "_", request.node.name.lower())[:40].strip("_")
    return postgres.create_database(f"t_{name}_{uuid.uuid4().hex[:8]}")
