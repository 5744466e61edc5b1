"""Bias and coverage of the least squares and the IV estimator under white force noise, over N seeds.

The least-squares experiment of docs/model.md §4 (the nonlinear plant under
white load-force noise, u = 6 sin(4 pi t) for 5 s at 1 kHz, eqs. 15-18) is
repeated for seeds 0..N-1 by eha_core.study.run_study (its thread pool,
``--workers``) at sigma = 1000 and 2000 N, with three estimators:

    ls/newey-west   the paper's least squares with its Newey-West errors (the default)
    ls/ewc          the same estimates with equal-weighted cosine errors and t quantiles
    iv/ewc          instrumental variables (identify_lse(estimator="iv")), its default intervals

For each, per parameter: the bias (mean - truth) and its Monte Carlo error
(SD / sqrt(N)), the bias against the mean reported standard error
(bias/SE), the estimates' standard deviation against the mean reported
error (SD/SE: 1 for an honest error; the t quantile of ewc also covers the
error's own randomness) and the coverage of the 95 % intervals. An honest
interval's coverage lies in the binomial band printed (99 % of studies of N
seeds), a coverage outside it is marked with ``*``; a bias beyond 2.58 of
its Monte Carlo error (99 %) is marked with ``!``. The last line sums it all
up, to paste:

    lse_coverage seeds=<N> band=<lo>-<hi> | <estimator>/<intervals> sigma=<s>: <name> <coverage> (<bias/SE>) ...

Time on this project's 2-core machine (2 threads, another job running at
low priority): 10-16 s per 1000 least-squares seeds, 40-46 s per 1000 IV
seeds (each runs 3-5 IV iterations, each a simulation and the regressors
again); the default, 1000 seeds of the three at both sigmas, took 2 min 16 s
(expect up to twice that on a busy machine). ``--seeds 200`` takes about
half a minute.

Measured (1000 seeds, sigma 1000 / 2000 N; bias in standard errors):
the least squares with Newey-West: M -0.47 / -0.96, coverage 0.889 / 0.815;
B, Af, d0 0.920-0.930 (their errors 6-8 % narrow; B and Af biased too, -0.27
and +0.23 at 2000 N); beta_e -0.51 / -1.55, 0.959 / 0.702 (its errors 25 %
wide). The same with ewc: B, Af, d0 0.940-0.953. The IV with ewc: every
bias within 0.04, coverage 0.943-0.957 for every parameter at both sigmas.

Run:  python benchmarks/bench_lse_coverage.py [--seeds N] [--sigmas 1000,2000] [--workers K]
"""

from __future__ import annotations

import argparse
import math
import os
import platform

from eha_core.study import MAX_SEEDS, StudyConfig, coverage_band, run_study

#: (estimator, intervals) of each study.
ESTIMATORS = (("ls", "newey-west"), ("ls", "ewc"), ("iv", "ewc"))
#: z of a two-sided 99 % band (a bias beyond it is flagged).
Z99 = 2.5758293035489004


def _sigmas(text: str) -> list[float]:
    values = [float(v) for v in text.split(",") if v.strip()]
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: give standard deviations > 0 N, separated by commas")
    return values


def table(res, band: tuple[float, float]) -> list[str]:
    """One study as lines: per parameter bias, its MC error, bias/SE, SD/SE, coverage."""
    lines = [f"{'parameter':10s}{'truth':>12s}{'bias':>13s}{'MC err':>11s}{'bias/SE':>10s}{'SD/SE':>8s}"
             f"{'coverage':>10s}"]
    for k in res.parameters:
        if k not in res.nominal:
            continue
        bias, err = res.bias[k], res.bias_std_error[k]
        flag_bias = "!" if res.biased(k) else " "
        cov = res.coverage[k]
        flag_cov = " " if band[0] <= cov <= band[1] else "*"
        lines.append(f"{k:10s}{res.nominal[k]:12.6g}{bias:+13.4g}{flag_bias}{err:10.3g}"
                     f"{res.bias_per_std_error[k]:+10.3f}{res.std[k] / res.mean_std_error[k]:8.3f}"
                     f"{cov:9.3f}{flag_cov}")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=MAX_SEEDS, help=f"seeds per study, 1 to {MAX_SEEDS} (default "
                                                                  f"{MAX_SEEDS})")
    ap.add_argument("--sigmas", type=_sigmas, default=[1000.0, 2000.0],
                    help="force noise standard deviations [N], comma-separated (default 1000,2000)")
    ap.add_argument("--workers", type=int, default=2, help="threads (default 2)")
    ap.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    args = ap.parse_args(argv)

    print(f"python {platform.python_version()}, {os.cpu_count()} cores, machine {platform.machine()}")
    band = coverage_band(args.seeds)
    print(f"{args.seeds} seeds from {args.first_seed}; honest 95 % intervals cover {band[0]:.3f}-{band[1]:.3f} in "
          "99 % of studies (* outside); ! a bias beyond 2.58 Monte Carlo errors")
    summary = []
    for sigma in args.sigmas:
        for estimator, intervals in ESTIMATORS:
            cfg = StudyConfig("lse", n_seeds=args.seeds, first_seed=args.first_seed, disturbance=f"white:{sigma:g}",
                              estimator=estimator, intervals=intervals)
            res = run_study(cfg, workers=args.workers)
            ok = res.n_successful
            print(f"\n{estimator}/{intervals}, sigma = {sigma:g} N: {ok} of {res.n_completed} seeds successful, "
                  f"{res.elapsed_s:.1f} s ({res.seconds_per_seed * 1e3:.1f} ms per seed)"
                  + (f"; {res.message}" if res.message != "ok" else ""))
            band_n = coverage_band(max(ok, 1))
            print("\n".join(table(res, band_n)))
            cells = " ".join(f"{k} {res.coverage[k]:.3f} ({res.bias_per_std_error[k]:+.2f})"
                             for k in res.parameters if k in res.nominal)
            summary.append(f"{estimator}/{intervals} sigma={sigma:g}: {cells}")
    print()
    print(f"lse_coverage seeds={args.seeds} band={band[0]:.3f}-{band[1]:.3f} | " + " | ".join(summary))


if __name__ == "__main__":
    main()
