"""A class server under a scan: Panel's /components/ route and websockets from other websites.

On 58ceb4b one GET of ``/components/eha_app.cli.__main__/x/_css/a`` ended the
server (Panel imported the module the URL named, and it re-read the server's
command line), and ``--address 0.0.0.0`` accepted websockets from any origin:
any website a student had open could use the class server through their browser.
"""

from __future__ import annotations

import asyncio
import re
import urllib.error
import urllib.request

import pytest
from tornado.httpclient import HTTPClientError, HTTPRequest
from tornado.websocket import websocket_connect

_TOKEN = re.compile(r'"token"\s*:\s*"([^"]+)"')

#: What a scan of the route tries: modules that run code when imported, the entry script, the
#: standard library, modules of the project that are no components, paths that go elsewhere.
SCAN = [
    "eha_app.cli.__main__/x/_css/a",
    "eha_app.eha/x/_css/a",
    "eha_app.cli/main/_css/a",
    "eha_app.cli.serve/run/__css__/a",
    "this/x/_css/a",
    "antigravity/x/_css/a",
    "os/system/_css/a",
    "subprocess/Popen/_css/a",
    "tests.conftest/x/_css/a",
    "benchmarks.bench_classroom/Server/_css/a",
    "tools.screenshots/main/_css/a",
    "panel.command/main/_css/a",
    "eha_app.session.form/Form/_stylesheets/..%2F..%2F..%2Fetc%2Fpasswd",
    "eha_app.session.form/Form/__javascript__/../../pyproject.toml",
    "..%2F..%2Fetc/passwd/_css/a",
    "a/b",
]


def _status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as exc:
        return exc.code


def _components(server) -> str:
    return server.url.rsplit("/", 1)[0] + "/components/"


@pytest.mark.parametrize("procs", ["1", "2"])
def test_the_server_survives_a_scan_of_the_components_route(serve, procs):
    server = serve("--num-procs", procs, "--workers", "1")
    statuses = {path: _status(_components(server) + path) for path in SCAN}
    # nothing is served, nothing is imported; the same server answers afterwards
    assert all(code in (400, 403, 404) for code in statuses.values()), statuses
    for _ in range(int(procs) * 4):                     # every process (SO_REUSEPORT spreads them)
        assert _status(server.url) == 200
    assert server.proc.poll() is None
    log = server.log_text()
    assert "Beautiful is better than ugly" not in log and "eha: error" not in log, log[-3000:]
    assert "exited with code" not in log and "Traceback" not in log, log[-3000:]
    # every process bound the one port (eha_app.runtime.patches.bind_port_shared took effect)
    pids = set(re.findall(r"Starting Bokeh server with process id: (\d+)", log))
    assert len(pids) == int(procs), log[-3000:]


async def _websocket_status(url: str, origin: str) -> int:
    """101 when the page's websocket opens with this ``Origin``, else the HTTP status of the refusal."""
    with urllib.request.urlopen(url, timeout=30) as r:
        token = _TOKEN.search(r.read().decode()).group(1)
    ws_url = url.replace("http://", "ws://") + "/ws"
    try:
        ws = await websocket_connect(HTTPRequest(ws_url, headers={"Origin": origin}), subprotocols=["bokeh", token])
    except HTTPClientError as exc:
        return exc.code
    ws.close()
    return 101


def test_a_page_from_another_website_cannot_open_a_session(serve):
    server = serve("--address", "0.0.0.0", "--workers", "1")
    port = server.port
    codes = asyncio.run(_statuses(server.url, [f"http://127.0.0.1:{port}", f"http://localhost:{port}",
                                               "http://evil.example", f"http://evil.example:{port}",
                                               "null"]))
    assert codes[:2] == [101, 101] and codes[2:] == [403, 403, 403], codes
    log = server.log_text()
    shown = re.search(r"Pages may connect from (.*)", log).group(1)
    assert f"localhost:{port}" in shown and "*" not in shown
    assert "Refusing websocket connection from Origin 'http://evil.example'" in log


def test_any_origin_only_when_the_teacher_asks_for_it(serve):
    server = serve("--allow-websocket-origin", "*", "--workers", "1")
    codes = asyncio.run(_statuses(server.url, ["http://evil.example"]))
    assert codes == [101]


async def _statuses(url, origins):
    return [await _websocket_status(url, o) for o in origins]
