"""Several real browsers on one server at once: every page works, no console error.

With ten browser sessions the page used to log "n is not iterable" errors;
each session here goes through the whole lab at the same time as the others.
"""

from __future__ import annotations

import asyncio
import threading

from tests.ui.browser_helpers import CHROMIUM_ARGS, IGNORED_CONSOLE, _chromium

SESSIONS = 6

JS_RESIDUALS_DRAWN = """() => {
  for (const m of window.Bokeh.documents[0].all_models) {
    if (m.title && m.title.text && m.title.text.startsWith('Residual autocorrelation')) {
      for (const r of m.renderers) {
        if (r.data_source && r.data_source.data.lag && r.data_source.data.lag.length > 0) return true;
      }
    }
  }
  return false;
}"""


async def _student(browser, url: str, i: int, problems: list) -> None:
    context = await browser.new_context(viewport={"width": 1366, "height": 768})
    page = await context.new_page()
    page.on("console", lambda m: problems.append(f"{i} {m.type}: {m.text}")
            if m.type in ("error", "warning") and not any(s in m.text for s in IGNORED_CONSOLE) else None)
    page.on("pageerror", lambda e: problems.append(f"{i} pageerror: {e}"))
    page.on("requestfailed", lambda r: problems.append(f"{i} request failed: {r.url}"))
    try:
        await page.goto(url)
        await page.wait_for_selector(".eha-field-M input", timeout=90_000)
        await page.locator(".eha-field-M input").fill(str(4000 + 500 * i))
        await page.locator(".bk-header .bk-tab", has_text="2. Simulation").first.click()
        await page.wait_for_selector(".eha-run-count >> text=run 1", timeout=90_000)
        await page.get_by_role("button", name="Compare both").click()
        await page.get_by_role("button", name="Compare both").click()     # a second click while it runs
        await page.wait_for_selector(".eha-sim-info >> text=nonlinear and linear", timeout=90_000)
        await page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        await page.get_by_role("button", name="Run least squares").click()
        await page.wait_for_selector(".eha-lse-table table", timeout=90_000)
        await page.locator(".bk-header .bk-tab", has_text="Frequency domain").first.click()
        await page.get_by_role("button", name="Run experiment and estimate").click()
        await page.wait_for_selector(".eha-freq-summary >> text=Validation on a fresh excitation", timeout=90_000)
        for fig in ("Fig. 12 Bode", "Residuals"):
            await page.locator(".bk-header .bk-tab", has_text=fig).first.click()
        # the residual plots arrived with the last result's data
        await page.wait_for_function(JS_RESIDUALS_DRAWN, timeout=30_000)
        # the board takes each student's own estimates; a short study runs beside the others'
        await page.locator(".bk-header .bk-tab", has_text="Model board").first.click()
        for name in ("LS1", "H1"):
            await page.wait_for_selector(f".eha-board-fits >> text={name}", timeout=90_000)
        await page.locator(".bk-header .bk-tab", has_text="Study over seeds").first.click()
        seeds = page.locator(".eha-study-form input").first
        await seeds.fill("20")
        await seeds.press("Enter")
        await page.get_by_role("button", name="Run the study").click()
        await page.wait_for_selector(".eha-study-status >> text=20 of 20 seeds", timeout=90_000)
    finally:
        await context.close()


def test_several_browsers_through_the_whole_lab_at_once(server):
    from playwright.async_api import async_playwright

    async def run():
        problems: list[str] = []
        async with async_playwright() as p:
            browser = await p.chromium.launch(executable_path=_chromium(), args=CHROMIUM_ARGS)
            try:
                await asyncio.gather(*(_student(browser, server, i, problems) for i in range(SESSIONS)))
            finally:
                await browser.close()
        return problems

    # a thread of its own: the session's synchronous Playwright already runs an
    # event loop in this one
    out: dict = {}

    def in_thread():
        try:
            out["problems"] = asyncio.run(run())
        except BaseException as exc:  # noqa: BLE001 - re-raised below, in the test's thread
            out["error"] = exc

    worker = threading.Thread(target=in_thread)
    worker.start()
    worker.join()
    if "error" in out:
        raise out["error"]
    assert not out["problems"], out["problems"][:10]
