"""Every change the server makes to a library's internals still takes effect (eha_app/runtime/patches.py).

The component route and the shared port are also checked against running
servers (tests/serve/test_hardening.py), the page's one layout per message in
Chromium (tests/ui/test_patches_in_browser.py), the strict mode by every server
of the suite.
"""

from __future__ import annotations

import asyncio
import json
import socket
import subprocess
import sys
import textwrap

import bokeh
import panel

from eha_app.runtime import patches


def test_the_libraries_are_the_versions_the_patches_were_written_for():
    """An upgrade fails here: check each patch below (and in the browser), then move WRITTEN_FOR."""
    assert panel.__version__.startswith(patches.WRITTEN_FOR["panel"] + ".")
    assert bokeh.__version__.startswith(patches.WRITTEN_FOR["bokeh"] + ".")
    assert sys.version_info[:2] in patches.PYTHONS


def test_the_loop_says_when_it_has_work():
    async def probe():
        loop = asyncio.get_running_loop()
        idle = patches.loop_has_work(loop)
        loop.call_soon(lambda: None)
        busy = patches.loop_has_work(loop)
        await asyncio.sleep(0)
        await asyncio.sleep(0)
        return idle, busy, patches.loop_has_work(loop)

    assert asyncio.run(probe()) == (False, True, False)

    class OtherLoop:                    # uvloop and the like: no way to tell, so never busy
        _ready = [1, 2]

    assert patches.loop_has_work(OtherLoop()) is False


def test_two_servers_can_bind_one_port(monkeypatch):
    import bokeh.server.server as bokeh_server

    monkeypatch.setattr(bokeh_server, "bind_sockets", bokeh_server.bind_sockets)
    patches.bind_port_shared()
    patches.bind_port_shared()                           # twice is once
    assert bokeh_server.bind_sockets.eha_shared
    first, port = bokeh_server.bind_sockets("127.0.0.1", 0)
    second, again = bokeh_server.bind_sockets("127.0.0.1", port)
    try:
        assert again == port and all(s.getsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT) for s in first + second)
    finally:
        for s in first + second:
            s.close()


def test_the_layout_patch_reports_itself_and_is_in_every_page():
    from eha_app.app import create_app
    from eha_app.runtime.connection import ConnectionWatch

    assert "function ehaLayoutOncePerMessage(doc)" in ConnectionWatch._esm
    assert "model.patches = applied" in ConnectionWatch._esm
    page = create_app()
    assert isinstance(page.connection, ConnectionWatch) and page.layout.objects[0] is page.connection


def test_the_teacher_paths_are_answered_before_bokehs_routes(monkeypatch, tmp_path):
    """Bokeh's application asks :func:`eha_app.runtime.teacher_access.route` first (patches.guard_paths)."""
    from bokeh.application import Application
    from bokeh.server.tornado import BokehTornado
    from tornado.httputil import HTTPHeaders, HTTPServerRequest, RequestStartLine

    from eha_app.runtime import teacher_access
    from eha_core.exercise import Exercise

    patches.guard_paths(teacher_access.route)
    patches.guard_paths(teacher_access.route)             # a second call changes nothing
    app = BokehTornado({"/eha": Application(), "/teacher": Application()})

    def handler(uri, cookie=None):
        headers = HTTPHeaders({"Host": "localhost"})
        if cookie:
            headers["Cookie"] = f"{teacher_access.COOKIE}={cookie}"
        d = app.find_handler(HTTPServerRequest(headers=headers, start_line=RequestStartLine("GET", uri, "HTTP/1.1")))
        return d.handler_class.__name__, (d.handler_kwargs or {}).get("status_code")

    monkeypatch.delenv("EHA_EXERCISE", raising=False)
    assert handler("/teacher") == ("ErrorHandler", 404)
    ex = Exercise.new(hide=("M",))
    ex.save(tmp_path / "class.json")
    monkeypatch.setenv("EHA_EXERCISE", str(tmp_path / "class.json"))
    assert handler("/teacher/ws") == ("ErrorHandler", 403)
    from eha_app.runtime.handins import HandIns

    token = teacher_access.ensure_token(ex, HandIns(tmp_path / "class.json").check())[0].token
    assert handler(f"/teacher?token={token}")[0] == "_Login"
    assert handler("/teacher/ws", teacher_access.cookie_value(token))[0] == "WSHandler"
    assert handler("/eha")[0] == "DocHandler"


def test_the_servers_websockets_send_each_frame_at_once(monkeypatch):
    """Bokeh writes a message as several frames (the reason for the patch); a connection opened by
    Bokeh's handler turns Nagle's algorithm off before Bokeh's own opening."""
    import inspect

    from bokeh.protocol.message import Message
    from bokeh.server.views.ws import WSHandler

    assert inspect.getsource(Message.send).count("write_message(") >= 3
    calls = []
    monkeypatch.setattr(WSHandler, "open", lambda self: calls.append("bokeh's open"))
    patches.websocket_nodelay()
    patches.websocket_nodelay()                 # twice: one wrapper

    class Handler:
        def set_nodelay(self, value):
            calls.append(("nodelay", value))

    WSHandler.open(Handler())
    assert calls == [("nodelay", True), "bokeh's open"]


def test_a_pages_message_asks_a_study_to_give_way(monkeypatch):
    from bokeh.server.views.ws import WSHandler

    from eha_app.runtime import background

    seen = []

    async def bokehs(self, fragment):
        seen.append(("bokeh", fragment))

    monkeypatch.setattr(WSHandler, "on_message", bokehs)
    monkeypatch.setattr(background, "give_way_now", lambda: seen.append("give way"))
    patches.give_way_on_messages()
    patches.give_way_on_messages()              # twice: one wrapper
    asyncio.run(WSHandler.on_message(object(), "frame"))
    assert seen == ["give way", ("bokeh", "frame")]


def test_full_collections_come_after_three_young_ones_on_a_thread_of_their_own():
    """In a process of its own (the collector's settings are the process's): with CPython's own
    full collections turned off, the full collections that still come are ours, about one per
    FULL_GC_AFTER young ones (the thread may wait its turn while young ones go on), each made on
    the thread; a second call adds no second thread."""
    script = textwrap.dedent("""
        import gc, json, threading, time
        from eha_app.runtime import patches

        patches.collect_often()
        patches.collect_often()
        g0, g1, _ = gc.get_threshold()
        gc.set_threshold(g0, g1, 10**9)         # CPython's own full collections off
        young, full = [0], []

        def seen(phase, info):
            if phase == "stop" and info["generation"] == 1:
                young[0] += 1
            elif phase == "stop" and info["generation"] == 2:
                full.append(threading.current_thread().name)

        gc.callbacks.append(seen)
        for _ in range(60):
            cycles = []
            for i in range(20000):
                c = [i]
                c.append(c)
                cycles.append(c)
            time.sleep(0.01)                    # the collector's thread gets its turn
        time.sleep(0.1)
        print(json.dumps({"young": young[0], "full": full,
                          "threads": sum(t.name == "eha-full-gc" for t in threading.enumerate())}))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True)
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["threads"] == 1
    assert seen["young"] >= 30
    assert set(seen["full"]) == {"eha-full-gc"}
    expected = seen["young"] / patches.FULL_GC_AFTER
    assert 0.5 * expected <= len(seen["full"]) <= expected + 1, seen
