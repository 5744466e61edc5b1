"""The server's job queue: one run per session, sessions in turn, cancellation, failures."""

from __future__ import annotations

import threading
import time

import pytest

from eha_app.runtime.jobs import JobQueue, worker_count

TIMEOUT = 10.0


def wait_for(condition, timeout=TIMEOUT):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.002)


@pytest.fixture
def queue():
    q = JobQueue(workers=1)
    yield q
    q.shutdown()


def gate():
    """A job body that runs until its gate opens (or it is cancelled)."""
    opened = threading.Event()

    def body(token):
        while not opened.wait(0.005):
            token.check()
        return "done"
    return opened, body


def test_one_run_per_session_and_a_new_request_replaces_the_waiting_one(queue):
    ended = []
    open_a, body_a = gate()
    a1, replaced = queue.submit("A", body_a, label="a1", on_done=ended.append)
    assert replaced is None
    wait_for(lambda: a1.state == "running")
    a2, replaced = queue.submit("A", lambda t: "a2", label="a2", on_done=ended.append)
    a3, replaced = queue.submit("A", lambda t: "a3", label="a3", on_done=ended.append)
    assert replaced is a2 and a2.state == "replaced" and a2.token.cancelled
    assert a3.state == "queued"                      # waits behind its own running job
    assert ended == [a2]                             # told at once that it was dropped
    open_a.set()
    wait_for(lambda: a3.finished)
    assert [j.label for j in ended] == ["a2", "a1", "a3"]
    assert a1.result == "done" and a3.result == "a3" and a2.started_at is None


def test_sessions_take_turns(queue):
    order = []
    open_a, body_a = gate()
    a1, _ = queue.submit("A", body_a, label="a1")
    wait_for(lambda: a1.state == "running")
    waiting = {label: queue.submit(owner, lambda t, label=label: order.append(label), label=label)[0]
               for owner, label in (("A", "a2"), ("B", "b1"), ("C", "c1"))}
    # A was just served: B and C, who have had nothing, go first
    assert queue.ahead_of(waiting["a2"]) == 2 and queue.ahead_of(waiting["b1"]) == 0
    open_a.set()
    wait_for(lambda: len(order) == 3)
    assert order == ["b1", "c1", "a2"]


def test_no_session_holds_two_workers_and_all_jobs_finish():
    q = JobQueue(workers=3)
    running: dict[str, int] = {}
    peak = {"total": 0, "per_owner": 0}
    lock = threading.Lock()

    def body(owner):
        def run(token):
            with lock:
                running[owner] = running.get(owner, 0) + 1
                peak["total"] = max(peak["total"], sum(running.values()))
                peak["per_owner"] = max(peak["per_owner"], running[owner])
            time.sleep(0.003)
            with lock:
                running[owner] -= 1
            return owner
        return run

    jobs = []
    try:
        for rnd in range(5):
            for k in range(30):
                owner = f"s{k}"
                job, _ = q.submit(owner, body(owner), label=f"{owner}-{rnd}")
                jobs.append(job)
        wait_for(lambda: all(j.finished for j in jobs))
    finally:
        q.shutdown()
    assert peak["per_owner"] == 1 and peak["total"] <= 3
    done = [j for j in jobs if j.state == "done"]
    replaced = [j for j in jobs if j.state == "replaced"]
    assert len(done) + len(replaced) == len(jobs)
    # every session's last request ran
    last = {j.owner: j for j in jobs}
    assert all(j.state == "done" for j in last.values())


def test_closing_a_session_cancels_its_running_and_waiting_jobs(queue):
    open_a, body_a = gate()
    ended = []
    a1, _ = queue.submit("A", body_a, label="a1", on_done=ended.append)
    wait_for(lambda: a1.state == "running")
    a2, _ = queue.submit("A", lambda t: "never", label="a2", on_done=ended.append)
    t0 = time.perf_counter()
    queue.cancel_owner("A", "the page was closed")
    wait_for(lambda: a1.finished)
    assert time.perf_counter() - t0 < 1.0           # the running job stopped at its next check
    assert a1.state == "cancelled" and a2.state == "cancelled"
    assert a1.token.reason == "the page was closed"
    assert {j.label for j in ended} == {"a1", "a2"}
    b, _ = queue.submit("B", lambda t: 42, label="b")  # the worker is free for the others
    wait_for(lambda: b.finished)
    assert b.result == 42


def test_a_failing_job_is_reported_and_the_worker_goes_on(queue):
    def boom(token):
        raise RuntimeError("integrator exploded")
    bad, _ = queue.submit("A", boom, label="bad")
    good, _ = queue.submit("B", lambda t: "fine", label="good")
    wait_for(lambda: bad.finished and good.finished)
    assert bad.state == "failed" and "integrator exploded" in str(bad.error)
    assert good.state == "done" and good.result == "fine"


def test_worker_count_from_the_environment(monkeypatch):
    monkeypatch.setenv("EHA_WORKERS", "3")
    assert worker_count() == 3
    monkeypatch.setenv("EHA_WORKERS", "0")
    with pytest.raises(ValueError, match="EHA_WORKERS = 0 is not allowed"):
        worker_count()
    monkeypatch.delenv("EHA_WORKERS")
    assert worker_count() >= 1


def test_closing_a_page_cancels_every_runner_of_its_session_and_forgets_them(queue):
    """A session's previews, board and study run under sub-owners: closing the page cancels them all,
    and the queue keeps no reference to the closed session."""
    from eha_app.runtime.tasks import SessionRunner

    root = SessionRunner("student", queue)
    board, study = root.sub("board views"), root.sub("study")
    assert board.owner == ("student", "board views") and study.sub("x").owner == (("student", "study"), "x")
    gate = threading.Event()
    running, _ = queue.submit(root.owner, lambda tok: gate.wait(TIMEOUT), label="experiment")
    waiting, _ = queue.submit(board.owner, lambda tok: 1, label="board")
    waiting2, _ = queue.submit(study.owner, lambda tok: 2, label="study")
    wait_for(lambda: running.state == "running")
    jobs = board.cancel_all("the page was closed")           # from any runner of the session
    gate.set()
    assert {j.label for j in jobs} == {"experiment", "board", "study"}
    wait_for(lambda: running.finished)
    assert waiting.state == waiting2.state == "cancelled"
    owners = {root.owner, board.owner, study.owner, ("student", "study"), ("student", "study"), "x"}
    assert not any(owners & set(served) for served in queue._last_served.values())
    assert not owners & set(queue._queued)


def test_a_sessions_runners_share_its_one_place_in_the_queue():
    """A study, a board job and a tab's run of one session take turns in that session's one place: with two
    workers, the session's second job waits for another session's, not beside its own first."""
    q = JobQueue(workers=2)
    order = []
    try:
        open_study, study = gate()
        s1, _ = q.submit(("A", "study"), study, label="a-study", place="A")
        wait_for(lambda: s1.state == "running")
        open_b, body_b = gate()
        a_run, _ = q.submit("A", lambda t: order.append("a-run"), label="a-run", place="A")
        b_run, _ = q.submit("B", lambda t: (order.append("b-run"), body_b(t)), label="b-run", place="B")
        wait_for(lambda: b_run.state == "running")
        time.sleep(0.05)
        assert a_run.state == "queued"              # a free worker, but A's place is taken by its study
        assert q.ahead_of(a_run) == 0
        open_study.set()
        wait_for(lambda: a_run.finished)
        open_b.set()
        wait_for(lambda: b_run.finished)
        assert order == ["b-run", "a-run"]
        # the session's study, asking again, goes behind a session that waits
        open_study2, study2 = gate()
        s2, _ = q.submit(("A", "study"), study2, label="a-study-2", place="A")
        c_run, _ = q.submit("C", lambda t: order.append("c-run"), label="c-run", place="C")
        wait_for(lambda: c_run.finished and s2.state == "running")
        open_study2.set()
        wait_for(lambda: s2.finished)
    finally:
        q.shutdown()


def test_background_work_runs_beside_the_workers_and_the_sessions_places(queue):
    """A study's part holds no worker and no turn: with one worker busy, another session's request
    and the study's own session's request wait for the worker only, never for the part."""
    open_a, body_a = gate()
    a, _ = queue.submit("A", body_a, label="a")
    wait_for(lambda: a.state == "running")
    open_s, body_s = gate()
    part, _ = queue.submit(("S", "study"), body_s, label="part", place="S", background=True)
    wait_for(lambda: part.state == "running")           # the worker is A's: the part runs anyway
    order = []
    s_run, _ = queue.submit("S", lambda t: order.append("s"), label="s-run", place="S")
    b_run, _ = queue.submit("B", lambda t: order.append("b"), label="b-run")
    assert queue.ahead_of(s_run) == 0 and queue.ahead_of(b_run) == 1 and queue.ahead_of(part) == 0
    open_a.set()
    wait_for(lambda: s_run.finished and b_run.finished)
    assert order == ["s", "b"] and part.state == "running"    # S's study did not cost S its turn
    open_s.set()
    wait_for(lambda: part.finished)
    assert part.state == "done" and queue.snapshot()["running"] == 0


def test_studies_take_turns_on_the_background_thread(queue):
    """One background part at a time; the session served least recently goes first, whatever waits
    longest."""
    order = []
    open_1, body_1 = gate()
    first, _ = queue.submit(("S", "study"), lambda t: (order.append("s1"), body_1(t)), label="s1", place="S",
                            background=True)
    wait_for(lambda: first.state == "running")
    s2, _ = queue.submit(("S", "study"), lambda t: order.append("s2"), label="s2", place="S", background=True)
    t1, _ = queue.submit(("T", "study"), lambda t: order.append("t1"), label="t1", place="T", background=True)
    assert queue.ahead_of(t1) == 0 and queue.ahead_of(s2) == 1
    time.sleep(0.05)
    assert s2.state == t1.state == "queued"
    open_1.set()
    wait_for(lambda: s2.finished and t1.finished)
    assert order == ["s1", "t1", "s2"]
