"""tfest on data whose input is linear between samples, taken as held (zoh) and as linear (foh).

For each seed: white input samples, the output simulated by
``scipy.signal.lsim`` (exact for an input linear between the samples given),
10 % output noise (of the noise-free output's standard deviation), 400
samples; ``tfest(u, y, ts, np, nz, intersample=...)`` both ways. For the
leading numerator coefficient ``b_0``: the mean relative error (with the
standard error of that mean), the spread over the seeds, the mean reported
standard error, and how often the 95 % interval ``b_0 +- 1.96 std`` covers
the true value. Two plants, each sampled at 0.4 of its time constant:
``10 / (s + 10)`` at 0.04 s and ``s / (s^2 + 2 s + 10)`` at 0.15 s. Then the
median CPU time of one estimate of each. The last line reads

    zoh_bias=<%> zoh_coverage=<fraction> foh_bias=<%> foh_coverage=<fraction>   (the first plant)

Run:  OMP_NUM_THREADS=1 python benchmarks/bench_tfest_intersample.py [--seeds N]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
import scipy.signal

from eha_core.identify.tfest import tfest

PLANTS = [([10.0], [1.0, 10.0], 0.04), ([1.0, 0.0], [1.0, 2.0, 10.0], 0.15)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=200)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    last = None
    for num, den, ts in PLANTS:
        n, m = len(den) - 1, len(num) - 1
        found = {"zoh": [], "foh": []}
        times = {"zoh": [], "foh": []}
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            u = rng.standard_normal(400)
            _, y0, _ = scipy.signal.lsim((num, den), u, ts * np.arange(u.size), interp=True)
            y = y0 + 0.1 * np.std(y0) * rng.standard_normal(u.size)
            for hold in found:
                t0 = time.process_time()
                est = tfest(u, y, ts, n, m, intersample=hold)
                times[hold].append(time.process_time() - t0)
                found[hold].append((est.num[0], est.param_std[n]))
        print(f"\n{num} / {den} at ts = {ts} s, {args.seeds} seeds")
        summary = {}
        for hold, rows in found.items():
            rows = np.array(rows)
            error = (rows[:, 0] - num[0]) / num[0]
            coverage = float(np.mean(np.abs(rows[:, 0] - num[0]) <= 1.96 * rows[:, 1]))
            summary[hold] = (100 * error.mean(), coverage)
            standard = 100 * error.std(ddof=1) / np.sqrt(error.size)
            print(f"  {hold}: b0 error {100 * error.mean():+.2f} % (+- {standard:.2f}), "
                  f"spread {100 * error.std(ddof=1):.2f} %, mean std {100 * rows[:, 1].mean() / num[0]:.2f} %, "
                  f"coverage {coverage:.3f}, {np.median(times[hold]) * 1e3:.1f} ms per estimate")
        last = last or summary
    print(f"zoh_bias={last['zoh'][0]:.2f} zoh_coverage={last['zoh'][1]:.3f} "
          f"foh_bias={last['foh'][0]:.2f} foh_coverage={last['foh'][1]:.3f}")


if __name__ == "__main__":
    main()
