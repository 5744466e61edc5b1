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
import pytest

from eha_app.runtime import patches


def test_the_libraries_are_the_versions_the_patches_were_written_for():
    """An upgrade fails here: check each patch below (and in the browser), then move WRITTEN_FOR."""
    assert panel.__version__.startswith(patches.WRITTEN_FOR["panel"] + ".")
    assert bokeh.__version__.startswith(patches.WRITTEN_FOR["bokeh"] + ".")
    assert sys.version_info[:2] in patches.PYTHONS
    # every patch fits what is installed here: the suite runs with all of them
    assert {name: patches.why_not(name) for name in patches.PATCHES} == dict.fromkeys(patches.PATCHES, "")


def test_the_declared_versions_are_the_tested_ones():
    """pyproject.toml admits the minor versions of Panel and Bokeh the patches were written for and
    the suite runs on, no other (Panel 1.4-1.8 once passed the install and then could not serve)."""
    import re
    from pathlib import Path

    from packaging.requirements import Requirement
    from packaging.version import Version

    text = (Path(__file__).parents[2] / "pyproject.toml").read_text()
    dependencies = re.findall(r'^\s*"((?:panel|bokeh)\b[^"]*)",', text, flags=re.M)
    required = {r.name: r.specifier for r in map(Requirement, dependencies)}
    assert set(required) == set(patches.WRITTEN_FOR)
    for library, minor in patches.WRITTEN_FOR.items():
        major, low = map(int, minor.split("."))
        spec = required[library]
        assert Version(f"{minor}.0") in spec and Version(f"{minor}.99") in spec
        assert Version(f"{major}.{low - 1}.99") not in spec and Version(f"{major}.{low + 1}.0") not in spec
        assert all(p.versions in (None, (minor,)) for p in patches.PATCHES.values() if p.library == library)


@pytest.fixture
def fresh_status(monkeypatch):
    monkeypatch.delenv("EHA_PATCHES_OFF", raising=False)
    patches.forget_status()
    yield
    patches.forget_status()


def test_a_patch_outside_its_versions_is_not_applied_and_says_so(monkeypatch, caplog, fresh_status):
    from bokeh.server.session import ServerSession

    real = patches.installed_version
    monkeypatch.setattr(patches, "installed_version", lambda lib: "3.10.0" if lib == "bokeh" else real(lib))
    monkeypatch.setattr(ServerSession, "unsubscribe", ServerSession.unsubscribe)
    before = ServerSession.unsubscribe
    with caplog.at_level("WARNING", logger="eha_app"):
        status = patches.apply_patches(["disconnects", "loop_has_work"])
        patches.apply_patches(["disconnects"])                  # said once
    assert status == {"disconnects": "bokeh 3.10.0 is not the 3.9 it was written for", "loop_has_work": "applied"}
    assert ServerSession.unsubscribe is before
    lines = [r.getMessage() for r in caplog.records if "disconnects" in r.getMessage()]
    assert lines == ["library patch disconnects not applied: bokeh 3.10.0 is not the 3.9 it was written for; "
                     "the app works without it, slower"]
    # and the run-time readers give way too: no lock is claimed, Bokeh's own freeze is used
    assert not patches.usable("lock_check") and not patches.usable("lazy_freeze")


def test_a_patch_whose_target_moved_is_not_applied(monkeypatch, fresh_status):
    from bokeh.server.session import ServerSession

    monkeypatch.delattr(ServerSession, "unsubscribe")
    assert patches.apply_patches(["disconnects"]) == {
        "disconnects": "bokeh.server.session.ServerSession.unsubscribe not found"}
    monkeypatch.setattr(patches, "_sets_in_init", patches._sets_in_init)
    check = patches._sets_in_init("bokeh.server.session.ServerSession", "_pending_writes", "_no_such_thing")
    assert check() == "bokeh.server.session.ServerSession no longer sets _no_such_thing"


def test_a_patch_can_be_turned_off_for_a_benchmark(monkeypatch, fresh_status):
    monkeypatch.setenv("EHA_PATCHES_OFF", "lazy_freeze, disconnects")
    assert patches.why_not("disconnects") == "turned off by EHA_PATCHES_OFF"
    assert not patches.usable("lazy_freeze") and patches.usable("gc_freeze")
    monkeypatch.setenv("EHA_PATCHES_OFF", "all, component_guard, lazy_freze")
    patches.forget_status()
    # every patch but the security guards (a server without them does not start); a typo is named
    assert {n for n in patches.PATCHES if patches.usable(n)} == set(patches.GUARDS)
    assert patches.unknown_turned_off() == ["lazy_freze"]


def _served_document():
    """A document as a Bokeh server holds it for a session (its session context and session)."""
    import weakref

    from bokeh.document import Document
    from bokeh.models import Div
    from bokeh.server.contexts import BokehSessionContext
    from bokeh.server.session import ServerSession

    doc = Document()
    div = Div(text="first")
    doc.add_root(div)
    context = BokehSessionContext("s", None, doc)
    doc._session_context = weakref.ref(context)
    session = ServerSession("s", doc, io_loop=None, token="t")
    context._set_session(session)
    session.eha_context = context           # the server holds the context; the document only a weak reference
    return doc, div, session


def test_strict_mode_raises_on_a_change_outside_the_lock(fresh_status):
    """A served page's model changed outside its lock raises at once (EHA_STRICT=1); the same change
    under Bokeh's own lock goes through."""
    doc, div, session = _served_document()
    patches.note_loop_thread()
    assert patches.apply_patches(["strict"]) == {"strict": "applied"}
    with pytest.raises(patches.UnlockedChange, match=r"Div\.text changed outside the page's lock"):
        div.text = "unlocked"

    async def locked():
        await session.with_document_locked(lambda: setattr(div, "text", "locked"))

    asyncio.run(locked())
    assert div.text == "locked"


def test_holds_lock_claims_no_lock_it_cannot_see(fresh_status):
    doc, _, session = _served_document()
    patches.note_loop_thread()
    session._pending_writes = []
    assert patches.holds_lock(doc)                      # Bokeh's lock held, on the loop's thread
    del session._pending_writes
    assert not patches.holds_lock(doc)                  # what it reads is missing: not locked
    del doc.session_context._session
    assert not patches.holds_lock(doc)
    doc.session_context._session = None                 # the page being built: nobody else has it
    assert patches.holds_lock(doc)

    class NotServed:
        session_context = None

    assert patches.holds_lock(NotServed())


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
