"""``eha identify greybox``: grey-box identification of the nonlinear model's physical parameters.

The arguments are checked before anything is simulated: a typo is refused at once.
"""

from __future__ import annotations

import math
import sys

from eha_core.errors import FieldError

from .columns import add_columns_option, checked_columns, read_with_columns
from .common import (
    NOISE_GRAMMAR,
    UsageError,
    as_option,
    as_typed,
    check_input_file,
    json_text,
    parse_noise,
    parse_params,
    refused,
)

#: The longest simulated record [s].
MAX_GREYBOX_T_END = 120.0


def add_parser(idsub) -> None:
    from eha_core.identify.greybox import GREYBOX_PARAMS, GREYBOX_SIGNALS
    from eha_core.signals import SIGNAL_GRAMMAR

    gb = idsub.add_parser(
        "greybox", help="grey-box: the nonlinear model's physical parameters by output error (like nlgreyest)",
        description="Grey-box identification: simulate the nonlinear model with candidate parameters, compare with "
                    "the measured signals, minimise (Levenberg-Marquardt with the model's sensitivities). Without "
                    "--data the nonlinear plant is simulated with --u (default sine:6:2) for --t-end s at 1 kHz, its "
                    "true values set by --param; the estimate starts from the paper's values.",
        epilog=SIGNAL_GRAMMAR)
    gb.add_argument("--params", default="M,B,Af,beta_e", metavar="NAMES",
                    help=f"the parameters to estimate, of {', '.join(GREYBOX_PARAMS)} (default M,B,Af,beta_e)")
    gb.add_argument("--measured", default="x,p1,p2", metavar="SIGNALS",
                    help=f"the signals compared, of {', '.join(GREYBOX_SIGNALS)} (default x,p1,p2; x alone works)")
    gb.add_argument("--data", metavar="FILE",
                    help="a CSV or .mat file with t, u and the measured columns (SI, or units in the header such as "
                         "p1[MPa]; other names: see --columns); the values not estimated are the paper's or "
                         "--param's")
    add_columns_option(gb, "t, u and the signals of --measured")
    gb.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="without --data: the simulated plant's true values; with --data: the values held")
    gb.add_argument("--u", help="the valve command as signal text (default sine:6:2, the paper's)")
    gb.add_argument("--disturbance", default="none", help="a load force d(t) known to the model (signal text, "
                                                          "e.g. sine:5000:1; default none)")
    gb.add_argument("--noise", default="x=0.01mm,p=0.05MPa", metavar="SIGNAL=SIGMA[UNIT],...",
                    help=f"without --data: the sensors' noise, {NOISE_GRAMMAR} (default x=0.01mm,p=0.05MPa)")
    gb.add_argument("--t-end", type=float, default=10.0, help=f"simulated record length [s] (default 10, at most "
                                                              f"{MAX_GREYBOX_T_END:g})")
    gb.add_argument("--intersample", default="read", help="with --data: how u moves between samples: read (from "
                                                          "the record, default), foh (linearly) or zoh (held, a "
                                                          "DAC's output)")
    gb.add_argument("--seed", type=int, default=0, help="seed of the noise (default 0)")
    gb.add_argument("--shooting", default="auto", metavar="HOW",
                    help="how the record is simulated: auto (default: the first 1 s, 3 s, ... of the record, then "
                         "all of it; multiple shooting when that estimate fails its checks), single (the whole "
                         "record from the start values) or multiple (multiple shooting, then the whole record)")
    gb.add_argument("--json", action="store_true", help="print JSON (default: a table)")
    # the core's names -> the options; what a simulation that fails, or a fit that cannot start, may follow
    # from, the likeliest first
    gb.set_defaults(handler=run_greybox, fields={"noise": "--noise"},
                    inputs=("--param", "--u", "--disturbance", "--data", "--columns", "--params", "--measured"))


def _names(option: str, text: str, allowed) -> tuple[str, ...]:
    names = tuple(n.strip() for n in str(text).split(",") if n.strip())
    for n in names:
        if n not in allowed:
            raise refused(option, text, f"{n} is not one of {', '.join(allowed)}")
    if not names:
        raise refused(option, text, f"name at least one of {', '.join(allowed)}")
    return names


def _record(args, measured, truth, noise, columns):
    """The record: the CSV of --data (its columns mapped by ``columns``, ``--columns``, or found as the web app
    finds them), or the simulated plant."""
    import numpy as np

    from eha_core.identify.greybox import GreyBoxData, greybox_data
    from eha_core.signals import parse_signal

    d = parse_signal(args.disturbance, name="--disturbance", seed=args.seed)
    if args.data:
        from eha_core.data import read_columns, sample_time

        needed = ("t", "u", *measured)
        cols = read_with_columns(
            lambda mapping: read_columns(args.data, needed, name="--data", min_rows=10, mapping=mapping),
            args.data, needed, columns)
        sample_time(cols["t"], name="--data", path=args.data)
        t = cols["t"]
        dvals = None if args.disturbance == "none" else np.asarray(d(t - t[0]), dtype=float)
        return GreyBoxData(t=t, u=cols["u"], d=dvals, signals={s: cols[s] for s in measured},
                           intersample=args.intersample, source=args.data)
    u = parse_signal(args.u, name="--u") if args.u else None
    from eha_core.experiments import LSE_INPUT

    try:
        return greybox_data(truth, u or LSE_INPUT, t_end=args.t_end, d=d, noise=noise, seed=args.seed,
                            measured=measured)
    except FieldError as exc:
        # the simulated plant's input and load are the signals typed (with --data they are the file's)
        raise UsageError(as_typed(exc, {"u": "--u", "d": "--disturbance"}, args.typed)) from None


def run_greybox(args) -> int:
    from eha_core.identify.greybox import GREYBOX_PARAMS, GREYBOX_SIGNALS, SHOOTING
    from eha_core.params import ActuatorParams

    names = _names("--params", args.params, GREYBOX_PARAMS)
    measured = _names("--measured", args.measured, GREYBOX_SIGNALS)
    if args.seed < 0:
        raise refused("--seed", args.seed, "use a whole number >= 0")
    if not (math.isfinite(args.t_end) and 0 < args.t_end <= MAX_GREYBOX_T_END):
        raise refused("--t-end", args.t_end, f"use a record length in (0, {MAX_GREYBOX_T_END:g}] s")
    if args.intersample not in ("read", "foh", "zoh"):
        raise refused("--intersample", args.intersample, "use read, foh or zoh")
    if args.shooting not in SHOOTING:
        raise refused("--shooting", args.shooting, f"use {', '.join(SHOOTING)}")
    check_input_file("--data", args.data)
    columns = checked_columns(args, ("t", "u", *measured))
    noise = parse_noise(args.noise)             # checked with or without --data: a typo is a typo
    given = parse_params(args.param)
    # without data the --param values are the plant's truth and the estimate starts from the paper's;
    # with data they are what is known of the rig
    truth, guess = (given, ActuatorParams()) if not args.data else (None, given)
    data = _record(args, measured, truth, noise, columns)

    from eha_core.identify.greybox import identify_greybox

    try:
        res = identify_greybox(data, names, measured=measured, guess=guess, shooting=args.shooting)
    except FieldError as exc:
        raise as_option(exc, {"params": "--params", "measured": "--measured", "record": "--t-end"}) from None
    out = res.to_dict()
    out["source"] = data.source
    if truth is not None:
        out["true"] = {n: float(getattr(truth, n)) for n in names if hasattr(truth, n)}
    if args.json:
        print(json_text(out))
        return 0 if res.success else 1
    print(report_text(res, names, measured, data, truth, from_file=bool(args.data)))
    if not res.success:
        print(f"eha identify greybox: warning: {res.message}", file=sys.stderr)
    return 0 if res.success else 1


def report_text(res, names, measured, data, truth, *, from_file: bool) -> str:
    """The estimate as the command line prints it: how it was fitted, the table, the fits, what the data
    determine, the held parameters and their bias, each check and what to try."""
    lines = [f"grey-box (output error) from {', '.join(measured)} of {data.source}: {res.nfev} simulations with "
             f"sensitivities, {res.time_s:.2f} s"]
    if res.strategy:
        lines.append(f"strategy: {res.strategy}")
    if from_file and "intersample" in res.extras:
        how = res.extras["intersample"]
        lines.append(f"u between samples: {'linear' if how['used'] == 'foh' else 'held'} ({how['how']})")
    lines.append(table_text(res, names, truth))
    lines.append("fit: " + ", ".join(f"{s} {v:.2f} %" for s, v in res.fit.items()))
    lines += [f"identifiability: {sentence}" for _, sentence in res.identifiability]
    lines += [f"held: {held_line(res, n)}" for n in res.held]
    lines.append("checks:")
    lines += [f"  {'✓' if c.passed else '✗'} {c.name}: {c.says}" for c in res.checks]
    if res.advice:
        lines.append("try:")
        lines += [f"  - {a}" for a in res.advice]
    return "\n".join(lines)


#: What the table prints for a value the estimate does not give (it failed its checks).
NOT_GIVEN = "—"


def table_text(res, names, truth=None) -> str:
    """The estimates as a table: estimate, standard error, 95 % interval (and the truth of a simulated
    record). An estimate that failed its checks has no standard error or interval (the core gives none,
    and they would read as if they held): "—" and a line saying why; a held parameter and one at a bound
    of its range say so."""
    bound = {n for c in res.failed_checks if c.name == "bounds" for n in c.about}
    lines = [(f"{'':8s}{'estimate':>14s}{'std error':>12s}   " + (f"{'95 % interval':<26s}{'true':>14s}" if truth
                                                                     else "95 % interval"))]
    for n in names:
        lo, hi = res.ci95[n]
        true = f"{getattr(truth, n):>14.6g}" if truth is not None and hasattr(truth, n) else ""
        if n in res.held:
            se, ci = f"{NOT_GIVEN:>12s}", "held at the initial value"
        elif res.success and math.isfinite(lo) and math.isfinite(hi):
            se, ci = f"{res.std_errors[n]:12.4g}", f"[{lo:.6g}, {hi:.6g}]"
        else:
            se, ci = f"{NOT_GIVEN:>12s}", "at the bound of its range" if n in bound else NOT_GIVEN
        lines.append(f"{n:8s}{res.estimates[n]:14.6g}{se}   {ci:<26s}{true}".rstrip())
    if not res.success:
        lines.append("no standard error or interval is given: the estimate failed its checks (below)")
    return "\n".join(lines)


def held_line(res, name: str) -> str:
    """A held parameter, its value and how it moves the estimates if it is 10 % off (the core's
    ``held_bias``): ``B held at 1500; if it is 10 % off, M moves by +4.1 %, Af by -2.0 %``."""
    from eha_app.render.formatting import pct_short
    from eha_core.param_table import FIELD_INFO

    unit = FIELD_INFO[name].unit if name in FIELD_INFO else "SI"
    text = f"{name} held at {res.estimates[name]:.6g} {unit}"
    moves = [(m, v) for m, v in (res.held_bias.get(name) or {}).items() if math.isfinite(v)]
    if moves:
        text += "; if it is 10 % off, " + ", ".join(f"{m} {'moves ' if k == 0 else ''}by {pct_short(v)}"
                                                     for k, (m, v) in enumerate(moves))
    return text
