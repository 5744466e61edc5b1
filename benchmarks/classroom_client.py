"""Students at the protocol level: what a browser says to the app's server, without drawing.

:class:`StudentSession` is one browser tab, spoken at the Bokeh websocket
protocol (Bokeh 3):

1. ``GET`` the page with a cookie jar of its own (behind nginx the cookies
   carry the session affinity, so they go with the websocket request too);
   the page's embed script holds the session token (``"token": "..."``);
2. open the websocket at ``<page path>/ws?<page query>`` with the
   subprotocols ``["bokeh", token]``; the server sends ``ACK``;
3. ``PULL-DOC-REQ``; the ``PULL-DOC-REPLY`` holds the whole document, every
   model once as ``{"type": "object", "name": ..., "id": ..., "attributes":
   {...}}`` and then by reference, ``{"id": ...}``;
4. a ``PATCH-DOC`` with the ``document_ready`` event, as BokehJS sends once the
   page is drawn.

A message is three text frames (header, metadata, content) and, for each of
the header's ``num_buffers``, a text frame naming the buffer and a binary frame
with its bytes. The session keeps an index of the document's models, updated
from every ``PATCH-DOC`` the server sends (new models arrive inline in the
events and are indexed as they come), and acts on it with the messages BokehJS
sends (checked against bokehjs ``Serializer``/``bokeh_events``, and against the
server, which applies them):

* a property change: ``{"kind": "ModelChanged", "model": {"id": ID}, "attr":
  A, "new": V}`` (a JS object value is encoded as ``{"type": "map",
  "entries": [[k, v], ...]}``);
* a UI event, e.g. a button press: ``{"kind": "MessageSent", "msg_type":
  "bokeh_event", "msg_data": {"type": "event", "name": "button_click",
  "values": {"type": "map", "entries": [["model", {"id": ID}]]}}}``;
  ``document_ready`` has no values, which BokehJS encodes ``{"type": "map"}``.

Nothing is drawn and only JSON is parsed, so thirty sessions cost the machine
little beside the server's own work. Nothing answers the server except the
initial pull: the server's ``OK`` replies are counted, its ``ERROR`` replies
recorded as errors.

:class:`Student` adds the app's vocabulary, one method per user action (type
into a parameter field, show a tab, press a run button and wait for its
result), finding models by type, css class and label, never by id; it waits
for a tab's content to arrive before it presses its buttons (tabs are built
when first shown). When the UI changes, that class is what to adapt.

In a class exercise (``eha serve --exercise FILE`` with a roster) the page
first shows a gate: a student made with ``code=`` types their join code into
``.eha-join-code`` and presses "Start" (``.eha-start``) as part of opening, and
types a parameter tab 1 still shows (``param_name``; M, B, Af and βe are
hidden there by default). The exercise's steps (:data:`EXERCISE_STEPS`) go on
from the frequency experiment to the grey-box estimation (an estimate that
fails its checks counts as done, noted in :attr:`Outcome.detail`), the model
board (done when its tables show every route's model) and a hand-in (the
grey-box's, or the least squares' when the grey-box's is refused).

:func:`run_class` (async) / :func:`run_students` drive N students through the
steps together, with an optional observer typing every 2 s; the tests and
``bench_classroom.py`` use them.
"""

from __future__ import annotations

import asyncio
import html
import json
import os
import random
import re
import signal
import subprocess
import time
import urllib.request
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import urlsplit

from tornado.httpclient import AsyncHTTPClient, HTTPRequest
from tornado.websocket import websocket_connect

__all__ = [
    "EXERCISE_OBSERVER_VALUES",
    "EXERCISE_PARAM",
    "EXERCISE_STEPS",
    "STEPS",
    "STEP_NAMES",
    "ClassResult",
    "Model",
    "ObserverSample",
    "Outcome",
    "ProtocolError",
    "StepFailed",
    "StepTimeout",
    "Student",
    "StudentSession",
    "exercise_texts",
    "run_class",
    "run_students",
]

_TOKEN = re.compile(r'"token"\s*:\s*"([^"]+)"')


def wait_served(proc: subprocess.Popen | None, url: str, timeout: float, log_tail: Callable[[], str] = str,
                stop: Callable[[], None] = lambda: None, poll_s: float = 0.2) -> None:
    """Wait until ``eha serve`` (``proc``; None: a server not ours, nginx say) answers ``url`` with 200;
    RuntimeError if it exits or does not answer within ``timeout`` seconds (``stop()`` first)."""
    deadline = time.monotonic() + timeout
    while True:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"eha serve exited with {proc.returncode}: {log_tail()[-2000:]}")
        try:
            with urllib.request.urlopen(url, timeout=10) as r:
                if r.status == 200:
                    return
        except OSError:
            pass
        if time.monotonic() > deadline:
            stop()
            raise RuntimeError(f"eha serve did not answer within {timeout:g} s")
        time.sleep(poll_s)


def stop_server(proc: subprocess.Popen) -> None:
    """Stop a server started with ``start_new_session=True`` and its children: SIGTERM, SIGKILL after 20 s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


class ProtocolError(RuntimeError):
    """The server said something a browser would not accept, or closed the connection."""


class StepTimeout(RuntimeError):
    """A waited-for condition did not happen in time."""


class StepFailed(RuntimeError):
    """The page showed a failure (an alert) instead of the result."""


# -- the document's models -------------------------------------------------------------------

@dataclass
class Model:
    """One Bokeh model as the client knows it: type name and attributes (references as ``{"id": ...}``)."""

    id: str
    type: str
    attributes: dict = field(default_factory=dict)

    @property
    def css(self) -> list:
        return self.attributes.get("css_classes") or []

    def get(self, attr: str, default=None):
        return self.attributes.get(attr, default)

    def text(self) -> str:
        """The model's text (Div, Panel's HTML/Markdown panes: their ``text``), HTML entities unescaped."""
        value = self.attributes.get("text", "")
        if isinstance(value, dict):          # a value spec
            value = value.get("value", "")
        return html.unescape("" if value is None else str(value))

    def __repr__(self) -> str:
        return f"<{self.type} {self.id} css={self.css}>"


def _plain(value):
    """Bokeh's JSON encodings made plain enough to read: maps to dicts, inline models to references."""
    if isinstance(value, dict):
        kind = value.get("type")
        if kind == "map":
            return {k: _plain(v) for k, v in value.get("entries", [])}
        if kind == "object" and "id" in value:
            return {"id": value["id"]}
        if kind in ("ndarray", "bytes", "typed_array", "number", "value", "field", "expr"):
            return value
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _refs(value, out: list) -> None:
    """The model ids ``value`` refers to."""
    if isinstance(value, dict):
        if "id" in value and len(value) == 1:
            out.append(value["id"])
        else:
            for v in value.values():
                if isinstance(v, (dict, list)):
                    _refs(v, out)
    elif isinstance(value, list):
        for v in value:
            if isinstance(v, (dict, list)):
                _refs(v, out)


def _encode(value):
    """A Python value as BokehJS's serializer sends it (plain objects as maps)."""
    if isinstance(value, Model):
        return {"id": value.id}
    if isinstance(value, dict):
        if set(value) == {"id"}:
            return value
        if not value:
            return {"type": "map"}
        return {"type": "map", "entries": [[k, _encode(v)] for k, v in value.items()]}
    if isinstance(value, (list, tuple)):
        return [_encode(v) for v in value]
    if isinstance(value, (bytes, bytearray, memoryview)):
        return {"type": "bytes", "data": _Buffer(bytes(value))}
    return value


class _Buffer:
    """Bytes in a message's content: sent as BokehJS sends an ``ArrayBuffer`` (its serializer with
    ``binary: true``, as ``Document.create_json_patch`` uses): the content holds ``{"id": "0"}``, the
    header ``num_buffers``, and after the three text frames each buffer follows as a text frame with
    its reference and a binary frame with its bytes (``Message.send``). Bokeh's ``Deserializer``
    resolves the reference to the buffer (``_decode_bytes``)."""

    __slots__ = ("data",)

    def __init__(self, data: bytes):
        self.data = data


def _with_buffers(content) -> tuple[str, list]:
    """``content`` as JSON with every :class:`_Buffer` replaced by a reference, and the buffers."""
    buffers: list = []

    def default(obj):
        if isinstance(obj, _Buffer):
            ref = {"id": str(len(buffers))}
            buffers.append((ref, obj.data))
            return ref
        raise TypeError(f"{type(obj).__name__} is not JSON serializable")

    return json.dumps(content, default=default), buffers


# -- one browser tab ----------------------------------------------------------------------------

class StudentSession:
    """One browser session at the Bokeh protocol level (see the module docstring)."""

    def __init__(self, url: str, *, name: str = "student", timeout: float = 180.0):
        self.url = url
        self.name = name
        self.timeout = timeout
        self.models: dict[str, Model] = {}
        self.roots: list[str] = []
        self.cookies: dict[str, str] = {}
        self.upstream = ""              # which backend served the page, if a proxy says so
        # what the student types into M: on tab 1 first ("param"), and again once every tab is built
        # ("retype"); a class with --distinct gives each student values of their own (nothing shared)
        self.param_text, self.retype_text = "6000", "6500"
        # what the server sent: messages, frames and bytes (all frames), by message type
        self.messages_in = 0
        self.frames_in = 0
        self.bytes_in = 0
        self.buffers_in = 0
        self.by_type: dict[str, int] = {}
        self.events_in: dict[str, int] = {}
        self.messages_out = 0
        self.errors: list[str] = []     # the server's ERROR replies and a broken connection
        self._ws = None
        self._reader: asyncio.Future | None = None
        self._changed = asyncio.Event()
        self._pending: dict[str, asyncio.Future] = {}
        self._ack: asyncio.Future | None = None
        self._live: set | None = None
        self._closed = False
        self._broken: str | None = None

    # -- opening ------------------------------------------------------------------------------
    async def open(self, timeout: float | None = None) -> float:
        """Open the page as a browser does; returns the seconds from the GET's start until the
        document is pulled and indexed."""
        timeout = self.timeout if timeout is None else timeout
        t0 = time.perf_counter()
        client = AsyncHTTPClient(force_instance=True)   # no shared 10-connection pool between students
        try:
            response = await client.fetch(HTTPRequest(self.url, request_timeout=timeout, follow_redirects=True,
                                                      headers=self._cookie_header()), raise_error=False)
        finally:
            client.close()
        if response.code != 200:
            raise ProtocolError(f"GET {self.url}: HTTP {response.code} {response.reason or ''}".strip())
        self._keep_cookies(response.headers.get_list("Set-Cookie"))
        self.upstream = response.headers.get("X-Eha-Upstream", "")
        self.bytes_in += len(response.body or b"")
        page = response.body.decode("utf-8", "replace")
        match = _TOKEN.search(page)
        if not match:
            raise ProtocolError("no session token in the page")
        parts = urlsplit(response.effective_url)
        scheme = "wss" if parts.scheme == "https" else "ws"
        ws_url = f"{scheme}://{parts.netloc}{parts.path.rstrip('/')}/ws" + (f"?{parts.query}" if parts.query else "")
        request = HTTPRequest(ws_url, request_timeout=timeout,
                              headers={**self._cookie_header(), "Origin": f"{parts.scheme}://{parts.netloc}"})
        loop = asyncio.get_running_loop()
        self._ack = loop.create_future()
        self._ws = await websocket_connect(request, subprotocols=["bokeh", match.group(1)],
                                           max_message_size=1024 * 2**20)
        # as a browser does (Chromium sets TCP_NODELAY on every socket): each frame of a message sent
        # at once, not after the server's acknowledgement of the one before (delayed up to 40 ms)
        self._ws.protocol.stream.set_nodelay(True)
        self._reader = asyncio.ensure_future(self._read_forever())
        await asyncio.wait_for(asyncio.shield(self._ack), timeout)
        reply = await self._request("PULL-DOC-REQ", {}, timeout)
        doc = reply["content"]["doc"]
        self._index(doc)
        self.roots = [r["id"] for r in doc.get("roots", []) if isinstance(r, dict) and "id" in r]
        self._live = None
        seconds = time.perf_counter() - t0
        await self.send_event("document_ready")
        return seconds

    def _cookie_header(self) -> dict:
        return {"Cookie": "; ".join(f"{k}={v}" for k, v in self.cookies.items())} if self.cookies else {}

    def _keep_cookies(self, headers) -> None:
        for h in headers:
            c = SimpleCookie()
            try:
                c.load(h)
            except Exception:  # noqa: BLE001, S112 - a cookie Python cannot parse is one a test cannot need
                continue
            for k, morsel in c.items():
                self.cookies[k] = morsel.value

    async def close(self) -> None:
        """Close the websocket, as closing the browser tab does."""
        self._closed = True
        if self._ws is not None:
            self._ws.close()
        if self._reader is not None:
            self._reader.cancel()
            try:
                await self._reader
            except (asyncio.CancelledError, Exception):  # noqa: BLE001, S110 - closing anyway
                pass
        for fut in self._pending.values():
            if not fut.done():
                fut.cancel()

    # -- the wire -------------------------------------------------------------------------------
    async def _frame(self):
        data = await self._ws.read_message()
        if data is None:
            raise ProtocolError("the server closed the connection")
        self.frames_in += 1
        self.bytes_in += len(data) if isinstance(data, bytes) else len(data.encode("utf-8"))
        return data

    async def _read_message(self) -> dict:
        parts = []
        for what in ("header", "metadata", "content"):
            frame = await self._frame()
            if not isinstance(frame, str):
                raise ProtocolError(f"expected the message's {what} as a text frame, got {len(frame)} bytes")
            parts.append(json.loads(frame))
        header, metadata, content = parts
        for _ in range(header.get("num_buffers", 0) or 0):
            ref = await self._frame()           # the buffer's header: {"id": ...}
            data = await self._frame()          # its bytes (not decoded: nothing here draws)
            if not isinstance(ref, str) or not isinstance(data, bytes):
                raise ProtocolError("a buffer was not a text frame followed by a binary frame")
            self.buffers_in += 1
        self.messages_in += 1
        kind = header.get("msgtype", "?")
        self.by_type[kind] = self.by_type.get(kind, 0) + 1
        return {"header": header, "metadata": metadata, "content": content}

    async def _send(self, msgtype: str, content: dict, msgid: str | None = None) -> str:
        if self._broken:
            raise ProtocolError(self._broken)
        msgid = msgid or uuid.uuid4().hex
        content_json, buffers = _with_buffers(content)
        header = {"msgid": msgid, "msgtype": msgtype}
        if buffers:
            header["num_buffers"] = len(buffers)
        await self._ws.write_message(json.dumps(header))
        await self._ws.write_message("{}")
        await self._ws.write_message(content_json)
        for ref, data in buffers:
            await self._ws.write_message(json.dumps(ref))
            await self._ws.write_message(data, binary=True)
        self.messages_out += 1
        return msgid

    async def _request(self, msgtype: str, content: dict, timeout: float) -> dict:
        fut = asyncio.get_running_loop().create_future()
        msgid = uuid.uuid4().hex
        self._pending[msgid] = fut          # before sending: the reply may come while the frames are flushed
        try:
            await self._send(msgtype, content, msgid)
            msg = await asyncio.wait_for(fut, timeout)
        finally:
            self._pending.pop(msgid, None)
        if msg["header"].get("msgtype") == "ERROR":
            raise ProtocolError(f"{msgtype}: {msg['content'].get('text')}")
        return msg

    async def _read_forever(self) -> None:
        try:
            while True:
                self._handle(await self._read_message())
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - recorded: a closed or broken connection
            if not self._closed:
                self._broken = f"connection: {type(exc).__name__}: {exc}"
                self.errors.append(self._broken)
                for fut in [self._ack, *self._pending.values()]:
                    if fut is not None and not fut.done():
                        fut.set_exception(ProtocolError(self._broken))
            self._changed.set()

    def _handle(self, msg: dict) -> None:
        header = msg["header"]
        kind = header.get("msgtype")
        if kind == "ACK" and self._ack is not None and not self._ack.done():
            self._ack.set_result(msg)
        elif kind == "ERROR":
            self.errors.append(f"server ERROR reply: {str(msg['content'].get('text', ''))[:300]}")
        elif kind == "PATCH-DOC":
            for event in msg["content"].get("events", []):
                self._apply(event)
            self._live = None
        reqid = header.get("reqid")
        if reqid in self._pending and not self._pending[reqid].done():
            self._pending[reqid].set_result(msg)
        self._changed.set()

    async def send_patch(self, events: list) -> None:
        """A ``PATCH-DOC`` with these events (the server answers OK, or ERROR)."""
        await self._send("PATCH-DOC", {"events": events})

    async def set_property(self, model: Model, attr: str, value) -> None:
        """Change a property as BokehJS does (and in the local copy)."""
        model.attributes[attr] = value
        await self.send_patch([{"kind": "ModelChanged", "model": {"id": model.id}, "attr": attr,
                                "new": _encode(value)}])

    async def set_properties(self, model: Model, values: dict) -> None:
        """Change several properties in one message, as BokehJS does for ``model.setv({...})`` (e.g. a
        file chooser's name and bytes together). Bytes go as binary buffers (see :class:`_Buffer`)."""
        model.attributes.update(values)
        await self.send_patch([{"kind": "ModelChanged", "model": {"id": model.id}, "attr": attr,
                                "new": _encode(value)} for attr, value in values.items()])

    async def round_trip(self, timeout: float | None = None) -> float:
        """An empty ``PATCH-DOC`` and the server's ``OK``: the connection and the session answer.
        Returns the seconds it took (raises :class:`ProtocolError` on an ERROR reply or a closed
        connection, ``asyncio.TimeoutError`` if nothing came back in time)."""
        t0 = time.perf_counter()
        await self._request("PATCH-DOC", {"events": []}, self.timeout if timeout is None else timeout)
        return time.perf_counter() - t0

    async def send_event(self, name: str, values: dict | None = None) -> None:
        """A UI event (``bokeh_event``), as BokehJS's ``EventManager.send_event`` sends it."""
        await self.send_patch([{"kind": "MessageSent", "msg_type": "bokeh_event",
                                "msg_data": {"type": "event", "name": name, "values": _encode(values or {})}}])

    async def click(self, button: Model) -> None:
        """Press a Button: its ``button_click`` event."""
        await self.send_event("button_click", {"model": {"id": button.id}})

    # -- the document -------------------------------------------------------------------------
    def _index(self, obj) -> None:
        """Index every model defined inline in ``obj``."""
        if isinstance(obj, dict):
            if obj.get("type") == "object" and "id" in obj and "name" in obj:
                attrs = {k: _plain(v) for k, v in (obj.get("attributes") or {}).items()}
                model = self.models.get(obj["id"])
                if model is None:
                    self.models[obj["id"]] = Model(obj["id"], obj["name"], attrs)
                else:
                    model.attributes.update(attrs)
            for v in obj.values():
                if isinstance(v, (dict, list)):
                    self._index(v)
        elif isinstance(obj, list):
            for v in obj:
                if isinstance(v, (dict, list)):
                    self._index(v)

    def _apply(self, event: dict) -> None:
        kind = event.get("kind", "?")
        self.events_in[kind] = self.events_in.get(kind, 0) + 1
        self._index(event)
        if kind == "ModelChanged":
            model = self.models.get(event["model"]["id"])
            if model is not None:
                model.attributes[event["attr"]] = _plain(event["new"])
        elif kind == "RootAdded":
            rid = event.get("model", {}).get("id")
            if rid and rid not in self.roots:
                self.roots.append(rid)
        elif kind == "RootRemoved":
            rid = event.get("model", {}).get("id")
            if rid in self.roots:
                self.roots.remove(rid)
        elif kind == "TitleChanged":
            self.title = event.get("title")
        # ColumnDataChanged / ColumnsStreamed / ColumnsPatched carry plot data: indexed
        # above for any models inside, their numbers are not kept (nothing here draws).

    def live_ids(self) -> set:
        """Ids of the models reachable from the document's roots (models replaced since are not)."""
        if self._live is None:
            seen, todo = set(), list(self.roots)
            while todo:
                mid = todo.pop()
                if mid in seen or mid not in self.models:
                    continue
                seen.add(mid)
                out: list = []
                _refs(self.models[mid].attributes, out)
                todo.extend(out)
            self._live = seen
        return self._live

    def find(self, type_suffix: str | None = None, *, css: str | None = None, label: str | None = None,
             where: Callable[[Model], bool] | None = None, live: bool = True) -> list[Model]:
        """Models whose type name ends with ``type_suffix``, with css class ``css``, label ``label``,
        for which ``where`` holds; by default only those in the document now."""
        ids = self.live_ids() if live else None
        out = []
        for m in self.models.values():
            if ids is not None and m.id not in ids:
                continue
            if type_suffix and not m.type.endswith(type_suffix):
                continue
            if css and css not in m.css:
                continue
            if label is not None and m.attributes.get("label") != label:
                continue
            if where is not None and not where(m):
                continue
            out.append(m)
        return out

    async def wait_for(self, condition: Callable[[], Any], timeout: float | None = None, what: str = "condition"):
        """Wait until ``condition()`` is truthy (checked after every message from the server) and
        return its value. ``condition`` may raise (e.g. :class:`StepFailed`) to stop waiting."""
        timeout = self.timeout if timeout is None else timeout
        deadline = time.perf_counter() + timeout
        while True:
            value = condition()
            if value:
                return value
            if self._broken:
                raise ProtocolError(f"{self.name}: {self._broken} (waiting for {what})")
            left = deadline - time.perf_counter()
            if left <= 0:
                raise StepTimeout(f"{self.name}: timed out after {timeout:g} s waiting for {what}")
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), left)
            except asyncio.TimeoutError:
                pass

    async def wait_for_model(self, type_suffix: str | None = None, *, css: str | None = None,
                             label: str | None = None, where: Callable[[Model], bool] | None = None,
                             timeout: float | None = None) -> Model:
        """Wait until a model matching these exists in the document; returns the first."""
        what = " ".join(x for x in (type_suffix or "model", f".{css}" if css else "",
                                    f"{label!r}" if label is not None else "") if x)
        found = await self.wait_for(lambda: self.find(type_suffix, css=css, label=label, where=where),
                                    timeout, what)
        return found[0]

    async def wait_until(self, model: Model, attr: str, predicate: Callable[[Any], bool],
                         timeout: float | None = None, what: str | None = None):
        """Wait until ``predicate(model.attr)`` holds; returns the attribute's value."""
        def check():
            value = model.attributes.get(attr)
            return (value,) if predicate(value) else None
        return (await self.wait_for(check, timeout, what or f"{model!r}.{attr}"))[0]


# -- a student of this app ------------------------------------------------------------------------


def _subtabs(keys: tuple) -> tuple:
    """The sub-tab index of each section ``keys`` on tab 3, from the app's registry."""
    from eha_app.sections import SECTIONS

    on_tab = [p.key for p in SECTIONS.on_tab("3. Identification")]
    return tuple(on_tab.index(k) for k in keys)


class Student(StudentSession):
    """A student of this app: its tabs, fields and buttons by name, one method per user action.

    Each action returns the seconds from its start (the first message it sends)
    until the page showed its result; it raises :class:`StepTimeout`,
    :class:`StepFailed` (the page's alert, e.g. "The experiment failed: ...")
    or :class:`ProtocolError`.
    """

    MAIN_TABS = "eha-main-tabs"
    IDENT_TABS = "eha-ident-tabs"
    FORM = "eha-param-form"
    #: Tab 3's sub-tabs, where the app's registry puts them (a sub-tab added later moves the ones after it).
    LSE_SUBTAB, FREQ_SUBTAB, GB_SUBTAB, BB_SUBTAB, BOARD_SUBTAB, STUDY_SUBTAB = _subtabs(
        ("least_squares", "frequency", "greybox", "blackbox", "board", "study"))

    def __init__(self, url: str, *, code: str | None = None, param_name: str = "M", **kwargs):
        super().__init__(url, **kwargs)
        self.code = code                    # an exercise's join code, typed into the gate when opening
        self.param_name = param_name        # the field of tab 1 the steps "param" and "retype" type into
        # the routes whose estimate this session made (LS, H, GB: their names' prefixes on the model board)
        self.posted: set[str] = set()
        self.detail: dict = {}              # what the last step noted beside its time (see do_step)

    def _one(self, what: str, found: list[Model]) -> Model:
        if not found:
            raise LookupError(f"{self.name}: no {what} in the page")
        return found[0]

    async def open(self, timeout: float | None = None) -> float:
        """Open the page; returns the seconds until tab 1's fields arrived (the
        server sends the page's frame first and its first tab right after). With
        a join ``code``: the gate's code typed and "Start" pressed in between."""
        t0 = time.perf_counter()
        await super().open(timeout)
        if self.code is not None:
            await self.join(self.code, timeout)
        await self.wait_for_model(css=self.FORM, timeout=timeout)
        return time.perf_counter() - t0

    async def join(self, code: str, timeout: float | None = None) -> None:
        """An exercise's gate: type ``code`` into ``.eha-join-code`` as BokehJS does (``value_input``, then
        ``value`` on Enter) and press "Start"; :class:`StepFailed` with the gate's message if it refuses."""
        box = await self.wait_for_model("TextInput", css="eha-join-code", timeout=timeout)
        e0 = len(self.errors)
        await self.set_property(box, "value_input", code)
        await self.set_property(box, "value", code)
        start = self._one("button 'Start'", self.find("Button", css="eha-start", label="Start"))
        message = self.find(css="eha-error-student")
        before = message[0].text() if message else ""
        await self.click(start)

        def joined():
            if self.find(css=self.FORM):
                return True
            refused = [e for e in self.errors[e0:] if e.startswith("server ERROR")]
            if refused:             # the code or the press never reached the gate: no page will come
                raise StepFailed(f"{self.name}: the join was not applied: {refused[0][:200]}")
            now = message[0].text() if message else ""
            if now != before and now.strip():
                raise StepFailed(f"{self.name}: the gate refused the code: {re.sub('<[^>]+>', ' ', now)[:200]}")
            return False

        await self.wait_for(joined, timeout, "tab 1 after the join code")

    def pane(self, css: str) -> Model:
        return self._one(f"pane .{css}", self.find(css=css))

    def form(self, css: str) -> Model:
        """The model holding the ``values`` of the form with css class ``css`` (its data model)."""
        form = self._one(f"form .{css}", self.find(css=css))
        ref = form.attributes.get("data")
        data = self.models.get(ref["id"]) if isinstance(ref, dict) and "id" in ref else None
        return data if data is not None and "values" in data.attributes else form

    def component_data(self, css: str) -> Model:
        """The data model of the custom component (a form, a file chooser) with css class ``css``:
        where its parameters live (Panel's ``JSComponent``: the component's ``data``)."""
        component = self._one(f"component .{css}", self.find(css=css))
        ref = component.attributes.get("data")
        data = self.models.get(ref["id"]) if isinstance(ref, dict) and "id" in ref else None
        return data if data is not None else component

    async def upload(self, css: str, filename: str, data: bytes) -> None:
        """Choose a file in the file chooser with css class ``css`` (the app's ``FileUpload``): its
        name and bytes in one message, as the page's ``model.data.setv({filename, value})`` sends them."""
        await self.set_properties(self.component_data(css), {"filename": filename, "value": bytes(data)})

    def button(self, label: str) -> Model:
        return self._one(f"button {label!r}", self.find("Button", label=label))

    def main_tabs(self) -> Model:
        # the page's Tabs: by css class, else the first Tabs of the page
        found = self.find("Tabs", css=self.MAIN_TABS) or self.find("Tabs")
        return self._one("tabs", found)

    def _alert(self, css: str | None) -> tuple[Model | None, tuple]:
        found = self.find(css=css) if css else []
        m = found[0] if found else None
        return m, ((m.attributes.get("visible"), m.text()) if m else (None, ""))

    @staticmethod
    def _alert_news(alert: Model | None, before: tuple) -> str | None:
        """The alert's text if it appeared or changed since ``before``."""
        if alert is None or not alert.attributes.get("visible", True):
            return None
        now = (alert.attributes.get("visible"), alert.text())
        return now[1] if now != before and now[1].strip() else None

    # the user's actions ----------------------------------------------------------------------------
    async def change_parameter(self, name: str, text: str, timeout: float | None = None) -> float:
        """Type ``text`` into tab 1's field ``name``; done when the derived values (``.eha-derived``) change
        (so ``text`` must differ from the field's current value).

        Today's tab 1 is one form component (``.eha-param-form``) whose data model's
        ``values`` holds every field's text: the browser sends the whole dict on each
        keystroke. A Panel ``TextInput`` with css class ``eha-field-NAME`` (the form
        before) is typed into as BokehJS does: ``value_input`` per keystroke, then
        ``value`` on Enter.
        """
        derived = self.pane("eha-derived")
        before = derived.text()
        t0 = time.perf_counter()
        box = self.find("TextInput", css=f"eha-field-{name}")
        if box:
            await self.set_property(box[0], "value_input", text)
            await self.set_property(box[0], "value", text)
        else:
            target = self.form(self.FORM)
            values = dict(target.attributes.get("values") or {})
            if name not in values:
                raise LookupError(f"{self.name}: no field {name!r} in the form")
            await self.set_property(target, "values", {**values, name: text})
        await self.wait_for(lambda: derived.text() != before, timeout, f"the derived values after {name} = {text}")
        return time.perf_counter() - t0

    async def show_tab(self, index: int, ready_css: str, timeout: float | None = None) -> float:
        """Click main tab ``index`` (0-based); done when its content (a model with ``ready_css``) arrived.
        Tabs are built when first shown: the content comes in a later PATCH-DOC."""
        t0 = time.perf_counter()
        tabs = self.main_tabs()
        if tabs.attributes.get("active") != index:
            await self.set_property(tabs, "active", index)
        await self.wait_for_model(css=ready_css, timeout=timeout)
        return time.perf_counter() - t0

    async def show_subtab(self, tabs_css: str, index: int, ready_css: str, timeout: float | None = None) -> float:
        t0 = time.perf_counter()
        tabs = await self.wait_for_model("Tabs", css=tabs_css, timeout=timeout)
        if tabs.attributes.get("active") != index:
            await self.set_property(tabs, "active", index)
        await self.wait_for_model(css=ready_css, timeout=timeout)
        return time.perf_counter() - t0

    async def press_and_wait(self, label: str, result_css: str, done: Callable[[Model, str], bool],
                             alert_css: str | None, timeout: float | None = None) -> tuple[float, str]:
        """Press the button ``label``; wait until ``done(result, text_before)`` holds for the pane
        ``result_css``, or fail with the alert's text if the alert (``alert_css``) appears."""
        result = self.pane(result_css)
        before = result.text()
        alert, alert_before = self._alert(alert_css)
        button = self.button(label)
        t0 = time.perf_counter()
        await self.click(button)

        def finished():
            news = self._alert_news(alert, alert_before)
            if news is not None and "failed" in news.lower():
                raise StepFailed(f"{self.name}: {news[:300]}")
            return done(result, before)

        await self.wait_for(finished, timeout, f"the result of {label!r}")
        seconds = time.perf_counter() - t0
        news = self._alert_news(alert, alert_before)
        if news is not None:
            raise StepFailed(f"{self.name}: {news[:300]}")
        return seconds, result.text()

    async def show_simulation(self, timeout: float | None = None) -> float:
        return await self.show_tab(1, "eha-sim-info", timeout)

    async def show_identification(self, timeout: float | None = None) -> float:
        return await self.show_tab(2, "eha-lse-table", timeout)

    async def show_frequency(self, timeout: float | None = None) -> float:
        """Tab 3's inner tab "Frequency domain: transfer function"."""
        t0 = time.perf_counter()
        await self.show_tab(2, self.IDENT_TABS, timeout)
        await self.show_subtab(self.IDENT_TABS, self.FREQ_SUBTAB, "eha-freq-summary", timeout)
        return time.perf_counter() - t0

    async def compare_both(self, timeout: float | None = None) -> float:
        """Tab 2, "Compare both"; done when the status line (``.eha-sim-info``) shows the next run."""
        t0 = time.perf_counter()
        await self.show_simulation(timeout)
        count = _run_count(self.pane("eha-sim-info").text())
        await self.press_and_wait("Compare both", "eha-sim-info", lambda m, _: _run_count(m.text()) > count,
                                  "eha-sim-alert", timeout)
        return time.perf_counter() - t0

    async def least_squares(self, timeout: float | None = None) -> float:
        """Tab 3, "Run least squares"; done when ``.eha-lse-table`` holds a new table."""
        t0 = time.perf_counter()
        await self.show_identification(timeout)
        await self.press_and_wait("Run least squares", "eha-lse-table",
                                  lambda m, before: m.text() != before and "<table" in m.text(),
                                  "eha-lse-alert", timeout)
        self.posted.add("LS")
        return time.perf_counter() - t0

    async def start_study(self, seeds: int, timeout: float | None = None, kind: str | None = None) -> None:
        """Tab 3's study: ``seeds`` seeds of the default experiment (or ``kind``: lse, tf, greybox),
        "Run the study" pressed."""
        await self.show_tab(2, self.IDENT_TABS, timeout)
        await self.show_subtab(self.IDENT_TABS, self.STUDY_SUBTAB, "eha-study-form", timeout)
        form = self.form("eha-study-form")
        values = dict(form.attributes.get("values") or {})
        await self.set_property(form, "values", {**values, "study_seeds": str(seeds),
                                                 **({"study_kind": kind} if kind else {})})
        await self.round_trip(timeout)
        await self.click(self.button("Run the study"))

    def study_running(self) -> bool:
        cancel = self.find(css="eha-cancel-study")
        return bool(cancel) and not cancel[0].attributes.get("disabled", True)

    async def frequency_experiment(self, timeout: float | None = None) -> float:
        """Tab 3's frequency panel, "Run experiment and estimate"; done when ``.eha-freq-summary``
        shows the estimate Ĥ(s)."""
        t0 = time.perf_counter()
        await self.show_frequency(timeout)
        _, text = await self.press_and_wait("Run experiment and estimate", "eha-freq-summary",
                                            lambda m, before: m.text() != before, "eha-freq-alert", timeout)
        if "Ĥ(s)" not in text:
            raise StepFailed(f"{self.name}: the summary has no estimate: {re.sub('<[^>]+>', ' ', text)[:200]}")
        self.posted.add("H")
        return time.perf_counter() - t0

    async def show_greybox(self, timeout: float | None = None) -> float:
        """Tab 3's inner tab "Grey-box (nonlinear)"; done when its run button arrived."""
        t0 = time.perf_counter()
        await self.show_tab(2, self.IDENT_TABS, timeout)
        await self.show_subtab(self.IDENT_TABS, self.GB_SUBTAB, "eha-run-gb", timeout)
        return time.perf_counter() - t0

    async def greybox(self, timeout: float | None = None) -> float:
        """Tab 3's grey-box panel, "Run grey-box estimation" with the page's settings; done when
        ``.eha-gb-table-pane`` holds a new table (an alert "... failed" is :class:`StepFailed`). An
        estimate that failed its checks (the red "may be wrong" box) is done too: ``detail["checks"]``
        says "passed" or "failed" (then ``detail["says"]``: the box's words)."""
        t0 = time.perf_counter()
        await self.show_greybox(timeout)
        _, text = await self.press_and_wait("Run grey-box estimation", "eha-gb-table-pane",
                                            lambda m, before: m.text() != before and "<table" in m.text(),
                                            "eha-gb-alert", timeout)
        seconds = time.perf_counter() - t0
        failed = re.search(r"<div[^>]*eha-gb-failed.*?</div>", text, re.S)
        if failed or "eha-gb-failed" in text:
            self.detail["checks"] = "failed"
            self.detail["says"] = _plain_text(failed.group(0) if failed else text)[:300]
        else:
            self.detail["checks"] = "passed"
            self.posted.add("GB")           # only an estimate that passed its checks goes to the board
        return seconds

    def tip(self, widget: Model) -> str:
        """A widget's tooltip (Panel's ``description``, sent as the button's ``tooltip``: a Tooltip whose content
        is an HTML model), as words."""
        value = widget.get("tooltip", widget.get("description"))
        for _ in range(3):                  # description -> Tooltip -> its content -> the HTML's parts
            if isinstance(value, dict) and set(value) == {"id"}:
                model = self.models.get(value["id"])
                value = None if model is None else model.get("content", model.get("html"))
            elif isinstance(value, list):
                value = " ".join(v for v in value if isinstance(v, str))
        return _plain_text(value) if isinstance(value, str) else ""

    def board_entries(self) -> list[tuple[str, bool]]:
        """The model board's list: (name, ticked) of each entry, in its order."""
        out = []
        for box in self.find("TextInput", css="eha-board-name"):
            key = next((c[len("eha-board-name-"):] for c in box.css if c.startswith("eha-board-name-")), None)
            tick = self.find(css=f"eha-board-tick-{key}") if key is not None else []
            out.append((str(box.get("value") or ""), bool(tick and tick[0].get("active"))))
        return out

    async def model_board(self, timeout: float | None = None) -> float:
        """Tab 3's "Model board" (built when first shown, with the estimates made before); done when its
        list holds a model of every route this session ran (:attr:`posted`: LS1, H1, GB1) and the view it
        opens on, the fit on the validation record, shows a row for each ticked one in its table (the
        other views are computed when their tabs are opened). A warning of the board that something
        failed is :class:`StepFailed`. ``detail["models"]``: the entries, ticked marked *."""
        t0 = time.perf_counter()
        await self.show_tab(2, self.IDENT_TABS, timeout)
        await self.show_subtab(self.IDENT_TABS, self.BOARD_SUBTAB, "eha-board-list", timeout)

        def row(name: str) -> str:
            return f"■</span> {html.escape(name)}</td>"

        def ready():
            note = self.find(css="eha-board-note")
            if note and "failed" in note[0].text():
                raise StepFailed(f"{self.name}: {_plain_text(note[0].text())[:300]}")
            entries = self.board_entries()
            made = [(n, t) for n, t in entries if re.fullmatch(r"(LS|H|GB)\d+", n)]
            if any(not any(re.fullmatch(rf"{p}\d+", n) for n, _ in made) for p in self.posted):
                return None
            fits = self.find(css="eha-board-fit-table")
            if not fits:
                return None
            fit = fits[0].text()
            if any(row(n) not in fit for n, t in made if t):
                return None
            return entries

        entries = await self.wait_for(ready, timeout, f"the model board's fit table ({', '.join(sorted(self.posted))})")
        seconds = time.perf_counter() - t0
        self.detail["models"] = ",".join(n + ("*" if t else "") for n, t in entries)
        return seconds

    async def hand_in(self, timeout: float | None = None) -> float:
        """The exercise's hand-in: the grey-box's ("Hand in the grey-box estimates" on its sub-tab); if
        that button is off (the estimate failed its checks, or there is none), the least squares' ("Hand
        in these estimates" on sub-tab 0). Done when a ``.eha-verdict`` pane shows new text.
        ``detail``: ``route`` (greybox or lse), ``handed_in`` (the store took it), ``within`` ("4/4": the
        verdicts), ``missed`` (the parameters outside their tolerance), ``refused`` (why the grey-box's
        button was off), ``says`` (a refusal's words)."""
        t0 = time.perf_counter()
        await self.show_greybox(timeout)
        route = "greybox"
        button = self.button("Hand in the grey-box estimates")
        if button.get("disabled") or button.get("visible") is False:
            self.detail["refused"] = self.tip(button)[:300]
            route = "lse"
            await self.show_subtab(self.IDENT_TABS, self.LSE_SUBTAB, "eha-lse-table", timeout)
            button = self.button("Hand in these estimates")
            if button.get("disabled") or button.get("visible") is False:
                raise StepFailed(f"{self.name}: nothing to hand in: the grey-box's button is off "
                                 f"({self.detail['refused'][:150]}), and the least squares' "
                                 f"({self.tip(button)[:150]})")
        panes = self.find(css="eha-verdict")
        before = {m.id: (m.get("visible"), m.text()) for m in panes}
        await self.click(button)

        def verdict():
            for m in panes:
                now = (m.get("visible"), m.text())
                if now != before[m.id] and now[0] and now[1].strip():
                    return now[1]
            return None

        text = await self.wait_for(verdict, timeout, f"the verdict of the {route} hand-in")
        seconds = time.perf_counter() - t0
        self.detail["route"] = route
        self.detail["handed_in"] = "<b>Handed in</b>" in text
        # "k of 4 accepted" (graded by the record), "k of 4 within tolerance" (an exercise file from before)
        within = re.search(r"(\d+) of (\d+) (?:accepted|within tolerance)", _plain_text(text))
        if within:
            self.detail["within"] = f"{within.group(1)}/{within.group(2)}"
            # the parameters outside their tolerance (✗), by their symbols on the page (M, B, A f, β e)
            self.detail["missed"] = [_plain_text(item).split(" =")[0].split(" not handed in")[0]
                                     for item in re.findall(r"<li>(.*?)</li>", text, re.S) if "✗" in item]
        if not self.detail["handed_in"]:
            self.detail["says"] = _plain_text(text)[:300]
        return seconds


def _plain_text(markup: str) -> str:
    """HTML as one line of its words."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", markup)).split())


def _run_count(text: str) -> int:
    m = re.search(r"run (\d+)", text)
    return int(m.group(1)) if m else 0


# -- a class ------------------------------------------------------------------------------------------

#: The workflow, in order. The "show" steps are a first visit of a tab (built then); a
#: run step shows its tab itself if no "show" step came before.
STEPS = ("open", "param", "tab2", "compare", "tab3", "lse", "freqtab", "freq", "retype")
#: The graded lab of an exercise (a roster's join codes): the workflow on to the grey-box estimation,
#: the model board and a hand-in, then the parameter typed again with every tab built.
EXERCISE_STEPS = ("open", "param", "tab2", "compare", "tab3", "lse", "freqtab", "freq", "gbtab", "gb", "board",
                  "handin", "retype")
STEP_NAMES = {"open": "open the page", "param": "change M (tab 1)", "tab2": "show tab 2 (first)",
              "compare": '"Compare both"', "tab3": "show tab 3 (first)", "lse": "least squares",
              "freqtab": "show frequency tab", "freq": "frequency experiment",
              "gbtab": "show grey-box tab", "gb": "grey-box estimation", "board": "model board (first)",
              "handin": "hand in", "retype": "change M, every tab built"}
#: In an exercise M, B, Af and βe are hidden (not on tab 1): the steps type the chamber length L0 [mm]
#: instead, which tab 1's derived values follow (as Dc, dc and p1(0) do; kp and the valve's do not).
EXERCISE_PARAM = "L0"
EXERCISE_OBSERVER_VALUES = ("330", "335")


def exercise_texts(i: int) -> tuple[str, str]:
    """What the i-th student (from 0) of an exercise types into L0 at "param" and at "retype" [mm]: values
    of their own, none another student or the observer types (up to 250 students)."""
    return f"{305 + 0.1 * i:.1f}", f"{295 - 0.1 * i:.1f}"

#: What the hog does (``run_class(hog=...)``): a 500-seed study (pressed again when it ends), or a
#: press every 0.3 s of whichever of "Run the study" and "Cancel" is on.
HOGS = ("study", "spam")
OBSERVER_VALUES = ("5000", "5500")


#: The steps that are one action of :class:`Student` (its method's name).
_ACTIONS = {"open": "open", "tab2": "show_simulation", "compare": "compare_both", "tab3": "show_identification",
            "lse": "least_squares", "freqtab": "show_frequency", "freq": "frequency_experiment",
            "gbtab": "show_greybox", "gb": "greybox", "board": "model_board", "handin": "hand_in"}


async def do_step(student: Student, step: str, timeout: float | None = None) -> float:
    """One step of the workflow (:data:`STEPS`, :data:`EXERCISE_STEPS`) for one student; returns its
    seconds. What a step notes beside (the grey-box's checks, the hand-in's route) is in ``student.detail``."""
    if step == "param":
        return await student.change_parameter(student.param_name, student.param_text, timeout)
    if step == "retype":
        # tab 1 once every tab holds results: each section hears of the change
        await student.show_tab(0, "eha-derived", timeout)
        return await student.change_parameter(student.param_name, student.retype_text, timeout)
    if step in _ACTIONS:
        return await getattr(student, _ACTIONS[step])(timeout)
    raise ValueError(f"step = {step} is not allowed: use one of {', '.join(EXERCISE_STEPS)}")


@dataclass
class Outcome:
    """One student's step: seconds (None if it failed), its error, what the server sent meanwhile."""

    student: str
    step: str
    start: float            # offset of the student's start within the step [s]
    seconds: float | None
    error: str | None
    messages: int           # Bokeh messages the server sent this student during the step
    bytes: int              # websocket bytes (all frames; the page's HTML for "open")
    server_errors: list = field(default_factory=list)   # ERROR replies during the step
    by_type: dict = field(default_factory=dict)         # those messages by type (ACK, OK, PATCH-DOC, ...)
    detail: dict = field(default_factory=dict)          # what the step noted (Student.detail), e.g. checks


@dataclass
class ObserverSample:
    step: str
    at: float               # seconds since the class started
    delay: float | None
    error: str | None = None


@dataclass
class ClassResult:
    sessions: int
    steps: dict             # step -> list[Outcome]
    observer: list          # list[ObserverSample]
    step_wall: dict         # step -> (start, end) seconds since the class started
    session_errors: list    # connection errors outside a step
    upstreams: dict = field(default_factory=dict)   # backend (a proxy's X-Eha-Upstream) -> students
    hog_log: list = field(default_factory=list)     # what the hog did (presses, an error)

    def ok(self, step: str) -> int:
        return sum(1 for o in self.steps.get(step, []) if o.seconds is not None and not o.server_errors)

    def times(self, step: str) -> list:
        return [o.seconds for o in self.steps.get(step, []) if o.seconds is not None]

    def noted(self, step: str, key: str, value=True) -> int:
        """How many students did ``step`` and noted ``key`` = ``value`` (e.g. ``noted("gb", "checks",
        "passed")``)."""
        return sum(1 for o in self.steps.get(step, []) if o.seconds is not None and o.detail.get(key) == value)

    def errors(self, step: str) -> list:
        out = []
        for o in self.steps.get(step, []):
            if o.error:
                out.append(f"{o.student}: {o.error}")
            out += [f"{o.student}: {e}" for e in o.server_errors]
        return out

    def error_count(self) -> int:
        return (sum(len(self.errors(s)) for s in self.steps) + len(self.session_errors)
                + sum(1 for o in self.observer if o.error))

    def to_json(self) -> dict:
        return {"sessions": self.sessions,
                "steps": {s: [asdict(o) for o in outs] for s, outs in self.steps.items()},
                "observer": [asdict(o) for o in self.observer],
                "step_wall": self.step_wall, "session_errors": self.session_errors, "upstreams": self.upstreams,
                "hog_log": self.hog_log}


async def _observe(url: str, result: ClassResult, current: list, stop: asyncio.Event, ready: asyncio.Event,
                   t_class: float, timeout: float, period: float, code: str | None = None, param: str = "M",
                   values: tuple = OBSERVER_VALUES) -> None:
    """The observer of :func:`run_class`: types ``values`` alternately into ``param`` every ``period``
    seconds until ``stop`` (``code``: its join code in an exercise)."""
    o = Student(url, name="observer", timeout=timeout, code=code, param_name=param)
    try:
        await o.open(timeout)
    except Exception as exc:  # noqa: BLE001 - recorded
        result.observer.append(ObserverSample("open", 0.0, None, f"observer: {type(exc).__name__}: {exc}"))
        ready.set()
        return
    ready.set()
    k = 0
    next_tick = time.perf_counter()
    try:
        while not stop.is_set():
            at = time.perf_counter() - t_class
            step = current[0]
            try:
                delay = await o.change_parameter(param, values[k % 2], timeout)
                result.observer.append(ObserverSample(step, at, delay))
            except Exception as exc:  # noqa: BLE001 - recorded
                result.observer.append(ObserverSample(step, at, None, f"{type(exc).__name__}: {exc}"))
                if o._broken:
                    return
            k += 1
            next_tick += period
            while next_tick < time.perf_counter():       # a late answer skips ticks, never bunches them
                next_tick += period
            try:
                await asyncio.wait_for(stop.wait(), next_tick - time.perf_counter())
            except asyncio.TimeoutError:
                pass
    finally:
        await o.close()


async def _hog(url: str, kind: str, stop: asyncio.Event, ready: asyncio.Event, timeout: float,
               log: list, t_class: float = 0.0, code: str | None = None) -> None:
    """One more student who takes what the app lets one student take: ``kind`` of :data:`HOGS`.
    ``log`` gets each press ("run at 12.3 s": seconds since ``t_class``) and an error."""
    h = Student(url, name="hog", timeout=timeout, code=code)
    try:
        await h.open(timeout)
        if kind == "study":
            await h.start_study(500, timeout)
        else:
            await h.start_study(100, timeout)
        ready.set()
        while not stop.is_set():
            period = 0.3 if kind == "spam" else 1.0
            try:
                await asyncio.wait_for(stop.wait(), period)
                break
            except asyncio.TimeoutError:
                pass
            running = h.study_running()
            if kind == "spam":
                await h.click(h.find(css="eha-cancel-study")[0] if running else h.button("Run the study"))
                log.append(f"{'cancel' if running else 'run'} at {time.perf_counter() - t_class:.1f} s")
            elif not running:
                await h.click(h.button("Run the study"))
                log.append(f"run at {time.perf_counter() - t_class:.1f} s")
    except Exception as exc:  # noqa: BLE001 - recorded, the class goes on
        log.append(f"error: {type(exc).__name__}: {exc}")
    finally:
        ready.set()
        await h.close()


async def _act(student: Student, step: str, start: float, timeout: float) -> Outcome:
    """One student's ``step``, begun ``start`` seconds into it."""
    # counted from the step's start: what arrives while the student waits to click belongs here
    m0, b0, e0 = student.messages_in, student.bytes_in, len(student.errors)
    types0 = dict(student.by_type)
    await asyncio.sleep(start)
    seconds, error = None, None
    student.detail = {}
    try:
        seconds = await do_step(student, step, timeout)
    except Exception as exc:  # noqa: BLE001 - every failure is a result here
        error = f"{type(exc).__name__}: {exc}" if not isinstance(exc, (StepTimeout, StepFailed)) else str(exc)
        if error.startswith(f"{student.name}: "):
            error = error[len(student.name) + 2:]
    new_errors = [e for e in student.errors[e0:] if not e.startswith("connection")]
    by_type = {k: v - types0.get(k, 0) for k, v in student.by_type.items() if v != types0.get(k, 0)}
    return Outcome(student.name, step, round(start, 4), seconds, error, student.messages_in - m0,
                   student.bytes_in - b0, new_errors, by_type, dict(student.detail))


def _students(url: str, n: int, timeout: float, codes: dict, param: str,
              texts: Callable[[int], tuple[str, str]] | None, distinct: bool) -> list[Student]:
    """The class of :func:`run_class`: "student 1", ..., each with their code and what they type."""
    students = [Student(url, name=f"student {i + 1}", timeout=timeout, code=codes.get(f"student {i + 1}"),
                        param_name=param) for i in range(n)]
    for i, st in enumerate(students):
        if texts is not None:
            st.param_text, st.retype_text = texts(i)
        elif distinct:
            st.param_text, st.retype_text = str(6000 + 7 * i), str(6500 + 7 * i)
    return students


async def run_class(url: str, n: int, steps=STEPS, *, spread: float = 1.0, timeout: float = 180.0,
                    observer: bool = True, observer_period: float = 2.0, seed: int = 0,
                    on_step: Callable[[str, str], Any] | None = None, distinct: bool = False,
                    hog: str | None = None, codes: dict | None = None, param: str = "M",
                    texts: Callable[[int], tuple[str, str]] | None = None,
                    observer_values: tuple = OBSERVER_VALUES) -> ClassResult:
    """N students through ``steps`` together: within a step each starts at a random moment of the
    first ``spread`` seconds; the next step starts when all are done (or timed out). An observer
    session, opened first and not counted, types into M every ``observer_period`` seconds and
    records how long the derived values take to change. ``on_step(step, "start"|"end")`` is
    called around each step (the benchmark samples the server's CPU time there). ``distinct``:
    each student types values of M of their own (no two runs alike, nothing for the server to
    share). ``hog``: one more student, started before the class and not counted, doing ``hog``
    (:data:`HOGS`) throughout.

    An exercise: ``codes`` maps each session's name ("student 1", ..., "observer", "hog") to its join
    code; ``param`` is the field of tab 1 every session types into (the observer ``observer_values``),
    ``texts(i)`` what student i (from 0) types at "param" and "retype" (:data:`EXERCISE_PARAM`,
    :func:`exercise_texts`, :data:`EXERCISE_OBSERVER_VALUES`)."""
    steps = list(steps)
    if not steps or steps[0] != "open":
        raise ValueError(f"steps = {','.join(steps)} is not allowed: the first step must be open")
    rng = random.Random(seed)
    codes = codes or {}
    students = _students(url, n, timeout, codes, param, texts, distinct)
    if hog is not None and hog not in HOGS:
        raise ValueError(f"hog = {hog} is not allowed: use one of {', '.join(HOGS)}")
    result = ClassResult(n, {s: [] for s in steps}, [], {}, [])
    current = ["before"]
    t_class = time.perf_counter()
    stop = asyncio.Event()
    obs_ready = asyncio.Event()
    obs_task = None
    if observer:
        obs_task = asyncio.ensure_future(
            _observe(url, result, current, stop, obs_ready, t_class, timeout, observer_period,
                     code=codes.get("observer"), param=param, values=observer_values))
    on_step = on_step or (lambda _step, _when: None)
    hog_task, hog_ready = None, asyncio.Event()
    if hog is not None:
        hog_task = asyncio.ensure_future(_hog(url, hog, stop, hog_ready, timeout, result.hog_log, t_class,
                                              code=codes.get("hog")))
    try:
        if obs_task is not None:
            await obs_ready.wait()
        if hog_task is not None:
            await hog_ready.wait()
        active = list(students)
        for step in steps:
            current[0] = step
            on_step(step, "start")
            t0 = time.perf_counter() - t_class
            outcomes = await asyncio.gather(*(_act(s, step, rng.uniform(0, spread) if spread > 0 else 0.0, timeout)
                                              for s in active))
            result.step_wall[step] = (round(t0, 3), round(time.perf_counter() - t_class, 3))
            on_step(step, "end")
            result.steps[step] = list(outcomes)
            if step == "open":
                # a student without a page cannot go on: later steps count only those who have one
                active = [s for s, o in zip(active, outcomes, strict=True) if o.seconds is not None]
            else:
                active = [s for s in active if not s._broken]
    finally:
        current[0] = "after"
        stop.set()
        if obs_task is not None:
            await obs_task
        if hog_task is not None:
            await hog_task
        result.session_errors = [f"{s.name}: {e}" for s in students for e in s.errors if e.startswith("connection")]
        for s in students:
            if s.upstream:
                result.upstreams[s.upstream] = result.upstreams.get(s.upstream, 0) + 1
        await asyncio.gather(*(s.close() for s in students), return_exceptions=True)
    return result


def run_students(url: str, n: int, steps=STEPS, **kwargs) -> ClassResult:
    """:func:`run_class` from synchronous code (a test): N students through ``steps``.

    >>> r = run_students("http://127.0.0.1:5006/eha", 3, ["open", "param"], observer=False)  # doctest: +SKIP
    >>> r.ok("param"), r.errors("param")                                                     # doctest: +SKIP
    (3, [])
    """
    return asyncio.run(run_class(url, n, steps, **kwargs))
