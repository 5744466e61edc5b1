"""A lab with actuators that differ in kind, graded by the precision of each student's own record, in
Chromium.

The teacher's exercise draws each actuator from a pool of two variants (leakage between the chambers,
Stribeck friction); Ada's has leakage. With the page's defaults her least squares do not determine B to
the lab's ±10 % ("not determined well enough": a 5 s record), and the paper's least squares' bias in M
counts against her. Every route says it fits the paper's model. The rich 20 s input with instrumental
variables earns a tighter acceptance, and M, Af and βe are accepted (the route's own error on her
leaking actuator, measured at the truth, is not held against her). The teacher's dashboard shows her variant, the
z-scores and the grading, and grants an extension (an id not on the roster is refused beside the
field); the gradebook file for Moodle carries the counted score."""

from __future__ import annotations

import csv
import os
import subprocess
from pathlib import Path

from playwright.sync_api import expect

from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise
from tests.serve.conftest import EHA, EhaServer, dashboard_token
from tests.ui.browser_helpers import JS_TEXT, text_of
from tests.ui.test_lab_in_browser import join

SHOTS = Path(os.environ.get("EHA_SCREENSHOTS", "/work/scratch"))


def _exercise(path):
    """The lab, with a secret under which Ada's actuator leaks (found by trying secrets in order)."""
    for i in range(256):
        ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), tolerance={"B": 0.10}, title="Lab 5",
                          secret=f"{i:02x}" * 32, roster=[("s1", "Ada Lovelace"), ("s2", "Alan Turing")],
                          variants=("leakage", "stribeck"), attempts=3, deadline="2099-01-01T12:00")
        if ex.variant_of("s1") == "leakage":
            ex.save(path)
            return ex
    raise AssertionError("no secret gives s1 a leaking actuator")


def _hand_in_lse(page, n: int, shows: str = "95 % interval") -> str:
    """Run the least squares, wait for the table to show ``shows``, hand in for the ``n``-th time."""
    page.get_by_role("button", name="Run least squares").click()
    page.locator(".eha-lse-table", has_text=shows).first.wait_for(state="visible", timeout=90_000)
    expect(page.get_by_role("button", name="Run least squares")).to_be_enabled(timeout=90_000)
    button = page.get_by_role("button", name="Hand in these estimates")
    expect(button).to_be_enabled(timeout=60_000)
    button.click()
    box = page.locator(".eha-verdict", has_text=f"hand-in {n} of 3 allowed")
    box.wait_for(timeout=120_000)
    return box.first.evaluate(JS_TEXT)


def test_a_lab_with_variants_graded_by_each_record(browser, tmp_path):
    path = tmp_path / "lab.json"
    ex = _exercise(path)
    server = EhaServer(tmp_path, "--exercise", str(path))
    contexts = []
    try:
        context, page = join(browser, server.url, ex.join_code("s1"))
        contexts.append(context)
        page.locator(".eha-lab-rules-pane", has_text="3 standard errors are at most").wait_for(timeout=60_000)
        page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        assert "leakage" not in text_of(page, "body")           # a student is not told their variant

        # the page's defaults: B is not determined by a 5 s record
        first = _hand_in_lse(page, 1)
        assert "not determined well enough" in first and "a longer record or a richer input narrows it" in first
        assert "fit the paper's model (eqs. 1-4)" in text_of(page, ".eha-lse-table")

        # every route says what it assumes: the grey-box too fits the paper's model
        page.locator(".bk-tab", has_text="Grey-box").first.click()
        page.get_by_role("button", name="Run grey-box estimation").click()
        page.get_by_text("The grey-box fits the paper's model (eqs. 1-4)").wait_for(timeout=180_000)

        # a sound experiment for the least squares: the rich input and instrumental variables
        page.locator(".bk-tab", has_text="Least squares").first.click()
        page.locator(".eha-field-lse_excitation select").select_option(
            label="u = 8 sin(4πt) + 4 sin(10πt), 20 s (narrows B)")
        page.locator(".eha-field-lse_estimator select").select_option(label="instrumental variables")
        second = _hand_in_lse(page, 2, shows="Estimator: instrumental variables")
        assert "3 of 4 accepted" in second, second
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.locator(".eha-verdict", has_text="hand-in 2 of 3").first.scroll_into_view_if_needed()
        page.screenshot(path=str(SHOTS / "graded_lab_verdict.png"))
        rows = HandIns(path).of("s1")
        judged = [ex.judge("s1", r.estimates, r.settings["std_errors"], r.settings["model_errors"]) for r in rows]
        assert [j["M"].ok for j in judged] == [False, True]
        assert all(judged[1][n].band < 0.6 * judged[0][n].band for n in ("M", "Af", "beta_e"))

        # the teacher: the variant, the z-scores, the grading; an extension for one student
        dash = browser.new_context(viewport={"width": 1366, "height": 900})
        contexts.append(dash)
        teacher = dash.new_page()
        teacher.goto(f"http://127.0.0.1:{server.port}/teacher?token={dashboard_token(path)}")
        teacher.locator(".eha-dash-roster").get_by_text("Ada Lovelace").wait_for(timeout=60_000)
        roster = text_of(teacher, ".eha-dash-roster")
        assert "(leakage)" in roster and "z " in roster
        assert "standard errors" in text_of(teacher, ".eha-dash-rules")
        teacher.locator(".eha-dash-extension-student input").fill("s9")
        teacher.locator(".eha-dash-extension-until input").fill("2099-02-01T12:00")
        teacher.get_by_role("button", name="Extend").click()
        teacher.locator(".eha-error-extension-student", has_text="s9").wait_for(timeout=30_000)
        teacher.locator(".eha-dash-extension-student input").fill("s2")
        teacher.get_by_role("button", name="Extend").click()
        teacher.locator(".eha-dash-extensions", has_text="s2").wait_for(timeout=30_000)
        assert HandIns(path).extension("s2") == "2099-02-01T12:00"
        teacher.screenshot(path=str(SHOTS / "graded_lab_dashboard.png"), full_page=True)
        assert "Traceback" not in server.log_text()
    finally:
        for c in contexts:
            c.close()
        server.stop()
    # the gradebook for Moodle: the counted score (the last hand-in's, 3 of 4) in points
    out = tmp_path / "moodle.csv"
    done = subprocess.run([str(EHA), "exercise", "results", str(path), "--format", "moodle", "--out", str(out)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    table = list(csv.reader(out.open(encoding="utf-8")))
    ada = next(r for r in table[1:] if r[2] == "s1")
    assert float(ada[-1]) == 75.0
