"""Long work in the server's child process: the same results, at the lowest priority, progress and
cancel across, a dead child replaced, nothing left behind when the server goes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

from eha_app.runtime.background import CHILD_NICE, BackgroundProcess
from eha_core.cancel import Cancelled, CancelToken
from eha_core.errors import ComputationError
from eha_core.study import StudyConfig, run_study


@pytest.fixture(scope="module")
def child():
    bp = BackgroundProcess()
    yield bp
    bp.shutdown()


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


def _gone(pid: int, within_s: float = 10.0) -> bool:
    """Whether process ``pid`` has ended, waiting up to ``within_s``."""
    deadline = time.monotonic() + within_s
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not _alive(pid)


def _start_server(tmp_path, body: str) -> tuple[subprocess.Popen, int]:
    """A script standing for a server: it starts a child for long work, prints the child's pid, then
    does ``body`` (indented code, ``bp`` the BackgroundProcess); returns the script's process and that pid."""
    script = textwrap.dedent("""
        import os, sys, threading, time
        from eha_app.runtime.background import BackgroundProcess
        if __name__ == "__main__":
            bp = BackgroundProcess()
            print(bp.call(os.getpid), flush=True)
    """) + textwrap.indent(textwrap.dedent(body), " " * 4)
    path = tmp_path / "server.py"
    path.write_text(script)
    server = subprocess.Popen([sys.executable, str(path)], stdout=subprocess.PIPE, text=True)
    return server, int(server.stdout.readline())


def _raise_unpicklable():
    class Local(Exception):     # a class defined in a function does not cross processes
        pass
    raise Local("the words still do")


def _sleep_cancellable(seconds, cancel=None):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        cancel.check()
        time.sleep(0.005)
    return "slept"


def test_a_study_in_the_child_is_the_studys_own_at_the_lowest_priority(child):
    cfg = StudyConfig("lse", n_seeds=12, disturbance="white:1000")
    seen = []
    res = child.call(run_study, cfg, workers=1, progress=lambda d, t: seen.append((d, t)), total=12,
                     cancel=CancelToken())
    direct = run_study(cfg, workers=1)
    assert child.pid != os.getpid() and _alive(child.pid)
    assert os.sched_getscheduler(child.pid) == os.SCHED_IDLE
    with open(f"/proc/{child.pid}/stat") as f:
        assert int(f.read().rsplit(")", 1)[1].split()[16]) == CHILD_NICE     # field 19: nice
    for name in res.parameters:
        np.testing.assert_allclose(res.values(name), direct.values(name), rtol=1e-12)
        assert res.coverage[name] == direct.coverage[name]
    done = [d for d, _ in seen]
    assert done == sorted(done) and done[-1] == 12 and all(t == 12 for _, t in seen)


def test_a_cancel_crosses_to_the_child_and_keeps_the_seeds_done(child):
    # the child compiles the simulator's kernels on its first seeds (seconds on a fresh clone, whose numba
    # cache is empty): warmed first, so that the cancel falls among seeds, not in the compiler
    child.call(run_study, StudyConfig("lse", n_seeds=2), workers=1)
    token = CancelToken()
    threading.Timer(0.3, token.cancel, args=("the page was closed",)).start()
    res = child.call(run_study, StudyConfig("lse", n_seeds=1000), workers=1, cancel=token)
    assert res.cancelled and 0 < res.n_completed < 1000
    # a function that stops by raising: Cancelled in the server, with the token's reason
    token = CancelToken()
    threading.Timer(0.2, token.cancel, args=("replaced",)).start()
    with pytest.raises(Cancelled, match="replaced"):
        child.call(_sleep_cancellable, 30.0, cancel=token)
    # the next call starts clean
    assert child.call(_sleep_cancellable, 0.01, cancel=CancelToken()) == "slept"


def _count_for(seconds, cancel=None, progress=None):
    """Checks its token and counts, for ``seconds`` of wall time."""
    n, end = 0, time.monotonic() + seconds
    while time.monotonic() < end:
        cancel.check()
        n += 1
        if n % 1000 == 0:
            progress(n, 0)
    return n


def _begun_at(cancel=None, progress=None):
    return time.time()


def test_the_child_waits_while_the_server_asks_it_to_give_way(child):
    # a call asked to give way from the start does not begin until the class is done
    t0 = time.time()
    begun = child.call(_begun_at, cancel=CancelToken(), progress=lambda d, t: None,
                       give_way=lambda: time.time() < t0 + 0.5)
    assert begun >= t0 + 0.45
    t1 = time.time()
    assert child.call(_begun_at, cancel=CancelToken(), give_way=lambda: False) - t1 < 0.3    # at once
    free = child.call(_count_for, 0.6, cancel=CancelToken(), progress=lambda d, t: None,
                      give_way=lambda: False)
    held = child.call(_count_for, 0.6, cancel=CancelToken(), progress=lambda d, t: None,
                      give_way=lambda: True)
    # not begun for MAX_PAUSE_S, then MIN_RUN_S (0.1 s) of its 0.6 s computing, then waiting again
    assert free > 10_000 and held < free / 4
    # a server busy without a break: after MAX_PAUSE_S the child still goes on, a little at a time
    from eha_app.runtime.background import MAX_PAUSE_S

    long = child.call(_count_for, MAX_PAUSE_S + 1.0, cancel=CancelToken(), progress=lambda d, t: None,
                      give_way=lambda: True)
    assert long > held
    # a cancel reaches a child that is giving way (else: 30 s of counting, and no Cancelled)
    token = CancelToken()
    threading.Timer(0.2, token.cancel, args=("closed",)).start()
    with pytest.raises(Cancelled):
        child.call(_count_for, 30.0, cancel=token, progress=lambda d, t: None, give_way=lambda: True)


def test_failures_come_back_as_themselves_or_in_words(child):
    with pytest.raises(ValueError, match="invalid literal"):
        child.call(int, "x")
    with pytest.raises(ComputationError, match="Local: the words still do"):
        child.call(_raise_unpicklable)
    assert child.call(int, "7") == 7


def test_a_child_that_died_is_replaced():
    bp = BackgroundProcess()
    try:
        first = bp.call(os.getpid)
        os.kill(first, signal.SIGKILL)
        # between calls: replaced before the next one, which works
        assert bp.call(os.getpid) not in (first, os.getpid())
        # during a call: that call fails, saying so; the next works
        threading.Timer(0.3, os.kill, args=(bp.pid, signal.SIGKILL)).start()
        with pytest.raises(ComputationError, match="stopped during this run"):
            bp.call(time.sleep, 30)
        assert bp.call(int, "3") == 3 and bp.restarts == 2
    finally:
        bp.shutdown()


def test_an_idle_child_is_stopped_and_started_again_when_needed():
    bp = BackgroundProcess(idle_s=0.4)
    try:
        pid = bp.call(os.getpid)
        assert _gone(pid) and bp.pid is None
        assert bp.call(os.getpid) not in (pid, os.getpid())
    finally:
        bp.shutdown()


def test_a_server_that_exits_stops_its_child_at_once(tmp_path):
    """Without a stop of its own the pool's exit hook would wait for the call in flight (60 s here)."""
    server, pid = _start_server(tmp_path, """
        threading.Thread(target=bp.call, args=(time.sleep, 60), daemon=True).start()
        time.sleep(0.5)
        sys.exit(0)
    """)
    try:
        assert server.wait(30) == 0
        assert _gone(pid)
    finally:
        server.kill()


def test_the_child_goes_when_its_server_is_killed(tmp_path):
    server, pid = _start_server(tmp_path, "time.sleep(60)")
    try:
        assert _alive(pid)
        server.kill()
        server.wait(10)
        assert _gone(pid)
    finally:
        server.kill()


def test_without_a_child_the_work_is_done_in_the_callers_thread(monkeypatch, caplog):
    bp = BackgroundProcess()

    def cannot(self, cancel=None):
        raise OSError("Resource temporarily unavailable")

    monkeypatch.setattr(BackgroundProcess, "_ensure", cannot)
    seen = []
    res = bp.call(run_study, StudyConfig("lse", n_seeds=3), workers=1, progress=lambda d, t: seen.append((d, t)),
                  total=3, cancel=CancelToken())
    assert res.n_completed == 3 and bp.without_child and bp.pid is None
    assert seen[-1] == (3, 3)
    assert "no process for long computations could start" in caplog.text
    # a cancel reaches the work done here too (else: 1000 seeds)
    token = CancelToken()
    threading.Timer(0.3, token.cancel, args=("the page was closed",)).start()
    res = bp.call(run_study, StudyConfig("lse", n_seeds=1000), workers=1, cancel=token)
    assert res.cancelled and 0 < res.n_completed < 1000 and bp.without_child
