"""Hosts behind nginx on one machine: ``eha serve`` as a "machine" of its own, and nginx in front.

A :class:`Host` is a process group of its own (``start_new_session=True``) with a working directory of its
own (a copy of the exercise file, ``class.json``) and a port of its own, running ``eha serve --exercise
class.json --store URL --behind-proxy --workers 1``; its output goes to ``serve.log`` in its directory.
:class:`Nginx` runs the configuration of :func:`eha_app.runtime.serving.nginx_standalone_config` (an
affinity cookie hashed consistently over the hosts) from a folder of its own, in a session of its own,
after ``nginx -t`` passed it; its error log is ``error.log`` there. Each has a :class:`ProcTree` of its
processes, for their memory and CPU time.

Used by benchmarks/bench_hosts.py and tests/serve/test_two_hosts.py.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

from benchmarks.bench_classroom import ProcTree, eha_command, free_port
from benchmarks.classroom_client import wait_served

NGINX = shutil.which("nginx") or ("/usr/sbin/nginx" if os.path.exists("/usr/sbin/nginx") else None)
_LINK = re.compile(r"/teacher\?token=([0-9a-f]+)")


class Host:
    """``eha serve`` as a machine of its own: a process group, a working directory, a port.

    ``origin``: the address the pages come from (nginx's, ``127.0.0.1:PORT``), allowed as the websocket's
    origin; ``own_origin``: the host's own address allowed besides (a page opened on the host directly,
    the teacher's dashboard say)."""

    def __init__(self, folder: Path, exercise: Path, store: str, origin: str, *, own_origin: bool = False):
        folder.mkdir()
        shutil.copy(exercise, folder / "class.json")
        self.folder = folder
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.log_path = folder / "serve.log"
        self.log = open(self.log_path, "w")
        origins = [origin, self.address] if own_origin else [origin]
        self.proc = subprocess.Popen(
            [*eha_command(), "serve", "--exercise", "class.json", "--store", store, "--port", str(self.port),
             "--address", "127.0.0.1", "--behind-proxy", "--workers", "1",
             *(a for o in origins for a in ("--allow-websocket-origin", o))],
            cwd=folder, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self.tree = ProcTree(self.proc.pid)

    def log_text(self) -> str:
        self.log.flush()
        return self.log_path.read_text(errors="replace")

    def wait(self) -> None:
        """Until the host serves its page; RuntimeError (with the log's end) if it exits or does not."""
        try:
            wait_served(self.proc, f"http://{self.address}/eha", 180, self.log_text)
        except RuntimeError as exc:
            raise RuntimeError(f"{exc}\n{self.log_text()[-3000:]}") from None

    def wait_for_link(self, timeout: float = 120) -> str:
        """The dashboard's token this host printed (it issues one, or takes the database's, before it serves);
        RuntimeError if it exits or prints none within ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while not (found := _LINK.findall(self.log_text())):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"no dashboard link from {self.address}:\n{self.log_text()[-3000:]}")
            time.sleep(0.1)
        return found[0]

    def links(self) -> list[str]:
        """Every dashboard token the host printed so far."""
        return _LINK.findall(self.log_text())

    def problems(self) -> list[str]:
        """The log's lines of a traceback's start or an ERROR / CRITICAL."""
        lines = self.log_text().splitlines()
        return [ln for ln in lines if ln.startswith("Traceback") or re.search(r"\b(ERROR|CRITICAL)\b", ln)]

    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill(self) -> None:
        """SIGKILL the whole process group: the machine is gone, nothing of it runs a line more."""
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(timeout=30)

    def stop(self) -> None:
        """SIGTERM to the process group, SIGKILL after 20 s; then any child left in the group; the log closed."""
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.kill()
            except ProcessLookupError:
                pass
        try:                # a child left in the group (none expected): by the group's id
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self.log.close()


class Nginx:
    """nginx in front of ``backends`` (``host:port`` each), listening on 127.0.0.1:``listen``, from ``folder``."""

    def __init__(self, folder: Path, listen: int, backends: list[str]):
        from eha_app.runtime.serving import nginx_standalone_config

        folder.mkdir()
        self.folder = folder
        conf = folder / "nginx.conf"
        conf.write_text(nginx_standalone_config(backends, listen=f"127.0.0.1:{listen}", workdir=str(folder)))
        test = subprocess.run([NGINX, "-t", "-c", str(conf), "-p", str(folder)], capture_output=True, text=True)
        if test.returncode != 0:
            raise RuntimeError(f"nginx -t refused {conf}:\n{test.stderr}")
        self.proc = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(folder)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.STDOUT, start_new_session=True)
        self.tree = ProcTree(self.proc.pid)
        self.url = f"http://127.0.0.1:{listen}/eha"

    def error_log(self) -> str:
        path = self.folder / "error.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def errors(self) -> list[str]:
        """The error log's ``[error]`` lines."""
        return [ln for ln in self.error_log().splitlines() if "[error]" in ln]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()           # the master stops its worker
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
