"""Uploads and the page's address under abuse, in a real browser.

On 58ceb4b a 19 MB CSV (under the app's own 20 MB limit) closed the websocket
and the page fell back to its first screen, a 1.56 MB .mat that inflates to
1.6 GB took the server from 302 MB to 4.87 GB, and a 70,000-character field
made the page's address too long to load again.
"""

from __future__ import annotations

import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

from eha_app.session.state import MAX_TEXT_CHARS
from tests.app.test_hardening import _csv_of_size, mat_bomb
from tests.ui.browser_helpers import ROOT, _free_port, text_of, wait_until

MB = 1_000_000


def _student(browser, url):
    context = browser.new_context(viewport={"width": 1366, "height": 900})
    page = context.new_page()
    problems, sent = [], []
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.on("websocket", lambda ws: ws.on("framesent", lambda f: sent.append(len(f))))
    page.goto(url)
    page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
    page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
    page.locator(".eha-lse-upload input[type=file]").wait_for(state="attached", timeout=60_000)
    return context, page, problems, sent


def _alive(page) -> bool:
    """The page still talks to its server: no 'connection lost' notice, and a click gets an answer."""
    if page.locator(".eha-offline").count():
        return False
    page.get_by_role("button", name="Run least squares").click()
    page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
    return page.locator(".eha-offline").count() == 0


def test_a_file_over_the_limit_is_refused_in_the_page_before_it_is_sent(browser, server, tmp_path):
    context, page, problems, sent = _student(browser, server)
    big = tmp_path / "too_big.csv"
    big.write_bytes(b"t,u\n" + b"0,0\n" * (25 * MB // 4))
    before = len(sent)
    page.locator(".eha-lse-upload input[type=file]").set_input_files(str(big))
    refused = page.locator(".eha-lse-upload .eha-upload-refused")
    wait_until(lambda: "not allowed" in refused.inner_text(), 10, message="the refusal beside the upload")
    assert refused.inner_text() == "your file = 'too_big.csv' is not allowed: it has 25.0 MB; at most 20 MB"
    assert max(sent[before:], default=0) < 100_000                 # not a byte of the file went out
    assert _alive(page)
    context.close()
    assert not problems, problems


def test_a_file_at_the_limit_is_read_and_the_page_stays(browser, server, tmp_path):
    context, page, problems, sent = _student(browser, server)
    data = tmp_path / "limit.csv"
    data.write_bytes(_csv_of_size(20 * MB))
    assert 20 * MB - 100 < data.stat().st_size <= 20 * MB
    page.locator(".eha-lse-upload input[type=file]").set_input_files(str(data))
    page.wait_for_selector(".eha-lse-upload-note >> text=Using your data: limit.csv", timeout=120_000)
    assert "273" in text_of(page, ".eha-lse-upload-note")           # its 273,000 samples were read
    assert max(sent) >= 20 * MB - 100                              # the file went as one message of raw bytes
    assert page.locator(".eha-offline").count() == 0
    context.close()
    assert not problems, problems


@pytest.fixture
def own_server(tmp_path):
    """A server of this test's own, so that its memory is this test's."""
    port = _free_port()
    log = open(tmp_path / "server.log", "w")
    proc = subprocess.Popen([str(Path(sys.executable).with_name("eha")), "serve", "--port", str(port),
                             "--address", "127.0.0.1", "--workers", "1"], cwd=ROOT, stdout=log,
                            stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}/eha"

    def up():
        assert proc.poll() is None, "the server exited"
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                return r.status == 200
        except OSError:
            return False

    wait_until(up, timeout=120, interval=0.2, message="the server")
    yield url, proc.pid
    proc.terminate()
    proc.wait(timeout=20)
    log.close()


def _memory_mb(pid: int) -> dict:
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if ":" in line)
    return {k: int(fields[k].split()[0]) / 1024 for k in ("VmRSS", "VmHWM")}


def test_a_decompression_bomb_gets_a_message_and_the_server_stays_within_its_memory(browser, own_server, tmp_path):
    from eha_app.runtime.limits import max_bytes

    url, pid = own_server
    context, page, problems, _ = _student(browser, url)
    before = _memory_mb(pid)
    bomb = tmp_path / "bomb.mat"
    bomb.write_bytes(mat_bomb(200_000_000))                        # 1.56 MB, 1.6 GB inflated
    page.locator(".eha-lse-upload input[type=file]").set_input_files(str(bomb))
    page.wait_for_selector(".eha-lse-upload-note >> text=once decompressed", timeout=60_000)
    assert "bomb.mat' is not allowed: it holds more than 20 MB once decompressed" in text_of(
        page, ".eha-lse-upload-note")
    after = _memory_mb(pid)
    grew = after["VmHWM"] - max(before["VmHWM"], before["VmRSS"])
    assert grew < max_bytes() / 2**20, (before, after)            # within one request's memory limit
    assert _alive(page)
    context.close()
    assert not problems, problems


def _address(page) -> str:
    return page.evaluate("() => location.href")


def test_a_very_long_field_stays_out_of_the_address_and_the_page_reloads(browser, server):
    context = browser.new_context(viewport={"width": 1366, "height": 900})
    page = context.new_page()
    page.goto(server)
    page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
    field = page.locator(".eha-field-M input").first
    field.click()
    field.press("Control+a")
    page.keyboard.insert_text("2" * 70_000)                       # a paste of 70,000 characters
    # the address as the page has it (Playwright's page.url can miss a replaceState)
    wait_until(lambda: "M=222" in _address(page), 15, message="the field in the address")
    assert field.input_value() == "2" * MAX_TEXT_CHARS            # the field holds what it may
    assert len(_address(page)) < 2000, len(_address(page))
    page.reload()                                                 # the address still loads, with the field
    page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
    wait_until(lambda: page.locator(".eha-field-M input").first.input_value() == "2" * MAX_TEXT_CHARS, 15,
               message="the field restored from the address")
    context.close()
