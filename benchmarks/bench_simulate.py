"""Speed and accuracy of the simulator against python-control and ODE solvers, in one run.

Two sets of 5 s runs of the nonlinear model, output every 1 ms, on the same equations
(eha_core.model.derivatives):

* smooth: the paper's four cases (sine inputs);
* jumps: ``--u square:3:1.5 --d step:4000:1.25`` with M = 9000 kg, B = 300 N s/m, whose edges
  (every 1/3 s, and 1.25 s) fall between the output samples.

They are simulated by

* ours: eha_core.simulate.simulate_many (compiled adaptive DOP853 with dense output, stopped at
  every discontinuity of the inputs; the four smooth cases as one batch);
* the previous integrator: compiled fixed-step RK4 at h = 5e-4 s, which the simulator still uses
  for an input given as a function of t (its jumps unknown), timed on the same runs;
* the peer: python-control, ``nlsys`` + ``input_output_response`` with its default solver (RK45),
  the right-hand side given as the same function compiled by numba (smooth set only);
* anchors, optional: numbalsoda's DOP853 and LSODA (``pip install numbalsoda``; it builds with
  gfortran; not a dependency of the project), the right-hand side a numba cfunc of the same
  derivatives with the inputs written out, on scaled states (its atol is one number). They do not
  know the jumps: they step over them under error control. Each is timed at the loosest of a
  ladder of tolerances that is as accurate as ours on the set ("matched accuracy");
* the reference: scipy ``solve_ivp`` (Radau, rtol 1e-10), restarted at every discontinuity of the
  inputs (it agrees with one Radau run over the jumps to ~5e-10 of the range).

Errors are the worst absolute deviation from the reference over the output samples, as a fraction
of each state's range in the reference run, worst over states and runs. Times are the best of
``--repeat``. The last line reads

    ratio=<python-control time / our time> err=<our worst relative error, smooth> jump_err=<... jumps>

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
from eha_core.experiments import PAPER_CASES, Case
from eha_core.params import ActuatorParams
from eha_core.signals import Sine, Square, Step, parse_signal
from eha_core.simulate import DEFAULT_H_MAX, simulate_many

T_END = 5.0
DT = 1e-3
#: the jump set: edges off the 1 ms grid
JUMP_PARAMS = dict(M=9000.0, B=300.0)
JUMP_CASE = Case(0, parse_signal("square:3:1.5"), parse_signal("step:4000:1.25"))
#: states scaled for the anchors' one atol (m, m/s, Pa, Pa)
SCALE = np.array([0.01, 0.01, 1e6, 1e6])
TOLERANCES = (1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 3e-11, 1e-11)


def best_time(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def reference(params, case, t):
    """Radau rtol 1e-10, restarted at every discontinuity of the inputs."""
    prm = model.pack_params(params)
    cuts = np.unique(np.concatenate([[0.0, T_END], case.u.discontinuities(T_END), case.d.discontinuities(T_END)]))
    y0, out = params.initial_state, np.full((t.size, 4), np.nan)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        inner = 1e-9 * (b - a)          # the inputs of this piece, not the next one's at its end

        def f(tt, y, a=a, b=b, inner=inner):
            tc = min(max(tt, a + inner), b - inner)
            return compiled_derivatives(y[0], y[1], y[2], y[3], float(case.u(tc)), float(case.d(tc)), prm)

        sol = solve_ivp(f, (a, b), y0, method="Radau", rtol=1e-10, atol=[1e-13, 1e-12, 1e-4, 1e-4],
                        dense_output=True)
        assert sol.success, sol.message
        sel = (t >= a) & (t <= b)
        out[sel] = sol.sol(t[sel]).T
        y0 = sol.y[:, -1]
    return out


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


# -- the optional anchors (numbalsoda) ------------------------------------------------------------

def _input_rows(sig):
    """A signal as rows (kind, a, b, c, d) for the anchors' cfunc: 0 sine, 1 square, 2 step."""
    from eha_core.signals import Sum

    rows = []
    for term in sig.terms if isinstance(sig, Sum) else (sig,):
        if isinstance(term, Sine):
            rows.append((0.0, term.amplitude, term.freq_hz, term.phase, term.offset))
        elif isinstance(term, Square):
            rows.append((1.0, term.amplitude, term.freq_hz, term.offset, 0.0))
        elif isinstance(term, Step):
            rows.append((2.0, term.amplitude, term.t0, term.initial, 0.0))
        elif term.spec != "none":
            raise ValueError(f"no anchor form for {term}")
    return rows


def _anchor_data(params, case):
    """[n_u, n_d, packed parameters (14), u rows, d rows] as one float array."""
    prm = model.pack_params(params)
    ur, dr = _input_rows(case.u), _input_rows(case.d)
    return np.concatenate([[len(ur), len(dr)], prm, np.ravel(ur), np.ravel(dr)]).astype(float)


def _anchor_rhs():
    import math

    from numba import carray, cfunc, njit, types

    n_prm = model.N_PACKED_PARAMS
    sc = SCALE.copy()

    @njit
    def sig(rows, n, t):
        val = 0.0
        for i in range(n):
            kind, a, b, c, d = rows[5 * i], rows[5 * i + 1], rows[5 * i + 2], rows[5 * i + 3], rows[5 * i + 4]
            if kind == 0.0:
                val += a * math.sin(2.0 * math.pi * b * t + c) + d
            elif kind == 1.0:
                ph = t * b - math.floor(t * b)
                val += (a if ph < 0.5 else -a) + c
            else:
                val += a if t >= b else c
        return val

    @cfunc(types.void(types.double, types.CPointer(types.double), types.CPointer(types.double),
                      types.CPointer(types.double)))
    def rhs(t, z, dz, p):
        nu, nd = int(p[0]), int(p[1])
        data = carray(p, 2 + n_prm + 5 * (nu + nd))
        prm = data[2:2 + n_prm]
        u = sig(data[2 + n_prm:], nu, t)
        d = sig(data[2 + n_prm + 5 * nu:], nd, t)
        f0, f1, f2, f3 = compiled_derivatives(z[0] * sc[0], z[1] * sc[1], z[2] * sc[2], z[3] * sc[3], u, d, prm)
        dz[0] = f0 / sc[0]
        dz[1] = f1 / sc[1]
        dz[2] = f2 / sc[2]
        dz[3] = f3 / sc[3]

    return rhs.address


def anchor_runs(solver, address, params_cases, t, tol):
    out = []
    for params, case in params_cases:
        z, ok = solver(address, params.initial_state / SCALE, t, data=_anchor_data(params, case), rtol=tol,
                       atol=tol, mxstep=10**7)
        out.append(z * SCALE if ok else np.full((t.size, 4), np.nan))
    return out


def matched(solver, address, params_cases, t, refs, target, repeat):
    """The loosest tolerance of :data:`TOLERANCES` at which ``solver`` is as accurate as ``target``:
    (tolerance, time, error), or None."""
    for tol in TOLERANCES:
        err = errors(anchor_runs(solver, address, params_cases, t, tol), refs)
        if err <= target:
            dt_, _ = best_time(lambda tol=tol: anchor_runs(solver, address, params_cases, t, tol), repeat)
            return tol, dt_, err
    return None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5, help="timing repeats (best of); default 5")
    args = ap.parse_args(argv)

    params = ActuatorParams()
    jump_params = ActuatorParams(**JUMP_PARAMS)
    cases = [PAPER_CASES[k] for k in (1, 2, 3, 4)]
    t = np.arange(int(round(T_END / DT)) + 1) * DT
    print(f"python {platform.python_version()}, numpy {np.__version__}, control {control.__version__}, "
          f"machine {platform.machine()}")

    def ours(p, cs):
        res = simulate_many(p, [c.u for c in cs], [c.d for c in cs], t_end=T_END, dt=DT)
        return [r.states for r in res]

    def rk4(p, cs):
        # an input given as a function of t takes the fixed-step RK4 (its jumps are not known)
        res = simulate_many(p, [(lambda tt, s=c.u: s(tt)) for c in cs], [(lambda tt, s=c.d: s(tt)) for c in cs],
                            t_end=T_END, dt=DT, h_max=DEFAULT_H_MAX)
        return [r.states for r in res]

    sets = {"smooth": (params, cases), "jumps": (jump_params, [JUMP_CASE])}
    refs = {}
    t0 = time.perf_counter()
    for name, (p, cs) in sets.items():
        refs[name] = [reference(p, c, t) for c in cs]
    t_ref = time.perf_counter() - t0

    print(f"{'set':7s} {'method':58s} {'time [s]':>10s} {'worst err':>10s} {'ratio':>7s}")
    res = {}
    for name, (p, cs) in sets.items():
        ours(p, cs)  # compile (or load the numba cache) outside the timing
        rk4(p, cs)
        t_ours, y_ours = best_time(lambda p=p, cs=cs: ours(p, cs), args.repeat)
        t_rk4, y_rk4 = best_time(lambda p=p, cs=cs: rk4(p, cs), args.repeat)
        e_ours, e_rk4 = errors(y_ours, refs[name]), errors(y_rk4, refs[name])
        res[name] = (t_ours, e_ours)
        print(f"{name:7s} {'ours: compiled adaptive DOP853, stops at the jumps':58s} {t_ours:10.4f} {e_ours:10.2e} "
              f"{1.0:7.2f}")
        print(f"{name:7s} {f'previous: compiled fixed-step RK4, h = {DEFAULT_H_MAX:g} s':58s} {t_rk4:10.4f} "
              f"{e_rk4:10.2e} {t_rk4 / t_ours:7.2f}")
    # python-control on the smooth set
    t_pc, y_pc = best_time(lambda: python_control_runs(params, cases, t, compiled_derivatives),
                           max(1, args.repeat // 2))
    t_pc_py, y_pc_py = best_time(lambda: python_control_runs(params, cases, t, model.derivatives), 1)
    t_ours = res["smooth"][0]
    print(f"{'smooth':7s} {'python-control nlsys+input_output_response, compiled rhs':58s} {t_pc:10.4f} "
          f"{errors(y_pc, refs['smooth']):10.2e} {t_pc / t_ours:7.2f}")
    print(f"{'smooth':7s} {'python-control nlsys+input_output_response, python rhs':58s} {t_pc_py:10.4f} "
          f"{errors(y_pc_py, refs['smooth']):10.2e} {t_pc_py / t_ours:7.2f}")
    print(f"{'both':7s} {'reference: solve_ivp Radau rtol 1e-10, restarted at jumps':58s} {t_ref:10.4f} "
          f"{'-':>10s} {'-':>7s}")

    try:
        import numbalsoda
    except ImportError as exc:
        print(f"anchors skipped: numbalsoda is not importable ({exc}); pip install numbalsoda (needs gfortran)")
    else:
        address = _anchor_rhs()
        for name, (p, cs) in sets.items():
            pcs = [(p, c) for c in cs]
            anchor_runs(numbalsoda.dop853, address, pcs, t, 1e-6)     # compile outside the timing
            t_ours, e_ours = res[name]
            for label, solver in (("numbalsoda DOP853", numbalsoda.dop853), ("numbalsoda LSODA", numbalsoda.lsoda)):
                m = matched(solver, address, pcs, t, refs[name], e_ours, args.repeat)
                if m is None:
                    print(f"{name:7s} {label + ': no tolerance down to 1e-11 is as accurate':58s}")
                    continue
                tol, t_a, e_a = m
                print(f"{name:7s} {f'{label}, matched accuracy (rtol = atol = {tol:g})':58s} {t_a:10.4f} "
                      f"{e_a:10.2e} {t_a / t_ours:7.2f}")
    print("ratio: that method's time / ours on the same set")
    print(f"ratio={t_pc / res['smooth'][0]:.1f} err={res['smooth'][1]:.2e} jump_err={res['jumps'][1]:.2e}")


if __name__ == "__main__":
    main()
