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

``--set K`` measures instead where a student starts from, on a set of problems (:func:`start_set`):
4 actuators (the paper's; light M 2000, B 300, Af 1000, βe 0.5 GPa; mid M 6500, B 800, Af 2000, βe
0.8 GPa; heavy M 9000, B 5000, Af 4000, βe 1.6 GPa) x 4 inputs (sine 6 V 2 Hz, square 3 V 1.5 Hz, a PRBS
of ±4 V, a chirp 5 V 0.2-8 Hz) x without and with a known load 5000 sin(2 pi t) N x the measured sets
x,p1,p2; p1,p2; x; 5 s records at 1 kHz, the sensors' noise of ``eha identify greybox`` (x 0.01 mm,
p 0.05 MPa), M, B, Af, βe estimated. Each problem from the paper's values and from K random starts (each
parameter the truth times a factor log-uniform in [0.5, 2]). A fit is *right* when it ends at the fit
from the truth (its weighted cost within 0.1 % + 1, or every parameter within half a standard error of
it); *confidently wrong* when it is not right and says success (the target: 0). A problem whose fit
from the truth itself fails its checks (x alone cannot always determine all four) is not identifiable
and counted apart. The default strategy (``shooting="auto"``) and, in the same run, the baseline:
single shooting over the whole record from the guess (``shooting="single"``), the same checks.

    set: fits=<n> right=<k> (<%>) confidently_wrong=<c> median=<s> p95=<s> | single: ...

Run:  python benchmarks/bench_greybox.py [--starts 100] [--repeats 3] [--rtol 1e-7] [--no-baseline]
      python benchmarks/bench_greybox.py --set 3
"""

from __future__ import annotations

import argparse
import math
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


# -- where a student starts from: the set ------------------------------------------------------------------

SET_T_END = 5.0
SET_NOISE = {"x": 1e-5, "v": 1e-3, "p1": 5e4, "p2": 5e4}
SET_MEASURED = {"x,p1,p2": ("x", "p1", "p2"), "p1,p2": ("p1", "p2"), "x": ("x",)}


def start_set():
    """The problems of ``--set``: (name, truth, input, load, measured) each."""
    import itertools
    import warnings

    from eha_core.excitation import idinput
    from eha_core.signals import Chirp, Sampled, Square

    actuators = {"paper": ActuatorParams(), "light": ActuatorParams(M=2000.0, B=300.0, Af=1000.0, beta_e=0.5e9),
                 "mid": ActuatorParams(M=6500.0, B=800.0, Af=2000.0, beta_e=0.8e9),
                 "heavy": ActuatorParams(M=9000.0, B=5000.0, Af=4000.0, beta_e=1.6e9)}
    t = np.arange(int(round(SET_T_END * 1000)) + 1) * 1e-3
    with warnings.catch_warnings():          # (it says that it delivers the first samples of a longer period)
        warnings.simplefilter("ignore", UserWarning)
        prbs = idinput(t.size, "prbs", band=(0, 0.04), range=(-4.0, 4.0))
    inputs = {"sine": Sine(6.0, 2.0), "square": Square(3.0, 1.5), "prbs": Sampled(t, np.asarray(prbs.u, float).ravel(),
                                                                                   hold="zoh", name="u"),
              "chirp": Chirp(5.0, 0.2, 8.0, SET_T_END)}
    loads = {"none": None, "load": Sine(5000.0, 1.0)}
    for (an, a), (un, u), (ln, d), (mn, m) in itertools.product(actuators.items(), inputs.items(), loads.items(),
                                                                SET_MEASURED.items()):
        yield f"{an}/{un}/{ln}/{mn}", a, u, d, m


def _set_cost(res, data) -> float:
    rows = [("x", "v", "p1", "p2").index(s) for s in res.measured]
    y = np.stack([data.signals[s] for s in res.measured], axis=1)
    sigma = np.array([SET_NOISE[s] for s in res.measured])
    return float(np.sum(((res.simulated[:, rows] - y) / sigma) ** 2))


def _set_right(res, ref, data) -> bool:
    if _set_cost(res, data) <= _set_cost(ref, data) * (1 + 1e-3) + 1:
        return True
    return all(abs(res.estimates[n] - ref.estimates[n]) <= 0.5 * ref.std_errors[n] for n in NAMES)


def run_set(k: int, seed: int = 0, shootings=("auto", "single")) -> dict:
    """Every problem of :func:`start_set` from the paper's values and ``k`` random starts, by each strategy."""
    rng = np.random.default_rng(seed)
    rows = {sh: [] for sh in shootings}
    apart = []
    for name, truth, u, d, measured in start_set():
        data = greybox_data(truth, u, t_end=SET_T_END, d=d, noise={s: SET_NOISE[s] for s in measured}, seed=seed,
                            measured=measured)
        ref = identify_greybox(data, NAMES, measured=measured, guess=truth)
        starts = [("paper", ActuatorParams())]
        for i in range(k):
            f = np.exp(rng.uniform(math.log(0.5), math.log(2.0), len(NAMES)))
            scaled = {n: getattr(truth, n) * fi for n, fi in zip(NAMES, f, strict=True)}
            starts.append((f"start {i}", truth.replace(**scaled)))
        if not ref.success or ref.held:
            apart.append(f"{name}: from the truth: {'held ' + ', '.join(ref.held) if ref.held else ref.message[:90]}")
            continue
        for start, guess in starts:
            for sh in shootings:
                t0 = time.perf_counter()
                try:
                    res = identify_greybox(data, NAMES, measured=measured, guess=guess, shooting=sh)
                    right, success, why = _set_right(res, ref, data), res.success, res.message[:120]
                except Exception as exc:           # counted, never the run's end
                    right, success, why = False, False, f"{type(exc).__name__}: {exc}"
                rows[sh].append((name, start, right, success, time.perf_counter() - t0, why))
    return {"rows": rows, "apart": apart}


def _set_summary(rows) -> str:
    n = len(rows)
    right = sum(r[2] for r in rows)
    wrong_sure = sum((not r[2]) and r[3] for r in rows)
    flagged = sum(r[2] and not r[3] for r in rows)
    times = np.array([r[4] for r in rows])
    return (f"fits={n} right={right} ({100 * right / max(n, 1):.1f} %) confidently_wrong={wrong_sure} "
            f"right_but_flagged={flagged} median={np.median(times):.3f}s p95={np.percentile(times, 95):.3f}s "
            f"max={times.max():.2f}s")


def main_set(k: int) -> None:
    print(f"python {platform.python_version()}, {os.cpu_count()} cores, machine {platform.machine()}")
    greybox_data(ActuatorParams(), LSE_INPUT, t_end=0.5)          # compiles numba's kernels before timing
    identify_greybox(greybox_data(ActuatorParams(), LSE_INPUT, t_end=1.0, noise=SET_NOISE, measured=("x",)), ("M",))
    out = run_set(k)
    for sh, rows in out["rows"].items():
        print(f"\n{sh}: " + _set_summary(rows))
        for name, start, right, success, dt, why in rows:
            if not right or not success:
                print(f"  {name} {start}: right={right} success={success} {dt:.2f} s  {why}")
        groups = {}
        for r in rows:
            for key in (r[0].split("/")[0], r[0].split("/")[1], r[0].split("/")[3]):
                groups.setdefault(key, []).append(r)
        for key, g in groups.items():
            print(f"  {key:10s} right {sum(r[2] for r in g)}/{len(g)}, median {np.median([r[4] for r in g]):.3f} s")
    print(f"\nnot identifiable from the truth ({len(out['apart'])} problems, counted apart):")
    for line in out["apart"]:
        print("  " + line)
    print("\nset: " + " | ".join(f"{sh}: {_set_summary(rows)}" for sh, rows in out["rows"].items()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--starts", type=int, default=100, help="random initial guesses (default 100)")
    ap.add_argument("--repeats", type=int, default=3, help="timed grey-box runs, their median (default 3)")
    ap.add_argument("--rtol", type=float, default=1e-7, help="Radau's relative tolerance (default 1e-7)")
    ap.add_argument("--diff-step", type=float, default=1e-3,
                    help="least_squares' relative difference step (default 1e-3)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the baseline (minutes)")
    ap.add_argument("--set", type=int, default=None, metavar="K",
                    help="measure the start set instead (each problem from the paper's values and K random starts)")
    ap.add_argument("--shooting", default="single", choices=("single", "multiple"),
                    help="the starts' simulation: output error alone (default: it converged from more starts) "
                         "or multiple shooting first")
    args = ap.parse_args(argv)
    if args.set is not None:
        main_set(args.set)
        return

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
