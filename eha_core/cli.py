"""The ``eha`` command: scripted and headless use, and serving the app.

Every bad input ends with one line on stderr naming the problem and exit code 2.
Heavy modules are imported inside each subcommand so that ``eha --help`` is quick.
"""

from __future__ import annotations

import argparse
import json
import sys

from .params import PARAM_NAMES, ParameterError

__all__ = ["main", "build_parser"]

EXIT_USAGE = 2


class UsageError(Exception):
    """Bad input on the command line (exit code 2, one line on stderr)."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line (no usage dump) and exit code 2."""

    def error(self, message):
        raise UsageError(f"{message} ({self.prog} --help tells more)")


PARAM_HELP = ("set a parameter or initial condition (SI units), repeatable; NAME is one of "
              + ", ".join(PARAM_NAMES) + ". p2_0=balance restores the force balance.")

SIMULATE_EPILOG = """\
inputs without --case:
  --u and --d take a signal as text; join terms with '+':
    sine:AMP:FREQ_HZ[:PHASE_RAD]   step:AMP[:T0]   square:AMP:FREQ_HZ
    chirp:AMP:F0_HZ:F1_HZ[:T1]     noise:SIGMA[:SEED[:HOLD_S]]   const:VALUE   none
  e.g.  eha simulate --u sine:6:2 --d "sine:5000:1+noise:100:7" --t-end 2
  With --case, --u/--d replace that case's input or disturbance.

output: CSV with header t,x,v,p1,p2,u,d in SI units (m, m/s, Pa, Pa, V, N), one row
per output sample; to stdout unless --out is given. The linear model's states are
absolute (operating point added back, eq. 14).
"""


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="eha", description="Electro-hydraulic actuator: simulation, identification and the classroom app.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    s = sub.add_parser("simulate", help="open-loop simulation to CSV", epilog=SIMULATE_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("--case", type=int, help="one of the paper's cases 1-4 (Figs. 2-7)")
    s.add_argument("--model", default="nonlinear", help="nonlinear (default) or linear")
    s.add_argument("--branch", default="switching",
                   help="linear model only: switching (default: l5, l6 follow the sign of u), positive or negative")
    s.add_argument("--u", help="valve command u(t) [V] as text (see below)")
    s.add_argument("--d", help="load disturbance d(t) [N] as text (see below)")
    s.add_argument("--t-end", type=float, help="horizon [s] (default 5, the paper's)")
    s.add_argument("--dt", type=float, default=1e-3, help="output interval [s] (default 0.001)")
    s.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    s.add_argument("--out", help="write the CSV to this file instead of stdout")
    s.set_defaults(handler=_cmd_simulate)

    lz = sub.add_parser("linearize", help="operating point, A, B, P(s) and H(s) (eqs. 10-24)")
    lz.add_argument("--kp", type=float, default=10.0, help="proportional gain for H(s) [V/m] (default 10)")
    lz.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    lz.add_argument("--json", action="store_true", help="print JSON (default: a readable summary)")
    lz.set_defaults(handler=_cmd_linearize)

    ii = sub.add_parser("idinput", help="excitation signal compatible with MATLAB's idinput",
                        description="Excitation compatible with MATLAB's idinput: conventions in eha_core.excitation.")
    ii.add_argument("--type", default="rgs", help="rgs (default), rbs, prbs or sine")
    ii.add_argument("--n", type=int, required=True, help="number of samples (one period)")
    ii.add_argument("--band", type=float, nargs=2, default=(0.0, 1.0), metavar=("LO", "HI"),
                    help="pass band in fractions of the Nyquist frequency (default 0 1); prbs: [0 B], clock period 1/B")
    ii.add_argument("--range", type=float, nargs=2, default=(-1.0, 1.0), metavar=("MIN", "MAX"),
                    help="levels (rbs, prbs), mean -/+ one std (rgs), or the span (sine); default -1 1")
    ii.add_argument("--sinedata", type=int, nargs=3, default=(10, 10, 1), metavar=("NS", "NT", "GS"),
                    help="sine: number of sinusoids, trials, grid skip (default 10 10 1)")
    ii.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    ii.add_argument("--out", help="write the CSV (columns k,u) to this file")
    ii.add_argument("--json", action="store_true", help='print {"u": [...], "freqs": [...]} (freqs in rad/sample)')
    ii.set_defaults(handler=_cmd_idinput)

    idf = sub.add_parser("identify", help="identification: least squares (lse) or transfer function (tf)")
    idsub = idf.add_subparsers(dest="method", metavar="METHOD", parser_class=_Parser)
    idf.set_defaults(handler=_missing_method)
    le = idsub.add_parser("lse", help="least squares for M, B, Af, d0, beta_e (eqs. 15-18)",
                          description="Least-squares identification (SPEC section 4). Without --data the "
                                      "nonlinear model is simulated with u = 6 sin(4 pi t) for 5 s at 1 kHz.")
    le.add_argument("--disturbance", default="none",
                    help="none (default), sine:AMP[:FREQ_HZ] (1 Hz default) or white:SIGMA (N, seeded)")
    le.add_argument("--disturbance-model", default="constant",
                    help="constant (the paper's d0) or harmonic[:FREQ_HZ] (d0 + a sinusoid; frequency estimated if not given)")
    le.add_argument("--seed", type=int, default=0, help="seed of the white-noise disturbance (default 0)")
    le.add_argument("--u", help="excitation as signal text (see eha simulate --help); default sine:6:2")
    le.add_argument("--t-end", type=float, default=5.0, help="record length [s] (default 5)")
    le.add_argument("--tau-f", type=float, default=0.01, help="prefilter time constant [s] (default 0.01, eq. 17)")
    le.add_argument("--data", help="identify from a CSV with columns t,x,v,p1,p2,u (SI units) instead of simulating")
    le.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="known/nominal parameters (Dc, dc, L0, Kq1, Kq2, ps, pr, k_f are taken as measured); " + PARAM_HELP)
    le.add_argument("--json", action="store_true", help="print JSON (default: a table)")
    le.set_defaults(handler=_cmd_identify_lse)

    tf = idsub.add_parser("tf", help="continuous-time transfer function (like MATLAB tfest)",
                          description="Transfer-function estimation. Without --data: the paper's closed-loop "
                                      "experiment (idinput sine reference, Kp = 10 at Ts = 0.01 s, nonlinear plant).")
    tf.add_argument("--data", help="CSV with columns t,u,y (uniformly sampled; u held between samples)")
    tf.add_argument("--ts", type=float, help="sample time [s]; default from t in --data, or 0.01")
    tf.add_argument("--np", dest="n_poles", type=int, default=3, help="number of poles (default 3)")
    tf.add_argument("--nz", dest="n_zeros", type=int, default=0, help="number of zeros (default 0)")
    tf.add_argument("--seed", type=int, default=0, help="seed of the idinput excitation (default 0)")
    tf.add_argument("--kp", type=float, default=10.0, help="paper experiment: proportional gain (default 10)")
    tf.add_argument("--plant", default="nonlinear", help="paper experiment: nonlinear (default) or linear plant")
    tf.add_argument("--initial-condition", default=None,
                    help="zero or estimate (default: estimate for the paper experiment, zero for --data)")
    tf.add_argument("--input-offset", default=None,
                    help="zero or estimate a constant input offset (default: estimate for the paper experiment, zero for --data)")
    tf.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    tf.add_argument("--json", action="store_true", help="print JSON (default: a summary)")
    tf.set_defaults(handler=_cmd_identify_tf)

    rp = sub.add_parser("reproduce", help="regenerate every figure and table of the paper in one report",
                        description="Write OUT/report.html (self-contained: opens offline, plots interactive) and "
                                    "the data behind it in OUT/data/ (CSV, and results.json with every number).")
    rp.add_argument("--out", default="eha-report", help="output folder (default ./eha-report)")
    rp.add_argument("--seed", type=int, default=0, help="seed of every random signal (default 0)")
    rp.add_argument("--quick", action="store_true", help="shorter runs (a few seconds; for checking the setup)")
    rp.set_defaults(handler=_cmd_reproduce)

    sv = sub.add_parser("serve", help="serve the classroom web app (one app and state per browser session)",
                        description="Serve the app with Panel from its file entry point eha_app/eha.py "
                                    "(equivalently: panel serve eha_app/eha.py). Each browser session gets its "
                                    "own app and state. For a classroom, use --address 0.0.0.0 and give the "
                                    "students the printed network URL.")
    sv.add_argument("--port", type=int, default=5006, help="port (default 5006)")
    sv.add_argument("--address", default="127.0.0.1",
                    help="address to listen on (default 127.0.0.1; 0.0.0.0 for every network interface)")
    sv.add_argument("--num-procs", type=int, default=1,
                    help="server processes sharing the port (default 1; see the README for sizing a class)")
    sv.add_argument("--workers", type=int, default=None,
                    help="computation threads per process (default: the cores divided by --num-procs)")
    sv.add_argument("--allow-websocket-origin", action="append", default=None, metavar="HOST[:PORT]",
                    help="hosts allowed to connect (default: this machine's names; '*' when listening on 0.0.0.0)")
    sv.add_argument("--behind-proxy", action="store_true",
                    help="trust X-Forwarded-* headers from a reverse proxy such as nginx")
    sv.add_argument("--nginx-config", type=int, default=None, metavar="N",
                    help="print an nginx configuration for N eha serve processes on ports PORT+1..PORT+N behind "
                         "nginx listening on PORT, with the commands that start them, and exit")
    sv.add_argument("--show", action="store_true", help="open the app in a browser")
    sv.add_argument("--share-port", action="store_true", help=argparse.SUPPRESS)
    sv.set_defaults(handler=_cmd_serve)
    return parser


# -- subcommands -----------------------------------------------------------------

def _params(items):
    from .params import parse_param_assignments

    return parse_param_assignments(items)


def _cmd_simulate(args) -> int:
    from .experiments import PAPER_CASES
    from .signals import ZERO, parse_signal
    from .simulate import simulate

    params = _params(args.param)
    u = d = ZERO
    t_end = 5.0
    label = "custom"
    if args.case is not None:
        if args.case not in PAPER_CASES:
            raise UsageError(f"--case = {args.case} is not allowed: use one of 1, 2, 3, 4")
        case = PAPER_CASES[args.case]
        u, d, t_end, label = case.u, case.d, case.t_end, case.name
    elif args.u is None and args.d is None:
        raise UsageError("--case or --u is required: give a paper case (1-4) or an input signal (see eha simulate --help)")
    if args.u is not None:
        u = parse_signal(args.u, name="--u")
    if args.d is not None:
        d = parse_signal(args.d, name="--d")
    if args.t_end is not None:
        t_end = args.t_end
    res = simulate(params, u, d, t_end=t_end, dt=args.dt, model=args.model, branch=args.branch, label=label)
    if not res.success:
        print(f"eha simulate: warning: {res.message}", file=sys.stderr)
    if args.out:
        try:
            res.to_csv(args.out)
        except OSError as exc:
            raise UsageError(f"--out = {args.out!r} is not allowed: {exc.strerror}") from None
    else:
        res.to_csv(sys.stdout)
    return 0 if res.success else 1


def _cmd_linearize(args) -> int:
    from .linear import linearize

    params = _params(args.param)
    lin = linearize(params)
    num, den = lin.tf_coeffs()
    cnum, cden = lin.closed_loop_coeffs(args.kp)
    data = {
        "operating_point": lin.op.to_dict(),
        "lambdas": list(lin.lambdas),
        "lambdas_negative_branch": list(lin.lambdas_negative),
        "A": lin.A.tolist(),
        "B": lin.B_positive.tolist(),
        "B_negative_branch": lin.B_negative.tolist(),
        "E": lin.E.tolist(),
        "tf": {"num": num.tolist(), "den": den.tolist()},
        "closed_loop_tf": {"num": cnum.tolist(), "den": cden.tolist(), "kp": args.kp},
        "poles": _complex_list(lin.poles()),
        "closed_loop_poles": _complex_list(lin.closed_loop_poles(args.kp)),
    }
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    op = lin.op
    print(f"operating point: x = {op.x:g} m, v = {op.v:g} m/s, p1 = {op.p1 / 1e6:.4g} MPa, "
          f"p2 = {op.p2 / 1e6:.5g} MPa, u = {op.u:g} V")
    for i, (lp, ln) in enumerate(zip(lin.lambdas, lin.lambdas_negative), start=1):
        extra = f"   (u < 0: {ln:.6g})" if lp != ln else ""
        print(f"l{i} = {lp:.6g}{extra}")
    print(f"P(s) = {num[-1]:.5g} / (s^3 + {den[1]:.5g} s^2 + {den[2]:.5g} s)          (eq. 23, u >= 0)")
    print(f"H(s) = {cnum[-1]:.5g} / (s^3 + {cden[1]:.5g} s^2 + {cden[2]:.5g} s + {cden[3]:.5g})   (eq. 24, Kp = {args.kp:g})")
    return 0


def _lan_address() -> str | None:
    """This machine's address on the local network (no packet is sent)."""
    import socket

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.connect(("10.255.255.255", 1))
            return sock.getsockname()[0]
    except OSError:
        return None


def serve_argv(args) -> list[str]:
    """The `panel serve` command line for `eha serve` (validated)."""
    from eha_app.serving import ENTRY_POINT, serve_argv as app_serve_argv

    if not 1 <= args.port <= 65535:
        raise UsageError(f"--port = {args.port} is not allowed: use 1-65535")
    if args.num_procs < 1:
        raise UsageError(f"--num-procs = {args.num_procs} is not allowed: use 1 or more")
    if not ENTRY_POINT.exists():
        raise UsageError(f"the app entry point {ENTRY_POINT} is missing: reinstall the package")
    return app_serve_argv(port=args.port, address=args.address, num_procs=args.num_procs,
                          allow_websocket_origin=args.allow_websocket_origin, show=args.show,
                          behind_proxy=args.behind_proxy)


def _cmd_serve(args) -> int:
    import os

    if args.nginx_config is not None:
        return _print_nginx_config(args)
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers = {args.workers} is not allowed: use 1 or more")
    argv = serve_argv(args)
    if args.workers is not None:
        os.environ["EHA_WORKERS"] = str(args.workers)
    elif "EHA_WORKERS" not in os.environ:
        # the processes share the cores: one computation per core in all
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        os.environ["EHA_WORKERS"] = str(max(1, cores // args.num_procs))
    if not args.share_port:
        host = "localhost" if args.address in ("127.0.0.1", "localhost", "0.0.0.0", "::") else args.address
        print(f"EHA app: http://{host}:{args.port}/eha", flush=True)
        if args.address in ("0.0.0.0", "::"):
            lan = _lan_address()
            if lan:
                print(f"for the class (same network): http://{lan}:{args.port}/eha", flush=True)
        print("Ctrl+C stops the server.", flush=True)
    if args.num_procs > 1:
        from eha_app.serving import supervise

        # N independent processes on one port (SO_REUSEPORT): the kernel spreads
        # the students evenly, where Bokeh's forked processes did not
        child = [sys.executable, "-c", "import sys; from eha_core.cli import main; sys.exit(main())", "serve",
                 "--port", str(args.port), "--address", args.address, "--num-procs", "1", "--share-port",
                 "--workers", os.environ["EHA_WORKERS"]]
        for origin in args.allow_websocket_origin or ():
            child += ["--allow-websocket-origin", origin]
        if args.behind_proxy:
            child.append("--behind-proxy")
        if args.show:
            import threading
            import webbrowser

            threading.Timer(8.0, webbrowser.open, args=(f"http://localhost:{args.port}/eha",)).start()
        return supervise(child, args.num_procs)
    if args.share_port:
        from eha_app.serving import share_port

        share_port()
    from panel.command import main as panel_main

    sys.argv = argv
    panel_main()
    return 0


def _print_nginx_config(args) -> int:
    from eha_app.serving import nginx_config

    n = args.nginx_config
    if not 1 <= n <= 64:
        raise UsageError(f"--nginx-config = {n} is not allowed: use 1-64 processes")
    if not 1 <= args.port <= 65535 - n:
        raise UsageError(f"--port = {args.port} is not allowed: use 1-{65535 - n} (the processes take the next ports)")
    import os

    backends = [f"127.0.0.1:{args.port + k}" for k in range(1, n + 1)]
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    print(nginx_config(backends, listen=str(args.port)))
    origin = f"{_lan_address() or 'localhost'}:{args.port}"
    print("# Start the app processes (each on its own port, all on this machine):")
    for k in range(1, n + 1):
        print(f"#   eha serve --port {args.port + k} --behind-proxy --workers {max(1, cores // n)} "
              f"--allow-websocket-origin {origin} &")
    print(f"# then put this file in /etc/nginx/conf.d/ and reload nginx; students open http://{origin}/eha")
    return 0


def _cmd_reproduce(args) -> int:
    from pathlib import Path

    if args.seed < 0:
        raise UsageError(f"--seed = {args.seed} is not allowed: use a whole number >= 0")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out = {args.out!r} is not allowed: it exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out = {args.out!r} is not allowed: {exc.strerror}") from None
    from eha_app.report import build_report

    result = build_report(out, seed=args.seed, reduced=args.quick)
    print(result.path)
    return 0


def _missing_method(args) -> int:
    raise UsageError("identify needs a METHOD: lse or tf (eha identify --help tells more)")


def _cmd_idinput(args) -> int:
    from .excitation import idinput

    ex = idinput(args.n, args.type, tuple(args.band), tuple(args.range), tuple(args.sinedata), seed=args.seed)
    if args.json:
        print(json.dumps({"u": ex.u.tolist(), "freqs": ex.freqs.ravel().tolist()}))
        return 0
    table = ex.to_pandas()
    if args.out:
        try:
            table.to_csv(args.out, index=False, float_format="%.10g")
        except OSError as exc:
            raise UsageError(f"--out = {args.out!r} is not allowed: {exc.strerror}") from None
    else:
        table.to_csv(sys.stdout, index=False, float_format="%.10g")
    return 0


def _cmd_identify_lse(args) -> int:
    from .experiments import LSE_INPUT, lse_data
    from .identify.lse import MeasuredData, identify_lse
    from .signals import parse_signal

    params = _params(args.param)
    model, _, freq_text = args.disturbance_model.partition(":")
    freq = None
    if freq_text:
        try:
            freq = float(freq_text)
        except ValueError:
            raise UsageError(f"--disturbance-model = {args.disturbance_model!r} is not allowed: "
                             "use constant or harmonic[:FREQ_HZ] with a number") from None
    if model not in ("constant", "harmonic") or (model == "constant" and freq_text):
        raise UsageError(f"--disturbance-model = {args.disturbance_model!r} is not allowed: use constant or harmonic[:FREQ_HZ]")
    if args.data:
        data = MeasuredData.from_csv(args.data)
        source = args.data
    else:
        u = parse_signal(args.u, name="--u") if args.u else LSE_INPUT
        data = lse_data(params, args.disturbance, u=u, t_end=args.t_end, seed=args.seed)
        source = f"simulation: u = {u.label}, d = {args.disturbance}, seed {args.seed}"
    res = identify_lse(data, params, tau_f=args.tau_f, disturbance_model=model, disturbance_freq_hz=freq)
    out = res.to_dict()
    out["source"] = source
    if args.json:
        print(json.dumps(out, indent=2))
        return 0 if res.success else 1
    print(f"least squares ({source}), disturbance model: {res.disturbance_model}"
          + (f" at {res.disturbance_freq_hz:.6g} Hz{' (estimated)' if res.freq_estimated else ''}" if res.disturbance_freq_hz else ""))
    print(f"{'':8s}{'nominal':>14s}{'estimate':>14s}{'rel. error':>12s}   95 % interval")
    for k, v in res.estimates.items():
        nom = res.nominal.get(k)
        rel = res.rel_error.get(k)
        lo, hi = res.ci95[k]
        print(f"{k:8s}{'' if nom is None else f'{nom:.6g}':>14s}{v:14.6g}{'' if rel is None else f'{100 * rel:+.3f} %':>12s}   [{lo:.6g}, {hi:.6g}]")
    if not res.success:
        print(f"warning: {res.message}", file=sys.stderr)
    return 0 if res.success else 1


def _cmd_identify_tf(args) -> int:
    from .experiments import FrequencyExperiment, run_frequency_identification
    from .identify.tfest import tfest

    if args.data:
        import numpy as np
        import pandas as pd

        try:
            table = pd.read_csv(args.data)
        except (OSError, ValueError) as exc:
            raise UsageError(f"--data = {args.data!r} is not allowed: cannot read it as CSV ({exc})") from None
        missing = [c for c in ("t", "u", "y") if c not in table]
        if missing:
            raise UsageError(f"--data = {args.data!r} is not allowed: missing column(s) {', '.join(missing)}; need t,u,y")
        t = table["t"].to_numpy(float)
        ts = args.ts if args.ts is not None else float(np.median(np.diff(t))) if t.size > 1 else float("nan")
        est = tfest(table["u"].to_numpy(float), table["y"].to_numpy(float), ts, args.n_poles, args.n_zeros,
                    initial_condition=args.initial_condition or "zero", input_offset=args.input_offset or "zero")
        out = {"num": est.num.tolist(), "den": est.den.tolist(), "fit_percent": est.fit_percent,
               "initial_condition": est.initial_condition, "input_offset": est.input_offset,
               "param_std": None if est.param_std is None else est.param_std.tolist(),
               "success": est.success, "message": est.message, "ts": ts}
        ok = est.success
    else:
        params = _params(args.param)
        cfg = FrequencyExperiment(seed=args.seed, kp=args.kp, plant=args.plant, n_poles=args.n_poles,
                                  n_zeros=args.n_zeros, ts=args.ts or 0.01,
                                  initial_condition=args.initial_condition or "estimate",
                                  input_offset=args.input_offset or "estimate")
        if args.plant not in ("nonlinear", "linear"):
            raise UsageError(f"--plant = {args.plant!r} is not allowed: use nonlinear or linear")
        fi = run_frequency_identification(params, cfg)
        out = fi.to_dict()
        ok = fi.success
    if args.json:
        print(json.dumps(out, indent=2, default=_json_default))
        return 0 if ok else 1
    print(_tf_text(out["num"], out["den"], "H_hat(s)" if not args.data else "G(s)"))
    print(f"fit {out['fit_percent']:.2f} % (initial condition {out['initial_condition']})")
    if "open_loop" in out:
        print(_tf_text(out["open_loop"]["num"], out["open_loop"]["den"], "P_hat(s)"))
        b = out["backout"]
        print(f"B + 2 k_f Af / pi = {b['damping_B_plus_2kfAf_over_pi']:.4g} N s/m (linearised: {b['damping_nominal']:.4g})")
        print(f"beta_e from the gain = {b['beta_e_from_gain']:.4g} Pa, from the s coefficient = "
              f"{b['beta_e_from_stiffness']:.4g} Pa (nominal {b['beta_e_nominal']:.4g})")
        if out.get("validation_fit_percent") is not None:
            print(f"validation fit on a fresh excitation (seed {out['validation_seed']}): {out['validation_fit_percent']:.2f} %")
    if not ok:
        print(f"warning: {out['message']}", file=sys.stderr)
    return 0 if ok else 1


def _poly_text(coeffs) -> str:
    n = len(coeffs) - 1
    text = ""
    for i, c in enumerate(coeffs):
        p = n - i
        power = "" if p == 0 else (" s" if p == 1 else f" s^{p}")
        mag = f"{abs(c):.4g}"
        if not text:
            text = ("-" if c < 0 else "") + (power.strip() if mag == "1" and p else mag + power)
        else:
            text += (" - " if c < 0 else " + ") + (power.strip() if mag == "1" and p else mag + power)
    return text


def _tf_text(num, den, name):
    return f"{name} = ({_poly_text(num)}) / ({_poly_text(den)})"


def _json_default(obj):
    import numpy as np

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _complex_list(values):
    return [[float(v.real), float(v.imag)] for v in values]


# -- entry point -------------------------------------------------------------------

def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return EXIT_USAGE
        return args.handler(args)
    except (UsageError, ParameterError) as exc:
        print(f"eha: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ValueError as exc:
        # ValueError from the core always names the argument, its value and what is allowed
        print(f"eha: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # e.g. `eha simulate ... | head`
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
