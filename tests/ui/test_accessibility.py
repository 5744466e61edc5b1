"""WCAG 2.1 AA on every view of the page (axe-core in Chromium), every figure's text alternative, and
the three steps done with the keyboard alone.

axe-core comes from npm, pinned by tests/ui/package-lock.json: ``npm ci --prefix tests/ui``; without
it the axe-core tests are skipped and say so. Bokeh draws each widget into a shadow root: axe-core
reads open shadow roots, and the tests check that it did (most nodes it checked are inside them, the
form's inputs among the controls it found labelled). No rule is turned off and no element excluded.

Each view is checked after its run, as a student sees it: tab 1; tab 2 after "Compare both"; tab 3's
least squares (and Table 4), the frequency domain's six figures, the grey-box estimate, the model
board's four views and the study over seeds, each after its run; an exercise's join page and its
tabs with the hand-in button.
"""

from __future__ import annotations

import re

import pytest

from tests.ui.browser_helpers import (
    AXE_JS,
    IGNORED_CONSOLE,
    axe_check,
    axe_path,
    text_of,
    violations_text,
    wait_until,
)

#: The figures on show: each visible canvas, the nearest element around it (across shadow roots) that
#: has a role and a name, and the extremes of each numeric column its Bokeh figure plots.
JS_FIGURES = """() => {
  const canvases = [];
  const visit = (root) => {
    for (const el of root.querySelectorAll('*')) {
      if (el.tagName === 'CANVAS') { canvases.push(el); }
      if (el.shadowRoot) { visit(el.shadowRoot); }
    }
  };
  visit(document);
  const up = (el) => el.parentElement || (el.getRootNode() instanceof ShadowRoot ? el.getRootNode().host : null);
  const numbers = (v, out) => {
    if (typeof v === 'number') { if (Number.isFinite(v)) { out.push(v); } return out; }
    if (v != null && typeof v !== 'string' && typeof v.length === 'number') {
      for (let i = 0; i < v.length; i++) { numbers(v[i], out); }
    }
    return out;
  };
  const shown = canvases.filter((c) => c.checkVisibility({visibilityProperty: true}) &&
                                       c.getBoundingClientRect().width > 0);
  const hosts = new Set();
  const figures = [];
  for (const canvas of shown) {
    let el = canvas;
    const named = (e) => e.getAttribute && e.getAttribute('role') && e.getAttribute('aria-label');
    while (el != null && !named(el)) { el = up(el); }
    if (el == null) { figures.push({label: null, role: null, extremes: []}); continue; }
    if (hosts.has(el)) { continue; }           // a figure draws on several canvases (its layers)
    hosts.add(el);
    const view = [...Bokeh.index.query((v) => v.el === el)][0];
    const extremes = [];
    for (const r of (view ? view.model.renderers : [])) {
      const data = r.data_source != null ? r.data_source.data : null;
      for (const [name, column] of Object.entries(data || {})) {
        const values = numbers(column, []);
        if (values.length) { extremes.push([name, Math.min(...values), Math.max(...values)]); }
      }
    }
    figures.push({label: el.getAttribute('aria-label'), role: el.getAttribute('role'), extremes});
  }
  return figures;
}"""

#: The element that has the keyboard's focus, looked for inside shadow roots.
JS_FOCUSED = """() => {
  let el = document.activeElement;
  while (el != null && el.shadowRoot != null && el.shadowRoot.activeElement != null) {
    el = el.shadowRoot.activeElement;
  }
  if (el == null || el === document.body) { return null; }
  const style = getComputedStyle(el);
  return {tag: el.tagName.toLowerCase(), id: el.id, role: el.getAttribute('role'),
          text: (el.textContent || '').trim().slice(0, 80), label: el.getAttribute('aria-label') || '',
          selected: el.getAttribute('aria-selected'), value: el.value === undefined ? null : String(el.value),
          ring: (style.outlineStyle !== 'none' && parseFloat(style.outlineWidth) > 0) || style.boxShadow !== 'none'};
}"""


def _tab(page, name: str):
    page.locator(".bk-header .bk-tab", has_text=name).first.click()


def _settled(page):
    # a newly shown tab lays its figures out after it is drawn: the canvases then have their size
    page.wait_for_timeout(300)


def walk(page):
    """Drive the page through each view after its run, yielding the view's name when it is shown."""
    page.wait_for_selector(".eha-derived >> text=Transfer functions", timeout=60_000)
    yield "tab 1"
    _tab(page, "2. Simulation")
    page.wait_for_selector(".eha-run-count >> text=run 1", timeout=60_000)
    page.get_by_role("button", name="Compare both").click()
    page.wait_for_selector(".eha-run-count >> text=run 2", timeout=60_000)
    _settled(page)
    yield "tab 2 after Compare both"
    _tab(page, "3. Identification")
    page.get_by_role("button", name="Run least squares").click()
    page.locator(".eha-lse-table table").wait_for(timeout=60_000)
    page.get_by_role("button", name="Run all four scenarios (Table 4)").click()
    page.wait_for_selector("text=Table 4: four scenarios", timeout=60_000)
    _settled(page)
    yield "tab 3 least squares after its run and Table 4"
    _tab(page, "Frequency domain")
    page.get_by_role("button", name="Run experiment and estimate").click()
    page.wait_for_selector("text=Backed-out parameters", timeout=120_000)
    for figure in ("Fig. 8", "Fig. 9", "Fig. 11", "Fig. 12 Bode", "Fig. 13", "Residuals"):
        page.locator(".eha-freq-figures .bk-tab", has_text=figure).first.click()
        _settled(page)
        yield f"tab 3 frequency domain after its run, {figure}"
    _tab(page, "Grey-box")
    page.get_by_role("button", name="Run grey-box estimation").click()
    page.locator(".eha-gb-table").wait_for(state="visible", timeout=120_000)
    _settled(page)
    yield "tab 3 grey-box after its run"
    _tab(page, "Model board")
    page.wait_for_selector(".eha-board-fits >> text=GB1", timeout=60_000)
    _settled(page)
    yield "tab 3 model board, fit"
    for view in ("Bode", "Step response", "Poles and zeros"):
        page.locator(".eha-board-views .bk-tab", has_text=view).first.click()
        page.wait_for_function(JS_A_FIGURE_DRAWN, timeout=60_000)
        _settled(page)
        yield f"tab 3 model board, {view}"
    _tab(page, "Study over seeds")
    page.get_by_role("button", name="Run the study").click()
    page.wait_for_selector(".eha-study-status >> text=100 of 100 seeds", timeout=180_000)
    _settled(page)
    yield "tab 3 study over seeds after its run"


#: Some figure on show has data (a board view is drawn once its curves are computed).
JS_A_FIGURE_DRAWN = "() => (" + JS_FIGURES + ")().some((f) => f.extremes.length > 0)"


@pytest.fixture(scope="module")
def views(browser, server):
    """Every view of the page, as axe-core (when installed) and the figures' texts found it, and what
    the browser's console said meanwhile."""
    context = browser.new_context(viewport={"width": 1366, "height": 900})
    page = context.new_page()
    console = []
    page.on("console", lambda m: console.append(f"{m.type}: {m.text}")
            if m.type == "error" and not any(s in m.text for s in IGNORED_CONSOLE) else None)
    page.on("pageerror", lambda e: console.append(f"pageerror: {e}"))
    try:
        page.goto(server)
        page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
        found = {name: {"axe": axe_check(page) if AXE_JS.exists() else None, "figures": page.evaluate(JS_FIGURES)}
                 for name in walk(page)}
    finally:
        context.close()
    return found, console


def test_every_view_passes_axe_cores_wcag_21_aa_rules(views):
    axe_path()
    found, console = views
    failing = {name: violations_text(v["axe"]) for name, v in found.items() if v["axe"]["violations"]}
    assert not failing, "\n\n".join(f"== {name}\n{text}" for name, text in failing.items())
    assert not console, console


def test_axe_core_reads_inside_bokehs_shadow_roots(views):
    """A check that saw only the page's outer shell would pass vacuously: most of what axe-core checked
    is inside shadow roots, and tab 1's form inputs are among the controls it found labelled."""
    axe_path()
    found, _ = views
    for name, v in found.items():
        assert v["axe"]["checked"] > 100 and v["axe"]["in_shadow"] > 0.8 * v["axe"]["checked"], (name, v["axe"])
    labelled = found["tab 1"]["axe"]["labelled"]
    assert {"#eha-input-M", "#eha-input-beta_e"} <= set(labelled), labelled


def _numbers(text: str) -> list[float]:
    return [float(m) for m in re.findall(r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?", text, flags=re.I)]


def _written(value: float, numbers: list[float]) -> bool:
    """``value`` among ``numbers``, as written with four significant digits."""
    return any(abs(value - n) <= 1e-3 * max(abs(value), abs(n)) + 1e-12 for n in numbers)


def test_every_figure_has_a_text_alternative_with_its_numbers(views):
    """Each canvas on each view is inside an element with ``role="figure"`` and an ``aria-label``
    that names the plotted data's extremes (a smallest and a largest value of its columns), so the
    text follows the figure's data."""
    found, _ = views
    counted = 0
    for name, v in found.items():
        for fig in v["figures"]:
            counted += 1
            assert fig["label"], f"{name}: a canvas without a text alternative"
            assert fig["role"] == "figure", (name, fig["role"])
            numbers = _numbers(fig["label"])
            lows = [lo for _, lo, _ in fig["extremes"] if _written(lo, numbers)]
            highs = [hi for _, _, hi in fig["extremes"] if _written(hi, numbers)]
            assert lows and highs, f"{name}: the text names no extreme of the plotted data\n{fig['label']}\n" \
                                   f"{fig['extremes']}"
    assert counted >= 20, counted                 # the views do show their figures


def _press_until(page, key: str, wanted, *, most: int = 150, what: str = "") -> dict:
    """Press ``key`` until the focused element satisfies ``wanted`` (at most ``most`` times)."""
    for _ in range(most):
        page.keyboard.press(key)
        focused = page.evaluate(JS_FOCUSED)
        if focused is not None and wanted(focused):
            return focused
    pytest.fail(f"{most} presses of {key} did not reach {what}; the focus is on {page.evaluate(JS_FOCUSED)}")


def test_the_three_steps_with_the_keyboard_alone(browser, server):
    """From opening the page: type a parameter on tab 1, open tab 2 and press "Compare both", open tab 3
    and run the least squares; Tab, Shift+Tab, the arrow keys, Enter and Space only (and the digits
    typed). Every stop on the way shows where the focus is."""
    context = browser.new_context(viewport={"width": 1366, "height": 768})
    page = context.new_page()
    try:
        page.goto(server)
        page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
        page.wait_for_selector(".eha-derived >> text=Transfer functions", timeout=60_000)

        # tab 1: the piston's mass M, typed over
        field = _press_until(page, "Tab", lambda f: f["id"] == "eha-input-M", what="the field M")
        assert field["ring"], field
        for _ in range(len(field["value"] or "")):
            page.keyboard.press("Backspace")
        page.keyboard.type("4500")
        wait_until(lambda: "M=4500" in page.url, 15, message="M = 4500 kg in the page's address")

        # tab 2: back to the tab list (its one stop is the open tab), right to "2. Simulation", Enter
        header = _press_until(page, "Shift+Tab", lambda f: f["role"] == "tab", what="the tab list")
        assert header["text"] == "1. Parameters" and header["selected"] == "true" and header["ring"], header
        page.keyboard.press("ArrowRight")
        header = page.evaluate(JS_FOCUSED)
        assert header["text"] == "2. Simulation" and header["selected"] == "false", header
        page.keyboard.press("Enter")
        page.wait_for_selector(".eha-run-count", state="visible", timeout=60_000)
        assert page.evaluate(JS_FOCUSED)["selected"] == "true"
        button = _press_until(page, "Tab", lambda f: f["tag"] == "button" and f["text"] == "Compare both",
                              what="“Compare both”")
        assert button["ring"], button
        page.keyboard.press("Space")
        page.wait_for_selector(".eha-sim-info >> text=nonlinear and linear model", timeout=60_000)

        # tab 3: the least squares, its sub-tab open first
        _press_until(page, "Shift+Tab", lambda f: f["role"] == "tab" and f["text"] == "2. Simulation",
                     what="the main tab list")
        page.keyboard.press("ArrowRight")
        page.keyboard.press("Enter")
        page.wait_for_selector("text=Time domain: least squares", timeout=60_000)
        _press_until(page, "Tab", lambda f: f["tag"] == "button" and f["text"] == "Run least squares",
                     what="“Run least squares”")
        page.keyboard.press("Enter")
        page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
        table = text_of(page, ".eha-lse-table")
        assert "β" in table and "M" in table, table[:300]
    finally:
        context.close()


def test_an_exercise_page_passes_axe_cores_rules(browser, tmp_path):
    """An exercise's join page, and the student's tabs with the hand-in button, after a least-squares run."""
    from tests.serve.conftest import EhaServer
    from tests.ui.test_exercise_in_browser import make_exercise

    axe_path()
    _, path = make_exercise(tmp_path)
    server = EhaServer(tmp_path, "--exercise", path)
    context = browser.new_context(viewport={"width": 1366, "height": 900})
    try:
        page = context.new_page()
        page.goto(server.url)
        page.wait_for_selector(".eha-student-id input", timeout=60_000)
        found = {"join page": axe_check(page)}
        page.locator(".eha-student-id input").fill("s1234567")
        page.get_by_role("button", name="Start").click()
        page.wait_for_selector(".eha-field-dc input", timeout=60_000)
        page.wait_for_selector(".eha-derived >> text=Geometry", timeout=60_000)
        found["tab 1 of an exercise"] = axe_check(page)
        _tab(page, "3. Identification")
        page.get_by_role("button", name="Run least squares").click()
        page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
        page.get_by_role("button", name="Hand in these estimates").wait_for(state="visible", timeout=30_000)
        found["tab 3 of an exercise after the least squares"] = axe_check(page)
        failing = {name: violations_text(r) for name, r in found.items() if r["violations"]}
        assert not failing, "\n\n".join(f"== {name}\n{text}" for name, text in failing.items())
    finally:
        context.close()
        server.stop()
