"""``eha simulate``: an open-loop run of the nonlinear or linearised model, to CSV."""

from __future__ import annotations

import argparse
import sys

from eha_core.errors import FieldError

from .common import PARAM_HELP, UsageError, check_output_file, parse_params, refused, refused_file

EPILOG = """\
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


def add_parser(sub) -> None:
    s = sub.add_parser("simulate", help="open-loop simulation to CSV", epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("--case", type=int, help="one of the paper's cases 1-4 (Figs. 2-7)")
    s.add_argument("--model", default="nonlinear", help="nonlinear (default) or linear")
    s.add_argument("--branch", default=None,
                   help="linear model only: switching (default: l5, l6 follow the sign of u), positive or negative")
    s.add_argument("--u", help="valve command u(t) [V] as text (see below)")
    s.add_argument("--d", help="load disturbance d(t) [N] as text (see below)")
    s.add_argument("--t-end", type=float, help="horizon [s] (default 5, the paper's)")
    s.add_argument("--dt", type=float, default=1e-3, help="output interval [s] (default 0.001)")
    s.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    s.add_argument("--out", help="write the CSV to this file instead of stdout")
    s.set_defaults(handler=run, fields={"t_end": "--t-end", "dt": "--dt", "u": "--u", "d": "--d"})


def run(args) -> int:
    from eha_core.experiments import PAPER_CASES
    from eha_core.signals import ZERO, parse_signal
    from eha_core.simulate import MODELS, SIMULATION_BRANCHES, simulate

    if args.model not in MODELS:
        raise refused("--model", args.model, f"use one of {', '.join(MODELS)}", value_text=args.model)
    if args.branch is not None and args.model != "linear":
        raise refused("--branch", args.branch, "the branch chooses the valve gains of the linearised model "
                      "(--model linear)", value_text=args.branch, context=f"with --model {args.model}")
    branch = args.branch or "switching"
    if branch not in SIMULATION_BRANCHES:
        raise refused("--branch", branch, f"use one of {', '.join(SIMULATION_BRANCHES)}", value_text=branch)
    check_output_file("--out", args.out)
    params = parse_params(args.param)
    u = d = ZERO
    t_end = 5.0
    label = "custom"
    if args.case is not None:
        if args.case not in PAPER_CASES:
            raise refused("--case", args.case, "use one of 1, 2, 3, 4")
        case = PAPER_CASES[args.case]
        u, d, t_end, label = case.u, case.d, case.t_end, case.name
    elif args.u is None and args.d is None:
        raise UsageError("--case or --u is required: give a paper case (1-4) or an input signal "
                         "(see eha simulate --help)")
    if args.u is not None:
        u = parse_signal(args.u, name="--u")
    if args.d is not None:
        d = parse_signal(args.d, name="--d")
    if args.t_end is not None:
        t_end = args.t_end
    try:
        res = simulate(params, u, d, t_end=t_end, dt=args.dt, model=args.model, branch=branch, label=label)
    except FieldError as exc:
        if exc.field == "t_end" and args.t_end is None:
            # the horizon is the case's or the default, not typed: the output interval typed does not fit it
            horizon = f"the horizon of --case {args.case}" if args.case is not None else "the default horizon"
            raise refused("--dt", args.dt, f"{horizon}, {t_end:g} s, must be a whole number of output intervals "
                                           "(--t-end sets another)", value_text=args.typed.get("--dt")) from None
        raise
    if not res.success:
        print(f"eha simulate: warning: {res.message}", file=sys.stderr)
    if args.out:
        try:
            res.to_csv(args.out)
        except OSError as exc:
            raise refused_file("--out", args.out, f"{exc.strerror or exc}") from None
    else:
        res.to_csv(sys.stdout)
    return 0 if res.success else 1
