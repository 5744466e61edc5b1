"""Every answer of a real ``eha serve`` carries the security headers, and a very long address gets an answer.

The headers (``eha_app.runtime.serving.security_headers``): a Content-Security-Policy that refuses
every frame (``frame-ancestors 'none'``), ``X-Frame-Options: DENY`` and ``X-Content-Type-Options:
nosniff``, once each, on the app's page, the teacher's dashboard, static files, autoload scripts, the
server's 302, 400, 403, 404, 405 and 414 answers and the websocket's own answers, in one process and in
two, with and without an exercise, and behind nginx (whose own answers carry them too).
"""

from __future__ import annotations

import asyncio
import http.client
import re
import subprocess

import pytest
from tornado.httpclient import HTTPClientError, HTTPRequest
from tornado.websocket import websocket_connect

from eha_app.runtime.serving import (
    MAX_ADDRESS_CHARS,
    MAX_HEADER_FIELDS_BYTES,
    MAX_REQUEST_HEAD_BYTES,
    nginx_standalone_config,
    security_headers,
)
from eha_app.runtime.teacher_access import COOKIE
from eha_core.exercise import Exercise
from tests.serve.conftest import dashboard_token, free_port, wait_http
from tests.serve.test_nginx import NGINX

SECURITY = ("content-security-policy", "x-frame-options", "x-content-type-options")


def _request(port: int, path: str, *, method: str = "GET", headers: dict | None = None):
    """One request on a new connection (two processes on one port both get some): (status, headers as
    (lower-case name, value) pairs, body)."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    try:
        conn.request(method, path, headers=headers or {})
        r = conn.getresponse()
        return r.status, [(k.lower(), v) for k, v in r.getheaders()], r.read().decode("utf-8", "replace")
    finally:
        conn.close()


def _assert_secure(port: int, path: str, status: int, *, host: str | None = "own", method: str = "GET",
                   headers: dict | None = None) -> str:
    """``path`` is answered ``status`` with the security headers for ``host`` (default: the server's
    address), each exactly once; returns the body."""
    got, pairs, body = _request(port, path, method=method, headers=headers)
    assert got == status, (path, got, body[:300])
    expected = security_headers(f"127.0.0.1:{port}" if host == "own" else host)
    for name in SECURITY:
        values = [v for k, v in pairs if k == name]
        assert values == [expected[next(k for k in expected if k.lower() == name)]], (path, name, values)
    policy = dict(pairs)["content-security-policy"]
    assert "frame-ancestors 'none'" in policy and "default-src 'none'" in policy
    return body


async def _websocket_status(port: int, path: str, origin: str) -> tuple[int, list]:
    """The status and headers of a websocket's opening handshake (refused: the HTTP answer's)."""
    try:
        ws = await websocket_connect(HTTPRequest(f"ws://127.0.0.1:{port}{path}", headers={"Origin": origin}))
    except HTTPClientError as exc:
        return exc.code, [(k.lower(), v) for k, v in exc.response.headers.get_all()]
    headers = [(k.lower(), v) for k, v in ws.headers.get_all()]
    ws.close()
    return 101, headers


def _app_paths(port: int) -> list[tuple[str, int]]:
    """Every kind of path the app's server answers, with its status."""
    return [("/eha", 200), ("/eha/", 200), ("/eha/metadata", 200),
            (f"/eha/autoload.js?bokeh-autoload-element=x&bokeh-absolute-url=http://127.0.0.1:{port}/eha", 200),
            ("/eha/autoload.js", 400), ("/eha/ws", 400),
            ("/static/js/bokeh.min.js", 200), ("/static/extensions/panel/panel.min.js", 200), ("/favicon.ico", 200),
            ("/static/nothing.js", 404), ("/nothing", 404), ("/components/this/x/_css/a", 404)]


def _exercise(tmp_path) -> str:
    path = tmp_path / "class.json"
    Exercise.new(hide=("M", "B"), title="Lab 3", roster=[("s1", "Ada Lovelace")]).save(path)
    return str(path)


@pytest.mark.parametrize("setting", ["one process", "an exercise in two processes"])
def test_every_answer_carries_the_security_headers(serve, tmp_path, setting):
    exercise = setting.startswith("an exercise")
    args = ("--exercise", _exercise(tmp_path), "--num-procs", "2") if exercise else ()
    server = serve(*args, "--workers", "1")
    port = server.port
    for _ in range(3 if exercise else 1):           # new connections: both processes answer some
        for path, status in _app_paths(port):
            _assert_secure(port, path, status)
        _assert_secure(port, "/eha", 405, method="POST")
        _assert_secure(port, "/", 302)
        # a page of another website may not open a session: refused, with the headers too
        status, pairs = asyncio.run(_websocket_status(port, "/eha/ws", "http://evil.example"))
        assert status == 403 and dict(pairs)["x-frame-options"] == "DENY", (status, pairs)
        if not exercise:
            _assert_secure(port, "/teacher", 404)
            continue
        for path in ("/teacher", "/teacher/autoload.js", "/teacher/metadata", "/teacher?token=" + "0" * 40):
            _assert_secure(port, path, 403)
    assert "Traceback" not in server.log_text()


def test_the_teachers_dashboard_carries_the_security_headers(serve, tmp_path):
    path = _exercise(tmp_path)
    server = serve("--exercise", path, "--workers", "1")
    port = server.port
    token = dashboard_token(path)
    _, pairs, _ = _request(port, f"/teacher?token={token}")
    _assert_secure(port, f"/teacher?token={token}", 302)
    cookie = re.search(rf"{COOKIE}=([^;]+);", next(v for k, v in pairs if k == "set-cookie" and COOKIE in v))
    page = _assert_secure(port, "/teacher", 200, headers={"Cookie": f"{COOKIE}={cookie.group(1)}"})
    assert "Lab 3" in page
    assert "Traceback" not in server.log_text()


def test_a_very_long_address_gets_an_answer_that_says_what_to_do(serve):
    server = serve("--workers", "1")
    port = server.port
    body = _assert_secure(port, "/eha?" + "a" * 70_000, 414)
    assert "URI Too Long" in body and "70,005 characters" in body and "/eha" in body, body
    assert len(body) < 300
    _assert_secure(port, "/eha/" + "x" * (MAX_ADDRESS_CHARS + 1), 414)
    # up to the bound, the app itself answers
    _assert_secure(port, "/eha?" + "a" * (MAX_ADDRESS_CHARS - 10), 200)
    _assert_secure(port, "/eha?case=3", 200)
    # header fields beyond what the server reads: 431, with what to do
    body = _assert_secure(port, "/eha", 431, headers={"Cookie": "a=" + "b" * MAX_HEADER_FIELDS_BYTES})
    assert "Request Header Fields Too Large" in body and "cookies" in body, body
    # beyond what the server reads at all, the connection is closed (the documented bound)
    with pytest.raises((ConnectionError, http.client.HTTPException)):
        _request(port, "/eha?" + "a" * (MAX_REQUEST_HEAD_BYTES + 1))
    # and the server is still there
    _assert_secure(port, "/eha", 200)
    assert "Traceback" not in server.log_text()


@pytest.mark.skipif(NGINX is None, reason="nginx not found: apt-get install -y nginx")
def test_behind_nginx_the_apps_answers_and_nginxs_own_carry_the_headers_once(serve, tmp_path):
    listen = free_port()
    backend = serve("--behind-proxy", "--workers", "1", "--allow-websocket-origin", f"127.0.0.1:{listen}")
    work = tmp_path / "nginx"
    work.mkdir()
    conf = work / "nginx.conf"
    conf.write_text(nginx_standalone_config([f"127.0.0.1:{backend.port}"], listen=f"127.0.0.1:{listen}",
                                            workdir=str(work)))
    test = subprocess.run([NGINX, "-t", "-c", str(conf), "-p", str(work)], capture_output=True, text=True)
    assert test.returncode == 0, test.stderr
    proc = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(work)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.STDOUT)
    try:
        wait_http(f"http://127.0.0.1:{listen}/eha", proc, timeout=30)
        # the app's answers, passed on (the app sees the address the browser used, through nginx's Host)
        for path, status in _app_paths(listen):
            _assert_secure(listen, path, status)
        _assert_secure(listen, "/teacher", 404)
        # nginx's own: its redirect of /, its 414 (past its 8 KiB request line), a backend that is gone
        _assert_secure(listen, "/", 302, host=None)
        body = _assert_secure(listen, "/eha?" + "a" * 70_000, 414, host=None)
        assert "414" in body
        backend.stop()
        _assert_secure(listen, "/eha", 502, host=None)
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    assert "[emerg]" not in (work / "error.log").read_text()
