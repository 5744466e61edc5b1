"""A graded lab, played in Chromium from the teacher's command line to the reveal.

The teacher makes the exercise with a roster and opens the dashboard with the token; three students
join with their codes (a wrong code first: refused); two hand in from the least squares, one from the
frequency domain's back-out; the dashboard follows without a reload; a student reloads and finds
their work; the teacher moves the deadline into the past and a late hand-in is refused; the teacher
reveals, and each student's page shows their own actuator and no one else's.
"""

from __future__ import annotations

import re
import subprocess

from playwright.sync_api import expect

from eha_app.runtime.handins import HandIns
from eha_core.exercise import Exercise
from tests.serve.conftest import EHA, EhaServer, dashboard_token
from tests.ui.browser_helpers import JS_TEXT, text_of

ROSTER = "id,name,email\ns1,Ada Lovelace,ada@uni.example\ns2,Alan Turing,alan@uni.example\ns3,Grace Hopper,g@x\n"


def join(browser, url, code):
    context = browser.new_context(viewport={"width": 1366, "height": 900})
    page = context.new_page()
    page.goto(url)
    page.locator(".eha-join-code input").fill(code, timeout=60_000)
    page.get_by_role("button", name="Start").click()
    return context, page


def hand_in_lse(page) -> str:
    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
    page.get_by_role("button", name="Run least squares").click()
    page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
    page.get_by_role("button", name="Hand in these estimates").click()
    box = page.locator(".eha-verdict", has_text="least squares")
    box.wait_for(timeout=60_000)
    return box.first.evaluate(JS_TEXT)


def test_a_lab_from_the_roster_to_the_reveal(browser, tmp_path):
    (tmp_path / "class.csv").write_text(ROSTER, encoding="utf-8")
    path = tmp_path / "lab.json"
    made = subprocess.run([str(EHA), "exercise", "new", "--roster", str(tmp_path / "class.csv"), "--title", "Lab 3",
                           "--deadline", "2099-01-01T12:00", "--out", str(path)], capture_output=True, text=True,
                          timeout=60)
    assert made.returncode == 0, made.stderr
    codes = subprocess.run([str(EHA), "exercise", "codes", str(path)], capture_output=True, text=True, timeout=60)
    code = {line.split()[-1]: line.split()[0] for line in codes.stdout.splitlines()}
    assert set(code) == {"s1", "s2", "s3"}
    ex = Exercise.load(path)
    server = EhaServer(tmp_path, "--exercise", str(path))
    teacher = browser.new_context(viewport={"width": 1366, "height": 900})
    contexts = [teacher]
    try:
        # the teacher: the link printed on their console
        token = dashboard_token(path)
        assert f"/teacher?token={token}" in server.log_text()
        dash = teacher.new_page()
        dash.goto(f"http://127.0.0.1:{server.port}/teacher?token={token}")
        roster = dash.locator(".eha-dash-roster")
        roster.get_by_text("Grace Hopper").wait_for(timeout=60_000)

        # three students; Ada first types a wrong code
        ctx, ada = join(browser, server.url, "ABCDE-FGHJK")
        contexts.append(ctx)
        ada.locator(".eha-error-student", has_text="it is no code of this exercise").wait_for(timeout=30_000)
        ada.locator(".eha-join-code input").fill(code["s1"].lower())
        ada.get_by_role("button", name="Start").click()
        ada.locator(".eha-student", has_text="Ada Lovelace").wait_for(timeout=60_000)
        students = {"s1": ada}
        for sid in ("s2", "s3"):
            ctx, page = join(browser, server.url, code[sid])
            contexts.append(ctx)
            page.locator(".eha-student", has_text=ex.entry(sid).name).wait_for(timeout=60_000)
            students[sid] = page

        # two routes: the least squares (Ada, Alan) and the frequency domain's back-out (Grace)
        ada_box = hand_in_lse(ada)
        assert re.search(r"hand-in 1 of 3 allowed.*[0-4] of 4 accepted", ada_box, re.S), ada_box
        lse_table = text_of(ada, ".eha-lse-table")
        hand_in_lse(students["s2"])
        grace = students["s3"]
        grace.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        grace.locator(".bk-tab", has_text="Frequency domain").first.click()
        grace.get_by_role("button", name="Run experiment and estimate").click()
        grace.wait_for_selector(".eha-freq-summary >> text=Validation on a fresh excitation", timeout=90_000)
        grace.get_by_role("button", name="Hand in the back-out's βe").click()
        grace.locator(".eha-verdict", has_text="transfer function and back-out").wait_for(timeout=60_000)

        # the dashboard has followed, without a reload
        roster.get_by_text("transfer function and back-out").wait_for(timeout=15_000)
        assert roster.get_by_text("least squares").count() >= 2

        # Ada reloads: her code again, her work back
        ada.reload()
        ada.locator(".eha-join-code input").fill(code["s1"], timeout=60_000)
        ada.get_by_role("button", name="Start").click()
        ada.locator(".eha-work-restored", has_text="Least squares").wait_for(timeout=90_000)
        ada.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        ada.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
        assert re.sub(r"Simulated, identified.*", "", text_of(ada, ".eha-lse-table"), flags=re.S) == \
            re.sub(r"Simulated, identified.*", "", lse_table, flags=re.S)

        # the deadline passes (the teacher moves it): Alan's page follows without a reload (it reads the
        # lab's rules every 5 s) and his hand-in button goes off, saying why. A click that beats the
        # page's reading is refused by the hand-in's own transaction (tests/app/test_exercise.py).
        dash.locator(".eha-dash-deadline input").fill("2020-01-01T00:00")
        dash.get_by_role("button", name="Set the deadline").click()
        dash.locator(".eha-dash-rules", has_text="2020-01-01T00:00").wait_for(timeout=15_000)
        alan = students["s2"]
        alan.locator(".eha-lab-rules-pane", has_text="Hand-ins are refused now: the deadline (2020-01-01T00:00) "
                     "has passed").wait_for(timeout=60_000)
        expect(alan.get_by_role("button", name="Hand in these estimates")).to_be_disabled(timeout=30_000)
        assert len(HandIns(path).all()) == 3

        # the reveal: each student sees their own actuator (the page looks every 5 s), no one else's
        dash.get_by_role("button", name="Reveal the verdicts to the students").click()
        truths = {sid: ex.student_params(sid) for sid in students}
        for sid, page in students.items():
            shown = page.locator(".eha-student-result", has_text="revealed your actuator")
            shown.wait_for(timeout=30_000)
            text = shown.first.evaluate(JS_TEXT)
            assert f"M = {truths[sid].M:.5g} kg" in text, text
            assert not any(f"{truths[o].M:.5g}" in text for o in truths if o != sid)
        assert "Traceback" not in server.log_text()
    finally:
        for c in contexts:
            c.close()
        server.stop()
