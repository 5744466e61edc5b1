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
