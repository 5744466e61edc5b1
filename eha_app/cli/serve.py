"""``eha serve``: the classroom web app, in one or several processes, or behind nginx."""

from __future__ import annotations

import argparse
import errno
import os
import socket
import subprocess
import sys
import threading
import time
import urllib.request

from eha_app.runtime.serving import lan_address

from .common import UsageError, add_store_option, open_store, refused, refused_file, require_app, terminal_text


def add_parser(sub) -> None:
    sv = sub.add_parser("serve", help="serve the classroom web app (one app and state per browser session)",
                        description="Serve the app (Panel, from its entry point eha_app/eha.py). Each browser "
                                    "session gets its own app and state. For a classroom, use --address 0.0.0.0 "
                                    "and give the students the printed network URL.")
    sv.add_argument("--port", type=int, default=5006, help="port (default 5006)")
    sv.add_argument("--address", default="127.0.0.1",
                    help="address to listen on (default 127.0.0.1; 0.0.0.0 for every network interface)")
    sv.add_argument("--num-procs", type=int, default=1,
                    help="server processes sharing the port (default 1; see the README for sizing a class)")
    sv.add_argument("--workers", type=int, default=None,
                    help="computation threads per process (default: the cores divided by --num-procs)")
    sv.add_argument("--allow-websocket-origin", action="append", default=None, metavar="HOST[:PORT]",
                    help="the address of pages allowed to connect, repeatable (default: the addresses this "
                         "command prints; '*' lets any website a student has open use the server: not advised)")
    sv.add_argument("--behind-proxy", action="store_true",
                    help="trust X-Forwarded-* headers from a reverse proxy such as nginx")
    sv.add_argument("--nginx-config", type=int, default=None, metavar="N",
                    help="print an nginx configuration for N eha serve processes on ports PORT+1..PORT+N behind "
                         "nginx listening on PORT, with the commands that start them, and exit")
    sv.add_argument("--exercise", metavar="FILE", help="run a class exercise (made by `eha exercise new`): each "
                    "student types the join code of their slip (`eha exercise codes`; an exercise without a roster "
                    "takes any id) and gets an actuator of their own, with the exercise's parameters hidden")
    add_store_option(sv)
    for flag, what in _OAUTH.items():
        sv.add_argument(flag, default=None, metavar="VALUE", help=what)
    sv.add_argument("--show", action="store_true", help="open the app in a browser")
    sv.add_argument("--share-port", action="store_true", help=argparse.SUPPRESS)
    sv.set_defaults(handler=run)


#: Panel's OAuth, passed on as given: with a provider, a student signed in by the institution joins an
#: exercise as the roster entry whose id is their user name (no join code).
_OAUTH = {"--oauth-provider": "an identity provider of Panel's OAuth (e.g. azure, github, generic): students sign "
                              "in with it and join an exercise as the roster id of their user name",
          "--oauth-key": "the provider's client id", "--oauth-secret": "the provider's client secret",
          "--oauth-redirect-uri": "this server's address as registered with the provider",
          "--oauth-extra-params": "the provider's extra settings (JSON, see Panel's documentation)",
          "--cookie-secret": "a long random text that signs the login cookie",
          "--oauth-encryption-key": "a key that encrypts the provider's tokens in the cookie"}


def _oauth_argv(args) -> list[str]:
    out = []
    for flag in _OAUTH:
        value = getattr(args, flag[2:].replace("-", "_"))
        if value is not None:
            out += [flag, value]
    return out


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


#: What --address takes, said when it is refused.
_ADDRESSES = "use 127.0.0.1 (this machine only), 0.0.0.0 (every network interface) or an address of this machine"


def check_address(address: str) -> None:
    """Refuse an address that is no address (a typo), before anything starts."""
    try:
        socket.getaddrinfo(address, None, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        what = exc.strerror if isinstance(exc, socket.gaierror) else "not a host name"
        raise refused("--address", address, f"not an address ({what}); {_ADDRESSES}") from None


def check_port_free(address: str, port: int) -> None:
    """Refuse a port another program listens on, or an address that is not this machine's, before anything
    starts."""
    family = socket.AF_INET6 if ":" in address else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((address, port))
        except OSError as exc:
            if exc.errno in (errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT) or isinstance(exc, socket.gaierror):
                # the address is another machine's (or none): the port is not the trouble
                raise refused("--address", address, f"this machine cannot listen on it ({exc.strerror}); "
                                                    f"{_ADDRESSES}") from None
            raise refused("--port", port, f"{address}:{port} is in use ({exc.strerror}; another eha serve?); "
                                          "choose another port") from None


def _validate(args) -> None:
    if not 1 <= args.port <= 65535:
        raise refused("--port", args.port, "use 1-65535")
    if not 1 <= args.num_procs <= 64:
        raise refused("--num-procs", args.num_procs, "use 1 to 64")
    if args.workers is not None and not 1 <= args.workers <= 256:
        raise refused("--workers", args.workers, "use 1 to 256")
    check_address(args.address)


def _announce_when_ready(url: str) -> None:
    """Print once the app answers (its first page also prepares the session students will reuse)."""
    def wait():
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(url, timeout=30) as r:
                    if r.status == 200:
                        print(f"Ready: {url}", flush=True)
                        return
            except OSError:
                time.sleep(0.5)
    threading.Thread(target=wait, daemon=True).start()


def _check_exercise(args) -> None:
    """Refuse an exercise file, or its hand-in database, that cannot be used, before anything starts."""
    from .exercise import load_exercise

    exercise = load_exercise("--exercise", args.exercise)   # refused now, with its message, if it is not one
    store = open_store(args.exercise, args.store, exercise_option="--exercise")   # unreachable, newer: refused now
    os.environ["EHA_EXERCISE"] = os.path.abspath(args.exercise)
    if args.store:
        os.environ["EHA_STORE"] = args.store                # the server processes' (never on a command line)
    if not args.share_port:
        print(f"Exercise {terminal_text(repr(exercise.title))}: hides {', '.join(exercise.hide)}; hand-ins go to "
              f"{store.shown if args.store else args.exercise.rsplit('.', 1)[0] + '.handins.sqlite'}", flush=True)


def _announce_dashboard(host: str, port: int) -> None:
    """The dashboard's link, printed here only: the token in it opens the teacher's dashboard (it is
    in no page and no log line; the server's access log shows it as [hidden])."""
    from eha_app.app import current_exercise
    from eha_app.runtime.handins import StoreError
    from eha_app.runtime.teacher_access import ensure_token

    exercise, store = current_exercise()
    try:
        # the link issued before, while it lasts (a restart keeps the teacher's link); else a new one
        issued, made = ensure_token(exercise, store)
    except StoreError as exc:
        raise UsageError(f"--store: {exc}" if os.environ.get("EHA_STORE") else
                         str(refused_file("--exercise", os.environ["EHA_EXERCISE"], f"{exc}"))) from None
    print(f"Teacher's dashboard (for you only, do not show it to the class): http://{host}:{port}/teacher?token="
          f"{issued.token}", flush=True)
    print(f"  {'a new link, ' if made else ''}valid until {issued.expires_text()}; a new one at any time (the old "
          f"one stops working): eha exercise token {os.environ['EHA_EXERCISE']} --rotate", flush=True)


def run(args) -> int:
    require_app("eha serve")
    _validate(args)
    if args.nginx_config is not None:
        return _print_nginx_config(args)
    if args.exercise:
        _check_exercise(args)
    from eha_app.runtime.serving import ENTRY_POINT, default_origins, serve_argv

    if not ENTRY_POINT.exists():
        raise UsageError(f"the app entry point {ENTRY_POINT} is missing: reinstall the package")
    # the library patches this server cannot do without, checked before anything starts
    refusal = _patch_refusal(shared=args.num_procs > 1 or args.share_port)
    if refusal:
        return _refuse(refusal)
    if not args.share_port:
        check_port_free(args.address, args.port)
    argv = serve_argv(port=args.port, address=args.address, num_procs=1,
                      allow_websocket_origin=args.allow_websocket_origin, show=args.show and args.num_procs == 1,
                      behind_proxy=args.behind_proxy, teacher=bool(args.exercise))
    os.environ["EHA_WORKERS"] = str(args.workers or os.environ.get("EHA_WORKERS") or max(1, _cores() // args.num_procs))
    host = "localhost" if args.address in ("127.0.0.1", "localhost", "0.0.0.0", "::") else args.address
    url = f"http://{host}:{args.port}/eha"
    if not args.share_port:
        print(f"EHA app: {url}", flush=True)
        if args.address in ("0.0.0.0", "::"):
            lan = lan_address()
            if lan:
                print(f"for the class (same network): http://{lan}:{args.port}/eha", flush=True)
        if args.exercise:
            _announce_dashboard(host, args.port)
        origins = args.allow_websocket_origin or default_origins(args.address, args.port)
        print(f"Pages may connect from {', '.join(origins)}"
              + ("" if args.allow_websocket_origin else " (--allow-websocket-origin names others)"), flush=True)
        print("Preparing the simulation kernels (the first start after an install compiles them, "
              "about 30 s)...", flush=True)
        _compile_kernels(args.num_procs)
        print("Starting the server. Ctrl+C stops it.", flush=True)
        _announce_when_ready(f"http://127.0.0.1:{args.port}/eha" if args.address in ("0.0.0.0", "::")
                             else f"http://{args.address}:{args.port}/eha")
    if args.num_procs > 1:
        from eha_app.runtime.serving import supervise

        # N independent processes on one port (SO_REUSEPORT): the kernel spreads
        # the students evenly, where Bokeh's own forked processes did not
        child = [sys.executable, "-m", "eha_app.cli", "serve", "--port", str(args.port), "--address", args.address,
                 "--num-procs", "1", "--share-port", "--workers", os.environ["EHA_WORKERS"]]
        for origin in args.allow_websocket_origin or ():
            child += ["--allow-websocket-origin", origin]
        if args.behind_proxy:
            child.append("--behind-proxy")
        if args.exercise:
            child += ["--exercise", os.environ["EHA_EXERCISE"]]
        child += _oauth_argv(args)
        if args.show:
            import webbrowser

            threading.Timer(8.0, webbrowser.open, args=(url,)).start()
        return supervise(child, args.num_procs)
    return _serve_here(args, argv)


def _serve_here(args, argv: list[str]) -> int:
    """Serve in this process (one of ``--num-procs`` when ``--share-port``) with Panel's command line
    ``argv``, the server's changes of its libraries installed first."""
    from eha_app.app import warm_up
    from eha_app.runtime.patches import (
        AFTER_LOAD_PATCHES,
        GUARDS,
        READ_PATCHES,
        SERVER_PATCHES,
        apply_patches,
        guard_paths,
        unknown_turned_off,
    )
    from eha_app.runtime.serving import first_answer, one_blas_thread, refuse_oversized
    from eha_app.runtime.teacher_access import route, watch_token

    # the libraries' internals this server changes, each checked against the installed versions and
    # what it replaces (eha_app/runtime/patches.py); one line says which were applied
    for name in unknown_turned_off():
        print(f"eha serve: EHA_PATCHES_OFF names {name!r}, which is no patch: nothing turned off for it",
              file=sys.stderr)
    status = apply_patches((("shared_port",) if args.share_port else ()) + SERVER_PATCHES + READ_PATCHES)
    failed = [n for n in (*GUARDS, *(("shared_port",) if args.share_port else ())) if status[n] != "applied"]
    if failed:
        return _refuse(f"the {failed[0]} patch failed to install ({status[failed[0]]}): see the warning above")
    # an address too long to serve gets 414 (not a closed connection), before anything else reads it;
    # then /teacher answers the teacher only (and 404 without an exercise)
    guard_paths(first_answer(refuse_oversized, route))
    if os.environ.get("EHA_EXERCISE"):
        watch_token()           # the dashboard's token read off the event loop, from now on
    sys.argv = argv + _oauth_argv(args)
    # the students' runs are the parallel work (the workers): a BLAS thread pool beside each only spins
    one_blas_thread()
    warm_up()                   # the kernels and the identification code loaded before the first page
    # what is loaded so far frozen out of the collector's sight, and full collections small and often
    status.update(apply_patches(AFTER_LOAD_PATCHES))
    _say_patches(status)
    # Panel's `panel serve`, its server putting the security headers on every answer (serving.py)
    from eha_app.runtime.serving import run_panel_serve

    return run_panel_serve(sys.argv)


def _say_patches(status: dict[str, str]) -> None:
    """One line on stderr: the library patches applied, and those not (a warning each above says why)."""
    applied = [n for n, s in status.items() if s == "applied"]
    others = [n for n, s in status.items() if s != "applied"]
    print(f"eha serve: library patches applied: {', '.join(applied) or 'none'}"
          + (f"; not applied: {', '.join(others)}" if others else ""), file=sys.stderr, flush=True)


def _patch_refusal(*, shared: bool) -> str:
    """Why this server must not start with the installed Panel and Bokeh ("" when it may): its two
    security guards do not fit them, or several processes would have to share a port without the
    patch that lets them."""
    from eha_app.runtime.patches import GUARDS, why_not

    for name in GUARDS:
        why = why_not(name)
        if why:
            return (f"the {name} security check cannot be installed ({why}): the server would not be safe "
                    "to open to a class; install panel 1.9 and bokeh 3.9")
    why = why_not("shared_port") if shared else ""
    if why:
        return (f"--num-procs above 1 needs the shared_port patch ({why}): serve with --num-procs 1, "
                "or install bokeh 3.9")
    return ""


def _refuse(message: str) -> int:
    print(f"eha serve: {message}", file=sys.stderr)
    return 2


def _compile_kernels(num_procs: int) -> None:
    """Compile the simulation kernels once (numba's cache on disk) before the server starts."""
    if num_procs > 1:
        # in a process of its own: the server processes load the compiled code from disk, and this
        # one, which only watches them, stays small (it kept 250 MB of libraries)
        subprocess.run([sys.executable, "-c", "from eha_app.app import warm_up; warm_up()"], check=True)
    else:
        from eha_app.app import warm_up

        warm_up()


def _print_nginx_config(args) -> int:
    from eha_app.runtime.serving import nginx_config

    n = args.nginx_config
    if not 1 <= n <= 64:
        raise refused("--nginx-config", n, "use 1-64 processes")
    if not 1 <= args.port <= 65535 - n:
        raise refused("--port", args.port, f"use 1-{65535 - n} (the processes take the next ports)")
    backends = [f"127.0.0.1:{args.port + k}" for k in range(1, n + 1)]
    print(nginx_config(backends, listen=str(args.port)))
    origin = f"{lan_address() or 'localhost'}:{args.port}"
    lab = f" --exercise {args.exercise}" if args.exercise else ""
    print("# Start the app processes (each on its own port, all on this machine):")
    if args.exercise and args.store:
        from eha_app.runtime.store_backend import shown_url

        # the URL goes into the environment, not onto a command line every user of the machine sees in ps
        print(f"#   export EHA_STORE='{shown_url(args.store)}'   (its password in ~/.pgpass or PGPASSWORD)")
    for k in range(1, n + 1):
        print(f"#   eha serve --port {args.port + k}{lab} --behind-proxy --workers {max(1, _cores() // n)} "
              f"--allow-websocket-origin {origin} &")
    print(f"# then put this file in /etc/nginx/conf.d/ and reload nginx; students open http://{origin}/eha")
    return 0
