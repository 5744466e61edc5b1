"""Many students on one server at once: every step succeeds, nobody waits on anybody's clicks."""

from __future__ import annotations

import asyncio
import time

from benchmarks.classroom_client import STEPS, Student, run_students


def test_a_class_runs_every_step_at_once_without_an_error(serve):
    server = serve()
    result = run_students(server.url, 8, STEPS, observer=True, spread=0.5, timeout=120)
    for step in STEPS:
        assert result.ok(step) == 8, (step, result.errors(step)[:3])
    assert result.error_count() == 0
    assert all(o.error is None for o in result.observer)
    log = server.log_text()
    assert "Traceback" not in log and "ERROR" not in log, log[-3000:]
    # the teacher is told what is happening, then that the app is ready
    assert "Preparing the simulation kernels" in log and f"Ready: http://127.0.0.1:{server.port}/eha" in log


def test_clicking_the_experiment_four_times_and_many_experiments_at_once(serve):
    """Concurrent experiments once broke the server for everyone (a blank page for new students)."""
    server = serve()

    async def scenario():
        students = [Student(server.url, name=f"s{i}", timeout=120) for i in range(6)]
        await asyncio.gather(*(s.open() for s in students))
        await asyncio.gather(*(s.show_frequency() for s in students))
        eager = students[0]
        # one student clicks four times in a row; the others once, all at the same moment
        button = eager.button("Run experiment and estimate")
        for _ in range(3):
            await eager.click(button)
        seconds = await asyncio.gather(*(s.frequency_experiment() for s in students))
        summaries = [s.pane("eha-freq-summary").text() for s in students]
        # a new student still gets a whole page afterwards
        late = Student(server.url, name="late", timeout=120)
        await late.open()
        await late.show_frequency()
        late_seconds = await late.frequency_experiment()
        notes = eager.pane("eha-queue-note").text() if eager.find(css="eha-queue-note") else ""
        for s in [*students, late]:
            await s.close()
        return seconds, summaries, late_seconds, notes

    seconds, summaries, late_seconds, _ = asyncio.run(scenario())
    assert all("Ĥ(s)" in text and "failed" not in text for text in summaries)
    assert late_seconds > 0
    log = server.log_text()
    assert "Traceback" not in log, log[-3000:]
    assert "has no attribute 'update'" not in log


async def _ask_for_a_long_run(server, name: str) -> Student:
    """A student who opens the page and asks for a frequency experiment of N × Ts = 20000 × 0.5 s."""
    s = Student(server.url, name=name, timeout=60)
    await s.open()
    await s.show_frequency()
    form = s.form("eha-freq-form")
    await s.set_property(form, "values", {**form.get("values"), "n_samples": "20000", "ts": "0.5"})
    await s.click(s.button("Run experiment and estimate"))
    return s


def test_a_request_beyond_the_limits_gets_a_message_not_a_run(serve):
    server = serve()

    async def scenario():
        s = await _ask_for_a_long_run(server, "heavy")
        alert = s.pane("eha-freq-alert")
        text = await s.wait_for(lambda: alert.get("visible") and alert.text(), 30, "the limit's message")
        await s.close()
        return text

    text = asyncio.run(scenario())
    assert "N × Ts = 20000 × 0.5 s is not allowed here" in text and "lower N or Ts" in text


def test_a_page_closed_while_its_run_computes_holds_up_nobody(serve, monkeypatch):
    monkeypatch.setenv("EHA_MAX_STEPS", "50000000")      # a run of about 10 s, for the test
    server = serve()

    async def scenario():
        leaver = await _ask_for_a_long_run(server, "leaver")
        await asyncio.sleep(0.2)
        await leaver.close()                          # the tab is closed mid-run
        stayer = Student(server.url, name="stayer", timeout=60)
        await stayer.open()
        seconds = [await stayer.show_simulation(), await stayer.compare_both()]
        await asyncio.sleep(8)                        # the closed session is discarded meanwhile
        late = Student(server.url, name="late", timeout=60)
        await late.open()
        seconds += [await late.show_simulation(), await late.compare_both()]
        await stayer.close()
        await late.close()
        return seconds

    seconds = asyncio.run(scenario())
    assert all(s < 30 for s in seconds)
    log = server.log_text()
    assert "Traceback" not in log
    # the closed page's experiment (2 x 10000 s of closed loop) was stopped, not finished for nobody
    assert "a page was closed: cancelled frequency experiment" in log


def test_a_closed_pages_run_is_cancelled_when_its_websocket_closes(serve, monkeypatch):
    """Not when Panel discards the session (eha serve: 4 s unused, checked every 1 s): the closed page's run
    is cancelled from the websocket's close. The bound is the session's lifetime, the property the order."""
    monkeypatch.setenv("EHA_MAX_STEPS", "50000000")      # a run of about 10 s, for the test
    server = serve()

    async def scenario():
        leaver = await _ask_for_a_long_run(server, "leaver")
        await asyncio.sleep(0.3)
        await leaver.close()
        t0 = time.perf_counter()
        while "a page was closed: cancelled frequency experiment" not in server.log_text():
            if time.perf_counter() - t0 > 3.5:
                return None
            await asyncio.sleep(0.05)
        return time.perf_counter() - t0

    after = asyncio.run(scenario())
    assert after is not None, "the run was cancelled only when the session was discarded, or not at all"
    assert "Traceback" not in server.log_text()
