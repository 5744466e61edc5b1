"""A class exercise in real browsers: the secret never reaches a page; three students hand in; a restart keeps it."""

from __future__ import annotations

import re
import subprocess
import threading

from eha_app.runtime.handins import HandIns
from eha_app.runtime.teacher_access import cookie_value
from eha_core.exercise import Exercise
from tests.serve.conftest import EHA, EhaServer, dashboard_token, free_port
from tests.ui.browser_helpers import text_of

HIDE = ("M", "B", "Af", "beta_e")
DISPLAY_SCALE = {"M": 1.0, "B": 1.0, "Af": 1.0, "beta_e": 1e9}


def make_exercise(tmp_path) -> tuple[Exercise, str]:
    path = tmp_path / "class.json"
    out = subprocess.run([str(EHA), "exercise", "new", "--hide", ",".join(HIDE), "--vary", "25%",
                          "--tolerance", "5%", "--title", "Lab 3", "--out", str(path)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return Exercise.load(path), str(path)


def formats(value: float, scale: float) -> set[str]:
    """The ways a page could write ``value``: full precision and rounded, in SI and display units.

    Seven or more significant digits: an estimate of the student's own, shown to them
    on purpose, agrees with the truth to about 5 digits and may legitimately appear."""
    out = set()
    for v in (value, value / scale):
        out |= {repr(v), str(v), f"{v:.17g}", f"{v:.15g}", f"{v:.12g}", f"{v:.10g}", f"{v:.9g}", f"{v:.8g}",
                f"{v:.7g}", f"{v:.7e}", f"{v:.8e}"}
    return {s for s in out if len(s.replace("-", "").replace(".", "").replace("e+", "").lstrip("0")) >= 7}


def _as_number(number: str) -> str:
    # not after a digit, a point or a letter: "p1734" is a Bokeh model's id (the server's simple ids,
    # numbered as the models are made), not the number 1734
    return rf"(?<![\w.]){re.escape(number)}(?![\d])"


def appears(number: str, text: str) -> bool:
    """``number`` written as a number of its own in ``text`` ("1.2085" in "βe = 1.2085 GPa", not in "21.20853"
    nor in the model id "p12085")."""
    return re.search(_as_number(number), text) is not None


def surroundings(number: str, text: str) -> str:
    m = re.search(_as_number(number), text)
    return text[max(0, m.start() - 80):m.end() + 40]


def rounded(value: float, scale: float) -> set[str]:
    """Four to six significant digits, as tables and messages write numbers (SI and display units)."""
    from eha_app.render.tables import _num

    out = set()
    for v in (value, value / scale):
        out |= {f"{v:.4g}", f"{v:.5g}", f"{v:.6g}", _num(v)}
    return {s for s in out if len(s.replace("-", "").replace(".", "").lstrip("0")) >= 4}


def the_students_own_numbers(truth) -> set[str]:
    """What the page legitimately shows: the student's own least-squares estimates and intervals
    (noise-free, they agree with the truth to about five digits), as the app writes them."""
    from eha_app.render.tables import _num
    from eha_core.experiments import lse_data
    from eha_core.identify.lse import identify_lse

    res = identify_lse(lse_data(truth, "none"), truth)
    out = set()
    for n in HIDE:
        for v in (res.estimates[n], *res.ci95[n]):
            for w in (v, v / DISPLAY_SCALE[n]):
                out |= {f"{w:.4g}", f"{w:.5g}", f"{w:.6g}"}
            out.add(_num(v).split("·")[0])          # the mantissa of 1.0199·10<sup>9</sup>
    return out


def student_session(browser, url, student_id, frames=None):
    context = browser.new_context(viewport={"width": 1366, "height": 900}, accept_downloads=True)
    page = context.new_page()
    if frames is not None:
        page.on("websocket", lambda ws: ws.on("framereceived", lambda payload: frames.append(payload)))
    page.goto(url)
    page.wait_for_selector(".eha-student-id input", timeout=60_000)
    page.locator(".eha-student-id input").fill(student_id)
    page.get_by_role("button", name="Start").click()
    page.wait_for_selector(".eha-field-dc input", timeout=60_000)
    return context, page


def identify_and_hand_in(page):
    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
    page.get_by_role("button", name="Run least squares").click()
    page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
    page.get_by_role("button", name="Hand in these estimates").click()
    page.wait_for_selector(".eha-verdict >> text=Handed in", timeout=60_000)
    return text_of(page, ".eha-verdict")


def test_the_secret_never_reaches_a_students_browser(browser, tmp_path):
    """Every page, websocket message and download of a student who runs everything: no hidden value.

    Checked at 7 or more significant digits everywhere, and at 4 to 6 digits once the
    student's own estimates are taken out (noise-free, they equal the truth to about 5
    digits: what the student found by identification is theirs to see).
    """
    ex, path = make_exercise(tmp_path)
    truth = ex.student_params("s42")
    server = EhaServer(tmp_path, "--exercise", path)
    frames: list = []
    context, page = student_session(browser, server.url, "S42", frames)
    try:
        pages = [page.content()]
        page.locator(".bk-header .bk-tab", has_text="2. Simulation").first.click()
        page.get_by_role("button", name="Compare both").click()
        page.wait_for_selector(".eha-sim-info >> text=nonlinear and linear", timeout=60_000)
        with page.expect_download() as download:
            page.get_by_role("button", name="Download CSV").click()
        csv_text = open(download.value.path(), encoding="utf-8").read()
        verdict = identify_and_hand_in(page)
        assert "accepted" in verdict
        page.locator(".bk-tab", has_text="Frequency domain").first.click()
        page.get_by_role("button", name="Run experiment and estimate").click()
        page.wait_for_selector(".eha-freq-summary >> text=Validation on a fresh excitation", timeout=90_000)
        for fig in ("Fig. 11", "Fig. 12 Bode", "Fig. 13"):
            page.locator(".bk-tab", has_text=fig).first.click()
        # the frequency domain's downloads, and its record uploaded again as the student's own
        import io
        import zipfile

        import numpy as np
        import scipy.io

        freq_files = []
        for button in ("eha-dl-freq-est-csv", "eha-dl-freq-bode", "eha-dl-freq-csv"):
            with page.expect_download() as download:
                page.locator(f".{button}").get_by_role("button").first.click()
            freq_files.append(open(download.value.path(), encoding="utf-8").read())
        assert "linearised_eq24" not in freq_files[1]                  # eq. 24 is computed from hidden values
        with page.expect_download() as download:
            page.locator(".eha-dl-freq-zip").get_by_role("button").first.click()
        with zipfile.ZipFile(download.value.path()) as z:
            figure_csvs = [z.read(n).decode() for n in z.namelist() if n.endswith(".csv")]
            mat = scipy.io.loadmat(io.BytesIO(z.read("figures.mat")))
        assert len(figure_csvs) >= 6 and not any("eq24" in k for k in mat)
        freq_files += figure_csvs + [repr(np.asarray(v, dtype=float).ravel().tolist()) for k, v in mat.items()
                                     if not k.startswith("__")]
        record = tmp_path / "my_loop.csv"
        record.write_text(freq_files[2])
        page.locator(".eha-freq-upload input[type=file]").set_input_files(str(record))
        page.wait_for_selector(".eha-freq-record-note >> text=Your record: my_loop.csv", timeout=60_000)
        page.get_by_role("button", name="Estimate from your record").click()
        page.wait_for_selector(".eha-freq-record-summary >> text=Validated on the last", timeout=90_000)
        pages.append(page.content())
        # the model board: the student's estimates and the paper's Ĥ, never eq. 24 (made of hidden values)
        page.locator(".bk-tab", has_text="Model board").first.click()
        for name in ("LS1", "H1", "R1"):
            page.wait_for_selector(f".eha-board-fits >> text={name}", timeout=60_000)
        for view in ("Bode", "Step response", "Poles and zeros"):
            page.locator(".eha-board-views .bk-tab", has_text=view).first.click()
        page.wait_for_selector(".eha-board-steps >> text=nonlinear plant", timeout=60_000)
        fits = text_of(page, ".eha-board-fit-table")
        assert "LS1" in fits and "H(s) eq. 24" not in fits
        pages.append(page.content())
        page.locator(".bk-header .bk-tab", has_text="1. Parameters").first.click()
        page.wait_for_selector(".eha-hidden-note")
        pages.append(page.content())
        downloads = []
        page.get_by_role("button", name="Report of this session").click()       # prepared by a worker
        page.locator(".eha-session-report-download").wait_for(state="visible", timeout=60_000)
        for button in ("Download the report", "Save settings", "Estimates (JSON)", "Data (CSV)"):
            with page.expect_download() as download:
                if button in ("Estimates (JSON)", "Data (CSV)"):
                    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
                    page.locator(".bk-tab", has_text="Time domain").first.click()
                page.get_by_role("button", name=button).first.click()
            downloads.append(open(download.value.path(), encoding="utf-8").read())
        report = downloads[0]
        assert "report of a session" in report and "Least squares" in report
        # the report's text without Bokeh's inlined JavaScript (its own numbers are not the student's)
        report_text = re.sub(r"<script[^>]*>.*?</script>", "", report, flags=re.S)
        messages = [f if isinstance(f, str) else f.decode("latin-1") for f in frames]
        blob = "\n".join(pages + [csv_text] + messages + downloads + freq_files)
        assert len(frames) > 20 and "s42" in blob                  # the capture saw the session
        assert ex.secret not in blob and "secret" not in blob.lower()
        # nor the teacher's dashboard: its token, its cookie, its address
        token = dashboard_token(path)
        assert token not in blob and cookie_value(token) not in blob and "/teacher" not in blob
        leaks = {n: s for n in HIDE for s in formats(getattr(truth, n), DISPLAY_SCALE[n]) if appears(s, blob)}
        assert not leaks, {n: surroundings(s, blob) for n, s in leaks.items()}
        # rounded to 4-6 digits too, in the pages and messages (the simulated data's thousands of numbers
        # hold any 4-digit one), once the student's own estimates are taken out of the text
        blob = "\n".join(pages + [m for m in messages if m.startswith("{")] + [report_text] + downloads[1:3])
        own = sorted(the_students_own_numbers(truth), key=len, reverse=True)
        for number in own:
            blob = blob.replace(number, "·")
        leaks = {n: s for n in HIDE for s in rounded(getattr(truth, n), DISPLAY_SCALE[n]) if appears(s, blob)}
        assert not leaks, {n: surroundings(s, blob) for n, s in leaks.items()}
    finally:
        context.close()
        server.stop()


def test_a_class_hands_in_and_the_results_survive_a_restart(browser, tmp_path):
    ex, path = make_exercise(tmp_path)
    port = free_port()
    server = EhaServer(tmp_path, "--exercise", path, port=port)
    ids = ["ada", "bob", "cy"]
    results, errors = {}, []

    def run_student(sid):
        # each student a browser of their own, in a thread of its own (Playwright's sync API
        # is one browser per thread): three pages on the server at the same time
        from playwright.sync_api import sync_playwright

        from tests.ui.browser_helpers import CHROMIUM_ARGS, _chromium

        with sync_playwright() as p:
            b = p.chromium.launch(executable_path=_chromium(), args=CHROMIUM_ARGS)
            try:
                context, page = student_session(b, server.url, sid)
                results[sid] = identify_and_hand_in(page)
                context.close()
            except Exception as exc:  # noqa: BLE001 - reported below
                errors.append(f"{sid}: {exc}")
            finally:
                b.close()

    threads = [threading.Thread(target=run_student, args=(sid,)) for sid in ids]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=300)
        assert not errors, errors
        # under the exercise's sensor noise the default least squares are not exact: the verdicts vary
        assert all(re.search(r"[0-4] of 4 accepted", results[sid]) for sid in ids), results
        table = subprocess.run([str(EHA), "exercise", "results", path], capture_output=True, text=True, timeout=60)
        assert table.returncode == 0, table.stderr
        stored = {h.student: h for h in HandIns(path).all()}
        for sid in ids:
            line = next(ln for ln in table.stdout.splitlines() if ln.startswith(sid + " "))
            ok = ["yes" if stored[sid].verdicts[n] else "no" for n in HIDE]
            assert stored[sid].method == "lse" and [c for c in line.split() if c in ("yes", "no")] == ok, line
        server.stop()
        server = EhaServer(tmp_path, "--exercise", path, port=port)           # the teacher restarts it
        again = subprocess.run([str(EHA), "exercise", "results", path, "--csv", str(tmp_path / "r.csv")],
                               capture_output=True, text=True, timeout=60)
        assert "3 students handed in" in again.stdout
        csv_rows = (tmp_path / "r.csv").read_text().splitlines()
        assert len(csv_rows) == 4 and csv_rows[0].startswith("id,name,joined,last seen,hand-ins")
        context, page = student_session(browser, server.url, "Ada")         # and Ada hands in once more
        try:
            assert "hand-in 2 of 3 allowed" in identify_and_hand_in(page)
        finally:
            context.close()
    finally:
        server.stop()
