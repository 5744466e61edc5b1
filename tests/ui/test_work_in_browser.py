"""A student's work survives a reload and a restart of the server: they type their id again and
find their settings and their least-squares table as they left them."""

from __future__ import annotations

import re

from eha_app.runtime.handins import HandIns
from eha_app.runtime.work_store import WorkStore
from tests.serve.conftest import EhaServer, free_port
from tests.ui.browser_helpers import text_of, wait_until
from tests.ui.test_exercise_in_browser import make_exercise, student_session


def lse_table(page) -> str:
    """The least-squares table's numbers, without the line that says how long the run took."""
    page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
    return re.sub(r"Simulated, identified.*", "", text_of(page, ".eha-lse-table"), flags=re.S).strip()


def open_least_squares(page) -> None:
    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
    page.locator(".eha-field-lse_seed input").first.wait_for(state="visible", timeout=60_000)


def test_a_reload_and_a_restart_give_the_student_their_work_back(browser, tmp_path):
    _, path = make_exercise(tmp_path)
    port = free_port()
    server = EhaServer(tmp_path, "--exercise", path, port=port)
    context, page = student_session(browser, server.url, "s7")
    try:
        open_least_squares(page)
        seed = page.locator(".eha-field-lse_seed input").first
        seed.fill("4")
        seed.press("Tab")
        page.get_by_role("button", name="Run least squares").click()
        table = lse_table(page)
        assert "hidden" in table
        store = WorkStore(HandIns(path))
        # saved a couple of seconds after the run, off the page
        wait_until(lambda: (w := store.load("s7")) is not None and "lse" in w.runs.get("least_squares", {}).get(
            "views", ()), timeout=30, message="the work saved")

        page.reload()                                   # the gate again: the same id gives it all back
        page.wait_for_selector(".eha-student-id input", timeout=60_000)
        page.locator(".eha-student-id input").fill("s7")
        page.get_by_role("button", name="Start").click()
        page.wait_for_selector(".eha-work-restored >> text=results of Least squares", timeout=90_000)
        open_least_squares(page)
        assert page.locator(".eha-field-lse_seed input").first.input_value() == "4"
        assert lse_table(page) == table
        context.close()

        server.stop()
        server = EhaServer(tmp_path, "--exercise", path, port=port)        # the teacher restarts it
        context, page = student_session(browser, server.url, "s7")
        page.wait_for_selector(".eha-work-restored >> text=results of Least squares", timeout=90_000)
        open_least_squares(page)
        assert lse_table(page) == table
        assert "Traceback" not in server.log_text()
    finally:
        context.close()
        server.stop()
