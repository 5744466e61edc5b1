"""Where a lab's state is kept: SQLite beside the exercise file (the default), or a PostgreSQL
database shared by every server of a course, chosen by a URL (``eha serve --store URL``).

Both backends hold the same tables (:mod:`eha_app.runtime.handins` writes its SQL once, with ``?``
placeholders; the PostgreSQL backend passes them on as psycopg's) and the same schema version,
kept in the table ``eha_schema``. A database of an older version is brought up to date at the
first start (:data:`MIGRATIONS`, one transaction, one server at a time); one of a newer version is
refused, saying which version made it.

Every write is one transaction that the backend serialises, as SQLite's ``BEGIN IMMEDIATE`` does on
one machine: on PostgreSQL a transaction-level advisory lock, the class's for the teacher's switches
and the student's for the writes of one student (their hand-ins, presence and kept work), so that a
student's two pages handing in on two servers at once cannot both take the last attempt, while
other students' writes go on beside. Reads see one consistent snapshot.

The URL is shown without its password in every message and log line (:func:`shown_url`).

psycopg 3 is the PostgreSQL driver: the project needs a plain connection, parameters bound by the
server and the error codes (wrong password, unknown database, a connection lost), which psycopg
gives directly and SQLAlchemy would only wrap; its binary wheel carries libpq, so a teacher's
``pip install`` needs no compiler.

>>> shown_url("postgresql://eha:s3cret@db.school.example:5432/lab")
'postgresql://eha@db.school.example:5432/lab'
>>> shown_url("postgresql://db.example/lab?password=s3cret&sslmode=require")
'postgresql://db.example/lab?sslmode=require'
"""

from __future__ import annotations

import logging
import os
import queue
import re
import sqlite3
import threading
import time
from contextlib import closing
from pathlib import Path
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

__all__ = ["StoreError", "StoreUnavailable", "SCHEMA_VERSION", "MIGRATIONS", "Backend", "SQLiteBackend",
           "PostgresBackend", "open_backend", "copy_lab", "take_lock", "LAB_TABLES", "shown_url", "is_postgres_url",
           "BUSY_TIMEOUT_S"]

log = logging.getLogger("eha_app")

#: How long one attempt waits for another connection's lock before it is tried again [s] (SQLite).
BUSY_TIMEOUT_S = 0.25
#: How long a connection to PostgreSQL may take before the database counts as unreachable [s].
CONNECT_TIMEOUT_S = 5
#: Idle connections a server process keeps open to PostgreSQL.
POOL_SIZE = 6


class StoreError(RuntimeError):
    """The lab's database cannot be used: what is wrong and what to do."""


class StoreUnavailable(StoreError):
    """The lab's database cannot be reached now (stopped, the network, a connection lost): a call can
    be tried again later and may then succeed (a hand-in waits to be saved)."""


def is_postgres_url(url: str | None) -> bool:
    return bool(url) and str(url).split(":", 1)[0].lower() in ("postgresql", "postgres")


def shown_url(url: str) -> str:
    """``url`` without its password (in the user part or as a ``password=`` parameter)."""
    try:
        parts = urlsplit(str(url))
    except ValueError:
        return "(a database URL that cannot be read)"
    if "@" not in parts.netloc and "password" not in parts.query.lower():
        return str(url)                     # nothing to hide: as typed (sqlite:///x stays sqlite:///x)
    netloc = parts.netloc
    if "@" in netloc:
        user, host = netloc.rsplit("@", 1)
        netloc = user.split(":", 1)[0] + "@" + host
    query = urlencode([(k, v) for k, v in parse_qsl(parts.query, keep_blank_values=True)
                       if k.lower() != "password"])
    return urlunsplit((parts.scheme, netloc, parts.path, query, parts.fragment))


# -- the schema, by version -------------------------------------------------------------------------
#: The schema this version of eha writes and reads.
SCHEMA_VERSION = 2

# Version 1: the tables as the SQLite store had them before versions were kept (a database without
# eha_schema is at version 1 once the columns added over time are there).
_SQLITE_V1 = """
CREATE TABLE IF NOT EXISTS handins (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    time TEXT NOT NULL,
    student TEXT NOT NULL,
    estimates TEXT NOT NULL,
    verdicts TEXT NOT NULL,
    score REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS handins_student ON handins (student, id);
CREATE TABLE IF NOT EXISTS control (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS presence (student TEXT PRIMARY KEY, joined TEXT NOT NULL, last_seen TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS clients (address TEXT NOT NULL, student TEXT NOT NULL, first REAL NOT NULL,
                                    PRIMARY KEY (address, student));
CREATE TABLE IF NOT EXISTS work (student TEXT PRIMARY KEY, time TEXT NOT NULL, settings TEXT NOT NULL,
                                 runs TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS work_files (student TEXT NOT NULL, slot TEXT NOT NULL, name TEXT NOT NULL,
                                       mapping TEXT NOT NULL, digest TEXT NOT NULL, data BLOB NOT NULL,
                                       PRIMARY KEY (student, slot));
CREATE TABLE IF NOT EXISTS refusals (id INTEGER PRIMARY KEY AUTOINCREMENT, time TEXT NOT NULL, student TEXT NOT NULL,
                                     method TEXT NOT NULL, why TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS extensions (student TEXT PRIMARY KEY, deadline TEXT NOT NULL, time TEXT NOT NULL);
"""
#: Columns added to version 1 before versions were kept, per table (an old SQLite file gets them).
_SQLITE_V1_ADDED = {
    "handins": (("method", "TEXT NOT NULL DEFAULT 'lse'"), ("settings", "TEXT NOT NULL DEFAULT '{}'"),
                ("conditions", "TEXT NOT NULL DEFAULT '{}'"), ("errors", "TEXT NOT NULL DEFAULT '{}'"),
                ("source", "TEXT NOT NULL DEFAULT '{}'")),
    # page: the live page's token (one code, one live page); pages: pages opened in all; overlaps: pages
    # opened while another of the same id was live (the teacher sees a code used twice)
    "presence": (("page", "TEXT NOT NULL DEFAULT ''"), ("pages", "INTEGER NOT NULL DEFAULT 0"),
                 ("overlaps", "INTEGER NOT NULL DEFAULT 0")),
    "work_files": (("size", "INTEGER NOT NULL DEFAULT -1"),),
}

_POSTGRES_V1 = """
CREATE TABLE handins (id BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY, time TEXT NOT NULL,
                      student TEXT NOT NULL, estimates TEXT NOT NULL, verdicts TEXT NOT NULL,
                      score DOUBLE PRECISION NOT NULL, method TEXT NOT NULL DEFAULT 'lse',
                      settings TEXT NOT NULL DEFAULT '{}', conditions TEXT NOT NULL DEFAULT '{}',
                      errors TEXT NOT NULL DEFAULT '{}', source TEXT NOT NULL DEFAULT '{}');
CREATE INDEX handins_student ON handins (student, id);
CREATE TABLE control (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE presence (student TEXT PRIMARY KEY, joined TEXT NOT NULL, last_seen TEXT NOT NULL,
                       page TEXT NOT NULL DEFAULT '', pages INTEGER NOT NULL DEFAULT 0,
                       "overlaps" INTEGER NOT NULL DEFAULT 0);
CREATE TABLE clients (address TEXT NOT NULL, student TEXT NOT NULL, first DOUBLE PRECISION NOT NULL,
                      PRIMARY KEY (address, student));
CREATE TABLE work (student TEXT PRIMARY KEY, time TEXT NOT NULL, settings TEXT NOT NULL, runs TEXT NOT NULL);
CREATE TABLE work_files (student TEXT NOT NULL, slot TEXT NOT NULL, name TEXT NOT NULL, mapping TEXT NOT NULL,
                         digest TEXT NOT NULL, data BYTEA NOT NULL, size BIGINT NOT NULL DEFAULT -1,
                         PRIMARY KEY (student, slot));
CREATE INDEX work_files_size ON work_files (student, slot, size);
CREATE TABLE refusals (id BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY, time TEXT NOT NULL,
                       student TEXT NOT NULL, method TEXT NOT NULL, why TEXT NOT NULL);
CREATE TABLE extensions (student TEXT PRIMARY KEY, deadline TEXT NOT NULL, time TEXT NOT NULL)
"""

# Version 2: a hand-in carries the key its page gave it, so that one sent again (a connection lost
# after the database took it, a server that died, a hand-in waiting to be saved) is stored once.
_V2 = """
ALTER TABLE handins ADD COLUMN key TEXT NOT NULL DEFAULT '';
CREATE UNIQUE INDEX handins_key ON handins (student, key) WHERE key <> ''
"""

#: backend -> [(version, SQL statements separated by ";")]: what brings a database from the version
#: before to this one.
MIGRATIONS = {
    "sqlite": [(1, None), (2, _V2)],         # 1: made or completed by SQLiteBackend._version_1
    "postgresql": [(1, _POSTGRES_V1), (2, _V2)],
}

_VERSION_TABLE = "CREATE TABLE IF NOT EXISTS eha_schema (version INTEGER NOT NULL, written_by TEXT NOT NULL)"


def _eha_version() -> str:
    try:
        from importlib.metadata import version
        return version("eha")
    except Exception:  # noqa: BLE001 - a source checkout without metadata
        return "unknown"


def _statements(sql: str) -> list[str]:
    return [s.strip() for s in sql.split(";") if s.strip()]


class Backend:
    """What :class:`~eha_app.runtime.handins.HandIns` needs of a database: ``write(fn)`` runs ``fn(db)``
    in one serialised write transaction, ``snapshot(fn)`` in one consistent read; ``db.execute(sql,
    args)`` takes ``?`` placeholders and returns a cursor (``fetchone``, ``fetchall``)."""

    kind = ""
    #: what messages call the database (a path, or the URL without its password)
    shown = ""
    #: the SQL aggregate that joins a column's values with commas
    def concat(self, expr: str) -> str:
        raise NotImplementedError

    def check(self) -> None:
        raise NotImplementedError

    def write(self, fn, patience: float, lock: str | None = None):
        """``fn(db)`` in one write transaction, serialised with every other write (``lock`` None) or with
        those of the same ``lock`` (one student's rows: PostgreSQL then runs other students' writes
        beside it; SQLite serialises every write anyway)."""
        raise NotImplementedError

    def snapshot(self, fn, patience: float):
        raise NotImplementedError

    def unusable(self, what) -> StoreError:
        return StoreError(f"the lab's database {self.shown} cannot be used ({what})")

    def newer(self, found: int, by: str) -> StoreError:
        return StoreError(f"the lab's database {self.shown} was made by a newer version of eha ({by}, schema "
                          f"version {found}; this eha {_eha_version()} knows up to version {SCHEMA_VERSION}): "
                          "install that version on this machine (pip install -U eha)")

    def schema_version(self) -> int:
        """The version of the database's schema (0: no tables yet)."""
        raise NotImplementedError


# -- SQLite -------------------------------------------------------------------------------------------
def _busy(exc: sqlite3.Error) -> bool:
    text = str(exc).lower()
    return isinstance(exc, sqlite3.OperationalError) and ("locked" in text or "busy" in text)


class SQLiteBackend(Backend):
    """The lab's state in one SQLite file (WAL: the teacher reads while students hand in).

    The file is the teacher's, like the exercise file: it is created readable by its owner only
    (SQLite gives its journal files the same permissions). One that disappears while the server
    runs is not made again behind the teacher's back (every student's attempts would start from
    0): the calls fail, saying so, until the teacher puts a copy back or starts the server again."""

    kind = "sqlite"

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.shown = repr(str(self.path))
        # the database existed when this process first looked: if it disappears later, it was deleted
        self._known = self.path.exists()
        self._missing_said = 0.0
        self._lock = threading.Lock()
        self._ready = False                 # the tables were checked by this instance

    def concat(self, expr: str) -> str:
        return f"group_concat({expr})"

    def unusable(self, what) -> StoreError:
        return StoreError(f"the hand-in database {self.shown} cannot be used ({what}); move it away to start "
                          "an empty one, or put back a copy")

    def check(self) -> None:
        if self.path.parent.exists() and not os.access(self.path.parent, os.W_OK):
            raise StoreError(f"the folder {str(self.path.parent)!r} of the hand-in database is read-only; the "
                             "server could not store a single hand-in: serve from a folder you can write to")
        self._known = False                 # made here if missing: the teacher asked for it
        self._ready = False
        try:
            with closing(self._connect()) as db:
                db.execute("PRAGMA journal_mode=WAL")
                problem = db.execute("PRAGMA quick_check").fetchone()[0]
        except sqlite3.Error as exc:
            raise self.unusable(exc) from None
        if problem != "ok":
            raise self.unusable(problem)

    def schema_version(self) -> int:
        with closing(sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)) as db:
            names = {r[0] for r in db.execute("SELECT name FROM sqlite_master")}
            if "eha_schema" in names:
                return int(db.execute("SELECT MAX(version) FROM eha_schema").fetchone()[0] or 0)
            return 1 if "handins" in names else 0

    def _version_1(self, db, names: set[str]) -> None:
        """Version 1: the tables, made if missing, and the columns added before versions were kept."""
        if not {"handins", "control", "presence", "clients", "work", "work_files", "refusals",
                "extensions"} <= names:
            for statement in _statements(_SQLITE_V1):    # not executescript: it would end the transaction
                db.execute(statement)
        for table, added in _SQLITE_V1_ADDED.items():
            have = {r[1] for r in db.execute(f"PRAGMA table_info({table})")}
            for name, decl in added:
                if name not in have:
                    db.execute(f"ALTER TABLE {table} ADD COLUMN {name} {decl}")
        # the uploads' sizes, for the class's quota (kept before the column existed: measured once); summed
        # from an index, without reading a single upload's bytes
        if db.execute("SELECT 1 FROM work_files WHERE size < 0 LIMIT 1").fetchone() is not None:
            db.execute("UPDATE work_files SET size = length(data) WHERE size < 0")
        db.execute("CREATE INDEX IF NOT EXISTS work_files_size ON work_files (student, slot, size)")

    def _schema(self, db) -> None:
        """Bring the database to :data:`SCHEMA_VERSION` (only reads when it is there: no write lock is
        asked for); a newer one is refused."""
        names = {r[0] for r in db.execute("SELECT name FROM sqlite_master")}
        if "eha_schema" in names:
            row = db.execute("SELECT version, written_by FROM eha_schema ORDER BY version DESC LIMIT 1").fetchone()
            found, by = (int(row[0]), str(row[1])) if row else (0, "")
            if found > SCHEMA_VERSION:
                raise self.newer(found, by)
            if found == SCHEMA_VERSION:
                return
        db.execute("BEGIN IMMEDIATE")       # one process migrates; the others wait, then find it done
        try:
            names = {r[0] for r in db.execute("SELECT name FROM sqlite_master")}
            db.execute(_VERSION_TABLE)
            row = db.execute("SELECT MAX(version) FROM eha_schema").fetchone()
            found = int(row[0] or 0)
            if found > SCHEMA_VERSION:
                raise self.newer(found, "")
            for version, sql in MIGRATIONS["sqlite"]:
                if version <= found:
                    continue
                if version == 1:
                    self._version_1(db, names)
                else:
                    for statement in _statements(sql):
                        db.execute(statement)
                db.execute("INSERT INTO eha_schema (version, written_by) VALUES (?, ?)",
                           (version, f"eha {_eha_version()}"))
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise

    def _connect(self) -> sqlite3.Connection:
        """A connection to the database, made (readable by its owner only, with its tables) if it is
        missing and was never there; StoreError if it was there and has gone."""
        if self._ready and self.path.exists():
            return sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        if not self.path.exists():
            if self._known:
                now = time.monotonic()
                if now - self._missing_said > 60:       # said once a minute, not at every page's poll
                    self._missing_said = now
                    log.error("the hand-in database %s is missing (deleted while the server ran): hand-ins and "
                              "saves are refused until a copy is put back or the server is started again",
                              self.path.name)
                raise StoreError(f"the hand-in database {self.shown} is missing: it was deleted while the "
                                 "server ran; put a copy back, or start the server again to begin an empty one")
            with self._lock:
                try:
                    os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
                    made = True
                except FileExistsError:
                    made = False            # another thread or process made it meanwhile
                except OSError as exc:
                    raise StoreError(f"the hand-in database {self.shown} cannot be made ({exc.strerror})") \
                        from None
                db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
                if made:
                    db.execute("PRAGMA journal_mode=WAL")
        else:
            db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        # this instance's first connection: the tables are made (or completed) before anything uses them,
        # one thread at a time (two threads of a new store once raced: "table handins has no column method")
        with self._lock:
            if not self._ready:
                try:
                    self._attempts(lambda: self._schema(db), 30.0)
                except BaseException:
                    db.close()
                    raise
                self._ready = True
        self._known = True
        return db

    def _attempts(self, fn, patience: float):
        """``fn()`` again while the database is locked by another connection, until ``patience`` is spent."""
        deadline = time.monotonic() + patience
        pause = 0.02
        while True:
            try:
                return fn()
            except sqlite3.Error as exc:
                if not _busy(exc) or time.monotonic() + pause > deadline:
                    if _busy(exc):
                        raise StoreError(f"the hand-in database {self.path.name!r} is busy: another program has "
                                         f"held its lock for {patience:.0f} s; try again in a moment") from None
                    raise self.unusable(exc) from None
            time.sleep(pause)
            pause = min(2 * pause, 0.5)

    def write(self, fn, patience: float, lock: str | None = None):
        def attempt():
            db = self._connect()
            try:
                db.execute("BEGIN IMMEDIATE")
                out = fn(db)
                db.execute("COMMIT")
                return out
            finally:
                try:
                    if db.in_transaction:
                        db.execute("ROLLBACK")
                except sqlite3.Error:
                    pass
                db.close()
        return self._attempts(attempt, patience)

    def snapshot(self, fn, patience: float):
        def attempt():
            with closing(self._connect()) as db:
                db.execute("BEGIN")
                try:
                    return fn(db)
                finally:
                    db.execute("COMMIT")
        return self._attempts(attempt, patience)


# -- PostgreSQL --------------------------------------------------------------------------------------
#: The advisory lock every write takes (any number; the same for every server of the lab).
_WRITE_LOCK = 0x65686101


class _PgConnection:
    """A psycopg connection that takes the store's SQL: ``?`` placeholders (the store's SQL has no
    literal ``?`` or ``%``)."""

    def __init__(self, conn):
        self.conn = conn

    def execute(self, sql: str, args=()):
        return self.conn.execute(sql.replace("%", "%%").replace("?", "%s"), tuple(args))


class PostgresBackend(Backend):
    """The lab's state in a PostgreSQL database that every server of the course shares."""

    kind = "postgresql"

    def __init__(self, url: str):
        self.url = str(url)
        self.shown = shown_url(self.url)
        self.path = None
        self._idle: queue.LifoQueue = queue.LifoQueue()
        self._lock = threading.Lock()
        self._ready = False
        self._down_said = 0.0

    def concat(self, expr: str) -> str:
        return f"string_agg(({expr})::text, ',' ORDER BY ({expr})::text)"

    # connections ------------------------------------------------------------------------------
    def _psycopg(self):
        try:
            import psycopg
        except ImportError:
            raise StoreError(f"the lab's database {self.shown} needs the PostgreSQL driver psycopg: "
                             "pip install 'eha[postgresql]'") from None
        return psycopg

    def _failure(self, exc) -> StoreError:
        """What a psycopg error means for the teacher: wrong credentials, no such database (not worth
        trying again), or a database that cannot be reached now (:class:`StoreUnavailable`)."""
        psycopg = self._psycopg()
        state = getattr(exc, "sqlstate", None) or ""
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        text = text.replace(self.url, self.shown)
        if state in ("28P01", "28000") or "password authentication failed" in text \
                or "no password supplied" in text:
            return StoreError(f"the lab's database {self.shown} refused the user name or password ({text}): "
                              "check the user and password in --store")
        if state == "3D000" or ("database" in text and "does not exist" in text):
            return StoreError(f"the lab's database {self.shown} does not exist ({text}): create it "
                              "(createdb) or correct the name in --store")
        if isinstance(exc, psycopg.OperationalError) or state.startswith("08") or state in ("57P01", "57P02",
                                                                                           "57P03"):
            return StoreUnavailable(f"the lab's database {self.shown} cannot be reached ({text})")
        return self.unusable(text)

    def _connect(self):
        """A new connection, the schema brought up to date by this instance's first one."""
        conn = self._connect_plain()
        if not self._ready:
            with self._lock:
                if not self._ready:
                    try:
                        self._schema(conn)
                    except BaseException:
                        conn.close()
                        raise
                    self._ready = True
        return conn

    def _take(self):
        while True:
            try:
                conn = self._idle.get_nowait()
            except queue.Empty:
                return self._connect()
            if not conn.closed and not conn.broken:
                return conn
            conn.close()

    def _give(self, conn) -> None:
        if conn.closed or conn.broken or self._idle.qsize() >= POOL_SIZE:
            conn.close()
        else:
            self._idle.put(conn)

    def close(self) -> None:
        while True:
            try:
                self._idle.get_nowait().close()
            except queue.Empty:
                return

    # schema -----------------------------------------------------------------------------------
    def schema_version(self) -> int:
        conn = self._connect_plain()
        try:
            if conn.execute("SELECT to_regclass('eha_schema')").fetchone()[0] is None:
                return 1 if conn.execute("SELECT to_regclass('handins')").fetchone()[0] is not None else 0
            return int(conn.execute("SELECT MAX(version) FROM eha_schema").fetchone()[0] or 0)
        finally:
            conn.close()

    def _connect_plain(self):
        psycopg = self._psycopg()
        try:
            return psycopg.connect(self.url, connect_timeout=CONNECT_TIMEOUT_S, autocommit=True,
                                   application_name="eha")
        except psycopg.Error as exc:
            raise self._failure(exc) from None

    def _schema(self, conn) -> None:
        psycopg = self._psycopg()
        try:
            if conn.execute("SELECT to_regclass('eha_schema')").fetchone()[0] is not None:
                row = conn.execute("SELECT version, written_by FROM eha_schema ORDER BY version DESC LIMIT 1") \
                    .fetchone()
                if row is not None and int(row[0]) > SCHEMA_VERSION:
                    raise self.newer(int(row[0]), str(row[1]))
                if row is not None and int(row[0]) == SCHEMA_VERSION:
                    return
            with conn.transaction():
                # one server migrates; the others wait here, then find it done
                conn.execute("SELECT pg_advisory_xact_lock(%s)", (_WRITE_LOCK,))
                conn.execute(_VERSION_TABLE)
                found = int(conn.execute("SELECT MAX(version) FROM eha_schema").fetchone()[0] or 0)
                if found > SCHEMA_VERSION:
                    raise self.newer(found, "")
                for version, sql in MIGRATIONS["postgresql"]:
                    if version <= found:
                        continue
                    for statement in _statements(sql):
                        conn.execute(statement)
                    conn.execute("INSERT INTO eha_schema (version, written_by) VALUES (%s, %s)",
                                 (version, f"eha {_eha_version()}"))
        except psycopg.Error as exc:
            raise self._failure(exc) from None

    def check(self) -> None:
        self._ready = False
        conn = self._connect()
        self._give(conn)

    # transactions -----------------------------------------------------------------------------
    def _run(self, fn, patience: float, write: bool, lock: str | None = None):
        psycopg = self._psycopg()
        deadline = time.monotonic() + patience
        pause = 0.2
        while True:
            try:
                conn = self._take()
                try:
                    if write:
                        with conn.transaction():
                            if lock is None:
                                conn.execute("SELECT pg_advisory_xact_lock(%s)", (_WRITE_LOCK,))
                            else:
                                conn.execute("SELECT pg_advisory_xact_lock(hashtext(%s))", (lock,))
                            out = fn(_PgConnection(conn))
                    else:
                        conn.execute("BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY")
                        try:
                            out = fn(_PgConnection(conn))
                        finally:
                            if not conn.broken and not conn.closed:
                                conn.execute("COMMIT")
                except psycopg.Error as exc:
                    conn.close()
                    raise self._failure(exc) from None
                except BaseException:
                    conn.close()
                    raise
                self._give(conn)
                return out
            except StoreUnavailable as exc:
                if time.monotonic() + pause > deadline:
                    now = time.monotonic()
                    if now - self._down_said > 30:      # said every 30 s while it lasts, not at every poll
                        self._down_said = now
                        log.error("%s; the server keeps serving and tries again", exc)
                    raise
            time.sleep(pause)
            pause = min(2 * pause, 2.0)

    def write(self, fn, patience: float, lock: str | None = None):
        return self._run(fn, patience, write=True, lock=lock)

    def snapshot(self, fn, patience: float):
        return self._run(fn, patience, write=False)


#: What a lab holds, table by table, with the columns copied (in the order of SCHEMA_VERSION).
LAB_TABLES = {
    "handins": ("id", "time", "student", "estimates", "verdicts", "score", "method", "settings", "conditions",
                "errors", "source", "key"),
    "refusals": ("id", "time", "student", "method", "why"),
    "control": ("key", "value"),
    "extensions": ("student", "deadline", "time"),
    "presence": ("student", "joined", "last_seen", "page", "pages", '"overlaps"'),
    "clients": ("address", "student", "first"),
    "work": ("student", "time", "settings", "runs"),
    "work_files": ("student", "slot", "name", "mapping", "digest", "data", "size"),
}


def copy_lab(source: Backend, target: Backend, batch: int = 200) -> dict[str, int]:
    """Copy every table of the lab in ``source`` into ``target``, which must hold no lab yet (its tables
    empty), in one transaction of the target over one snapshot of the source: a copy is whole or
    nothing. Row ids are kept (a hand-in keeps its number). Returns the rows copied per table."""
    target.check()
    source.check()

    def into(t):
        held = {table: t.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0] for table in LAB_TABLES}
        if any(held.values()):
            what = ", ".join(f"{n} {table}" for table, n in held.items() if n)
            raise StoreError(f"the lab's database {target.shown} is not empty ({what}): copy into an empty "
                             "database, so that no hand-in is mixed with another lab's")
        counts = {}

        def read(s):
            for table, columns in LAB_TABLES.items():
                cols = ", ".join(columns)
                marks = ", ".join("?" for _ in columns)
                cur = s.execute(f"SELECT {cols} FROM {table}")
                n = 0
                while True:
                    rows = cur.fetchmany(batch)
                    if not rows:
                        break
                    for row in rows:
                        t.execute(f"INSERT INTO {table} ({cols}) VALUES ({marks})", tuple(row))
                    n += len(rows)
                counts[table] = n
        source.snapshot(read, 30.0)
        if target.kind == "postgresql":
            for table in ("handins", "refusals"):       # the next id follows the copied ones
                t.execute(f"SELECT setval(pg_get_serial_sequence('{table}', 'id'), GREATEST(COALESCE(MAX(id), 0), "
                          f"1), MAX(id) IS NOT NULL) FROM {table}")
        return counts
    return target.write(into, 60.0)


def take_lock(db, key: str) -> None:
    """Inside a write whose ``lock`` was one student's: serialise the rest of it with the writes of ``key``
    too (the class's quota of kept uploads; a no-op on SQLite, whose writes are all serialised)."""
    if isinstance(db, _PgConnection):
        db.conn.execute("SELECT pg_advisory_xact_lock(hashtext(%s))", (key,))


_PG_BACKENDS: dict[str, PostgresBackend] = {}
_PG_LOCK = threading.Lock()


def open_backend(exercise_path: str | Path, store: str | None = None) -> Backend:
    """The backend ``store`` names: None or "" -> SQLite beside ``exercise_path``
    (``class.json`` -> ``class.handins.sqlite``); ``sqlite:///relative/path`` or ``sqlite:////absolute/path``
    -> that file;
    ``postgresql://user:password@host:port/database`` -> PostgreSQL (one backend, and one pool of
    connections, per URL in a process)."""
    if not store:
        p = Path(exercise_path)
        return SQLiteBackend(p.with_name(p.stem + ".handins.sqlite"))
    text = str(store).strip()
    if is_postgres_url(text):
        with _PG_LOCK:
            backend = _PG_BACKENDS.get(text)
            if backend is None:
                backend = _PG_BACKENDS[text] = PostgresBackend(text)
            return backend
    # as SQLAlchemy writes it: sqlite:///class.sqlite is relative to the working directory,
    # sqlite:////var/backups/class.sqlite absolute
    m = re.match(r"sqlite:(?:///)?(.+)$", text, re.IGNORECASE)
    if m:
        return SQLiteBackend(m.group(1))
    raise StoreError(f"{shown_url(text)!r} is not a database URL: give postgresql://USER@HOST:PORT/DATABASE "
                     "(the password from ~/.pgpass or PGPASSWORD), or sqlite:///PATH (relative; sqlite:////PATH "
                     "absolute; the default is a SQLite file beside the exercise)")
