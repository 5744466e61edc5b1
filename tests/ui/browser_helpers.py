"""Helpers of the browser tests (imported by conftest.py and the tests)."""

from __future__ import annotations

import os
import shutil
import socket
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]
# Chromium's own chatter, not the page's
IGNORED_CONSOLE = ("GL Driver Message", "GPU stall")


def _chromium() -> str:
    path = os.environ.get("EHA_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
    if not Path(path).exists():
        pytest.skip("headless Chromium not found: install Debian's chromium (apt-get install -y chromium) "
                    "or set EHA_CHROMIUM; the README's test command installs it")
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(condition, timeout: float = 30.0, interval: float = 0.05, message: str = "condition"):
    """Poll ``condition`` until it is truthy (returns it) or fail after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {message}")
        time.sleep(interval)


JS_TEXT = """el => {
  const root = el.shadowRoot || el;
  const kids = Array.from(root.children).filter(c => !['STYLE', 'LINK'].includes(c.tagName));
  return kids.length ? kids.map(c => c.innerText).join('\\n') : el.innerText;
}"""


def text_of(page, selector: str) -> str:
    """Rendered text of a Panel component (its content lives in a shadow root)."""
    loc = page.locator(selector)
    return loc.first.evaluate(JS_TEXT) if loc.count() else ""


class Session:
    """One student's browser session, with the console messages it produced."""

    def __init__(self, browser, url):
        self.context = browser.new_context(viewport={"width": 1366, "height": 768})
        self.page = self.context.new_page()
        self.console: list[str] = []
        self.page.on("console", self._console)
        self.page.on("pageerror", lambda e: self.console.append(f"pageerror: {e}"))
        self.page.on("requestfailed", lambda r: self.console.append(f"request failed: {r.url}"))
        self.page.goto(url)
        self.page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)

    def _console(self, msg):
        if msg.type in ("error", "warning") and not any(s in msg.text for s in IGNORED_CONSOLE):
            self.console.append(f"{msg.type}: {msg.text}")

    def tab(self, name: str):
        # Bokeh's tab headers carry no ARIA role: find them by their text
        self.tab_header(name).click()

    def tab_header(self, name: str):
        return self.page.locator(".bk-header .bk-tab", has_text=name).first

    def close(self):
        self.context.close()
