"""How the app is served: the `panel serve` command line, and nginx in front of several processes.

Several processes on one machine
    ``eha serve --num-procs N`` starts N independent server processes that
    all listen on the same port with ``SO_REUSEPORT``, so that the kernel
    spreads the connections evenly over them (:func:`supervise`,
    :func:`eha_app.runtime.patches.bind_port_shared`). Bokeh's own ``--num-procs`` forks processes that share
    one listening socket, and Linux then wakes the same busy process again and
    again: 28 of 30 students landed in one of two processes.

One process
    ``eha serve`` runs Panel's server on the file entry point
    :mod:`eha_app.eha` with settings for a class:

    * ``--reuse-sessions``: the HTTP request for the page is answered from one
      prepared session; the student's own session is built once, when the
      page's websocket connects. Besides saving a build per student, this is
      what makes ``--num-procs`` correct: Bokeh forks processes that share
      the port, and without it the page's request and its websocket could
      land in different processes, each building the session.
    * sessions are discarded ``UNUSED_SESSION_MS`` after their page closed
      (Bokeh's default is 15-32 s), which also cancels their computations.

Several processes or machines
    Bokeh's own recommendation: independent ``eha serve`` processes behind
    nginx, with websocket upgrade and session affinity (a page's requests and
    its websocket must reach the same process). :func:`nginx_config` writes
    the configuration. Affinity is by a cookie that nginx sets on the first
    request (hashed consistently over the backends), not by client address:
    a class behind one school NAT would otherwise all land on one process.

Every answer's security headers
    ``eha serve`` runs Panel's ``serve`` command through :func:`run_panel_serve`, a subclass of
    it whose ``customize_kwargs`` (Bokeh's documented hook for that) hands Tornado's
    ``Application`` an output transform, :func:`security_transform`: every answer of the
    server (the app's page, the dashboard's, static files, autoload scripts, 403s and 404s,
    the websocket's handshake) carries :func:`security_headers`: a Content-Security-Policy, the
    page refusing to be framed (``frame-ancestors 'none'``, ``X-Frame-Options: DENY``) and
    ``X-Content-Type-Options: nosniff``. Behind nginx, :func:`nginx_config` adds the same to
    nginx's own answers (its redirect of ``/``, its 414 and 502 pages), and only to those.

A long address gets an answer
    Tornado closes the connection, with no answer, on a request whose line and headers exceed
    its ``max_header_size`` (64 KiB by default): a student who pasted a 70,000-character link
    saw "connection reset". The server reads up to :data:`MAX_REQUEST_HEAD_BYTES` (Bokeh's
    ``http_server_kwargs``, set in the same hook) and :func:`refuse_oversized` answers an
    address longer than :data:`MAX_ADDRESS_CHARS` with 414, and header fields beyond
    :data:`MAX_HEADER_FIELDS_BYTES` with 431, each with a line saying what to do, before
    Bokeh's handlers see the request. Beyond :data:`MAX_REQUEST_HEAD_BYTES` the connection is
    still closed without an answer (Tornado's ``UnsatisfiableReadError``): a bound on what one
    connection may make the server hold. Behind nginx, nginx answers 414 itself past its own
    ``large_client_header_buffers`` (8 KiB by default).
"""

from __future__ import annotations

import functools
import logging
import re
import weakref
from pathlib import Path

from eha_core.data import MAX_DATA_BYTES

__all__ = ["ENTRY_POINT", "TEACHER_ENTRY_POINT", "LOG_FORMAT", "UNUSED_SESSION_MS", "WEBSOCKET_MAX_MESSAGE_BYTES",
           "serve_argv", "default_origins", "lan_address", "local_names", "nginx_config", "nginx_standalone_config",
           "use_local_resources", "supervise", "quiet_closed_websockets", "CONTENT_SECURITY_POLICY",
           "security_headers", "security_transform", "MAX_REQUEST_HEAD_BYTES", "MAX_ADDRESS_CHARS",
           "MAX_HEADER_FIELDS_BYTES", "refuse_oversized", "first_answer", "run_panel_serve", "plain_answer",
           "one_blas_thread"]

ENTRY_POINT = Path(__file__).resolve().parents[1] / "eha.py"
#: The teacher's dashboard, served at /teacher beside the app in an exercise (see runtime/teacher_access.py).
TEACHER_ENTRY_POINT = ENTRY_POINT.with_name("teacher.py")
#: A closed page's session (and its computations) ends this long after its websocket closed.
UNUSED_SESSION_MS = 4000
#: How often the server looks for closed sessions.
CHECK_SESSIONS_MS = 1000
#: The server log's lines: with their level, so that a warning or an error can be found.
LOG_FORMAT = "%(asctime)s %(levelname)s %(message)s"


#: The largest message a page may send (Tornado closes the websocket beyond it, and the student's
#: page with it; Bokeh's default is 20 MiB): an upload at the app's limit, which the page's
#: :class:`~eha_app.sections.uploads.FileUpload` sends as one message of raw bytes, with room to spare.
WEBSOCKET_MAX_MESSAGE_BYTES = MAX_DATA_BYTES + 2**20

#: The Content-Security-Policy of every answer (``connect-src`` gets the page's own websocket
#: address besides, see :func:`security_headers`): nothing but what Bokeh 3.9 and Panel 1.9 were
#: seen to need in Chromium, through every tab and sub-tab, a run in each route and the teacher's
#: dashboard (tests/ui/test_csp_in_browser.py; each relaxation below, taken away, was a violation):
#:
#: * ``script-src 'unsafe-inline'``: the page's document and its start are inline ``<script>``
#:   elements, different for every session (no hash fits, and Bokeh's template takes no nonce);
#:   ``'unsafe-eval'``: BokehJS evaluates code given as text (``new Function``);
#:   ``blob:``, in ``script-src`` and ``connect-src``: Panel's ES-module shim loads the modules of
#:   the app's ``JSComponent``\ s (the connection watch, the forms, the uploads) as blob URLs it
#:   makes and fetches;
#: * ``style-src 'unsafe-inline'``: BokehJS styles its shadow roots with ``<style>`` and ``style=``;
#: * ``img-src data:``: Bokeh's and Panel's icons are SVG data URLs.
#:
#: Everything else is refused: any other origin (every resource is this server's:
#: :func:`use_local_resources`), plugins, workers, frames, ``<base>``, forms posting elsewhere;
#: and no page may frame the app (``frame-ancestors 'none'``): a page elsewhere cannot overlay a
#: student's.
CONTENT_SECURITY_POLICY = ("default-src 'none'; script-src 'self' 'unsafe-inline' 'unsafe-eval' blob:; "
                           "style-src 'self' 'unsafe-inline'; img-src 'self' data:; font-src 'self'; "
                           "connect-src 'self' blob:; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")

#: What Tornado reads of a request's line and headers (its default, 64 KiB, closed the connection
#: on a 70,000-character address without an answer). Past it the connection is still closed.
MAX_REQUEST_HEAD_BYTES = 2**20
#: A longer address (path and query) is answered 414 before Bokeh's handlers see it.
MAX_ADDRESS_CHARS = 32 * 1024
#: Header fields (cookies included) beyond this are answered 431: Tornado's own former bound,
#: which the app, Bokeh and Panel were served with (they copy a request's headers into a session).
MAX_HEADER_FIELDS_BYTES = 64 * 1024

_HOST = re.compile(r"[A-Za-z0-9.\-]+(:[0-9]{1,5})?|\[[0-9A-Fa-f:.]+\](:[0-9]{1,5})?")


def security_headers(host: str | None = None) -> dict[str, str]:
    """The security headers of an answer to a request for ``host`` (its Host header).

    ``connect-src`` names the page's websocket, ``ws://host`` and ``wss://host``, besides
    ``'self'``: a browser of CSP level 2 (an older Safari) does not count a websocket to the
    page's own host as ``'self'``, and a student's old iPad would get a page that never connects.
    A host that is not a plain ``name[:port]`` is left out (it cannot reach a policy).

    >>> [d for d in security_headers("localhost:5006")["Content-Security-Policy"].split("; ") if "ws:" in d]
    ["connect-src 'self' ws://localhost:5006 wss://localhost:5006 blob:"]
    >>> security_headers("evil; script-src *")["Content-Security-Policy"] == CONTENT_SECURITY_POLICY
    True
    """
    policy = CONTENT_SECURITY_POLICY
    if host and _HOST.fullmatch(host):
        policy = policy.replace("connect-src 'self'", f"connect-src 'self' ws://{host} wss://{host}")
    return {"Content-Security-Policy": policy, "X-Frame-Options": "DENY", "X-Content-Type-Options": "nosniff"}


@functools.cache
def security_transform():
    """The Tornado output transform that puts :func:`security_headers` on every answer (an
    ``OutputTransform``, for ``Application(transforms=...)`` / ``Application.add_transform``).

    A transform sees every answer of every handler once, when its headers are written: error
    pages and Tornado's own 404 included, which no handler's ``set_default_headers`` reaches.
    (A class made at the first call: this module is imported by every ``eha`` command, Tornado
    only by the server.)"""
    from tornado.web import OutputTransform

    class SecurityHeaders(OutputTransform):
        def __init__(self, request):
            super().__init__(request)
            self.host = request.host

        def transform_first_chunk(self, status_code, headers, chunk, finishing):
            for name, value in security_headers(self.host).items():
                headers[name] = value
            return status_code, headers, chunk

    return SecurityHeaders


@functools.cache
def plain_answer():
    """A Tornado handler answering every method with a status and a line of text."""
    from tornado.web import RequestHandler

    class PlainAnswer(RequestHandler):
        def initialize(self, status: int, text: str) -> None:
            self.answer_status, self.answer_text = status, text

        def prepare(self) -> None:
            self.set_status(self.answer_status)
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            self.set_header("Cache-Control", "no-store")
            self.finish(self.answer_text)

    return PlainAnswer


def refuse_oversized(request):
    """``(handler, kwargs)`` answering a request whose address or headers are too long to serve
    (414, 431: see the module docstring), or None for every other request. A route for
    :func:`eha_app.runtime.patches.guard_paths`, which asks it before Bokeh's handlers."""
    if len(request.uri) > MAX_ADDRESS_CHARS:
        return plain_answer(), {"status": 414, "text": (
            f"414 URI Too Long: this address is {len(request.uri):,} characters long, more than the "
            f"{MAX_ADDRESS_CHARS:,} this server reads. Open the app's plain address (ending in /eha) instead.\n")}
    size = sum(len(k) + len(v) + 4 for k, v in request.headers.get_all())
    if size > MAX_HEADER_FIELDS_BYTES:
        return plain_answer(), {"status": 431, "text": (
            f"431 Request Header Fields Too Large: this request's headers take {size:,} bytes, more than the "
            f"{MAX_HEADER_FIELDS_BYTES:,} this server reads. Delete this site's cookies and reload.\n")}
    return None


def first_answer(*routes):
    """One route (for :func:`~eha_app.runtime.patches.guard_paths`) asking ``routes`` in turn: the
    first answer that is not None is taken."""
    def route(request):
        for r in routes:
            answer = r(request)
            if answer is not None:
                return answer
        return None
    return route


def one_blas_thread() -> list[str]:
    """Let each BLAS library of this process (numpy's and scipy's OpenBLAS) use one thread.

    A server computes each student's run in a worker thread of its own; OpenBLAS's threads, one per
    core, only spun beside them waiting for work on small matrices: a grey-box estimate took 0.30
    CPU-s with them and 0.15 without, least squares 0.16 and 0.09 (wall time the same or less). The
    libraries limited, by name ("openblas" twice on a pip install; none if threadpoolctl is missing).
    """
    try:
        from threadpoolctl import threadpool_info, threadpool_limits
    except ImportError:
        return []
    # a library is limited only once it is loaded: scipy's own OpenBLAS comes with scipy.linalg
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401

    threadpool_limits(limits=1, user_api="blas")
    return [lib["internal_api"] for lib in threadpool_info() if lib.get("user_api") == "blas"]


def run_panel_serve(argv: list[str]) -> int:
    """Run ``panel serve`` with the command line ``argv`` (``["panel", "serve", ...]``, from
    :func:`serve_argv`) as Panel's own ``panel`` command does, but through a subclass of its
    ``serve`` command whose server puts :func:`security_headers` on every answer and reads
    addresses up to :data:`MAX_REQUEST_HEAD_BYTES` (see the module docstring).

    Both go through Bokeh's documented hook for a subclass of the command,
    ``customize_kwargs``: ``transforms`` reaches Tornado's ``Application`` (``BokehTornado``
    passes keyword arguments it does not know on to it) and ``http_server_kwargs`` Tornado's
    ``HTTPServer`` (``bokeh.server.server.Server``'s own argument)."""
    import argparse

    from bokeh.command.util import die
    from panel.command.serve import Serve
    from panel.config import config

    class ClassroomServe(Serve):
        def customize_kwargs(self, args, server_kwargs):
            kwargs = super().customize_kwargs(args, server_kwargs)
            # (an explicit list: Tornado then adds no gzip of its own, which Bokeh does not ask for)
            kwargs["transforms"] = [*(kwargs.get("transforms") or ()), security_transform()]
            kwargs["http_server_kwargs"] = {**(kwargs.get("http_server_kwargs") or {}),
                                            "max_header_size": MAX_REQUEST_HEAD_BYTES}
            return kwargs

    parser = argparse.ArgumentParser(prog="panel serve")
    command = ClassroomServe(parser=parser)
    args = parser.parse_args(argv[2:])
    try:
        command.invoke(args)
    except Exception as exc:
        # as panel's own command: the message alone, unless Panel logs in detail
        if config.autoreload or config.log_level in ("DEBUG", "INFO"):
            raise
        die("ERROR: " + str(exc))
    return 0


def use_local_resources(doc) -> None:
    """Make the session's Panel stylesheets load from this server, not from a CDN.

    Panel records where its CSS lives when it renders the page for a session;
    with ``--reuse-sessions`` the student's session is built when the
    websocket connects and never rendered, so its components would point at
    cdn.holoviz.org: no style in a classroom without internet (and a console
    error per file). Call before building the page.
    """
    import panel as pn
    from panel.io.resources import LOCAL_DIST

    if doc is None or getattr(doc, "session_context", None) is None:
        return
    if "dist_url" not in doc.template_variables:
        rel = pn.state.rel_path
        doc.template_variables["dist_url"] = f"{rel}/{LOCAL_DIST}" if rel else LOCAL_DIST


class _ClosedPageNote(logging.Filter):
    """Bokeh's and Panel's warning of a message to a closed page, and Python's warnings, written as
    notes (INFO): events of a class at work, not faults of the server."""

    def filter(self, record: logging.LogRecord) -> bool:
        closed = record.getMessage().startswith("Failed sending message as connection")
        if record.levelno == logging.WARNING and (closed or record.name == "py.warnings"):
            record.levelno, record.levelname = logging.INFO, "INFO"
        return True


_closed_page_note = _ClosedPageNote()

#: The event loops already told to be quiet (a set, not an attribute on the loop: uvloop's take none).
_quiet_loops: weakref.WeakSet = weakref.WeakSet()


def quiet_closed_websockets() -> None:
    """Do not log a traceback when a page closes while the server writes to it.

    Tornado reports each write to a websocket closed meanwhile as "Task
    exception was never retrieved" with two tracebacks: with a class closing
    their laptops that fills the log with noise that hides real errors. Only
    these are silenced; everything else goes to asyncio's default handler.
    Safe to call more than once (process-wide, on the server's event loop).
    """
    import asyncio

    from tornado.iostream import StreamClosedError
    from tornado.websocket import WebSocketClosedError

    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        return
    if loop in _quiet_loops:
        return
    previous = loop.get_exception_handler()

    def handler(loop, context):
        if isinstance(context.get("exception"), (WebSocketClosedError, StreamClosedError)):
            return
        if previous is not None:
            previous(loop, context)
        else:
            loop.default_exception_handler(context)

    loop.set_exception_handler(handler)
    _quiet_loops.add(loop)
    # Bokeh and Panel warn when a message finds its page closed (a reload, a laptop shut): a
    # normal event of a class, not a fault; it goes to the log as a note
    for name in ("bokeh.server.views.ws", "panel.io.document"):
        logger = logging.getLogger(name)
        if _closed_page_note not in logger.filters:
            logger.addFilter(_closed_page_note)
    # Python's warnings (numpy's "All-NaN slice" on a student's diverged run, a library's notice)
    # go to the log as notes, with their place, instead of bare lines on stderr
    logging.captureWarnings(True)
    warnings_logger = logging.getLogger("py.warnings")
    if _closed_page_note not in warnings_logger.filters:
        warnings_logger.addFilter(_closed_page_note)
    # BokehJS sends a button's whole definition with its click when the button
    # arrived in a patch (our tabs are built when first shown); Bokeh then warns
    # "reference already known" and uses the model it has. Nothing is wrong.
    import warnings

    from bokeh.util.warnings import BokehUserWarning

    warnings.filterwarnings("ignore", message="reference already known", category=BokehUserWarning)


def supervise(child_argv: list[str], n: int, *, env: dict | None = None, restart_delay_s: float = 2.0) -> int:
    """Run ``n`` copies of ``child_argv`` until interrupted; restart one that dies.

    A crashed process must not take the class down with it: its students
    reload (the page reconnects by itself) and land on the others meanwhile.
    """
    import signal
    import subprocess
    import sys
    import time

    procs: list = [None] * n

    def start(k):
        procs[k] = subprocess.Popen(child_argv, env=env)

    def stop(*_args, code: int = 0):
        for p in procs:
            if p is not None and p.poll() is None:
                p.terminate()
        deadline = time.monotonic() + 10
        for p in procs:
            if p is not None:
                try:
                    p.wait(timeout=max(0.1, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    p.kill()
        raise SystemExit(code)

    signal.signal(signal.SIGTERM, stop)
    for k in range(n):
        start(k)
    try:
        while True:
            time.sleep(0.5)
            for k, p in enumerate(procs):
                code = p.poll()
                if code == 2:
                    # it refused to serve (its reason is on stderr above): another start would refuse too
                    print(f"eha serve: process {k + 1} of {n} refused to start; stopping", file=sys.stderr,
                          flush=True)
                    stop(code=2)
                if code is not None:
                    print(f"eha serve: process {k + 1} of {n} exited with code {code}; restarting it",
                          file=sys.stderr, flush=True)
                    time.sleep(restart_delay_s)
                    start(k)
    except KeyboardInterrupt:
        stop()
    return 0


def lan_address() -> str | None:
    """This machine's address on the local network (no packet is sent)."""
    import socket

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.connect(("10.255.255.255", 1))
            return sock.getsockname()[0]
    except OSError:
        return None


def local_names() -> list[str]:
    """This machine's names and addresses a student may type: the LAN address, the host name."""
    import socket

    names = []
    for name in (lan_address(), socket.gethostname()):      # (getfqdn may wait for a DNS server)
        if name and name not in names and name not in ("localhost", "127.0.0.1", "0.0.0.0"):
            names.append(name.lower())
    return names


def default_origins(address: str, port: int) -> list[str]:
    """The pages allowed to open a websocket when the teacher names none: those served at the
    addresses ``eha serve`` prints (``host:port``), never ``*``.

    A browser sends the page's own address as the websocket's ``Origin``; any
    other website a student has open would send its own, and is refused. On
    every interface (``0.0.0.0``) that is this machine's LAN address and host
    names besides localhost.

    >>> default_origins("127.0.0.1", 5006)
    ['localhost:5006', '127.0.0.1:5006']
    """
    hosts = ["localhost", "127.0.0.1"]
    if address in ("0.0.0.0", "::"):
        hosts += local_names()
    elif address not in hosts:
        hosts.append(address)
    return [f"{h}:{port}" for h in dict.fromkeys(hosts)]


def serve_argv(*, port: int, address: str, num_procs: int = 1, allow_websocket_origin=None,
               show: bool = False, behind_proxy: bool = False, teacher: bool = False) -> list[str]:
    """The `panel serve` command line for `eha serve`.

    ``allow_websocket_origin``: the ``host:port`` of pages allowed to connect; by
    default :func:`default_origins` (``*``, any website, only when asked for).
    ``teacher``: serve the teacher's dashboard at /teacher too (an exercise).
    """
    entries = [str(ENTRY_POINT)] + ([str(TEACHER_ENTRY_POINT)] if teacher else [])
    argv = ["panel", "serve", *entries, "--port", str(port), "--address", address,
            "--num-procs", str(num_procs), "--reuse-sessions",
            "--unused-session-lifetime", str(UNUSED_SESSION_MS), "--check-unused-sessions", str(CHECK_SESSIONS_MS),
            "--websocket-max-message-size", str(WEBSOCKET_MAX_MESSAGE_BYTES), "--log-format", LOG_FORMAT]
    for origin in allow_websocket_origin or default_origins(address, port):
        argv += ["--allow-websocket-origin", origin]
    if behind_proxy:
        argv.append("--use-xheaders")
    if show:
        argv.append("--show")
    return argv


def nginx_config(backends, *, listen: str = "80", server_name: str = "_", prefix: str = "/eha") -> str:
    """``upstream`` and ``server`` blocks for nginx's ``http`` context (e.g. /etc/nginx/conf.d/eha.conf).

    ``backends`` are ``host:port`` of ``eha serve`` processes, on this
    machine or others. Start each with ``--allow-websocket-origin`` set to the
    address students type (nginx's) and ``--behind-proxy``.
    """
    backends = list(backends)
    if not backends:
        from eha_core.errors import not_allowed

        raise not_allowed("backends", [], "give at least one host:port of an eha serve process")
    # a machine that is down (no answer at all, not even a refusal) is left after 3 s and then for 10 s:
    # its students' requests go to the others at once, not after nginx's 60 s per request
    servers = "\n".join(f"    server {b} max_fails=1 fail_timeout=10s;" for b in backends)
    proxy = """        proxy_pass http://eha_app;
        proxy_http_version 1.1;
        proxy_set_header Upgrade $http_upgrade;
        proxy_set_header Connection $eha_connection_upgrade;
        proxy_set_header Host $host:$server_port;
        proxy_set_header X-Real-IP $remote_addr;
        proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
        proxy_set_header X-Forwarded-Proto $scheme;
        proxy_buffering off;
        proxy_connect_timeout 3s;
        proxy_read_timeout 3600s;
        proxy_send_timeout 3600s;
        add_header Set-Cookie "eha_affinity=$eha_affinity; Path=/; HttpOnly; SameSite=Lax" always;
        add_header X-Eha-Upstream $upstream_addr always;
{security}"""
    # (a location with add_header of its own inherits none of the server's: each lists them)
    security = "\n".join(f"        add_header {name} ${var} always;" for name, var in _NGINX_SECURITY.items())
    proxy = proxy.replace("{security}", security)
    own = security_headers()
    maps = "\n".join(f"map $upstream_http_content_security_policy ${var} {{\n    \"\"      \"{own[name]}\";\n"
                     f"    default \"\";\n}}" for name, var in _NGINX_SECURITY.items())
    return f"""# eha: {len(backends)} app process(es) behind nginx (generated by `eha serve --nginx-config`)
# A page's HTTP request and its websocket must reach the same process: nginx
# gives every new browser a random affinity cookie and hashes it consistently
# over the backends.
map $cookie_eha_affinity $eha_affinity {{
    ""      $request_id;
    default $cookie_eha_affinity;
}}
map $http_upgrade $eha_connection_upgrade {{
    default upgrade;
    ""      close;
}}
# The app's security headers (Content-Security-Policy, no framing, no sniffing) on nginx's own
# answers too (its redirect of /, its 414 and 502 pages): only where no app process answered (an
# empty value adds no header), the app's own are passed on as they are.
{maps}
upstream eha_app {{
    hash $eha_affinity consistent;
{servers}
}}
server {{
    listen {listen};
    server_name {server_name};
{security.replace("        add_header", "    add_header")}
    location / {{
{proxy}
    }}
    # the teacher's dashboard: its first address carries the teacher's token, which nginx's
    # access log would keep; the app logs these requests itself, with the token hidden
    location ^~ /teacher {{
        access_log off;
{proxy}
    }}
    location = / {{
        return 302 {prefix};
    }}
}}
"""


#: The security headers nginx adds to its own answers, and the variables that hold them.
_NGINX_SECURITY = {"Content-Security-Policy": "eha_csp", "X-Frame-Options": "eha_frame_options",
                   "X-Content-Type-Options": "eha_nosniff"}


def nginx_standalone_config(backends, *, listen: str, workdir: str) -> str:
    """A whole nginx configuration (``nginx -c``), for running nginx without root (tests, a laptop)."""
    body = nginx_config(backends, listen=listen)
    body = "\n".join("    " + line if line else line for line in body.splitlines())
    return f"""worker_processes 1;
daemon off;
pid {workdir}/nginx.pid;
error_log {workdir}/error.log warn;
events {{ worker_connections 1024; }}
http {{
    access_log {workdir}/access.log;
    client_body_temp_path {workdir}/client_body;
    proxy_temp_path {workdir}/proxy;
    fastcgi_temp_path {workdir}/fastcgi;
    uwsgi_temp_path {workdir}/uwsgi;
    scgi_temp_path {workdir}/scgi;
{body}
}}
"""
