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


# -- accessibility: axe-core (installed from tests/ui/package-lock.json) ------------------------------

AXE_JS = Path(__file__).with_name("node_modules") / "axe-core" / "axe.min.js"
AXE_INSTALL = "npm ci --prefix tests/ui"
#: WCAG 2.0 and 2.1, levels A and AA, as axe-core tags its rules
WCAG_AA_TAGS = ("wcag2a", "wcag2aa", "wcag21a", "wcag21aa")


def axe_path() -> Path:
    """axe-core's script, or the test is skipped saying how to install it."""
    if not AXE_JS.exists():
        pytest.skip(f"axe-core is not installed: run `{AXE_INSTALL}` (tests/ui/package.json pins its version; the "
                    "README's test command runs it)")
    return AXE_JS


JS_AXE = """async (tags) => {
  const r = await axe.run(document, {runOnly: {type: 'tag', values: tags}});
  // a node inside a shadow root is named by a path of selectors, one per shadow root (Bokeh draws
  // every widget into one)
  const deep = (n) => n.target.some((t) => Array.isArray(t));
  const last = (n) => { const t = n.target[n.target.length - 1]; return Array.isArray(t) ? t[t.length - 1] : t; };
  const nodes = [...r.passes, ...r.violations, ...r.incomplete].flatMap((rule) => rule.nodes);
  return {
    violations: r.violations.map((v) => ({id: v.id, impact: v.impact, help: v.help,
      nodes: v.nodes.map((n) => ({target: JSON.stringify(n.target), html: n.html.slice(0, 300),
                                  summary: n.failureSummary}))})),
    checked: nodes.length,
    in_shadow: nodes.filter(deep).length,
    // the form controls axe-core found named (rule "label"), by the last selector of their path
    labelled: (r.passes.find((p) => p.id === 'label') || {nodes: []}).nodes.filter(deep).map(last),
    version: axe.version,
  };
}"""


def axe_check(page) -> dict:
    """axe-core's WCAG 2.1 AA rules (:data:`WCAG_AA_TAGS`) on ``page`` as it is shown now: its
    ``violations`` (rule, impact, nodes), how many nodes it ``checked`` and how many of those are
    ``in_shadow`` roots, the form controls it found ``labelled``."""
    if not page.evaluate("typeof axe !== 'undefined'"):
        page.add_script_tag(path=str(axe_path()))
    return page.evaluate(JS_AXE, list(WCAG_AA_TAGS))


def violations_text(result: dict) -> str:
    """axe-core's violations, one line per node: rule (impact), where, what to fix."""
    lines = []
    for v in result["violations"]:
        for n in v["nodes"]:
            lines.append(f"{v['id']} ({v['impact']}): {n['target']}\n    {n['html'][:160]}\n    "
                         + " ".join(n["summary"].split())[:300])
    return "\n".join(lines)
