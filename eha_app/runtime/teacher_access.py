"""Who may reach the teacher's dashboard (``/teacher``): the holder of the exercise's teacher token.

Checked at the HTTP level, before Bokeh sees the request
(:func:`eha_app.runtime.patches.guard_paths` hands every request to
:func:`route` first), so that no part of the dashboard's app (its page, its
websocket, its autoload script, its metadata) answers anyone else:

* ``GET /teacher?token=T`` with the right token sets a cookie (HttpOnly,
  SameSite=Lax, Path=/teacher) and redirects to ``/teacher``: the token
  does not stay in the address bar, the browser's history or a screenshot of
  the projector;
* every request under ``/teacher`` needs that cookie, else it gets 403;
* without an exercise there is no dashboard: 404.

The token is drawn from the exercise's secret and a nonce kept in the class's
database with the token's expiry (:meth:`eha_core.exercise.Exercise.teacher_token`,
:func:`issue`), so every process of ``--num-procs N``, and a restarted server,
accept the same one; the cookie is drawn from the token. A leaked link is
undone by ``eha exercise token FILE --rotate`` (a new nonce: the old link and
every cookie made from it stop working within :data:`REFRESH_S` on every
server), and a link expires by itself (:data:`TOKEN_DAYS` after it was issued
unless ``--days`` says otherwise): neither changes any student's actuator or
code. Both are compared in constant time. The token is registered with
:func:`~eha_app.runtime.redaction.keep_out_of_logs`: Tornado's access log
writes the URL asked for, query included.

The requests are answered on the server's event loop, which never reads the
database: the token and its expiry come from a copy refreshed every
:data:`REFRESH_S` by a thread of its own (:class:`TokenWatch`), started with
the server.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import re
import secrets
import threading
import time
from dataclasses import dataclass
from urllib.parse import unquote

from tornado.web import ErrorHandler, RequestHandler

__all__ = ["TEACHER_PATH", "COOKIE", "TOKEN_DAYS", "REFRESH_S", "Issued", "cookie_value", "same_secret",
           "is_teacher_path", "route", "decide", "issue", "issued", "ensure_token", "TokenWatch", "watch_token"]

log = logging.getLogger("eha_app")

TEACHER_PATH = "/teacher"
COOKIE = "eha_teacher"
#: How long a dashboard link lasts unless the teacher says otherwise (``eha exercise token --days``).
TOKEN_DAYS = 30
#: How often each server reads the token's nonce and expiry again (a rotation holds within this) [s].
REFRESH_S = 2.0


@dataclass(frozen=True)
class Issued:
    """The dashboard's current token and when it expires (POSIX time)."""

    token: str
    expires: float

    @property
    def expired(self) -> bool:
        return time.time() >= self.expires

    def expires_text(self) -> str:
        return time.strftime("%Y-%m-%d %H:%M", time.localtime(self.expires))


def issued(exercise, store) -> Issued | None:
    """The token the class's database holds now (expired or not), None if none was ever issued."""
    control = store.control()
    nonce, expires = control.get("token_nonce", ""), control.get("token_expires", "")
    if not nonce:
        return None
    try:
        when = float(expires)
    except ValueError:
        when = 0.0
    return Issued(exercise.teacher_token(nonce), when)


def issue(exercise, store, days: float = TOKEN_DAYS) -> Issued:
    """A new token (a new nonce), valid for ``days``: the one before stops working on every server."""
    expires = time.time() + days * 86400.0
    nonce = secrets.token_hex(16)
    store.set_controls({"token_nonce": nonce, "token_expires": f"{expires:.0f}"})
    return Issued(exercise.teacher_token(nonce), float(f"{expires:.0f}"))


def ensure_token(exercise, store, days: float = TOKEN_DAYS) -> tuple[Issued, bool]:
    """The current token if it is still valid, else a new one: ``(token, made now)``. Looked at and
    issued in one transaction: servers started together on one database print one link."""
    now = issued(exercise, store)
    if now is not None and not now.expired:
        return now, False
    nonce, expires = secrets.token_hex(16), f"{time.time() + days * 86400.0:.0f}"

    def valid(control):
        try:
            if control.get("token_nonce") and float(control.get("token_expires", "0")) > time.time():
                return control["token_nonce"], control["token_expires"]    # another server issued it a moment ago
        except ValueError:
            pass
        return None
    kept = store.set_controls({"token_nonce": nonce, "token_expires": expires}, keep=valid)
    got, when = kept or (nonce, expires)
    return Issued(exercise.teacher_token(got), float(when)), kept is None


def cookie_value(token: str) -> str:
    """The cookie's value: drawn from the token, so that the cookie is not the link itself."""
    return hmac.new(token.encode(), b"eha-teacher-cookie", hashlib.sha256).hexdigest()


def same_secret(given: str | None, expected: str) -> bool:
    """``given == expected`` in constant time (any text: compared as UTF-8 bytes)."""
    return given is not None and hmac.compare_digest(given.encode("utf-8", "replace"), expected.encode())


def is_teacher_path(path: str) -> bool:
    """Is ``path`` the dashboard's or under it (however it is spelt: escaped, doubled slashes, capitals)?

    >>> [is_teacher_path(p) for p in ("/teacher", "/teacher/ws", "//Teacher/", "/te%61cher", "/eha", "/teachers")]
    [True, True, True, True, False, False]
    """
    p = re.sub(r"/+", "/", unquote(path)).lower()
    return p == TEACHER_PATH or p.startswith(TEACHER_PATH + "/")


def decide(path: str, query_token: str | None, cookie: str | None, token: str | None, *,
           expired: bool = False) -> str:
    """What to do with a request of ``path``: "pass" (to Bokeh), "login", "forbidden", "expired" or "absent".

    ``token``: the exercise's teacher token (None: no exercise, or none issued); ``expired``: it has expired.

    >>> t = "ab" * 20
    >>> decide("/teacher", t, None, t), decide("/teacher", None, cookie_value(t), t)
    ('login', 'pass')
    >>> decide("/teacher/ws", t, None, t), decide("/teacher", "x" * 40, None, t), decide("/teacher", t, None, None)
    ('forbidden', 'forbidden', 'absent')
    >>> decide("/eha", None, None, t)
    'pass'
    """
    if not is_teacher_path(path):
        return "pass"
    if token is None:
        return "absent"
    if not token:
        return "forbidden"              # none issued yet: nobody's link opens it
    if expired:
        return "expired"
    # the token opens the page only: what the page loads afterwards goes by the cookie
    if path.rstrip("/") == TEACHER_PATH and query_token is not None and same_secret(query_token, token):
        return "login"
    if cookie is not None and same_secret(cookie, cookie_value(token)):
        return "pass"
    return "forbidden"


class _Login(RequestHandler):
    """Set the teacher's cookie and send the browser on to the dashboard without the token."""

    def initialize(self, value: str, max_age: int | None = None) -> None:
        self.value = value
        self.max_age = max_age

    def get(self) -> None:
        # the cookie ends with the token (a rotation changes the cookie's value too)
        self.set_cookie(COOKIE, self.value, path=TEACHER_PATH, httponly=True, samesite="Lax",
                        secure=self.request.protocol == "https", max_age=self.max_age)
        self.set_header("Cache-Control", "no-store")
        self.set_header("Referrer-Policy", "no-referrer")
        # relative: right behind nginx as well, whatever host name the teacher typed
        self.redirect("teacher" if self.request.path.endswith("/teacher") else "../teacher")

    head = get


class TokenWatch:
    """The current token and its expiry, read from the class's database by a thread of its own every
    :data:`REFRESH_S` (the event loop, which answers the requests, never reads the database).

    :meth:`get` returns the last reading; the first is made at :meth:`start` (before the server
    serves). Without a server (tests, a notebook: never started) every :meth:`get` reads."""

    def __init__(self, refresh_s: float = REFRESH_S):
        self.refresh_s = refresh_s
        self._value: Issued | None = None
        self._loaded = False
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def _read(self) -> None:
        from .exercise_file import current_exercise
        from .redaction import keep_out_of_logs

        try:
            found = current_exercise()
            value = issued(*found) if found is not None else None
        except Exception as exc:  # noqa: BLE001 - a damaged store or file: no dashboard until it is fixed
            if self._loaded:
                log.warning("the teacher's dashboard link could not be read (%s): the last one stays", exc)
                return
            value = None
        if value is not None:
            keep_out_of_logs(value.token)
        with self._lock:
            self._value, self._loaded = value, True

    def _run(self) -> None:
        while True:
            time.sleep(self.refresh_s)
            self._read()

    def start(self) -> TokenWatch:
        """Read now, then every :attr:`refresh_s` on a thread of its own (once)."""
        if self._thread is None:
            self._read()
            self._thread = threading.Thread(target=self._run, name="eha-teacher-token", daemon=True)
            self._thread.start()
        return self

    def get(self) -> Issued | None:
        if self._thread is None:
            self._read()                # no server started the watch: read here (never on a served loop)
        with self._lock:
            return self._value


_watch = TokenWatch()


def watch_token() -> TokenWatch:
    """Start this process's :class:`TokenWatch` (``eha serve`` does, before it serves)."""
    return _watch.start()


def _teacher_token() -> Issued | None:
    """The running exercise's teacher token (None without an exercise; an empty token when none was issued:
    the dashboard exists, and nobody can open it)."""
    from .exercise_file import current_exercise

    try:
        if current_exercise() is None:
            return None
    except (OSError, ValueError) as exc:
        log.warning("the teacher's dashboard is unavailable: the exercise file cannot be read (%s)",
                    type(exc).__name__)
        return None
    from .redaction import redact_server_logs

    redact_server_logs()        # the server's log handlers exist by now (the first request comes after them)
    return _watch.get() or Issued("", 0.0)


class _ToApp(RequestHandler):
    def get(self) -> None:
        self.redirect("./eha")

    head = get


def route(request) -> tuple[type[RequestHandler], dict] | None:
    """The handler that answers ``request`` instead of Bokeh's, or None to let Bokeh's routes answer."""
    if request.path == "/":
        # with the dashboard served beside it, Panel's root would list both apps to every student
        return _ToApp, {}
    if not is_teacher_path(request.path):
        return None
    current = _teacher_token()
    token = current.token if current is not None else None
    given = request.query_arguments.get("token")
    cookie = request.cookies.get(COOKIE)
    what = decide(request.path, given[-1].decode("utf-8", "replace") if given else None,
                  cookie.value if cookie is not None else None, token,
                  expired=current is not None and bool(current.token) and current.expired)
    if what == "pass":
        return None
    if what == "login":
        return _Login, {"value": cookie_value(token), "max_age": max(1, int(current.expires - time.time()))}
    if what == "expired":
        from .serving import plain_answer

        return plain_answer(), {"status": 403, "text": "403: this dashboard link has expired. On the server, run: "
                                "eha exercise token FILE --rotate (it prints a new link)\n"}
    return ErrorHandler, {"status_code": 404 if what == "absent" else 403}
