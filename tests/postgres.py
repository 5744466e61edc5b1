"""A real, throwaway PostgreSQL server for the tests of the PostgreSQL store.

``PostgresServer().start()`` runs ``initdb`` in a fresh temporary directory and starts the postmaster
on a free TCP port of 127.0.0.1 (its unix socket in that directory too), then creates the role
``eha`` (password login over TCP, scram-sha-256) and the database ``eha_test``. ``url()`` is what the
store connects with; ``create_database()`` gives each test a fresh, empty database; ``kill()`` and
``restart()`` make the database go away mid-lab and come back; ``stop()`` (also run at interpreter
exit) stops it by its PID and removes the directory.

As root (initdb refuses to run as root) every PostgreSQL program runs as Debian's ``postgres`` user
(``setpriv``), and the directory is that user's. The postmaster is this process's own child (not
daemonized by ``pg_ctl``), so that stopping it reaps it: in a container whose init reaps no orphans, a
daemonized postmaster would stay a zombie and its PID would still answer ``os.kill(pid, 0)``.

Nothing heavy is imported here: psycopg only when a server is started (pytest imports this module for
its doctests).
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

ROLE = "eha"
PASSWORD = "s3cret-pw"
DATABASE = "eha_test"
SUPERUSER = "postgres"
OS_USER = "postgres"  # the Debian package's system user, for running as root

# Quick and disposable: no fsync anywhere, nothing worth surviving an OS crash. A commit still writes its
# WAL to the kernel before it returns (synchronous_commit stays on, which costs nothing without fsync): a
# killed server (kill()) comes back with every committed row, as a real one would.
SERVER_SETTINGS = {
    "listen_addresses": "127.0.0.1",
    "max_connections": "200",
    "fsync": "off",
    "full_page_writes": "off",
    "logging_collector": "off",
    "shared_buffers": "16MB",
}

_live: set[PostgresServer] = set()


def find_pg_bin() -> Path | None:
    """The directory of ``initdb``, ``pg_ctl`` and ``postgres``: the one of the ``initdb`` on PATH first
    (symlinks resolved), then the newest ``/usr/lib/postgresql/<major>/bin`` (Debian keeps them off PATH);
    None without one."""

    def complete(bin_dir: Path) -> bool:
        return all((bin_dir / name).is_file() for name in ("initdb", "pg_ctl", "postgres"))

    on_path = shutil.which("initdb")
    if on_path and complete(Path(on_path).resolve().parent):
        return Path(on_path).resolve().parent
    candidates = []
    for bin_dir in Path("/usr/lib/postgresql").glob("*/bin"):
        if complete(bin_dir):
            major = tuple(int(part) for part in bin_dir.parent.name.split(".") if part.isdigit())
            candidates.append((major, str(bin_dir)))
    return Path(max(candidates)[1]) if candidates else None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _gone(pid: int) -> bool:
    """No process with that PID, or only a zombie nobody reaps (an orphan in a container whose init
    reaps none): either way nothing runs."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def _children(pid: int) -> list[int]:
    """The PIDs whose parent is ``pid`` (the postmaster's backends and workers), from /proc."""
    kids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                kids.append(int(entry.name))
    return kids


class PostgresServer:
    """One throwaway PostgreSQL cluster on 127.0.0.1; see the module's docstring."""

    def __init__(self, bin_dir: Path | None = None, *, start_timeout: float = 30.0, stop_timeout: float = 15.0):
        self.bin_dir = Path(bin_dir) if bin_dir else find_pg_bin()
        if self.bin_dir is None:
            raise RuntimeError("PostgreSQL not found (no initdb): apt-get install -y postgresql")
        self.start_timeout = start_timeout
        self.stop_timeout = stop_timeout
        self.port: int | None = None
        self.pid: int | None = None  # the postmaster's, from postmaster.pid
        self.tmp_dir: Path | None = None
        self._proc: subprocess.Popen | None = None
        self._orphans: list[int] = []
        self._log_file = None

    # ---------------------------------------------------------------- paths and URLs
    @property
    def data_dir(self) -> Path:
        return self.tmp_dir / "data"

    @property
    def socket_dir(self) -> Path:
        return self.tmp_dir / "socket"

    @property
    def log_path(self) -> Path:
        return self.tmp_dir / "server.log"

    def url(self, dbname: str = DATABASE, password: bool = True) -> str:
        """``postgresql://eha:<password>@127.0.0.1:<port>/<dbname>`` (no password with password=False)."""
        auth = f"{ROLE}:{quote(PASSWORD, safe='')}" if password else ROLE
        return f"postgresql://{auth}@127.0.0.1:{self.port}/{quote(dbname, safe='')}"

    def log_text(self, last: int = 4000) -> str:
        """The end of the server's log (stderr of initdb and the postmaster)."""
        try:
            return self.log_path.read_text(errors="replace")[-last:]
        except (OSError, TypeError):
            return "(no log)"

    # ---------------------------------------------------------------- running programs
    def _as_owner(self, argv: list[str], pdeathsig: bool = False) -> list[str]:
        """``argv`` run as the cluster's owner: Debian's postgres user when we are root."""
        prefix = ["setpriv", f"--reuid={OS_USER}", f"--regid={OS_USER}", "--init-groups"] if os.geteuid() == 0 else []
        if pdeathsig and shutil.which("setpriv"):
            # A test run killed outright (SIGKILL, os._exit: no atexit) takes its server along: SIGQUIT is
            # the postmaster's immediate shutdown. The signal comes when the *thread* that started the
            # server ends, so start it from a thread that lives as long as the server (pytest's main one).
            prefix = [*(prefix or ["setpriv"]), "--pdeathsig=QUIT"]
        return [*prefix, "--", *argv] if prefix else argv

    def _run(self, argv: list[str]) -> None:
        result = subprocess.run(self._as_owner(argv), cwd=self.tmp_dir, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, env=self._env())
        with open(self.log_path, "a") as log:
            log.write(result.stdout)
        if result.returncode != 0:
            raise RuntimeError(f"{argv[0]} failed (exit {result.returncode}):\n{result.stdout[-4000:]}")

    def _env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PG")}
        env.update(LC_ALL="C", LANG="C")
        return env

    def _superuser_connect(self):
        import psycopg

        return psycopg.connect(host=str(self.socket_dir), port=self.port, user=SUPERUSER, dbname="postgres",
                               autocommit=True, connect_timeout=5)

    # ---------------------------------------------------------------- lifecycle
    def start(self) -> PostgresServer:
        """initdb in a fresh temporary directory, start the postmaster on a free port, wait until it
        accepts connections, create the role ``eha`` and the database ``eha_test``. Returns self."""
        import psycopg  # noqa: F401 - fail early, before initdb, when the driver is missing

        if self.tmp_dir is not None:
            raise RuntimeError("already started")
        self.tmp_dir = Path(tempfile.mkdtemp(prefix="eha-pg-"))
        _live.add(self)
        try:
            if os.geteuid() == 0:
                import pwd

                try:
                    owner = pwd.getpwnam(OS_USER)
                except KeyError:
                    raise RuntimeError(f"running as root needs the {OS_USER!r} user (the Debian package makes it): "
                                       "apt-get install -y postgresql") from None
                os.chown(self.tmp_dir, owner.pw_uid, owner.pw_gid)
            self.socket_dir.mkdir()
            self.log_path.touch()
            if os.geteuid() == 0:
                for path in (self.socket_dir, self.log_path):
                    os.chown(path, owner.pw_uid, owner.pw_gid)
            self._run([str(self.bin_dir / "initdb"), "-D", str(self.data_dir), "-U", SUPERUSER, "-N",
                       "-E", "UTF8", "--locale=C", "--auth-local=trust", "--auth-host=scram-sha-256"])
            for attempt in range(3):  # another process may take the free port between choosing and binding
                self.port = _free_port()
                try:
                    self._launch()
                    break
                except RuntimeError:
                    if attempt == 2 or "could not bind" not in self.log_text(2000).lower():
                        raise
            self._create_role_and_database()
        except BaseException:
            self.stop()
            raise
        return self

    def _launch(self) -> None:
        """Start the postmaster on self.port and wait until it accepts connections."""
        settings = [arg for key, value in SERVER_SETTINGS.items() for arg in ("-c", f"{key}={value}")]
        argv = [str(self.bin_dir / "postgres"), "-D", str(self.data_dir), "-p", str(self.port),
                "-k", str(self.socket_dir), *settings]
        self._log_file = open(self.log_path, "ab")
        self._proc = subprocess.Popen(self._as_owner(argv, pdeathsig=True), cwd=self.tmp_dir, env=self._env(),
                                      stdin=subprocess.DEVNULL, stdout=self._log_file, stderr=subprocess.STDOUT,
                                      start_new_session=True)
        self.pid = self._proc.pid
        self._wait_ready()
        pid_file = (self.data_dir / "postmaster.pid").read_text().split("\n")
        self.pid = int(pid_file[0])

    def _wait_ready(self) -> None:
        import psycopg

        deadline = time.monotonic() + self.start_timeout
        while True:
            if self._proc.poll() is not None:
                code = self._proc.returncode
                self._proc = None
                raise RuntimeError(f"PostgreSQL exited at start (exit {code}); its log:\n{self.log_text()}")
            try:
                with self._superuser_connect() as conn:
                    conn.execute("SELECT 1")
                return
            except psycopg.OperationalError as exc:
                if time.monotonic() > deadline:
                    self._stop_process()
                    raise RuntimeError(f"PostgreSQL did not accept connections within {self.start_timeout:.0f} s "
                                       f"({exc}); its log:\n{self.log_text()}") from None
            time.sleep(0.05)

    def _create_role_and_database(self) -> None:
        from psycopg import sql

        with self._superuser_connect() as conn:
            conn.execute(sql.SQL("CREATE ROLE {} LOGIN CREATEDB PASSWORD {}").format(
                sql.Identifier(ROLE), sql.Literal(PASSWORD)))
        self.create_database(DATABASE)

    def create_database(self, name: str) -> str:
        """A fresh, empty database owned by ``eha`` (for one test's isolation): its URL."""
        from psycopg import sql

        with self._superuser_connect() as conn:
            conn.execute(sql.SQL("CREATE DATABASE {} OWNER {} TEMPLATE template0").format(
                sql.Identifier(name), sql.Identifier(ROLE)))
        return self.url(name)

    def kill(self) -> None:
        """SIGKILL the postmaster by its PID (and its backends): the database is lost mid-lab. The data
        directory stays; ``restart()`` brings it back (after crash recovery)."""
        if self.pid is None:
            return
        kids = _children(self.pid)
        _signal(self.pid, signal.SIGKILL)
        for kid in kids:
            _signal(kid, signal.SIGKILL)
        self._orphans.extend(kids)
        self._reap(self.stop_timeout)
        self._wait_gone(self._orphans, self.stop_timeout)

    def restart(self) -> None:
        """Start again on the same port and data directory (a fast stop first if it still runs)."""
        if self.tmp_dir is None:
            raise RuntimeError("never started, or stopped")
        self._stop_process()
        self._wait_gone(self._orphans, self.stop_timeout)
        self._orphans.clear()
        self._launch()

    def stop(self) -> None:
        """Stop the server by its PID (SIGINT, a fast shutdown; SIGKILL after stop_timeout) and remove
        its temporary directory. Safe to call twice."""
        try:
            self._stop_process()
            self._wait_gone(self._orphans, self.stop_timeout)
        finally:
            if self.tmp_dir is not None:
                shutil.rmtree(self.tmp_dir, ignore_errors=True)
                self.tmp_dir = None
            _live.discard(self)

    def _stop_process(self) -> None:
        if self.pid is not None and not _gone(self.pid):
            kids = _children(self.pid)
            _signal(self.pid, signal.SIGINT)
            if not self._reap(self.stop_timeout):
                _signal(self.pid, signal.SIGKILL)
                for kid in kids:
                    _signal(kid, signal.SIGKILL)
                self._orphans.extend(kids)
        self._reap(self.stop_timeout)
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None

    def _reap(self, timeout: float) -> bool:
        """Wait until the postmaster has exited (reaping it when it is our child): True if it has."""
        if self._proc is not None:
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:
                return False
            self._proc = None
            return True
        return self.pid is None or self._wait_gone([self.pid], timeout)

    @staticmethod
    def _wait_gone(pids: list[int], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not all(_gone(pid) for pid in pids):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def __enter__(self) -> PostgresServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _signal(pid: int, sig: int) -> None:
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass


@atexit.register
def _stop_all() -> None:
    """A test run that ends without stopping its servers (a crash, Ctrl-C) leaves none behind."""
    for server in list(_live):
        server.stop()
