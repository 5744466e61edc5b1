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

The token and the cookie are drawn from the exercise's secret
(:meth:`eha_core.exercise.Exercise.teacher_token`), so every process of
``--num-procs N``, and a restarted server, accept the same ones. Both are
compared in constant time. The token is registered with
:func:`~eha_app.runtime.redaction.keep_out_of_logs`: Tornado's access log
writes the URL asked for, query included.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import re
from urllib.parse import unquote

from tornado.web import ErrorHandler, RequestHandler

__all__ = ["TEACHER_PATH", "COOKIE", "cookie_value", "same_secret", "is_teacher_path", "route", "decide"]

log = logging.getLogger("eha_app")

TEACHER_PATH = "/teacher"
COOKIE = "eha_teacher"


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


def decide(path: str, query_token: str | None, cookie: str | None, token: str | None) -> str:
    """What to do with a request of ``path``: "pass" (to Bokeh), "login", "forbidden" or "absent".

    ``token``: the exercise's teacher token (None: no exercise).

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
    # the token opens the page only: what the page loads afterwards goes by the cookie
    if path.rstrip("/") == TEACHER_PATH and query_token is not None and same_secret(query_token, token):
        return "login"
    if cookie is not None and same_secret(cookie, cookie_value(token)):
        return "pass"
    return "forbidden"


class _Login(RequestHandler):
    """Set the teacher's cookie and send the browser on to the dashboard without the token."""

    def initialize(self, value: str) -> None:
        self.value = value

    def get(self) -> None:
        self.set_cookie(COOKIE, self.value, path=TEACHER_PATH, httponly=True, samesite="Lax",
                        secure=self.request.protocol == "https")
        self.set_header("Cache-Control", "no-store")
        self.set_header("Referrer-Policy", "no-referrer")
        # relative: right behind nginx as well, whatever host name the teacher typed
        self.redirect("teacher" if self.request.path.endswith("/teacher") else "../teacher")

    head = get


def _teacher_token() -> str | None:
    """The running exercise's teacher token (None without an exercise)."""
    from .exercise_file import current_exercise

    try:
        found = current_exercise()
    except (OSError, ValueError) as exc:
        log.warning("the teacher's dashboard is unavailable: the exercise file cannot be read (%s)",
                    type(exc).__name__)
        return None
    if found is None:
        return None
    from .redaction import keep_out_of_logs, redact_server_logs

    token = found[0].teacher_token()
    keep_out_of_logs(token)
    redact_server_logs()        # the server's log handlers exist by now (the first request comes after them)
    return token


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
    token = _teacher_token()
    given = request.query_arguments.get("token")
    cookie = request.cookies.get(COOKIE)
    what = decide(request.path, given[-1].decode("utf-8", "replace") if given else None,
                  cookie.value if cookie is not None else None, token)
    if what == "pass":
        return None
    if what == "login":
        return _Login, {"value": cookie_value(token)}
    return ErrorHandler, {"status_code": 404 if what == "absent" else 403}
