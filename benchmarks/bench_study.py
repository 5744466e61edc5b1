"""A study of 200 least-squares seeds (white force noise) on a thread pool, against one run.

The study (eha_core.study.run_study) repeats the least-squares experiment of
docs/model.md §4 (the nonlinear plant under white force noise, sigma 1000 N,
u = 6 sin(4 pi t) for 5 s at 1 kHz, eqs. 15-18) for seeds 0..N-1 on K worker
threads. The single run (eha_core.experiments.run_lse, seed 0) is timed in the
same process, after a warm-up that loads the compiled kernels, best of
``--repeat``. ``ratio`` is the study's time per seed over the single run's:
1 / ratio is the speed-up the threads give (at most K, at most the cores).
With ``--serial`` the study is also run on one thread, for the threads'
speed-up measured directly. The last line reads

    study_seeds=<N> total_s=<study wall time> per_seed_s=<total / N> single_run_s=<one run> ratio=<per seed / single>

Target: 200 seeds within 30 s on this project's 2-core machine.

Run:  python benchmarks/bench_study.py [--seeds N] [--workers K] [--serial]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from eha_core.experiments import run_lse
from eha_core.study import StudyConfig, run_study

DISTURBANCE = "white:1000"


def single_run_seconds(repeat: int) -> float:
    run_lse(disturbance=DISTURBANCE, seed=0)   # warm-up: numba's cached kernels, scipy's imports
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        run_lse(disturbance=DISTURBANCE, seed=0)
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=200, help="seeds in the study (default 200)")
    ap.add_argument("--workers", type=int, default=2, help="threads (default 2)")
    ap.add_argument("--repeat", type=int, default=5, help="timing repeats of the single run (best of); default 5")
    ap.add_argument("--serial", action="store_true", help="also run the study on one thread")
    args = ap.parse_args(argv)

    print(f"python {platform.python_version()}, {os.cpu_count()} cores, machine {platform.machine()}")
    single = single_run_seconds(args.repeat)
    print(f"single run (run_lse, {DISTURBANCE}, seed 0, best of {args.repeat}): {single:.4f} s")
    config = StudyConfig("lse", n_seeds=args.seeds, disturbance=DISTURBANCE)
    if args.serial:
        serial = run_study(config, workers=1)
        print(f"study on 1 thread: {serial.elapsed_s:.2f} s, {serial.seconds_per_seed:.4f} s per seed, "
              f"ratio to the single run {serial.seconds_per_seed / single:.2f}")
    res = run_study(config, workers=args.workers)
    per_seed = res.seconds_per_seed
    print(f"study on {res.workers} threads: {res.n_completed} seeds in {res.elapsed_s:.2f} s, "
          f"{per_seed:.4f} s per seed ({res.n_failed} failed)")
    if args.serial:
        print(f"threads' speed-up: {serial.elapsed_s / res.elapsed_s:.2f} (at most {res.workers})")
    print("coverage: " + ", ".join(f"{k} {v:.3f}" for k, v in res.coverage.items())
          + f" (honest intervals: {res.coverage_band()[0]:.3f}-{res.coverage_band()[1]:.3f} in 99 % of studies)")
    print(f"target: {args.seeds} seeds within 30 s: {'met' if res.elapsed_s <= 30 else 'missed'}")
    print(f"study_seeds={res.n_completed} total_s={res.elapsed_s:.2f} per_seed_s={per_seed:.4f} "
          f"single_run_s={single:.4f} ratio={per_seed / single:.2f}")


if __name__ == "__main__":
    main()
