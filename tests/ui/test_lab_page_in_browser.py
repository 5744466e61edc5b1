"""The lab page tells the student what they need, in Chromium: the rules always in view, a question
before a physically impossible estimate uses an attempt, and no hand-in after the last attempt.

Under the exercise's 5000 N sinusoidal load the paper's least squares (constant d0) put every
student's B below zero (Table 4's case: the sinusoid leaks into B): an impossible estimate that a
student might hand in without a second look."""

from __future__ import annotations

import subprocess

from playwright.sync_api import expect

from tests.serve.conftest import EHA, EhaServer
from tests.ui.browser_helpers import text_of
from tests.ui.test_lab_in_browser import join

ROSTER = "id,name\ns1,Ada Lovelace\n"


def _rules(page) -> str:
    return text_of(page, ".eha-lab-rules-pane")



def test_the_rules_the_impossible_estimate_and_the_last_attempt(browser, tmp_path):
    (tmp_path / "class.csv").write_text(ROSTER, encoding="utf-8")
    path = tmp_path / "lab.json"
    made = subprocess.run([str(EHA), "exercise", "new", "--roster", str(tmp_path / "class.csv"), "--title", "Lab 4",
                           "--deadline", "2099-01-01T12:00", "--attempts", "2", "--disturbance", "sine:5000:1",
                           "--out", str(path)], capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    codes = subprocess.run([str(EHA), "exercise", "codes", str(path)], capture_output=True, text=True, timeout=60)
    code = {line.split()[-1]: line.split()[0] for line in codes.stdout.splitlines()}
    server = EhaServer(tmp_path, "--exercise", str(path))
    context = None
    try:
        context, page = join(browser, server.url, code["s1"])
        page.locator(".eha-student", has_text="Ada Lovelace").wait_for(timeout=60_000)
        page.locator(".eha-lab-rules-pane", has_text="hand-ins: 0 of 2 used, 2 left").wait_for(timeout=30_000)
        rules = _rules(page)
        assert "deadline 2099-01-01 12:00 UTC" in rules and "3 standard errors are at most" in rules
        assert "feedback:" in rules

        page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        page.get_by_role("button", name="Run least squares").click()
        page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
        hand_in = page.get_by_role("button", name="Hand in these estimates")
        question = page.locator(".eha-handin-confirm")

        # an impossible B: asked first, and "Keep it" uses no attempt
        hand_in.click()
        question.filter(has_text="Physically impossible").wait_for(timeout=30_000)
        question.filter(has_text="It would use hand-in 1 of 2").wait_for(timeout=5_000)
        page.get_by_role("button", name="Keep it").click()
        question.wait_for(state="hidden", timeout=30_000)
        assert "0 of 2 used" in _rules(page)

        # handed in anyway, twice: the second is the last, and the button goes off
        for used in (1, 2):
            hand_in.click()
            page.get_by_role("button", name="Hand in anyway").click()
            page.locator(".eha-lab-rules-pane", has_text=f"hand-ins: {used} of 2 used").wait_for(timeout=30_000)
        page.locator(".eha-lab-rules-pane", has_text="Hand-ins are refused now").wait_for(timeout=30_000)
        expect(hand_in).to_be_disabled(timeout=30_000)
    finally:
        if context is not None:
            context.close()
        server.stop()
