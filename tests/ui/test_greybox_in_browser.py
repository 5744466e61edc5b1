"""The grey-box sub-tab in a real browser, at 1366 and 800 px: run, the table and the figure, no
horizontal scroll on the narrow page."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from tests.ui.browser_helpers import text_of

SHOTS = Path(os.environ.get("EHA_SCREENSHOTS", "/work/scratch"))


@pytest.mark.ui
@pytest.mark.parametrize("width", [1366, 800])
def test_the_greybox_subtab_runs_and_shows_its_results(browser, server, width):
    context = browser.new_context(viewport={"width": width, "height": 900})
    page = context.new_page()
    problems = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    try:
        page.goto(server)
        page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
        page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        page.locator(".bk-tab", has_text="Grey-box").first.click()
        page.get_by_role("button", name="Run grey-box estimation").click()
        page.locator(".eha-gb-table").wait_for(state="visible", timeout=120_000)
        page.locator(".eha-gb-plot canvas").first.wait_for(state="visible", timeout=60_000)
        table = text_of(page, ".eha-gb-table-pane")
        for word in ("95 % interval", "covers ✓", "nominal (tab 1)", "Fit of the simulated signals"):
            assert word in table, word
        assert "The three routes side by side" in text_of(page, ".eha-routes-pane")
        assert "Residuals of x" in text_of(page, ".eha-gb-details")
        scroll = page.evaluate("document.documentElement.scrollWidth")
        assert scroll <= width, f"the page scrolls sideways: {scroll} px at {width} px"
        page.locator(".eha-gb-plot").first.scroll_into_view_if_needed()
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / f"greybox_{width}.png"), full_page=True)
        if width == 1366:
            # on the board the estimate is a nonlinear model: simulated on the validation record it fits
            # as the plant does, where eq. 24's linearisation misses the friction
            page.locator(".bk-tab", has_text="Model board").first.click()
            page.locator(".eha-board-fits", has_text="GB1").wait_for(state="visible", timeout=60_000)
            fits = dict(re.findall(r"(GB1|H\(s\) eq\. 24)\s+([\d.]+) %", text_of(page, ".eha-board-fit-table")))
            assert float(fits["GB1"]) > 99 > 95 > float(fits["H(s) eq. 24"]), fits
            page.get_by_text("the nonlinear model, Kp = 10 V/m").first.wait_for(state="visible", timeout=10_000)
        assert not problems, problems
    finally:
        context.close()
