"""What a student sees, in Chromium at 1366 x 768 and 800 px: marks that agree with the numbers, a
guide through the three steps, uploads and reports that work the first time (one test per item)."""

from __future__ import annotations

import re

import pytest

from tests.ui.browser_helpers import IGNORED_CONSOLE, text_of, wait_until

JS_BUTTON_BOX = """(label) => {
  const find = (root) => {
    for (const el of root.querySelectorAll('button')) if (el.textContent.trim() === label) return el;
    for (const el of root.querySelectorAll('*')) if (el.shadowRoot) { const f = find(el.shadowRoot); if (f) return f; }
    return null;
  };
  const b = find(document);
  if (!b) return null;
  const r = b.getBoundingClientRect();
  return [r.left, r.top, r.right, r.bottom];
}"""

JS_WATCH_REPORT_LABEL = """() => {
  // every label the report's button is given, as the page's model receives it: a report of a short
  // session is ready in ~100 ms, and under load the "Preparing" label and its return can arrive in
  // one batch, between two paints, so the page's drawn text would miss it
  window.__ehaLabels = [];
  for (const doc of window.Bokeh.documents)
    for (const m of doc.all_models)
      if (m.label === 'Report of this session') {
        window.__ehaLabels.push(m.label);
        m.properties.label.change.connect(() => window.__ehaLabels.push(m.label));
      }
}"""


@pytest.fixture
def open_page(browser, server):
    contexts = []
    problems = []

    def make(query: str = "", width: int = 1366, height: int = 768):
        context = browser.new_context(viewport={"width": width, "height": height}, accept_downloads=True)
        contexts.append(context)
        page = context.new_page()
        page.on("console", lambda m: problems.append(m.text)
                if m.type == "error" and not any(s in m.text for s in IGNORED_CONSOLE) else None)
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.goto(server + (f"?{query}" if query else ""))
        page.wait_for_selector(".eha-guide-where >> text=Step", timeout=60_000)     # the page is there
        return page

    yield make
    for c in contexts:
        c.close()
    assert not problems, problems


def _run_lse(page):
    page.get_by_role("button", name="Run least squares").click()
    page.wait_for_selector(".eha-lse-table >> text=Disturbance model", timeout=60_000)
    return text_of(page, ".eha-lse-table")


def _run_frequency(page):
    page.get_by_role("button", name="Run experiment and estimate").click()
    page.wait_for_selector(".eha-freq-summary >> text=Validation on a fresh excitation", timeout=90_000)


def test_1_noise_free_estimates_read_exact_not_failing(open_page):
    page = open_page("tab=3")
    table = _run_lse(page)
    assert table.count("exact ✓") == 5 and "✗" not in table
    assert "Exact (M, B, Af, d0, βe)" in table.replace("\n", " ")


def test_2_an_impossible_estimate_is_flagged_and_explained(open_page):
    page = open_page("tab=3&lse_scenario=5000%20sin")
    table = _run_lse(page)
    assert "impossible ✗" in table and "B = -1573" in table
    assert "Why the constant model fails here." in table and "with d0 + a sinusoid" in table


def test_3_each_paper_value_cites_one_table_and_case(open_page):
    page = open_page("tab=3")
    table = _run_lse(page)
    assert table.count("Table 4, d = 0") == 5 and "Table 3/4" not in table


def test_4_fig11_fits_the_linearised_model_as_the_board_does(open_page):
    page = open_page("tab=3")
    page.locator(".bk-tab", has_text="Frequency domain").first.click()
    _run_frequency(page)
    page.locator(".eha-freq-figures .bk-tab", has_text="Fig. 11").first.click()
    page.wait_for_selector(".eha-fit-note >> text=initial state and input offset fitted", timeout=20_000)
    note = text_of(page, ".eha-fit-note")
    eq24 = float(re.search(r"linearised H\(s\) of eq. 24: fit (-?[\d.]+) %", note).group(1))
    assert eq24 > 70, note


def test_5_the_board_names_a_changed_actuator(open_page):
    page = open_page("tab=3")
    page.locator(".bk-tab", has_text="Frequency domain").first.click()
    _run_frequency(page)
    page.locator(".bk-header .bk-tab", has_text="1. Parameters").first.click()
    page.locator(".eha-field-M input").fill("6000")
    page.locator(".eha-field-M input").press("Tab")
    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
    page.locator(".bk-tab", has_text="Model board").first.click()
    page.wait_for_selector(".eha-board-fit-table >> text=Estimated on another actuator (M 4000 → 6000 kg)",
                           timeout=60_000)


def test_6_an_unstable_open_loop_estimate_says_so(open_page):
    page = open_page("tab=3")
    page.locator(".bk-tab", has_text="Frequency domain").first.click()
    _run_frequency(page)
    summary = text_of(page, ".eha-freq-summary")
    assert "P̂(s) is unstable: a pole at +" in summary and "Ĥ(0) = 1.0" in summary


def test_8_a_first_time_student_reaches_the_frequency_identification(open_page):
    page = open_page()
    page.wait_for_selector(".eha-start >> text=Three steps", timeout=20_000)
    page.get_by_role("button", name="Start here").click()
    nxt = page.locator(".eha-guide-next button")
    nxt.click()                                         # tab 1 asks for no run: on to tab 2
    page.wait_for_selector(".eha-guide-where >> text=Press Compare both", timeout=20_000)
    assert nxt.is_disabled()                            # "Next" once the step's result is on the page
    page.get_by_role("button", name="Compare both").click()
    page.wait_for_selector(".eha-guide-next button:not([disabled])", timeout=60_000)
    nxt.click()
    page.wait_for_selector(".eha-guide-where >> text=Press Run least squares", timeout=20_000)
    page.get_by_role("button", name="Run least squares").click()
    page.wait_for_selector(".eha-guide-next button:not([disabled])", timeout=60_000)
    nxt.click()
    page.wait_for_selector(".eha-guide-where >> text=Step 3, frequency domain", timeout=20_000)
    page.wait_for_selector("button:has-text('Run experiment and estimate')", timeout=60_000)
    assert page.locator(".eha-start").first.is_hidden()


@pytest.mark.parametrize("subtab, label", [("Time domain", "Run least squares"),
                                           ("Frequency domain", "Run experiment and estimate")])
def test_9_the_main_button_is_in_view_at_1366_x_768(open_page, subtab, label):
    page = open_page("tab=3")
    page.locator(".bk-tab", has_text=subtab).first.click()
    wait_until(lambda: page.evaluate(JS_BUTTON_BOX, label) is not None, 30, message=label)
    left, top, right, bottom = page.evaluate(JS_BUTTON_BOX, label)
    assert 0 <= top and bottom <= 768 and 0 <= left and right <= 1366, (label, top, bottom)


def test_10_at_800_px_every_sub_tab_header_is_in_view(open_page):
    page = open_page("tab=3", width=800, height=768)
    page.locator(".bk-tab", has_text="Frequency domain").first.click()
    page.wait_for_selector(".eha-freq-form", timeout=60_000)
    tabs = page.locator(".eha-freq-figures .bk-tab")
    wait_until(lambda: tabs.count() == 6, 20, message="the figure tabs")
    for k in range(tabs.count()):
        box = tabs.nth(k).bounding_box()
        assert box["x"] >= 0 and box["x"] + box["width"] <= 800, (tabs.nth(k).inner_text(), box)
    assert page.evaluate("() => document.documentElement.scrollWidth") <= 800
    # every figure after a run: Fig. 11's and Fig. 12's legends on one row made the page 1007 and 861 px wide
    _run_frequency(page)
    for k in range(tabs.count()):
        tabs.nth(k).click()
        page.wait_for_timeout(300)
        width = page.evaluate("() => document.documentElement.scrollWidth")
        assert width <= 800, (tabs.nth(k).inner_text(), width)


def test_10_at_800_px_the_results_scroll_in_their_own_boxes(open_page):
    """The least squares' eight columns and the study's table: their box scrolls, never the page."""
    page = open_page("tab=3&lse_scenario=5000%20sin&study_seeds=4", width=800, height=768)
    _run_lse(page)
    assert page.evaluate("() => document.documentElement.scrollWidth") <= 800
    page.locator(".bk-tab", has_text="Study over seeds").first.click()
    page.get_by_role("button", name="Run the study").click()
    wait_until(lambda: "bias / its std error" in text_of(page, ".eha-study-summary"), 120, message="the study")
    wait_until(lambda: page.evaluate("() => document.documentElement.scrollWidth") <= 800, 10,
               message="the study within 800 px")


def test_11_compare_both_over_four_cases_shows_one_case_at_a_time(open_page):
    page = open_page("tab=2")
    page.get_by_role("button", name="All four cases").click()
    page.get_by_role("button", name="Compare both").click()
    page.wait_for_selector(".eha-sim-info >> text=Case 1 of Case 1, Case 2, Case 3, Case 4", timeout=60_000)
    page.wait_for_selector(".eha-sim-case-select >> text=Case 3", timeout=10_000)
    assert "not used for them" in text_of(page, ".eha-sim-form-note")


def test_12_a_lab_file_is_guessed_and_waits_for_the_student(open_page, tmp_path):
    from eha_core.experiments import lse_data

    d = lse_data(t_end=0.5)
    path = tmp_path / "lab.csv"
    rows = "".join(f"{t:.6g},{x * 1e3:.9g},{v * 1e3:.9g},{p1 / 1e5:.9g},{p2 / 1e5:.9g},{u:.9g}\n"
                   for t, x, v, p1, p2, u in zip(d.t, d.x, d.v, d.p1, d.p2, d.u, strict=True))
    path.write_text("time,position[mm],velocity[mm/s],pA[bar],pB[bar],valve[V]\n" + rows)
    page = open_page("tab=3")
    page.locator(".eha-lse-upload input[type=file]").set_input_files(str(path))
    page.wait_for_selector(".eha-lse-mapping >> text=Which columns of lab.csv are which?", timeout=60_000)
    assert page.locator(".eha-map-x select").input_value() == "position[mm]"
    assert page.locator(".eha-map-p2 select").input_value() == "pB[bar]"
    assert "is not allowed" not in text_of(page, ".eha-lse-mapping")
    assert page.get_by_role("button", name="Run least squares").is_disabled()
    page.get_by_role("button", name="Use these columns").click()
    wait_until(lambda: page.get_by_role("button", name="Run least squares").is_enabled(), 30, message="the run")
    table = _run_lse(page)
    assert "nominal" not in table.split("Disturbance model")[0] and "paper" not in table.split("Disturbance")[0]


def test_13_the_report_shows_progress_at_once_and_names_the_student(open_page):
    page = open_page()
    page.wait_for_selector(".eha-derived >> text=Transfer functions", timeout=60_000)     # tab 1 is drawn
    page.locator(".eha-report-name input").fill("Ada")
    page.locator(".eha-report-name input").press("Tab")
    page.wait_for_timeout(500)          # (clicked in the same instant, the label's change was not seen)
    page.evaluate(JS_WATCH_REPORT_LABEL)
    page.get_by_role("button", name="Report of this session").click()
    # at once: the button says it is working (its label comes back when the file is ready)
    wait_until(lambda: any("Preparing the report" in t for t in page.evaluate("() => window.__ehaLabels")), 30,
               message=f"the report's progress on its button (labels: {page.evaluate('() => window.__ehaLabels')})")
    page.wait_for_selector("button:has-text('Download the report')", timeout=60_000)
    with page.expect_download() as dl:
        page.get_by_role("button", name=re.compile("Download the report")).click()
    text = open(dl.value.path(), encoding="utf-8").read()
    assert "Student: <b>Ada</b>" in text and "β<sub>e</sub>" in text


def test_14_the_study_speaks_the_apps_vocabulary(open_page):
    page = open_page("tab=3&study_seeds=4")
    page.locator(".bk-tab", has_text="Study over seeds").first.click()
    page.get_by_role("button", name="Run the study").click()
    wait_until(lambda: "bias / its std error" in text_of(page, ".eha-study-summary"), 120, message="the study")
    summary = text_of(page, ".eha-study-summary")
    assert "βe [GPa]" in summary and "beta_e" not in summary and not re.search(r"\d[eE][+-]\d", summary)
    assert "Histograms:" in summary


def test_7_the_instrumental_variables_are_chosen_in_the_form(open_page):
    page = open_page("tab=3&lse_scenario=white%20noise&lse_estimator=iv")
    table = _run_lse(page)
    assert "Estimator: instrumental variables" in table and "equal-weighted cosine" in table


JS_HANDIN_TIP = """() => {
  for (const doc of window.Bokeh.documents)
    for (const m of doc.all_models)
      if (m.label === 'Hand in these estimates') {
        // Panel sends a button's description as a Tooltip model (its text in "content")
        const d = m.tooltip;
        if (d == null) return null;
        const c = typeof d === 'string' ? d : d.content;
        return c == null ? null : (typeof c === 'string' ? c : String(c.text || c));
      }
  return null;
}"""


def test_15_the_hand_in_tooltip_says_what_is_true_now(browser, tmp_path):
    from tests.ui.test_exercise_in_browser import EhaServer, make_exercise, student_session

    _ex, path = make_exercise(tmp_path)
    server = EhaServer(tmp_path, "--exercise", path)
    context, page = student_session(browser, server.url, "S7")
    try:
        page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        wait_until(lambda: page.evaluate(JS_HANDIN_TIP) is not None, 30, message="the hand-in button")
        assert page.evaluate(JS_HANDIN_TIP).startswith("run the least squares first")
        _run_lse(page)
        wait_until(lambda: (page.evaluate(JS_HANDIN_TIP) or "").startswith("hand in the estimates of M, B, Af, βe"),
                   30, message=f"the tooltip after a run ({page.evaluate(JS_HANDIN_TIP)})")
    finally:
        context.close()
        server.stop()
