"""Black-box identification: speed, structure selection, and agreement with SIPPY, in one run.

Four sections:

* speed: each estimator on 10,000 samples of a system of its own structure (ARX, ARMAX, OE and BJ at
  orders 2/2/2/2/2, nk = 1; n4sid at n = 2, 3, 4; procest P1D and P2DI on sampled continuous-time
  systems), the median of a few repeats after a warm-up, beside the target of 0.2 s each;
* selection: :func:`eha_core.identify.selection.select_structure` over MATLAB's 32 ARX structures
  (``struc(1:4, 1:4, 1:2)``) at 10,000 estimation samples, target 2 s;
* SIPPY (sippy_unipi, the University of Pisa's Systems Identification Package for Python, LGPL-3.0):
  ARX, ARMAX, OE, BJ and N4SID on the same data in the same run, for several seeds of systems whose
  truth is known. SIPPY runs in its own virtual environment when it is not importable here: the data
  go to a temporary ``.npz``, a small script runs under SIPPY's Python and sends back its estimates
  and its own times (imports and a warm-up excluded). Compared: time (SIPPY's / ours), the
  parameter error ``||theta - theta0|| / ||theta0||`` over the structure's free coefficients (for
  N4SID, which has no such coefficients, the impulse response's relative error over 100 samples), and
  the fit by simulation on a fresh validation record, computed by the same
  :func:`eha_core.identify.blackbox.compare` for both;
* the actuator: :class:`eha_core.identify.blackbox_experiment.BlackBoxExperiment` records (closed
  loop r -> x, open loop u -> x), the validation fit of each structure (and SIPPY's, when present).

SIPPY is looked for, in this order, in ``--sippy-python``, ``$SIPPY_PYTHON``, this interpreter and
``/tmp/sippy-venv/bin/python``. To make that venv (the project's own venv is left alone):

    python3.11 -m venv /tmp/sippy-venv && /tmp/sippy-venv/bin/pip install sippy_unipi

(sippy_unipi 1.0.1 installs on Python 3.11 with numpy 2.) The last line reads

    blackbox slowest=<estimator> <s> (target 0.2) selection=<s> (target 2) sippy=<ok|absent> \
time_ratio=<median SIPPY/ours> fit_diff=<median ours - SIPPY, %> param_err_ratio=<median ours/SIPPY>

Run:  python benchmarks/bench_blackbox.py [--quick] [--seeds N] [--sippy-python PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.signal

from eha_core.identify.blackbox import IdData, LinearModel, compare, predict

SPEED_TARGET_S = 0.2
SELECTION_TARGET_S = 2.0
N_SPEED = 10_000

# the true plant of every polynomial case: G0 = (q^-1 + 0.5 q^-2) / (1 - 1.5 q^-1 + 0.7 q^-2)
G_NUM = np.array([0.0, 1.0, 0.5])
G_DEN = np.array([1.0, -1.5, 0.7])
C_TRUE = np.array([1.0, 0.5, 0.3])          # roots of modulus sqrt(0.3): a well-behaved MA part
D_TRUE = np.array([1.0, -1.0, 0.2])         # real poles 0.72 and 0.28
NOISE_STD = 0.5

# each structure's truth, as (gb, ga, hc, hd) in ascending powers of q^-1
TRUTH = {
    "arx": (G_NUM, G_DEN, np.array([1.0]), G_DEN),
    "armax": (G_NUM, G_DEN, C_TRUE, G_DEN),
    "oe": (G_NUM, G_DEN, np.array([1.0]), np.array([1.0])),
    "bj": (G_NUM, G_DEN, C_TRUE, D_TRUE),
    "n4sid": (G_NUM, G_DEN, C_TRUE, G_DEN),   # an ARMAX system is an order-2 innovation state space
}
STRUCTURE_LABEL = {"arx": "ARX 2/2/1", "armax": "ARMAX 2/2/2/1", "oe": "OE 2/2/1", "bj": "BJ 2/2/2/2/1",
                   "n4sid": "N4SID n=2"}
# SIPPY's names and orders for the same structures (its delay ``theta`` counts from nk = 1)
SIPPY_JOBS = {
    "arx": ("ARX", {"ARX_orders": [2, 2, 0]}),
    "armax": ("ARMAX", {"ARMAX_orders": [2, 2, 2, 0]}),
    "oe": ("OE", {"OE_orders": [2, 2, 0]}),
    "bj": ("BJ", {"BJ_orders": [2, 2, 2, 2, 0]}),
    "n4sid": ("N4SID", {"SS_fixed_order": 2}),
}

# run under SIPPY's interpreter: argv = data.npz jobs.json out.json
SIPPY_SCRIPT = r'''
import contextlib, io, json, sys, time
import numpy as np
from sippy_unipi import system_identification

data = np.load(sys.argv[1])
jobs = json.load(open(sys.argv[2]))
out = []
with contextlib.redirect_stdout(io.StringIO()):
    # warm-up: imports and first calls are not timed
    rng = np.random.default_rng(0)
    system_identification(rng.standard_normal(300), rng.standard_normal(300), "ARX", ARX_orders=[1, 1, 0])
for job in jobs:
    y, u = data["y_" + job["id"]], data["u_" + job["id"]]
    rec = {"id": job["id"]}
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            t0 = time.perf_counter()
            model = system_identification(y, u, job["method"], **job["kwargs"])
            rec["time_s"] = time.perf_counter() - t0
        if job["method"] in ("N4SID", "MOESP", "CVA"):
            rec["ss"] = {k: np.atleast_2d(np.asarray(getattr(model, k), float)).tolist() for k in "ABCDK"}
        else:
            rec["G"] = [np.ravel(model.G.num[0][0]).tolist(), np.ravel(model.G.den[0][0]).tolist()]
            rec["H"] = [np.ravel(model.H.num[0][0]).tolist(), np.ravel(model.H.den[0][0]).tolist()]
    except BaseException as exc:        # SIPPY calls sys.exit on bad orders
        rec["error"] = f"{type(exc).__name__}: {exc}"
    out.append(rec)
json.dump(out, open(sys.argv[3], "w"))
'''


# ---------------------------------------------------------------------------
# data and models
# ---------------------------------------------------------------------------
def polynomial_record(structure: str, n: int, seed: int) -> IdData:
    """``y = G0 u + H0 e`` of ``structure``'s truth, white Gaussian input and noise."""
    gb, ga, hc, hd = TRUTH[structure]
    rng = np.random.default_rng([seed, n])
    u = rng.standard_normal(n)
    e = NOISE_STD * rng.standard_normal(n)
    y = scipy.signal.lfilter(gb, ga, u) + scipy.signal.lfilter(hc, hd, e)
    return IdData(y, u, 1.0, name=f"{structure} truth, seed {seed}")


def process_record(kind: str, n: int, seed: int) -> IdData:
    """A held random binary input through P1D (K 2, Tp1 0.5 s, Td 0.23 s) or P2DI (K 1, Tp1 0.3 s,
    Tp2 0.1 s, Td 0.15 s), sampled at 0.05 s, with white output noise."""
    from eha_core.identify._ctmodels import simulate_tf

    rng = np.random.default_rng([seed, n, 7])
    ts = 0.05
    u = np.repeat(rng.choice([-1.0, 1.0], n // 5 + 1), 5)[:n]
    if kind == "P1D":
        y = simulate_tf([2.0], [0.5, 1.0], u, ts, input_delay=0.23)
    else:
        y = simulate_tf([1.0], np.polymul(np.polymul([0.3, 1.0], [0.1, 1.0]), [1.0, 0.0]), u, ts,
                        input_delay=0.15)
    return IdData(y + 0.01 * np.std(y) * rng.standard_normal(n), u, ts, name=f"{kind} truth, seed {seed}")


@dataclass(frozen=True, eq=False)
class GivenModel(LinearModel):
    """Another implementation's estimate, given by its polynomials in ascending powers of ``q^-1``."""

    gb: np.ndarray
    ga: np.ndarray
    hc: np.ndarray
    hd: np.ndarray
    ts: float = 1.0

    def g_poly(self):
        return np.asarray(self.gb, float), np.asarray(self.ga, float)

    def h_poly(self):
        return np.asarray(self.hc, float), np.asarray(self.hd, float)


def _z_to_qinv(num, den) -> tuple[np.ndarray, np.ndarray]:
    """A transfer function in descending powers of ``z`` as ascending powers of ``q^-1``."""
    num, den = np.atleast_1d(np.asarray(num, float)), np.atleast_1d(np.asarray(den, float))
    n = max(num.size, den.size)
    num, den = np.pad(num, (n - num.size, 0)), np.pad(den, (n - den.size, 0))
    return num / den[0], den / den[0]


def sippy_model(rec: dict, ts: float) -> GivenModel:
    if "ss" in rec:
        a, b, c, d, k = (np.asarray(rec["ss"][key], float) for key in "ABCDK")
        gnum, gden = scipy.signal.ss2tf(a, b, c, d)
        hnum, hden = scipy.signal.ss2tf(a, k, c, np.eye(c.shape[0]))
        gb, ga = _z_to_qinv(gnum[0], gden)
        hc, hd = _z_to_qinv(hnum[0], hden)
    else:
        gb, ga = _z_to_qinv(*rec["G"])
        hc, hd = _z_to_qinv(*rec["H"])
    return GivenModel(gb, ga, hc, hd, ts)


def _first(poly, k: int) -> np.ndarray:
    p = np.asarray(poly, float)[:k]
    return np.pad(p, (0, k - p.size))


def free_coefficients(structure: str, model: LinearModel) -> np.ndarray:
    """The structure's free coefficients (orders 2/2/2/2/2, nk = 1) read off G and H."""
    gb, ga = model.g_poly()
    hc, hd = model.h_poly()
    parts = [_first(ga, 3)[1:], _first(gb, 3)[1:]]
    if structure in ("armax", "bj"):
        parts.append(_first(hc, 3)[1:])
    if structure == "bj":
        parts.append(_first(hd, 3)[1:])
    return np.concatenate(parts)


def impulse(model: LinearModel, n: int = 100) -> np.ndarray:
    gb, ga = model.g_poly()
    x = np.zeros(n)
    x[0] = 1.0
    return scipy.signal.lfilter(gb, ga, x)


def accuracy(structure: str, model: LinearModel) -> float:
    """Relative error of the free coefficients (N4SID: of the impulse response)."""
    truth = GivenModel(*TRUTH[structure])
    if structure == "n4sid":
        g0 = impulse(truth)
        return float(np.linalg.norm(impulse(model) - g0) / np.linalg.norm(g0))
    p0 = free_coefficients(structure, truth)
    return float(np.linalg.norm(free_coefficients(structure, model) - p0) / np.linalg.norm(p0))


def ours(structure: str, data: IdData):
    from eha_core.identify import polynomial, subspace

    if structure == "arx":
        return polynomial.arx(data, 2, 2, 1)
    if structure == "armax":
        return polynomial.armax(data, 2, 2, 2, 1)
    if structure == "oe":
        return polynomial.oe(data, 2, 2, 1)
    if structure == "bj":
        return polynomial.bj(data, 2, 2, 2, 2, 1)
    return subspace.n4sid(data, 2)


def one_step_loss(model: LinearModel, data: IdData) -> float:
    """Mean squared one-step prediction error from rest: the criterion ARMAX, OE and BJ minimise."""
    with np.errstate(all="ignore"):
        e = data.y - predict(model, data, 1, "zero")
    return float(np.mean(e ** 2))


def _median_time(fn, repeats: int) -> tuple[float, object]:
    result = fn()                           # warm-up (imports, caches)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), result


# ---------------------------------------------------------------------------
# SIPPY
# ---------------------------------------------------------------------------
def find_sippy(explicit: str | None) -> tuple[str | None, str]:
    """The interpreter that imports sippy_unipi, and what was tried."""
    tried = []
    for candidate in (explicit, os.environ.get("SIPPY_PYTHON"), sys.executable, "/tmp/sippy-venv/bin/python"):
        if not candidate or candidate in tried:
            continue
        tried.append(candidate)
        if candidate != sys.executable and not pathlib.Path(candidate).exists():
            continue
        probe = subprocess.run([candidate, "-c", "import sippy_unipi"], capture_output=True, text=True,
                               timeout=120)
        if probe.returncode == 0:
            return candidate, ""
    return None, ("sippy_unipi is importable from none of " + ", ".join(tried) + "; make it with: "
                  "python3.11 -m venv /tmp/sippy-venv && /tmp/sippy-venv/bin/pip install sippy_unipi")


def run_sippy(python: str, cases: dict) -> dict:
    """SIPPY on each ``cases[id] = (data, method, kwargs)``: ``{id: record}`` (its estimate, its time)."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        arrays, jobs = {}, []
        for key, (data, method, kwargs) in cases.items():
            arrays[f"y_{key}"], arrays[f"u_{key}"] = data.y, data.u
            jobs.append({"id": key, "method": method, "kwargs": kwargs})
        np.savez(tmp / "data.npz", **arrays)
        (tmp / "jobs.json").write_text(json.dumps(jobs))
        (tmp / "run.py").write_text(SIPPY_SCRIPT)
        done = subprocess.run([python, str(tmp / "run.py"), str(tmp / "data.npz"), str(tmp / "jobs.json"),
                               str(tmp / "out.json")], capture_output=True, text=True, timeout=3600)
        if done.returncode != 0:
            raise RuntimeError(f"SIPPY's run failed: {done.stderr.strip().splitlines()[-1:]}")
        return {rec["id"]: rec for rec in json.loads((tmp / "out.json").read_text())}


# ---------------------------------------------------------------------------
# sections
# ---------------------------------------------------------------------------
def speed_section(repeats: int) -> tuple[str, float]:
    from eha_core.identify import polynomial, process, subspace

    # a shared machine's load stretches every time: print it so a reader can judge the figures
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"speed: one estimate from {N_SPEED} samples (median of {repeats} after a warm-up; "
          f"target <= {SPEED_TARGET_S} s); load average {load:.1f} on {os.cpu_count()} cores")
    cases = [
        ("arx(2, 2, 1)", "arx", lambda d: polynomial.arx(d, 2, 2, 1)),
        ("armax(2, 2, 2, 1)", "armax", lambda d: polynomial.armax(d, 2, 2, 2, 1)),
        ("oe(2, 2, 1)", "oe", lambda d: polynomial.oe(d, 2, 2, 1)),
        ("bj(2, 2, 2, 2, 1)", "bj", lambda d: polynomial.bj(d, 2, 2, 2, 2, 1)),
        *[(f"n4sid(n={n})", "n4sid", lambda d, n=n: subspace.n4sid(d, n)) for n in (2, 3, 4)],
        ("procest P1D", "P1D", lambda d: process.procest(d, "P1D")),
        ("procest P2DI", "P2DI", lambda d: process.procest(d, "P2DI")),
    ]
    print(f"  {'estimator':20s} {'time [s]':>9s} {'target':>7s} {'success':>8s}  fit on its data")
    slowest, slowest_t = "", 0.0
    for label, system, fn in cases:
        data = (process_record(system, N_SPEED, 0) if system in ("P1D", "P2DI")
                else polynomial_record(system, N_SPEED, 0))
        t, model = _median_time(lambda fn=fn, data=data: fn(data), repeats)
        flag = "" if t <= SPEED_TARGET_S else "  ABOVE TARGET"
        print(f"  {label:20s} {t:9.3f} {SPEED_TARGET_S:7.2f} {str(bool(model.success)):>8s}  "
              f"{model.fit.label}{flag}")
        if t > slowest_t:
            slowest, slowest_t = label, t
    return slowest, slowest_t


def selection_section(repeats: int) -> float:
    from eha_core.identify.selection import select_structure

    est, val = polynomial_record("arx", N_SPEED, 1), polynomial_record("arx", N_SPEED, 2)
    t, table = _median_time(lambda: select_structure(est, val), repeats)
    print(f"\nselection: {len(table.rows)} ARX structures (struc(1:4, 1:4, 1:2)) at {N_SPEED} samples: "
          f"{t:.3f} s (target <= {SELECTION_TARGET_S} s){'' if t <= SELECTION_TARGET_S else '  ABOVE TARGET'}; "
          f"picked {table.best_model.name if table.best_model is not None else 'none'} by {table.criterion} "
          f"(truth ARX(na=2, nb=2, nk=1))")
    return t


def sippy_section(python: str | None, why_not: str, seeds: int, n: int, repeats: int) -> dict:
    """Ours against SIPPY, per structure and seed; returns the medians for the summary."""
    print(f"\nagainst SIPPY: {n} estimation samples, a fresh validation record of {n}, seeds 0..{seeds - 1}, "
          f"noise sigma {NOISE_STD}")
    if python is None:
        print(f"  SIPPY: not available ({why_not})")
    else:
        version = subprocess.run([python, "-c", "import importlib.metadata as m; print(m.version('sippy_unipi'))"],
                                 capture_output=True, text=True).stdout.strip()
        print(f"  SIPPY {version} under {python} (SIPPY's defaults: ARMAX by iterative least squares, OE and BJ by "
              f"IPOPT, N4SID f = 20)")
    records, cases = {}, {}
    for structure in TRUTH:
        for seed in range(seeds):
            est = polynomial_record(structure, n, seed)
            val = polynomial_record(structure, n, seed + 1000)
            records[structure, seed] = (est, val)
            method, kwargs = SIPPY_JOBS[structure]
            cases[f"{structure}-{seed}"] = (est, method, kwargs)
    theirs = {}
    if python is not None:
        try:
            theirs = run_sippy(python, cases)
        except (RuntimeError, subprocess.TimeoutExpired, OSError, ValueError) as exc:
            print(f"  SIPPY: its run failed ({exc})")
    print(f"  {'structure':14s} {'seed':>4s} {'ours [s]':>9s} {'SIPPY [s]':>10s} {'ratio':>6s} "
          f"{'err ours':>9s} {'err SIPPY':>10s} {'V ratio':>8s} {'fit ours':>9s} {'fit SIPPY':>10s} {'fit truth':>10s}")
    ratios, fit_diffs, err_ratios = [], [], []
    for structure in TRUTH:
        per = {"t": [], "ts": [], "e": [], "es": [], "f": [], "fs": []}
        for seed in range(seeds):
            est, val = records[structure, seed]
            t, model = _median_time(lambda est=est, s=structure: ours(s, est), repeats)
            err, fit = accuracy(structure, model), compare(model, val).fit_percent
            truth_fit = compare(GivenModel(*TRUTH[structure]), val).fit_percent
            rec = theirs.get(f"{structure}-{seed}")
            t_s = err_s = fit_s = v_ratio = float("nan")
            note = ""
            if rec is not None and "error" in rec:
                note = f"  SIPPY failed: {rec['error'][:80]}"
            elif rec is not None:
                theirs_model = sippy_model(rec, est.ts)
                t_s, err_s = rec["time_s"], accuracy(structure, theirs_model)
                with np.errstate(all="ignore"):
                    fit_s = compare(theirs_model, val).fit_percent
                    v_ratio = one_step_loss(model, est) / one_step_loss(theirs_model, est)
            ratio = t_s / t if np.isfinite(t_s) else float("nan")
            print(f"  {STRUCTURE_LABEL[structure]:14s} {seed:4d} {t:9.3f} {t_s:10.3f} {ratio:6.1f} {err:9.4f} "
                  f"{err_s:10.4f} {v_ratio:8.4f} {fit:9.2f} {fit_s:10.2f} {truth_fit:10.2f}{note}")
            for key, v in zip(("t", "ts", "e", "es", "f", "fs"), (t, t_s, err, err_s, fit, fit_s), strict=True):
                per[key].append(v)
        if np.all(np.isfinite(per["ts"])):
            ratios.append(np.median(np.array(per["ts"]) / np.array(per["t"])))
            fit_diffs.append(np.median(np.array(per["f"]) - np.array(per["fs"])))
            err_ratios.append(np.median(np.array(per["e"]) / np.array(per["es"])))
        med = {key: np.nanmedian(v) if np.any(np.isfinite(v)) else np.nan for key, v in per.items()}
        print(f"  {'':14s} {'med':>4s} {med['t']:9.3f} {med['ts']:10.3f} {'':6s} {med['e']:9.4f} {med['es']:10.4f} "
              f"{'':8s} {med['f']:9.2f} {med['fs']:10.2f}")
    print("  (ratio: SIPPY's time / ours; err: relative error of the free coefficients, N4SID of the impulse "
          "response; V ratio: our one-step loss on the estimation record / SIPPY's, both by the same predictor "
          "from rest, < 1 where ours is the lower; fit: % by simulation on the validation record)")
    if not ratios:
        return {}
    return {"time_ratio": float(np.median(ratios)), "fit_diff": float(np.median(fit_diffs)),
            "param_err_ratio": float(np.median(err_ratios))}


def actuator_section(python: str | None, n: int) -> None:
    from eha_core.identify import polynomial, process, subspace
    from eha_core.identify.blackbox_experiment import BlackBoxExperiment

    structures = [
        ("ARX 2/2/1", lambda d: polynomial.arx(d, 2, 2, 1), ("ARX", {"ARX_orders": [2, 2, 0]})),
        ("ARX 4/4/1", lambda d: polynomial.arx(d, 4, 4, 1), ("ARX", {"ARX_orders": [4, 4, 0]})),
        ("ARMAX 2/2/2/1", lambda d: polynomial.armax(d, 2, 2, 2, 1), ("ARMAX", {"ARMAX_orders": [2, 2, 2, 0]})),
        ("OE 2/2/1", lambda d: polynomial.oe(d, 2, 2, 1), ("OE", {"OE_orders": [2, 2, 0]})),
        ("BJ 2/2/2/2/1", lambda d: polynomial.bj(d, 2, 2, 2, 2, 1), ("BJ", {"BJ_orders": [2, 2, 2, 2, 0]})),
        ("N4SID n=2", lambda d: subspace.n4sid(d, 2), ("N4SID", {"SS_fixed_order": 2})),
        ("N4SID n=3", lambda d: subspace.n4sid(d, 3), ("N4SID", {"SS_fixed_order": 3})),
    ]
    setups = {
        "closed": (BlackBoxExperiment(loop="closed", n_samples=n), ("P1D", "P2D")),
        "open": (BlackBoxExperiment(loop="open", n_samples=n), ("P1DI", "P2DI")),
    }
    print(f"\nthe actuator: BlackBoxExperiment records of {n} samples (estimation seed 0, validation seed 1); "
          f"fit % by simulation on the validation record, zero initial conditions")
    for loop, (experiment, kinds) in setups.items():
        est, val = experiment.records()
        # the open loop integrates: its mean is not an operating point, the closed loop's is
        est_d, val_d = (est.detrended(), val.detrended()) if loop == "closed" else (est, val)
        cases = {label: (est_d, *job) for label, _fn, job in structures}
        theirs = {}
        if python is not None:
            try:
                theirs = run_sippy(python, cases)
            except (RuntimeError, subprocess.TimeoutExpired, OSError, ValueError) as exc:
                print(f"  SIPPY: its run failed ({exc})")
        print(f"  {loop} loop, {experiment.input_name} -> {experiment.output_name}:")
        print(f"    {'structure':16s} {'ours fit':>9s} {'ok':>5s} {'time [s]':>9s} {'SIPPY fit':>10s} "
              f"{'SIPPY [s]':>10s} {'V ratio':>8s}")
        rows = [(label, fn) for label, fn, _job in structures] + [
            (f"procest {k}", lambda d, k=k: process.procest(d, k)) for k in kinds]
        for label, fn in rows:
            t0 = time.perf_counter()
            model = fn(est_d)
            t = time.perf_counter() - t0
            with np.errstate(all="ignore"):
                fit = compare(model, val_d).fit_percent
            rec = theirs.get(label)
            fit_s = t_s = v_ratio = float("nan")
            if rec is not None and "error" not in rec:
                theirs_model = sippy_model(rec, est.ts)
                with np.errstate(all="ignore"):
                    fit_s = compare(theirs_model, val_d).fit_percent
                    v_ratio = one_step_loss(model, est_d) / one_step_loss(theirs_model, est_d)
                t_s = rec["time_s"]
            note = f"  SIPPY failed: {rec['error'][:60]}" if rec is not None and "error" in rec else ""
            note += "" if model.success else f"  ours: {model.message[:90]}"
            print(f"    {label:16s} {fit:9.2f} {str(bool(model.success)):>5s} {t:9.3f} {fit_s:10.2f} {t_s:10.3f} "
                  f"{v_ratio:8.4f}{note}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true",
                    help="2 seeds of 2000 samples against SIPPY, 3 repeats, actuator records of 1000 samples")
    ap.add_argument("--seeds", type=int, default=None, help="seeds against SIPPY (default 3; 2 with --quick)")
    ap.add_argument("--sippy-python", default=None, help="a Python interpreter that imports sippy_unipi")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    repeats = 3
    seeds = args.seeds if args.seeds is not None else (2 if args.quick else 3)
    n_sippy = 2000 if args.quick else N_SPEED
    n_actuator = 1000 if args.quick else 2000

    slowest, slowest_t = speed_section(repeats)
    selection_t = selection_section(repeats)
    python, why_not = find_sippy(args.sippy_python)
    medians = sippy_section(python, why_not, seeds, n_sippy, repeats)
    actuator_section(python, n_actuator)
    if medians:
        tail = (f"sippy=ok time_ratio={medians['time_ratio']:.1f} fit_diff={medians['fit_diff']:+.2f} "
                f"param_err_ratio={medians['param_err_ratio']:.2f}")
    else:
        tail = "sippy=absent"
    print(f"blackbox slowest={slowest.replace(' ', '')} {slowest_t:.3f} (target {SPEED_TARGET_S}) "
          f"selection={selection_t:.3f} (target {SELECTION_TARGET_S}) {tail}")


if __name__ == "__main__":
    main()
