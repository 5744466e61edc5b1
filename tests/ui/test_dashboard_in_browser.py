"""The teacher's dashboard in Chromium: the link with the token opens it (and leaves the address bar),
the class shows, a hand-in appears without a reload, the switches write the store."""

from __future__ import annotations

from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise
from tests.serve.conftest import EhaServer, dashboard_token
from tests.ui.browser_helpers import wait_until


def test_the_dashboard_follows_the_class_without_a_reload(browser, tmp_path):
    ex = Exercise.new(hide=("M", "B"), title="Lab 3", deadline="2099-01-01T12:00",
                      roster=[("s1", "Ada Lovelace"), ("s2", "<b>Alan</b> Turing")])
    path = tmp_path / "class.json"
    ex.save(path)
    store = HandIns(path).check()
    server = EhaServer(tmp_path, "--exercise", str(path), "--workers", "1")
    context = browser.new_context(viewport={"width": 1366, "height": 768})
    page = context.new_page()
    problems = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    try:
        page.goto(f"http://127.0.0.1:{server.port}/teacher?token={dashboard_token(path)}")
        assert page.url.endswith("/teacher"), page.url              # the token left the address bar
        roster = page.locator(".eha-dash-roster")
        roster.get_by_text("Ada Lovelace").wait_for(timeout=60_000)
        assert roster.get_by_text("<b>Alan</b> Turing").count() == 1  # shown as typed, not as markup
        # a hand-in stored by a student's page (here: directly) appears within a poll or two
        truth = ex.student_params("s1")
        est = {"M": truth.M * 1.03, "B": truth.B * 1.2}
        store.seen("s1")
        store.add("s1", est, ex.verdicts("s1", est), errors=ex.errors("s1", est))
        page.locator(".eha-dash-roster", has_text="+20.00 %").wait_for(timeout=15_000)
        page.locator(".eha-dash-history", has_text="+3.00 %").wait_for(timeout=5_000)
        # the switches
        page.get_by_role("button", name="Close hand-ins").click()
        wait_until(lambda: store.control().get("open") == "0", timeout=15, message="hand-ins closed")
        page.get_by_role("button", name="Open hand-ins").wait_for(timeout=10_000)
        page.locator(".eha-dash-deadline input").fill("next friday")
        page.get_by_role("button", name="Set the deadline").click()
        page.locator(".eha-error-deadline", has_text="is not allowed").wait_for(timeout=10_000)
        page.get_by_role("button", name="Reveal the verdicts to the students").click()
        page.locator(".eha-dash-reveal-message", has_text="has not passed").wait_for(timeout=10_000)
        assert "revealed" not in store.control() and "deadline" not in store.control()
        with page.expect_download(timeout=30_000) as download:
            page.get_by_role("button", name="Download the results (CSV)").click()
        assert "Ada Lovelace" in open(download.value.path(), encoding="utf-8").read()
        assert "Traceback" not in server.log_text()
    finally:
        context.close()
        server.stop()
    assert not problems, problems
