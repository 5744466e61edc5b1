"""``eha linearize``: operating point, A, B, P(s) and H(s) (eqs. 10-24)."""

from __future__ import annotations

from .common import PARAM_HELP, json_text, parse_params


def add_parser(sub) -> None:
    lz = sub.add_parser("linearize", help="operating point, A, B, P(s) and H(s) (eqs. 10-24)")
    lz.add_argument("--kp", type=float, default=10.0, help="proportional gain for H(s) [V/m] (default 10)")
    lz.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    lz.add_argument("--json", action="store_true", help="print JSON (default: a readable summary)")
    lz.set_defaults(handler=run)


def run(args) -> int:
    from eha_core.linear import linearize

    params = parse_params(args.param)
    lin = linearize(params)
    data = lin.to_dict(kp=args.kp)
    if args.json:
        print(json_text(data))
        return 0
    op = lin.op
    num, den = lin.tf_coeffs()
    cnum, cden = lin.closed_loop_coeffs(args.kp)
    print(f"operating point: x = {op.x:g} m, v = {op.v:g} m/s, p1 = {op.p1 / 1e6:.4g} MPa, "
          f"p2 = {op.p2 / 1e6:.5g} MPa, u = {op.u:g} V")
    for i, (lp, ln) in enumerate(zip(lin.lambdas, lin.lambdas_negative, strict=True), start=1):
        extra = f"   (u < 0: {ln:.6g})" if lp != ln else ""
        print(f"l{i} = {lp:.6g}{extra}")
    print(f"P(s) = {num[-1]:.5g} / (s^3 + {den[1]:.5g} s^2 + {den[2]:.5g} s)          (eq. 23, u >= 0)")
    print(f"H(s) = {cnum[-1]:.5g} / (s^3 + {cden[1]:.5g} s^2 + {cden[2]:.5g} s + {cden[3]:.5g})   "
          f"(eq. 24, Kp = {args.kp:g})")
    return 0
