"""The report opens offline in Chromium, its figures render, nothing fails to load."""

import pytest

from eha_app.render.report import build_report
from tests.ui.browser_helpers import IGNORED_CONSOLE


@pytest.fixture(scope="module")
def report_path(tmp_path_factory):
    out = tmp_path_factory.mktemp("report_ui")
    with open(out / "progress.txt", "w") as progress:
        return build_report(out, stream=progress).path


def test_report_renders_offline(browser, report_path, tmp_path):
    problems = []
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    page.on("console", lambda m: problems.append(m.text)
            if m.type == "error" and not any(s in m.text for s in IGNORED_CONSOLE) else None)
    page.on("requestfailed", lambda r: problems.append(f"request failed: {r.url}"))
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(report_path.as_uri())
    page.wait_for_function("() => window.Bokeh && Bokeh.index && Object.keys(Bokeh.index).length >= 12",
                           timeout=60_000)
    page.screenshot(path=str(tmp_path / "report_first_screen.png"))
    page.evaluate("document.getElementById('figs8-13').scrollIntoView()")
    page.screenshot(path=str(tmp_path / "report_figs8-13.png"))
    context.close()
    assert not problems, problems
