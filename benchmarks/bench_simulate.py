"""Speed and accuracy of the simulator against python-control, in one run.

The paper's four cases (5 s each, nonlinear model, output every 1 ms) are
simulated three ways on the same model, eha_core.model.derivatives:

* ours: eha_core.simulate.simulate_many (compiled fixed-step RK4, the four
  cases as one batch);
* the peer: python-control, ``nlsys`` + ``input_output_response`` with its
  default solver (RK45), the right-hand side given as the same function
  compiled by numba (its fastest form; the interpreted form is timed too);
* the reference: scipy ``solve_ivp`` (Radau, rtol 1e-10).

Errors are the worst absolute deviation from the reference over the output
samples, as a fraction of each state's range in the reference run, worst over
states and cases. The last line reads

    ratio=<python-control time / our time> err=<our worst relative error>

Run:  python benchmarks/bench_simulate.py [--repeat N]
"""

from __future__ import annotations

import argparse
import platform
import time

import control
import numpy as np
from scipy.integrate import solve_ivp

from eha_core import model
from eha_core._kernels import derivatives as compiled_derivatives
from eha_core.experiments import PAPER_CASES
from eha_core.params import ActuatorParams
from eha_core.simulate import DEFAULT_H_MAX, simulate_many

T_END = 5.0
DT = 1e-3


def best_time(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def reference(params, case, t):
    prm = model.pack_params(params)

    def f(tt, y):
        return compiled_derivatives(y[0], y[1], y[2], y[3], float(case.u(tt)), float(case.d(tt)), prm)

    sol = solve_ivp(f, (0.0, T_END), params.initial_state, method="Radau", rtol=1e-10,
                    atol=[1e-13, 1e-12, 1e-4, 1e-4], t_eval=t)
    assert sol.success, sol.message
    return sol.y.T


def python_control_runs(params, cases, t, rhs):
    prm = model.pack_params(params)

    def upd(tt, x, u, _params):
        return np.array(rhs(x[0], x[1], x[2], x[3], u[0], u[1], prm))

    sys = control.nlsys(upd, None, inputs=["u", "d"], states=4, outputs=4, name="eha")
    out = []
    for case in cases:
        U = np.vstack([case.u(t), case.d(t)])
        resp = control.input_output_response(sys, t, U, X0=params.initial_state)
        out.append(resp.states.T)
    return out


def errors(runs, refs):
    worst = 0.0
    for y, ref in zip(runs, refs, strict=True):
        span = ref.max(axis=0) - ref.min(axis=0)
        worst = max(worst, float(np.max(np.abs(y - ref).max(axis=0) / span)))
    return worst


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5, help="timing repeats (best of); default 5")
    ap.add_argument("--h-max", type=float, default=DEFAULT_H_MAX, help="our integration step limit")
    args = ap.parse_args(argv)

    params = ActuatorParams()
    cases = [PAPER_CASES[k] for k in (1, 2, 3, 4)]
    t = np.arange(int(round(T_END / DT)) + 1) * DT
    print(f"python {platform.python_version()}, numpy {np.__version__}, control {control.__version__}, "
          f"machine {platform.machine()}")

    def ours():
        res = simulate_many(params, [c.u for c in cases], [c.d for c in cases],
                            t_end=T_END, dt=DT, h_max=args.h_max)
        return [r.states for r in res]

    ours()  # compile (or load the numba cache) outside the timing
    t_ours, y_ours = best_time(ours, args.repeat)

    t0 = time.perf_counter()
    refs = [reference(params, c, t) for c in cases]
    t_ref = time.perf_counter() - t0

    t_pc, y_pc = best_time(lambda: python_control_runs(params, cases, t, compiled_derivatives),
                           max(1, args.repeat // 2))
    t_pc_py, y_pc_py = best_time(lambda: python_control_runs(params, cases, t, model.derivatives), 1)

    err_ours, err_pc, err_pc_py = errors(y_ours, refs), errors(y_pc, refs), errors(y_pc_py, refs)
    print(f"{'method':58s} {'time [s]':>10s} {'worst err':>10s}")
    ours = f"ours: compiled RK4, batch of 4, h_max = {args.h_max:g} s"
    print(f"{ours:58s} {t_ours:10.4f} {err_ours:10.2e}")
    print(f"{'python-control nlsys+input_output_response, compiled rhs':58s} {t_pc:10.4f} {err_pc:10.2e}")
    print(f"{'python-control nlsys+input_output_response, python rhs':58s} {t_pc_py:10.4f} {err_pc_py:10.2e}")
    print(f"{'reference: solve_ivp Radau rtol 1e-10':58s} {t_ref:10.4f} {'-':>10s}")
    print(f"ratio vs python-control with its interpreted rhs: {t_pc_py / t_ours:.0f}")
    print(f"ratio={t_pc / t_ours:.1f} err={err_ours:.2e}")


if __name__ == "__main__":
    main()
