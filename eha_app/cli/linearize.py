"""``eha linearize``: operating point, A, B, P(s) and H(s) (eqs. 10-24)."""

from __future__ import annotations

from .common import PARAM_HELP, computation_refused, json_text, parse_params


def add_parser(sub) -> None:
    lz = sub.add_parser("linearize", help="operating point, A, B, P(s) and H(s) (eqs. 10-24)")
    lz.add_argument("--kp", type=float, default=10.0, help="proportional gain for H(s) [V/m] (default 10)")
    lz.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
    lz.add_argument("--json", action="store_true", help="print JSON (default: a readable summary)")
    # the core's names -> the options; what a linearisation that overflows follows from
    lz.set_defaults(handler=run, fields={"kp": "--kp"}, inputs=("--param", "--kp"))


def run(args) -> int:
    import numpy as np

    from eha_core.errors import ComputationError, not_allowed
    from eha_core.linear import linearize

    params = parse_params(args.param)
    # an overflow is refused below, naming what was typed, instead of numpy's warnings and a NaN
    with np.errstate(all="ignore"):
        lin = linearize(params)
        num, den = lin.tf_coeffs()
        if not all(np.all(np.isfinite(a)) for a in (lin.A, lin.B_positive, lin.B_negative, num, den)):
            # P(s) follows from the parameters alone
            raise computation_refused(ComputationError("the linearised model (eqs. 10-23) has coefficients beyond "
                                                       "the largest number a float holds"), ("--param",), args.typed)
        cnum, cden = lin.closed_loop_coeffs(args.kp)
        if not (np.all(np.isfinite(cnum)) and np.all(np.isfinite(cden))):
            largest = np.finfo(float).max / abs(num[-1])
            raise not_allowed("kp", args.kp, f"Kp times the gain of P(s), {num[-1]:.4g}, is beyond the largest number "
                                             f"a float holds; use Kp below {largest:.3g} V/m")
        data = lin.to_dict(kp=args.kp)
    if args.json:
        print(json_text(data))
        return 0
    op = lin.op
    print(f"operating point: x = {op.x:g} m, v = {op.v:g} m/s, p1 = {op.p1 / 1e6:.4g} MPa, "
          f"p2 = {op.p2 / 1e6:.5g} MPa, u = {op.u:g} V")
    for i, (lp, ln) in enumerate(zip(lin.lambdas, lin.lambdas_negative, strict=True), start=1):
        extra = f"   (u < 0: {ln:.6g})" if lp != ln else ""
        print(f"l{i} = {lp:.6g}{extra}")
    print(f"P(s) = {num[-1]:.5g} / (s^3 + {den[1]:.5g} s^2 + {den[2]:.5g} s)          (eq. 23, u >= 0)")
    print(f"H(s) = {cnum[-1]:.5g} / (s^3 + {cden[1]:.5g} s^2 + {cden[2]:.5g} s + {cden[3]:.5g})   "
          f"(eq. 24, Kp = {args.kp:g})")
    return 0
