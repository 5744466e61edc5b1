"""Uploads in a real browser: a student downloads what the app exported and uploads it again.

Least squares: the data CSV downloaded and uploaded gives the same estimates.
Frequency domain: the closed-loop record downloaded, uploaded with other column
names, mapped, cut to a time range with a trend removed (drawn on the record's
plot), and estimated.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from tests.ui.browser_helpers import text_of, wait_until

SHOTS = os.environ.get("EHA_SCREENSHOTS")      # a directory: also save what the student sees


def _download(page, button: str) -> str:
    with page.expect_download() as download:
        page.get_by_role("button", name=button).first.click()
    return open(download.value.path(), encoding="utf-8").read()


def _download_class(page, css_class: str) -> str:
    with page.expect_download() as download:
        page.locator(f".{css_class}").get_by_role("button").first.click()
    return open(download.value.path(), encoding="utf-8").read()


@pytest.fixture
def student(browser, server):
    context = browser.new_context(viewport={"width": 1366, "height": 900}, accept_downloads=True)
    page = context.new_page()
    problems = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(server)
    page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
    yield page
    context.close()
    assert not problems, problems


def test_least_squares_data_downloaded_and_uploaded_gives_the_same_estimates(student, tmp_path):
    page = student
    page.get_by_role("button", name="Run least squares").click()
    page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
    simulated = json.loads(_download(page, "Estimates (JSON)"))["estimates"]
    data = tmp_path / "my_run.csv"
    data.write_text(_download(page, "Data (CSV)"))
    page.locator(".eha-lse-upload input[type=file]").set_input_files(str(data))
    page.wait_for_selector(".eha-lse-upload-note >> text=Using your data: my_run.csv", timeout=60_000)
    page.get_by_role("button", name="Run least squares").click()
    page.wait_for_selector(".eha-lse-table >> text=my_run.csv", timeout=90_000)
    own = json.loads(_download(page, "Estimates (JSON)"))
    assert "my_run.csv" in own["data"]
    for a, b in zip(simulated, own["estimates"], strict=True):
        assert a["parameter"] == b["parameter"]
        np.testing.assert_allclose(b["estimate"], a["estimate"], rtol=1e-6, atol=1e-6, err_msg=a["parameter"])
    bad = tmp_path / "broken.csv"
    bad.write_text("t,x,v,p1,p2,u\n" + "".join(f"{k / 1000},0,0,1e7,1e7,{'oops' if k == 7 else 0}\n"
                                               for k in range(100)))
    page.locator(".eha-lse-upload input[type=file]").set_input_files(str(bad))
    page.wait_for_selector(".eha-lse-upload-note >> text=broken.csv", timeout=60_000)
    message = text_of(page, ".eha-lse-upload-note")
    assert "column u" in message and "row" in message and "oops" in message, message


def test_a_record_is_mapped_cut_detrended_drawn_and_estimated(student, tmp_path):
    page = student
    page.locator(".bk-tab", has_text="Frequency domain").first.click()
    page.get_by_role("button", name="Run experiment and estimate").click()
    page.wait_for_selector(".eha-freq-summary >> text=Validation on a fresh excitation", timeout=90_000)
    record = _download(page, "Data (CSV)").splitlines()
    assert record[0] == "t[s],r[m],x[m],u[V]"                 # the header names the units
    # the same record as a lab's logger would name it: time, cmd, pos in mm
    renamed = tmp_path / "lab.csv"
    rows = [line.split(",") for line in record[1:]]
    renamed.write_text("time,cmd,pos[mm]\n" + "".join(f"{r[0]},{r[1]},{float(r[2]) * 1e3:.9g}\n" for r in rows))
    page.locator(".eha-freq-upload input[type=file]").set_input_files(str(renamed))
    page.wait_for_selector(".eha-freq-record-mapping >> text=Use these columns", timeout=60_000)
    # a question with its guesses (names, then units), not an error
    page.wait_for_selector(".eha-freq-record-mapping >> text=Which columns of lab.csv are which?", timeout=10_000)
    assert page.locator(".eha-map-y select").input_value() == "pos[mm]"
    for column, name in (("t", "time"), ("u", "cmd"), ("y", "pos[mm]")):
        page.locator(f".eha-map-{column} select").select_option(name)
    page.get_by_role("button", name="Use these columns").click()
    page.wait_for_selector(".eha-freq-record-note >> text=Your record: lab.csv, 1000 samples", timeout=60_000)
    page.locator(".eha-freq-record-data canvas").first.wait_for(state="visible", timeout=60_000)
    page.locator(".eha-freq-record-detrend select").select_option(label="a linear trend")
    page.wait_for_selector(".eha-record-data-note >> text=a linear trend removed", timeout=60_000)
    window = page.locator(".eha-freq-record-window input")
    window.nth(0).fill("1")
    window.nth(0).press("Enter")
    page.wait_for_selector(".eha-record-data-note >> text=Estimation on t ∈ [1,", timeout=60_000)
    window.nth(1).fill("99")
    window.nth(1).press("Enter")
    page.wait_for_selector("text=to t = 99 is not allowed: your record runs from 0 to 9.99 s", timeout=60_000)
    assert page.get_by_role("button", name="Estimate from your record").is_disabled()
    window.nth(1).fill("")
    window.nth(1).press("Enter")
    page.wait_for_function(
        "() => !document.querySelector('.eha-freq-record-run button')?.disabled", timeout=60_000)
    page.get_by_role("button", name="Estimate from your record").click()
    page.wait_for_selector(".eha-freq-record-summary >> text=Validated on the last", timeout=90_000)
    summary = text_of(page, ".eha-freq-record-summary")
    assert "lab.csv" in summary and "A linear trend was removed" in summary and "t ∈ [1," in summary
    with page.expect_download() as download:
        page.locator(".eha-dl-record-csv").get_by_role("button").first.click()
    estimate = open(download.value.path(), encoding="utf-8").read().splitlines()
    assert "lab.csv" in json.loads(_download_class(page, "eha-dl-record-json"))["settings"]["file"]
    assert estimate[0].startswith("coefficient,of,power_of_s,unit,value,std_error")        # units named
    assert [line.split(",")[0] for line in estimate[1:4]] == ["a1", "a2", "a3"]
    if SHOTS:
        page.locator(".eha-freq-record-data").scroll_into_view_if_needed()
        page.screenshot(path=os.path.join(SHOTS, "record_1366.png"), full_page=True)
    # on an 800 px screen the record's two panels share the results column: no sideways scrolling
    page.set_viewport_size({"width": 800, "height": 900})
    wait_until(lambda: page.evaluate("document.documentElement.scrollWidth") <= 800, timeout=20,
               message="the page to fit 800 px")
    if SHOTS:
        page.screenshot(path=os.path.join(SHOTS, "record_800.png"), full_page=True)
