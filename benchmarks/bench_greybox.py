"""Grey-box identification: its speed against the textbook way, and where it converges from.

The problem: four parameters (M, B, Af, beta_e) of the nonlinear plant from a 10 s record at
Ts = 1 ms, u = 6 sin(4 pi t) (eha_core.experiments.LSE_INPUT continued for 10 s), a load
d = 5000 sin(2 pi t) the model knows, white noise on x, p1 and p2 at 30 dB (σ = the clean signal's
standard deviation / 10^1.5), the truth M = 5200, B = 1900, Af = 2400, beta_e = 9e8, the paper's
values (ActuatorParams()) as the initial guess.

Three measurements, all in this run:

1. ``greybox_s``: the wall time of ``identify_greybox`` (the median of ``--repeats`` runs after one
   warm-up that compiles numba's kernels).
2. ``baseline_s``: the same problem solved the way one writes it with scipy alone:
   ``least_squares`` (Levenberg-Marquardt, as identify_greybox) over ``solve_ivp`` (Radau) with the
   interpreted right-hand side ``eha_core.model.derivatives``, the Jacobian by forward differences
   (least_squares' default '2-point'), the same scaling (the logarithm of the parameters) and
   weighting (each residual over its signal's σ, the σ identify_greybox weighted its fit with: the
   two minimise the same sum). Radau's tolerance (``--rtol``) is set so that its trajectory departs from the
   simulator's by far less than the noise (printed); the difference step (``--diff-step``, in log
   units) is well above that tolerance, or the differenced Jacobian would be the solver's error.
   ``ratio`` = baseline_s / greybox_s; ``err`` = the largest relative difference between the two
   estimates (printed too in standard errors: they should agree to a fraction of one).
3. ``converged``: from ``--starts`` random initial guesses (each estimated parameter the truth times
   a factor uniform in [0.5, 1.5], seed 20), how many end at the estimate from the true values
   (every parameter within 3 standard errors of it, or the weighted cost within 1 % of its cost).
   Multiple shooting when identify_greybox offers it (``shooting="multiple"``), else single (said).

Measured on this project's 2-core machine (another job running), the core of 89901f3 (single
shooting only): greybox_s 1.58 s (18 simulations with sensitivities), the baseline 127.6 s (95 Radau
runs of 1.25 s), ratio 80.7; the two estimates 0.02-0.03 standard errors apart (the largest relative
difference 4.3e-3, in B, whose standard error is 17 % of it), the grey-box's weighted cost the lower
(by 0.001 of 15208); 100 of 100 starts converged, 1.3 s a start. The whole run takes 5-7 minutes. With
the difference step at 1e-4 the baseline stopped 0.25 standard errors away in B: Radau's error,
differenced, is then a visible part of its Jacobian.

The last line, to paste:

    greybox_s=<s> baseline_s=<s> ratio=<r> err=<e> converged=<k>/<n>

Run:  python benchmarks/bench_greybox.py [--starts 100] [--repeats 3] [--rtol 1e-7] [--no-baseline]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from eha_core.experiments import LSE_INPUT
from eha_core.identify.greybox import greybox_data, identify_greybox, noise_guess, simulate_with_sensitivities
from eha_core.model import derivatives, pack_params
from eha_core.params import ActuatorParams
from eha_core.signals import Sine

NAMES = ("M", "B", "Af", "beta_e")
TRUTH = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8)
MEASURED = ("x", "p1", "p2")
ROWS = (0, 2, 3)          # x, p1, p2 in the state vector
LOAD = Sine(5000.0, 1.0)
T_END = 10.0
SNR_DB = 30.0
SEED = 1


def problem():
    """The record (noise at 30 dB on x, p1, p2) and the σ it was drawn with."""
    clean = greybox_data(TRUTH, LSE_INPUT, t_end=T_END, d=LOAD, measured=MEASURED)
    sigma = {s: float(np.std(y)) / 10 ** (SNR_DB / 20) for s, y in clean.signals.items()}
    return greybox_data(TRUTH, LSE_INPUT, t_end=T_END, d=LOAD, noise=sigma, seed=SEED, measured=MEASURED), sigma


def run_greybox(data, guess=None, shooting=None):
    kwargs = {"shooting": shooting} if shooting else {}
    return identify_greybox(data, NAMES, measured=MEASURED, guess=guess, **kwargs)


def shooting_available(data) -> bool:
    try:
        identify_greybox(data, ("M",), measured=MEASURED, shooting="multiple", max_nfev=1)
    except TypeError:
        return False
    return True


# -- the baseline: scipy alone ----------------------------------------------------------------------------

def radau_run(params: ActuatorParams, data, rtol: float) -> np.ndarray:
    """x, v, p1, p2 at data.t by solve_ivp (Radau) over the interpreted right-hand side; the input and
    the load between their samples linearly, as the record (and the simulator) has them."""
    from scipy.integrate import solve_ivp

    prm = pack_params(params)
    t, u, d, ts = data.t, data.u, data.d, data.ts
    last = t.size - 2

    def f(tt, y):
        k = min(int(tt / ts), last)
        a = tt / ts - k
        return derivatives(y[0], y[1], y[2], y[3], u[k] + a * (u[k + 1] - u[k]), d[k] + a * (d[k + 1] - d[k]),
                           prm)

    # absolute tolerances on each state's own scale (m, m/s, Pa)
    atol = rtol * np.array([1e-2, 1e-2, 1e6, 1e6])
    sol = solve_ivp(f, (t[0], t[-1]), params.initial_state, method="Radau", t_eval=t, rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y.T


def baseline(data, sigma: np.ndarray, rtol: float, diff_step: float):
    """least_squares over solve_ivp: the estimate, the number of simulations, the wall time."""
    from scipy.optimize import least_squares

    y_meas = np.stack([data.signals[s] for s in MEASURED], axis=1)
    guess = ActuatorParams()
    count = [0]

    def fun(z):
        count[0] += 1
        p = guess.replace(**dict(zip(NAMES, np.exp(z), strict=True)))
        try:
            out = radau_run(p, data, rtol)
        except (RuntimeError, ValueError):
            return np.full(y_meas.size, 1e6)
        return ((out[:, ROWS] - y_meas) / sigma).ravel()

    z0 = np.log([getattr(guess, n) for n in NAMES])
    t0 = time.perf_counter()
    sol = least_squares(fun, z0, method="lm", diff_step=diff_step, xtol=1e-10, ftol=1e-10)
    elapsed = time.perf_counter() - t0
    return dict(zip(NAMES, np.exp(sol.x), strict=True)), count[0], elapsed, sol


def weighted_cost(params: ActuatorParams, data, sigma: np.ndarray) -> float:
    out, _ = simulate_with_sensitivities(params, (), data)
    y_meas = np.stack([data.signals[s] for s in MEASURED], axis=1)
    return 0.5 * float(np.sum(((out[:, ROWS] - y_meas) / sigma) ** 2))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--starts", type=int, default=100, help="random initial guesses (default 100)")
    ap.add_argument("--repeats", type=int, default=3, help="timed grey-box runs, their median (default 3)")
    ap.add_argument("--rtol", type=float, default=1e-7, help="Radau's relative tolerance (default 1e-7)")
    ap.add_argument("--diff-step", type=float, default=1e-3,
                    help="least_squares' relative difference step (default 1e-3)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the baseline (minutes)")
    ap.add_argument("--shooting", default="single", choices=("single", "multiple"),
                    help="the starts' simulation: output error alone (default: it converged from more starts) "
                         "or multiple shooting first")
    args = ap.parse_args(argv)

    print(f"python {platform.python_version()}, {os.cpu_count()} cores, machine {platform.machine()}")
    data, noise = problem()
    print(f"record: {T_END:g} s at {data.ts * 1e3:g} ms, {data.t.size} samples; noise at {SNR_DB:g} dB: "
          + ", ".join(f"{s} {v:.4g}" for s, v in noise.items()))

    # 1. the grey-box estimate
    run_greybox(data)                                # compiles numba's kernels
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        ref = run_greybox(data)
        times.append(time.perf_counter() - t0)
    greybox_s = statistics.median(times)
    print(f"\ngrey-box from the paper's values: {greybox_s:.3f} s (median of {args.repeats}: "
          + ", ".join(f"{t:.3f}" for t in times) + f"), {ref.nfev} simulations, success {ref.success}")
    for n in NAMES:
        print(f"  {n:7s} {ref.estimates[n]:12.6g} ± {ref.std_errors[n]:.3g}   truth {getattr(TRUTH, n):.6g}   "
              f"({(ref.estimates[n] - getattr(TRUTH, n)) / ref.std_errors[n]:+.2f} SE)")
    # the σ identify_greybox weighted its fit with: its first guess from the data (it refits with the
    # residuals' σ only when they differ by more than 20 %; said below if they did)
    sigma = np.array([noise_guess(data.signals[s]) for s in MEASURED])
    refit = max(abs(np.log(ref.noise_std[s] / sigma[k])) for k, s in enumerate(MEASURED)) > np.log(1.2)
    print("  weighting: " + ", ".join(f"{s} σ {sigma[k]:.4g}" for k, s in enumerate(MEASURED))
          + (" (identify_greybox refitted with its residuals' σ: the baseline's weighting differs)" if refit else ""))

    # 2. the baseline
    if args.no_baseline:
        baseline_s = ratio = err = float("nan")
        print("\nbaseline skipped (--no-baseline)")
    else:
        t0 = time.perf_counter()
        y_radau = radau_run(TRUTH, data, args.rtol)
        one = time.perf_counter() - t0
        y_rk, _ = simulate_with_sensitivities(TRUTH, (), data)
        gap = ", ".join(f"{s} {np.max(np.abs(y_radau[:, r] - y_rk[:, r])) / noise[s]:.2g} σ"
                        for s, r in zip(MEASURED, ROWS, strict=True))
        print(f"\nbaseline: Radau rtol {args.rtol:g}, one run {one:.2f} s; its largest departure from the "
              f"simulator's: {gap}")
        est, sims, baseline_s, sol = baseline(data, sigma, args.rtol, args.diff_step)
        ratio = baseline_s / greybox_s
        costs = (weighted_cost(ref.params, data, sigma),
                 weighted_cost(ActuatorParams().replace(**est), data, sigma))
        err = max(abs(est[n] / ref.estimates[n] - 1) for n in NAMES)
        print(f"least_squares + solve_ivp: {baseline_s:.1f} s, {sims} simulations, status {sol.status} "
              f"({sol.message})")
        for n in NAMES:
            print(f"  {n:7s} {est[n]:12.6g}   grey-box {ref.estimates[n]:.6g}   "
                  f"differ by {abs(est[n] - ref.estimates[n]) / ref.std_errors[n]:.3f} SE")
        print(f"ratio {ratio:.1f}, largest relative difference {err:.2e}; the weighted cost (the simulator's) at "
              f"the grey-box estimate {costs[0]:.4f}, at the baseline's {costs[1]:.4f}")

    # 3. convergence from guesses 50 % off
    shooting = args.shooting if args.shooting == "single" or shooting_available(data) else None
    print(f"\n{args.starts} starts, each parameter the truth times U[0.5, 1.5]; shooting: "
          + (shooting or "single (identify_greybox has no shooting= keyword yet)"))
    ref_start = run_greybox(data, guess=TRUTH, shooting=shooting)
    ref_cost = weighted_cost(ref_start.params, data, sigma)
    rng = np.random.default_rng(20)
    converged, t_all, failures = 0, time.perf_counter(), []
    for k in range(args.starts):
        guess = TRUTH.replace(**{n: getattr(TRUTH, n) * rng.uniform(0.5, 1.5) for n in NAMES})
        try:
            res = run_greybox(data, guess=guess, shooting=shooting)
        except Exception as exc:                     # a start the model cannot even be simulated from
            failures.append(f"start {k}: {exc}")
            continue
        near = all(abs(res.estimates[n] - ref_start.estimates[n]) <= 3 * ref_start.std_errors[n] for n in NAMES)
        ok = near or weighted_cost(res.params, data, sigma) <= 1.01 * ref_cost
        converged += ok
        if not ok:
            failures.append(f"start {k}: from " + ", ".join(f"{n} {getattr(guess, n):.4g}" for n in NAMES)
                            + " to " + ", ".join(f"{n} {res.estimates[n]:.4g}" for n in NAMES))
    elapsed = time.perf_counter() - t_all
    print(f"converged {converged}/{args.starts} in {elapsed:.1f} s ({elapsed / max(args.starts, 1):.2f} s a start)")
    for line in failures[:10]:
        print("  " + line)
    print(f"\ngreybox_s={greybox_s:.3f} baseline_s={baseline_s:.1f} ratio={ratio:.1f} err={err:.2e} "
          f"converged={converged}/{args.starts}")


if __name__ == "__main__":
    main()
