"""``eha identify lse|tf``: least squares (eqs. 15-18) and transfer-function estimation (eqs. 19-27).

The arguments are checked before the estimators (scipy) are imported: a typo
is refused at once.
"""

from __future__ import annotations

import math
import sys

from eha_core.errors import FieldError

from .columns import add_columns_option, checked_columns, read_with_columns
from .common import (
    PARAM_HELP,
    Parser,
    UsageError,
    as_option,
    as_typed,
    check_input_file,
    json_text,
    parse_params,
    refused,
    table_text,
    tf_text,
)

#: Poles of an estimated model at most (and zeros at most poles - 1).
MAX_POLES = 8
#: Length of a simulated least-squares record at most [s] (60 s is 60 000 samples).
MAX_LSE_T_END = 600.0
#: ... and at least [s]: 100 samples, of which the default prefilter's start-up (5 tau_f) leaves 50.
MIN_LSE_T_END = 0.1
#: The columns each estimate reads of --data.
LSE_COLUMNS = ("t", "x", "v", "p1", "p2", "u")
TF_COLUMNS = ("t", "u", "y")
#: More names u and y may go by when they are guessed: a closed loop's reference r and position x, as the
#: web app's frequency tab reads a record.
TF_ALIASES = {"u": ("r",), "y": ("x",)}


def add_parser(sub) -> None:
    from eha_core.signals import SIGNAL_GRAMMAR

    idf = sub.add_parser("identify", help="identification: least squares (lse), transfer function (tf), grey-box "
                                          "(greybox) or black-box (arx, armax, oe, bj, ss, process; select for "
                                          "the structure)")
    idsub = idf.add_subparsers(dest="method", metavar="METHOD", parser_class=Parser)
    idf.set_defaults(handler=_missing_method)
    le = idsub.add_parser("lse", help="least squares for M, B, Af, d0, beta_e (eqs. 15-18)",
                          description="Least-squares identification. Without --data the nonlinear model is "
                                      "simulated with u = 6 sin(4 pi t) for 5 s at 1 kHz.",
                          epilog=SIGNAL_GRAMMAR)
    le.add_argument("--disturbance", default="none",
                    help="load disturbance d(t) as signal text, e.g. none (default), sine:5000:1, white:1000")
    le.add_argument("--disturbance-model", default="constant",
                    help="constant (the paper's d0) or harmonic[:FREQ_HZ] (d0 + a sinusoid; frequency estimated "
                         "if not given)")
    le.add_argument("--seed", type=int, default=0, help="seed of a noise disturbance without one (default 0)")
    le.add_argument("--u", help="excitation as signal text; default sine:6:2")
    le.add_argument("--t-end", type=float, default=5.0,
                    help=f"record length [s] (default 5, {MIN_LSE_T_END:g} to {MAX_LSE_T_END:g})")
    le.add_argument("--tau-f", type=float, default=0.01, help="prefilter time constant [s] (default 0.01, eq. 17)")
    le.add_argument("--estimator", default="ls",
                    help="ls (the paper's least squares, eq. 18; the default) or iv (instrumental variables from a "
                         "noise-free simulation of the model: unbiased under a noisy load force)")
    le.add_argument("--intervals", default=None,
                    help="newey-west (normal quantile) or ewc (equal-weighted cosines, t quantile); default "
                         "newey-west for ls, ewc for iv")
    le.add_argument("--data", metavar="FILE",
                    help="identify from a CSV or .mat file with columns t,x,v,p1,p2,u (SI, or units in the header "
                         "such as x[mm], p1[bar]; other names: see --columns) instead of simulating")
    add_columns_option(le, "t, x, v, p1, p2, u")
    le.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="known/nominal parameters (Dc, dc, L0, Kq1, Kq2, ps, pr, k_f are taken as measured); "
                         + PARAM_HELP)
    le.add_argument("--json", action="store_true", help="print JSON (default: a table)")
    # the core's names -> the options; what a failed simulation or fit may follow from, the likeliest first
    le.set_defaults(handler=run_lse, fields={"tau_f": "--tau-f"},
                    inputs=("--param", "--u", "--disturbance", "--data", "--columns"))

    tf = idsub.add_parser("tf", help="continuous-time transfer function (like MATLAB tfest)",
                          description="Transfer-function estimation. Without --data: the paper's closed-loop "
                                      "experiment (idinput sine reference, Kp = 10 at Ts = 0.01 s, nonlinear plant).")
    tf.add_argument("--data", metavar="FILE",
                    help="a CSV or .mat file with columns t,u,y, or t,r,x (a closed loop's reference and position, "
                         "as the web app writes them), uniformly sampled; u held or linear between samples, see "
                         "--intersample; other names: see --columns")
    add_columns_option(tf, "t, u, y (u may be a closed loop's reference r, y its position x)")
    tf.add_argument("--ts", type=float, help="sample time [s]; default from t in --data, or 0.01")
    tf.add_argument("--np", dest="n_poles", type=int, default=3, help=f"number of poles, 1 to {MAX_POLES} (default 3)")
    tf.add_argument("--nz", dest="n_zeros", type=int, default=0, help="number of zeros, 0 to np - 1 (default 0)")
    tf.add_argument("--seed", type=int, default=0, help="seed of the idinput excitation (default 0)")
    tf.add_argument("--kp", type=float, default=10.0, help="paper experiment: proportional gain (default 10)")
    tf.add_argument("--model", default="nonlinear",
                    help="paper experiment: the actuator's model in the loop, nonlinear (default) or linear")
    tf.add_argument("--initial-condition", default=None,
                    help="zero or estimate (default: estimate for the paper experiment, zero for --data)")
    tf.add_argument("--input-offset", default=None,
                    help="zero or estimate a constant input offset (default: estimate for the paper experiment, "
                         "zero for --data)")
    tf.add_argument("--delay", default=None, metavar="SECONDS|estimate",
                    help="input delay of the model G(s) exp(-s tau): a fixed delay >= 0 s (any multiple of the "
                         "sample time or not), or estimate; default 0 (none). With --data only")
    tf.add_argument("--max-delay", type=float, default=None, metavar="SECONDS",
                    help="upper bound of an estimated delay [s] (default a tenth of the record)")
    tf.add_argument("--intersample", default=None, metavar="zoh|foh",
                    help="the input between samples (MATLAB's InterSample): zoh, held (default, a digital "
                         "controller's output), or foh, linear (a smooth signal sampled), with --data only")
    tf.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    tf.add_argument("--json", action="store_true", help="print JSON (default: a summary)")
    from .greybox import add_parser as add_greybox

    add_greybox(idsub)
    from .blackbox import add_parser as add_blackbox

    add_blackbox(idsub)
    # what the paper experiment's closed-loop simulation, or a fit, may fail on, the likeliest first
    tf.set_defaults(handler=run_tf, inputs=("--kp", "--param", "--ts", "--model", "--data", "--columns"))


def _missing_method(args) -> int:
    raise UsageError("identify needs a METHOD: lse, tf or greybox (eha identify --help tells more)")


def _positive(option: str, value: float, unit: str) -> None:
    if not (math.isfinite(value) and value > 0):
        raise refused(option, value, f"use a number > 0 {unit}".rstrip())


def run_lse(args) -> int:
    from eha_core.identify.disturbance import parse_disturbance_model
    from eha_core.identify.lse_choices import checked_choices
    from eha_core.signals import parse_signal

    if args.seed < 0:
        raise refused("--seed", args.seed, "use a whole number >= 0")
    estimator, intervals = checked_choices(args.estimator, args.intervals, name="--estimator",
                                           intervals_name="--intervals")
    _positive("--tau-f", args.tau_f, "s")
    if not (math.isfinite(args.t_end) and MIN_LSE_T_END <= args.t_end <= MAX_LSE_T_END):
        raise refused("--t-end", args.t_end, f"use a record length in [{MIN_LSE_T_END:g}, {MAX_LSE_T_END:g}] s")
    model, freq = parse_disturbance_model(args.disturbance_model, name="--disturbance-model")
    d = parse_signal(args.disturbance, name="--disturbance", seed=args.seed)
    u = parse_signal(args.u, name="--u") if args.u else None
    check_input_file("--data", args.data)
    given = checked_columns(args, LSE_COLUMNS)
    params = parse_params(args.param)

    from eha_core.experiments import LSE_INPUT, lse_data
    from eha_core.identify.lse import MeasuredData, identify_lse

    if args.data:
        data = read_with_columns(lambda mapping: MeasuredData.from_csv(args.data, name="--data", mapping=mapping),
                                 args.data, LSE_COLUMNS, given)
        source = args.data
    else:
        u = u or LSE_INPUT
        try:
            data = lse_data(params, d, u=u, t_end=args.t_end, seed=args.seed)
        except FieldError as exc:
            # the simulated record's times, input and load are what was typed (with --data, the file's)
            raise UsageError(as_typed(exc, {"t": "--t-end", "u": "--u", "d": "--disturbance"}, args.typed)) from None
        source = f"simulation: u = {u.label}, d = {d.label}"
    res = identify_lse(data, params, tau_f=args.tau_f, disturbance_model=model, disturbance_freq_hz=freq,
                       estimator=estimator, intervals=intervals)
    out = res.to_dict()
    out["source"] = source
    if args.json:
        print(json_text(out))
        return 0 if res.success else 1
    method = "instrumental variables" if res.estimator == "iv" else "least squares"
    print(f"{method} ({source}), disturbance model: {res.disturbance_model}"
          + (f" at {res.disturbance_freq_hz:.6g} Hz{' (estimated)' if res.freq_estimated else ''}"
             if res.disturbance_freq_hz else ""))
    print(lse_table(res, against_nominal=not args.data))
    if res.intervals == "ewc":
        print(f"95 % interval: estimate +- {res.critical_value:.4g} standard errors (Student's t, "
              f"{res.cosine_terms} equal-weighted cosines)")
    if not res.success:
        print(f"eha identify lse: warning: {res.message}", file=sys.stderr)
    return 0 if res.success else 1


def lse_table(res, *, against_nominal: bool) -> str:
    """The estimates as a table: estimate and 95 % interval, with the nominal value and the relative error
    against it when ``against_nominal`` (a simulated record, whose truth is known: a user's file has none,
    and the paper's values beside its estimates would read as its truth)."""
    header = ["", *(["nominal"] if against_nominal else []), "estimate",
              *(["rel. error"] if against_nominal else []), "95 % interval"]
    rows = []
    for k, v in res.estimates.items():
        lo, hi = res.ci95[k]
        nom, rel = res.nominal.get(k), res.rel_error.get(k)
        rows.append([k, *(["" if nom is None else f"{nom:.6g}"] if against_nominal else []), f"{v:.6g}",
                     *(["" if rel is None else f"{100 * rel:+.3f} %"] if against_nominal else []),
                     f"[{lo:.6g}, {hi:.6g}]"])
    return "\n".join(table_text(header, rows, align="l" + "r" * (len(header) - 2) + "l"))


def _choice(option: str, value, allowed) -> None:
    if value is not None and value not in allowed:
        raise refused(option, value, f"use {' or '.join(allowed)}", value_text=str(value))


def _delay(text: str | None):
    """``--delay`` as seconds (0.0 when not given) or ``"estimate"``."""
    if text is None:
        return 0.0
    if text.strip() == "estimate":
        return "estimate"
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise refused("--delay", text, "use a delay >= 0 s or estimate")
    return value


def _checked_delay(args):
    """``--delay`` (seconds or ``"estimate"``), checked with ``--max-delay`` against the other options."""
    delay = _delay(args.delay)
    if delay != 0.0 and not args.data:
        raise refused("--delay", args.delay, "the paper experiment's loop has no delay", context="without --data")
    if args.max_delay is not None:
        _positive("--max-delay", args.max_delay, "s")
        if delay != "estimate":
            raise refused("--max-delay", args.max_delay, "it bounds an estimated delay; give it with --delay estimate")
    return delay


def _checked_intersample(args) -> str:
    """``--intersample`` (default zoh), checked against ``--data``."""
    _choice("--intersample", args.intersample, ("zoh", "foh"))
    if args.intersample == "foh" and not args.data:
        raise refused("--intersample", args.intersample, "the paper experiment's reference is held between samples",
                      context="without --data")
    return args.intersample or "zoh"


#: The core's names of the delay arguments, and the options that set them.
_DELAY_OPTIONS = {"input_delay": "--delay", "max_delay": "--max-delay"}


def _tf_on_data(args, delay, intersample, given) -> dict:
    """``tfest`` on the CSV of ``--data``, its columns mapped by ``given`` (``--columns``) or found as the
    web app finds them: the estimate's dictionary with ``ts``."""
    from eha_core.data import read_columns, sample_time
    from eha_core.identify.tfest import tfest

    def read(mapping, names=TF_COLUMNS):
        cols = read_columns(args.data, names, name="--data", min_rows=args.n_poles + args.n_zeros + 3,
                            mapping=mapping)
        return dict(zip(TF_COLUMNS, (cols[n] for n in names), strict=True))

    cols = read_with_columns(read, args.data, TF_COLUMNS, given, aliases=TF_ALIASES,
                             also=(lambda: read(None, ("t", "r", "x")), "t, r, x"))
    ts = args.ts if args.ts is not None else sample_time(cols["t"], name="--data", path=args.data)
    try:
        est = tfest(cols["u"], cols["y"], ts, args.n_poles, args.n_zeros,
                    initial_condition=args.initial_condition or "zero", input_offset=args.input_offset or "zero",
                    input_delay=delay, max_delay=args.max_delay, intersample=intersample)
    except FieldError as exc:
        # a delay the record cannot hold (that needs the record's length): name the option
        if exc.field in _DELAY_OPTIONS:
            raise as_option(exc, _DELAY_OPTIONS) from None
        raise
    return {**est.to_dict(), "ts": ts}


def run_tf(args) -> int:
    if not 1 <= args.n_poles <= MAX_POLES:
        raise refused("--np", args.n_poles, f"use 1 to {MAX_POLES} poles")
    if not 0 <= args.n_zeros < args.n_poles:
        raise refused("--nz", args.n_zeros, f"use 0 to np - 1 = {args.n_poles - 1} zeros")
    if args.ts is not None:
        _positive("--ts", args.ts, "s")
    _positive("--kp", args.kp, "V/m")
    if args.seed < 0:
        raise refused("--seed", args.seed, "use a whole number >= 0")
    _choice("--model", args.model, ("nonlinear", "linear"))
    _choice("--initial-condition", args.initial_condition, ("zero", "estimate"))
    _choice("--input-offset", args.input_offset, ("zero", "estimate"))
    delay = _checked_delay(args)
    intersample = _checked_intersample(args)
    check_input_file("--data", args.data)
    given = checked_columns(args, TF_COLUMNS)
    params = parse_params(args.param)

    if args.data:
        out = _tf_on_data(args, delay, intersample, given)
        ok = out["success"]
    else:
        from eha_core.experiments import FrequencyExperiment, run_frequency_identification

        cfg = FrequencyExperiment(seed=args.seed, kp=args.kp, model=args.model, n_poles=args.n_poles,
                                  n_zeros=args.n_zeros, ts=args.ts or 0.01,
                                  initial_condition=args.initial_condition or "estimate",
                                  input_offset=args.input_offset or "estimate")
        try:
            fi = run_frequency_identification(params, cfg)
        except FieldError as exc:
            if exc.field != "t_end":
                raise
            # the experiment's record is its samples times --ts: a run too long is a sample time too long
            raise refused("--ts", args.ts, f"the record of {cfg.n_samples} samples would last {exc.value:g} s: "
                                           f"{exc.what}", value_text=args.typed.get("--ts")) from None
        out = fi.to_dict()
        ok = fi.success
    if args.json:
        print(json_text(out))
        return 0 if ok else 1
    print(tf_text(out["num"], out["den"], "H_hat(s)" if not args.data else "G(s)"))
    print(f"fit {out['fit_percent']:.2f} % (initial condition {out['initial_condition']})")
    if args.data and args.delay is not None:
        tau, tau_std = out["input_delay"], out["input_delay_std"]
        how = "fixed" if tau_std is None else f"estimated, standard error {tau_std:.2g} s"
        print(f"input delay {tau:.6g} s = {tau / out['ts']:.4g} samples ({how}); G(s) above excludes it")
    if args.data and args.intersample is not None:
        how = "held" if out["intersample"] == "zoh" else "linear"
        print(f"input {how} between samples ({out['intersample']})")
    if "open_loop" in out:
        print(tf_text(out["open_loop"]["num"], out["open_loop"]["den"], "P_hat(s)"))
        from eha_core.identify.backout import open_loop_instability

        unstable = open_loop_instability(out["num"], out["den"], args.kp)
        if unstable is not None:
            print(f"P_hat(s) is unstable: a pole at +{unstable[0]:.3g} rad/s"
                  + (f", because H_hat(0) = {unstable[1]:.4g} > 1 (the actuator's P(s) has a pole at 0, so H(0) = 1)"
                     if unstable[1] > 1 else ""))
        b = out["backout"]
        print(f"B + 2 k_f Af / pi = {b['damping_B_plus_2kfAf_over_pi']:.4g} N s/m "
              f"(linearised: {b['damping_nominal']:.4g})")
        print(f"beta_e from the gain = {b['beta_e_from_gain']:.4g} Pa, from the s coefficient = "
              f"{b['beta_e_from_stiffness']:.4g} Pa (nominal {b['beta_e_nominal']:.4g})")
        if out.get("validation_fit_percent") is not None:
            print(f"validation fit on a fresh excitation (seed {out['validation_seed']}): "
                  f"{out['validation_fit_percent']:.2f} %")
    if not ok:
        print(f"eha identify tf: warning: {out['message']}", file=sys.stderr)
    return 0 if ok else 1
