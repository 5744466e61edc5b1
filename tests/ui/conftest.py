"""Real-browser tests: the app served by `panel serve`, driven in headless Chromium.

Chromium comes from Debian (`apt-get install chromium`, done by .ci/run);
Playwright drives it through ``executable_path`` (its own browser download does
not work here). Set EHA_CHROMIUM to use another binary. Tests wait on
conditions, never on fixed sleeps.
"""

from __future__ import annotations

import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

from tests.ui.browser_helpers import CHROMIUM_ARGS, ROOT, Session, _chromium, _free_port, wait_until


def pytest_collection_modifyitems(items):
    for item in items:
        if "tests/ui" in str(item.fspath):
            item.add_marker(pytest.mark.ui)


@pytest.fixture(scope="session")
def server():
    port = _free_port()
    # the command a teacher runs (its settings for a class included)
    cmd = [str(Path(sys.executable).with_name("eha")), "serve", "--port", str(port), "--address", "127.0.0.1",
           "--allow-websocket-origin", f"127.0.0.1:{port}"]
    cache = ROOT / ".pytest_cache"
    log = open(cache / "ui_server.log", "w") if cache.exists() else subprocess.DEVNULL
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}/eha"

    def up():
        if proc.poll() is not None:
            pytest.fail(f"the app server exited with code {proc.returncode}")
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                return r.status == 200
        except OSError:
            return False

    wait_until(up, timeout=90, interval=0.2, message="the app server")
    yield url
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()


@pytest.fixture(scope="session")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=_chromium(), args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def session(browser, server):
    s = Session(browser, server)
    yield s
    problems = list(s.console)
    s.close()
    assert not problems, f"browser console: {problems}"


@pytest.fixture
def new_session(browser, server):
    made = []

    def make():
        s = Session(browser, server)
        made.append(s)
        return s

    yield make
    problems = [m for s in made for m in s.console]
    for s in made:
        s.close()
    assert not problems, f"browser console: {problems}"
