"""The Content-Security-Policy in Chromium: the app works under it with no violation, through the three
tabs, every sub-tab and a run in each route, and the teacher's dashboard too; no other website can frame
the app (``frame-ancestors 'none'``).

A violation is caught as the page's ``securitypolicyviolation`` events (they cross shadow roots: BokehJS
draws inside them) and as the console's report of one.
"""

from __future__ import annotations

import http.server
import os
import threading
from pathlib import Path

import pytest

from tests.ui.browser_helpers import text_of, wait_until

pytestmark = pytest.mark.ui

#: Recorded from the first script on: each violation's directive, what was blocked and where.
RECORD_VIOLATIONS = """
window.__eha_csp = [];
document.addEventListener('securitypolicyviolation', (e) => {
  window.__eha_csp.push(`${e.effectiveDirective} blocked ${e.blockedURI} at ${e.sourceFile}:${e.lineNumber}`);
}, true);
"""


def _watched_page(browser, width: int = 1366, height: int = 768):
    """A new page recording CSP violations, its errors and the console's reports of violations."""
    context = browser.new_context(viewport={"width": width, "height": height})
    page = context.new_page()
    page.add_init_script(RECORD_VIOLATIONS)
    problems: list[str] = []
    page.on("console", lambda m: problems.append(f"{m.type}: {m.text}")
            if m.type == "error" or "Content Security Policy" in m.text else None)
    page.on("pageerror", lambda e: problems.append(f"pageerror: {e}"))
    return context, page, problems


def _violations(page) -> list[str]:
    return page.evaluate("window.__eha_csp")


def _show(page, name: str, within: str = "") -> None:
    """Click the tab ``name`` (of the tabs ``within`` a css class, when another tab has the same word, as the
    frequency panel's "Fig. 12 Bode" and the board's "Bode") and wait until it is the one shown."""
    tabs = f"{within} .bk-tab".strip()
    page.locator(tabs, has_text=name).first.click()
    page.locator(f"{tabs}.bk-active", has_text=name).first.wait_for(timeout=30_000)


def test_the_app_works_under_its_policy_without_a_violation(browser, server, tmp_path):
    context, page, problems = _watched_page(browser)
    try:
        page.goto(server)
        page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
        # tab 1: a parameter typed moves a derived value (the page's websocket works)
        page.locator(".eha-field-M input").fill("8000")
        wait_until(lambda: "215" in text_of(page, ".eha-derived"), message="l1 = 215 after M = 8000")
        page.get_by_role("button", name="Reset to paper defaults").click()
        wait_until(lambda: "430.1" in text_of(page, ".eha-derived"), message="the defaults back")
        # tab 2: a simulation
        _show(page, "2. Simulation")
        page.get_by_role("button", name="Case 3", exact=True).click()
        page.wait_for_selector(".eha-sim-info >> text=Case 3", timeout=60_000)
        page.locator("canvas").first.wait_for(state="visible", timeout=60_000)
        # tab 3: least squares and the grey-box estimate, then every sub-tab (the board's included)
        _show(page, "3. Identification")
        page.get_by_role("button", name="Run least squares").click()
        page.locator(".eha-lse-table table").wait_for(state="visible", timeout=60_000)
        _show(page, "Grey-box")
        page.get_by_role("button", name="Run grey-box estimation").click()
        page.locator(".eha-gb-table").wait_for(state="visible", timeout=120_000)
        page.locator(".eha-gb-plot canvas").first.wait_for(state="visible", timeout=60_000)
        shots = Path(os.environ.get("EHA_SCREENSHOTS") or tmp_path)
        shots.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(shots / "csp_greybox_1366x768.png"))
        for name in ("Frequency domain", "Study over seeds", "Model board"):
            _show(page, name)
        for name in ("Bode", "Step response", "Poles and zeros", "Fit on validation data"):    # the board's
            _show(page, name, within=".eha-board-views")
        _show(page, "1. Parameters")
        page.get_by_text("Load, friction, cylinder").first.wait_for(timeout=30_000)
        page.screenshot(path=str(shots / "csp_1366x768.png"))
        assert _violations(page) == [], _violations(page)
        assert not problems, problems
    finally:
        context.close()


class _OtherWebsite(http.server.BaseHTTPRequestHandler):
    """Another origin (another port): ``/`` frames the app (``?app=...``), ``/plain`` is a page that may be
    framed (the control: a frame from here shows)."""

    app = ""

    def do_GET(self):
        if self.path == "/plain":
            body = b"<p id='plain'>a page anyone may frame</p>"
        else:
            body = (f"<iframe id='app' src='{self.app}' width='800' height='600'></iframe>"
                    "<iframe id='plain' src='/plain' width='300' height='100'></iframe>").encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@pytest.fixture
def other_website(server):
    handler = type("Framing", (_OtherWebsite,), {"app": server})
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}/"
    httpd.shutdown()
    httpd.server_close()


def test_no_other_website_can_frame_the_app(browser, server, other_website):
    # (a data: page is no test of this: Chromium lets no page of an opaque origin frame a local
    # address at all, the control below included)
    context = browser.new_context(viewport={"width": 1366, "height": 768})
    page = context.new_page()
    try:
        with page.expect_console_message(lambda m: "frame-ancestors" in m.text, timeout=60_000) as refusal:
            page.goto(other_website)
        assert "frame-ancestors 'none'" in refusal.value.text, refusal.value.text
        # the control: the other website's own page, which allows framing, is drawn in its frame
        page.frame_locator("#plain").locator("#plain").wait_for(timeout=30_000)
        # the app's frame holds Chromium's error page, not the app
        app = page.locator("#app").element_handle().content_frame()
        assert app is not None and "/eha" not in app.url, app.url if app else None
        assert page.frame_locator("#app").get_by_text("Reset to paper defaults").count() == 0
    finally:
        context.close()


def test_the_teachers_dashboard_works_under_its_policy_without_a_violation(browser, tmp_path):
    from eha_core.exercise import Exercise
    from tests.serve.conftest import EhaServer, dashboard_token

    path = tmp_path / "class.json"
    Exercise.new(hide=("M", "B"), title="Lab 3", roster=[("s1", "Ada Lovelace")]).save(path)
    server = EhaServer(tmp_path, "--exercise", str(path), "--workers", "1")
    context, page, problems = _watched_page(browser)
    try:
        page.goto(f"http://127.0.0.1:{server.port}/teacher?token={dashboard_token(path)}")
        page.locator(".eha-dash-roster").get_by_text("Ada Lovelace").wait_for(timeout=60_000)
        assert _violations(page) == [], _violations(page)
        assert not problems, problems
    finally:
        context.close()
        server.stop()
