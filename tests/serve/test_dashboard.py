"""The teacher's dashboard on a real server: only the teacher's token opens it, and the token goes nowhere else.

``GET /teacher?token=T`` sets the teacher's cookie and redirects to /teacher;
anything under /teacher (page, websocket, autoload, metadata) without that
cookie gets 403, with one or two processes (each derives the same token from
the exercise's secret); without an exercise there is no /teacher at all.
"""

from __future__ import annotations

import asyncio
import http.client
import re

import pytest
from tornado.httpclient import HTTPClientError, HTTPRequest
from tornado.websocket import websocket_connect

from eha_app.runtime.teacher_access import COOKIE, cookie_value
from eha_core.exercise import Exercise
from tests.serve.conftest import dashboard_token

_SESSION_TOKEN = re.compile(r'"token"\s*:\s*"([^"]+)"')


def _exercise(tmp_path) -> tuple[Exercise, str]:
    ex = Exercise.new(hide=("M", "B"), title="Lab 3", roster=[("s1", "Ada Lovelace"), ("s2", "Alan Turing")])
    path = tmp_path / "class.json"
    ex.save(path)
    return ex, str(path)


def _get(port: int, path: str, cookie: str | None = None) -> tuple[int, dict, str]:
    """One request on a new connection (so that two processes on one port both get some), no redirect followed."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        conn.request("GET", path, headers={"Cookie": f"{COOKIE}={cookie}"} if cookie else {})
        r = conn.getresponse()
        headers: dict[str, str] = {}
        for k, v in r.getheaders():         # several Set-Cookie behind nginx: one line each
            headers[k.lower()] = headers[k.lower()] + "\n" + v if k.lower() in headers else v
        return r.status, headers, r.read().decode("utf-8", "replace")
    finally:
        conn.close()


async def _websocket(port: int, cookie: str | None, session_token: str = "x") -> int:
    headers = {"Origin": f"http://127.0.0.1:{port}"}
    if cookie:
        headers["Cookie"] = f"{COOKIE}={cookie}"
    try:
        ws = await websocket_connect(HTTPRequest(f"ws://127.0.0.1:{port}/teacher/ws", headers=headers),
                                     subprotocols=["bokeh", session_token])
    except HTTPClientError as exc:
        return exc.code
    ws.close()
    return 101


@pytest.mark.parametrize("procs", ["1", "2"])
def test_only_the_teacher_reaches_the_dashboard(serve, tmp_path, procs):
    ex, path = _exercise(tmp_path)
    server = serve("--exercise", path, "--num-procs", procs, "--workers", "1")
    token = dashboard_token(path)
    port = server.port
    for _ in range(2 * int(procs)):                 # new connections: every process answers some
        for p in ("/teacher", "/teacher/", "/teacher/autoload.js", "/teacher/metadata", "/teacher?token=" + "0" * 40,
                  f"/teacher/ws?token={token}", "/Teacher", "//teacher", "/te%61cher"):
            assert _get(port, p)[0] == 403, p
        assert _get(port, "/teacher", cookie="0" * 64)[0] == 403
        assert asyncio.run(_websocket(port, None)) == 403
        assert asyncio.run(_websocket(port, "0" * 64)) == 403
        # the token: a cookie for /teacher only, and the address without it
        status, headers, _ = _get(port, f"/teacher?token={token}")
        assert status == 302 and headers["location"] == "teacher", headers
        cookie = next(c for c in headers["set-cookie"].splitlines() if c.startswith(COOKIE))
        assert re.search(rf"{COOKIE}=([0-9a-f]+);", cookie).group(1) == cookie_value(token)
        assert "HttpOnly" in cookie and "SameSite=Lax" in cookie and "Path=/teacher" in cookie, cookie
        status, _, page = _get(port, "/teacher", cookie=cookie_value(token))
        assert status == 200 and "Lab 3" in page and token not in page
        # the page's websocket opens with the cookie (and its session token)
        session_token = _SESSION_TOKEN.search(page).group(1)
        assert asyncio.run(_websocket(port, cookie_value(token), session_token)) == 101
        # a student's page knows neither the token nor the cookie; the root goes to the app, not to a list of apps
        status, _, student = _get(port, "/eha")
        assert status == 200 and token not in student and cookie_value(token) not in student
        assert "/teacher" not in student
        assert _get(port, "/")[0] == 302
    log = server.log_text()
    # the token is printed once, for the teacher; the access log hides it where a request carried it
    lines = [line for line in log.splitlines() if token in line]
    assert len(lines) == 1 and lines[0].startswith("Teacher's dashboard (for you only"), lines
    assert "/teacher/ws?token=[hidden]" in log
    assert "Traceback" not in log, log[-3000:]


def test_without_an_exercise_there_is_no_dashboard(serve):
    server = serve("--workers", "1")
    for p in ("/teacher", "/teacher?token=" + "0" * 40, "/teacher/ws"):
        assert _get(server.port, p)[0] == 404, p
    assert _get(server.port, "/eha")[0] == 200
    assert "Teacher's dashboard" not in server.log_text()


def test_the_dashboard_through_nginx(serve, tmp_path):
    """nginx's configuration (``eha serve --nginx-config``) passes /teacher, its cookie and its websocket."""
    import subprocess

    from eha_app.runtime.serving import nginx_standalone_config
    from tests.serve.conftest import free_port, wait_http
    from tests.serve.test_nginx import NGINX

    if NGINX is None:
        pytest.skip("nginx not found")
    ex, path = _exercise(tmp_path)
    listen = free_port()
    backend = serve("--exercise", path, "--behind-proxy", "--workers", "1", "--allow-websocket-origin",
                    f"127.0.0.1:{listen}")
    token = dashboard_token(path)
    work = tmp_path / "nginx"
    work.mkdir()
    conf = work / "nginx.conf"
    conf.write_text(nginx_standalone_config([f"127.0.0.1:{backend.port}"], listen=f"127.0.0.1:{listen}",
                                            workdir=str(work)))
    proc = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(work)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.STDOUT)
    try:
        wait_http(f"http://127.0.0.1:{listen}/eha", proc, timeout=30)
        assert _get(listen, "/teacher")[0] == 403
        assert asyncio.run(_websocket(listen, None)) == 403
        status, headers, _ = _get(listen, f"/teacher?token={token}")
        assert status == 302 and headers["location"] == "teacher"
        assert f"{COOKIE}={cookie_value(token)}" in headers["set-cookie"], headers
        status, _, page = _get(listen, "/teacher", cookie=cookie_value(token))
        assert status == 200 and token not in page
        assert asyncio.run(_websocket(listen, cookie_value(token), _SESSION_TOKEN.search(page).group(1))) == 101
        assert token not in (work / "access.log").read_text()       # nginx logs the URLs it passes, but these
        assert "/eha" in (work / "access.log").read_text()
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_a_rotated_or_expired_link_stops_opening_the_dashboard(serve, tmp_path):
    """A leaked link is undone on the running server (both processes) by `eha exercise token --rotate`,
    and a link past its expiry says so; the students' pages are untouched."""
    import subprocess
    import time

    from eha_app.runtime.handins import HandIns
    from tests.serve.conftest import EHA

    ex, path = _exercise(tmp_path)
    server = serve("--exercise", path, "--num-procs", "2", "--workers", "1")
    old = dashboard_token(path)
    assert f"/teacher?token={old}" in server.log_text() and "valid until" in server.log_text()
    assert _get(server.port, f"/teacher?token={old}")[0] == 302
    out = subprocess.run([str(EHA), "exercise", "token", path, "--rotate"], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    new = re.search(r"token=([0-9a-f]{40})", out.stdout).group(1)
    assert new == dashboard_token(path) != old

    def statuses(token, cookie=None):          # several requests: both processes answer some
        return {_get(server.port, f"/teacher?token={token}" if token else "/teacher", cookie)[0] for _ in range(8)}

    deadline = time.monotonic() + 30
    while statuses(old) != {403} or statuses(new) != {302} or statuses(None, cookie_value(old)) != {403}:
        assert time.monotonic() < deadline, (statuses(old), statuses(new))
        time.sleep(0.5)
    assert statuses(None, cookie_value(new)) == {200}
    HandIns(path).set_controls({"token_expires": "1000"})          # the link's time is up
    deadline = time.monotonic() + 30
    while statuses(new) != {403}:
        assert time.monotonic() < deadline
        time.sleep(0.5)
    status, _, body = _get(server.port, f"/teacher?token={new}")
    assert "this dashboard link has expired" in body and "eha exercise token" in body
    assert _get(server.port, "/eha")[0] == 200
    assert new not in server.log_text().split("valid until")[-1] and "Traceback" not in server.log_text()
