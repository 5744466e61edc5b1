"""Every change the server makes to a library's internals still takes effect (eha_app/runtime/patches.py).

The component route and the shared port are also checked against running
servers (tests/serve/test_hardening.py), the page's one layout per message in
Chromium (tests/ui/test_patches_in_browser.py), the strict mode by every server
of the suite.
"""

from __future__ import annotations

import asyncio
import socket
import sys

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
