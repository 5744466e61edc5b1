"""A server restart in the middle of a lesson: the page says so, waits, comes back with what was typed."""

from __future__ import annotations

from tests.serve.conftest import EhaServer, free_port
from tests.ui.browser_helpers import text_of, wait_until

# what a page legitimately logs while its server is down
EXPECTED_WHILE_DOWN = ("ERR_CONNECTION_REFUSED", "Lost websocket", "websocket", "WebSocket", "Failed to load resource",
                       "net::ERR")


def test_a_restarted_server_is_announced_and_the_page_comes_back_with_the_students_values(browser, tmp_path):
    port = free_port()
    server = EhaServer(tmp_path, port=port)
    context = browser.new_context(viewport={"width": 1366, "height": 768})
    page = context.new_page()
    console = []
    page.on("console", lambda m: console.append(f"{m.type}: {m.text}") if m.type in ("error", "warning") else None)
    try:
        page.goto(server.url)
        page.wait_for_selector(".eha-field-M input", timeout=60_000)
        page.locator(".eha-field-M input").fill("6000")
        wait_until(lambda: "286.7" in text_of(page, ".eha-derived"), message="l1 for M = 6000")
        page.locator(".bk-header .bk-tab", has_text="2. Simulation").first.click()
        page.wait_for_selector(".eha-sim-info")
        address = page.evaluate("() => location.href")           # (Playwright's page.url can miss a replaceState)
        assert "M=6000" in address and "tab=2" in address          # the address holds what was typed

        server.stop()
        overlay = page.locator(".eha-offline")
        overlay.wait_for(state="visible", timeout=30_000)
        assert "connection to the server was lost" in overlay.inner_text()

        server = EhaServer(tmp_path, port=port)                   # the teacher restarts it
        # the page notices, reloads itself (a new document: no notice), and opens where the student was
        overlay.wait_for(state="detached", timeout=60_000)
        page.wait_for_selector(".eha-sim-info >> text=Case 1, Case 2, Case 3, Case 4", timeout=20_000)
        page.locator(".bk-header .bk-tab", has_text="1. Parameters").first.click()
        page.wait_for_selector(".eha-field-M input")
        assert page.locator(".eha-field-M input").input_value() == "6000"
        wait_until(lambda: "286.7" in text_of(page, ".eha-derived"), message="the restored M in use")
    finally:
        context.close()
        server.stop()
    unexpected = [m for m in console if not any(s in m for s in EXPECTED_WHILE_DOWN)]
    assert not unexpected, unexpected
