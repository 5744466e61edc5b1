"""Served-app tests: real `eha serve` processes (and nginx), driven at the protocol level.

The students are :class:`benchmarks.classroom_client.Student` sessions: the
page, the Bokeh websocket, widget changes and button events exactly as BokehJS
sends them, without a browser (tests/ui drives a real one).
"""

from __future__ import annotations

import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from benchmarks.classroom_client import stop_server, wait_served

ROOT = Path(__file__).resolve().parents[2]
EHA = Path(sys.executable).with_name("eha")


def dashboard_token(exercise_path) -> str:
    """The teacher's dashboard token the served exercise issued at its start (kept in its database)."""
    from eha_app.runtime.handins import HandIns
    from eha_app.runtime.teacher_access import issued
    from eha_core.exercise import Exercise

    now = issued(Exercise.load(exercise_path), HandIns(exercise_path))
    assert now is not None, "the server issued no dashboard token"
    return now.token


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_http(url: str, proc=None, timeout: float = 120.0) -> None:
    """The benchmarks' wait for a server (:func:`benchmarks.classroom_client.wait_served`), failing the test."""
    try:
        wait_served(proc, url, timeout)
    except RuntimeError as exc:
        pytest.fail(str(exc))


class EhaServer:
    """``eha serve`` in a subprocess; its log is kept for the assertions."""

    def __init__(self, tmp_path: Path, *args: str, port: int | None = None):
        self.port = port or free_port()
        self.log_path = tmp_path / f"eha-serve-{self.port}.log"
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen([str(EHA), "serve", "--port", str(self.port), "--address", "127.0.0.1", *args],
                                     cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self.url = f"http://127.0.0.1:{self.port}/eha"
        wait_http(self.url, self.proc)
        # with --num-procs N, every process serving: each loads the kernels before it binds the port,
        # and the first to bind answers the first request
        procs = int(args[args.index("--num-procs") + 1]) if "--num-procs" in args else 1
        deadline = time.monotonic() + 120
        while len(set(re.findall(r"Starting Bokeh server with process id: (\d+)", self.log_text()))) < procs:
            if time.monotonic() > deadline or self.proc.poll() is not None:
                pytest.fail(f"{procs} processes did not all start:\n{self.log_text()[-3000:]}")
            time.sleep(0.2)

    def log_text(self) -> str:
        self.log.flush()
        return self.log_path.read_text(errors="replace")

    def stop(self) -> None:
        stop_server(self.proc)
        self.log.close()


@pytest.fixture
def serve(tmp_path):
    """Start ``eha serve`` with the given options; stopped after the test."""
    started = []

    def start(*args, port=None):
        s = EhaServer(tmp_path, *args, port=port)
        started.append(s)
        return s

    yield start
    for s in started:
        s.stop()
