"""The estimated input delay of tfest on a plant whose cost has two local minima over the delay.

The plant ``(1 - s) / (s^2 + s + 1)`` behind 8 s, sampled at 0.5 s (16
samples), 600 samples of a random binary level held 4 samples, white output
noise at a given SNR (variance of the noise-free output over the noise's).
Its right-half-plane zero's initial undershoot is mimicked by a longer delay
(about 9.4 s) with a zero in the left half-plane: a second local minimum of
the output-error cost over the delay. For each seed,
``tfest(u, y, ts, 2, 1, input_delay="estimate")`` is compared with the fit at
the true delay (``input_delay=8``); a *search failure* is an estimate whose
cost exceeds that one by more than 1e-4 (relative): the search ended in a
worse local minimum. The last line reads

    failures=<count>/<seeds> off=<delay off by more than ts/2>/<seeds> time=<median CPU s per estimate>

Run:  OMP_NUM_THREADS=1 python benchmarks/bench_tfest_delay.py [--seeds N] [--snr DB]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from eha_core.identify.tfest import simulate_tf, tfest

NUM, DEN, TS, TAU = [-1.0, 1.0], [1.0, 1.0, 1.0], 0.5, 8.0


def record(seed: int, snr_db: float, n: int = 600):
    """Input and noisy output of one seed (the same as tests/core/test_tfest_delay.py's ``rhp_case``)."""
    rng = np.random.default_rng(seed)
    u = np.repeat(np.sign(rng.standard_normal(n // 4)), 4)
    y0 = simulate_tf(NUM, DEN, u, TS, input_delay=TAU)
    return u, y0 + np.std(y0) / 10 ** (snr_db / 20) * rng.standard_normal(n)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--snr", type=float, default=5.0, help="signal-to-noise ratio in dB (default 5)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    failures, off, times = [], [], []
    for seed in range(args.seeds):
        u, y = record(seed, args.snr)
        t0 = time.process_time()
        est = tfest(u, y, TS, 2, 1, input_delay="estimate")
        times.append(time.process_time() - t0)
        at_true = tfest(u, y, TS, 2, 1, input_delay=TAU)
        if est.cost > at_true.cost * (1 + 1e-4):
            failures.append(seed)
            print(f"seed {seed}: delay {est.input_delay:.4g} s, cost {est.cost:.5g} against {at_true.cost:.5g} "
                  f"at {TAU:g} s (success {est.success})")
        if abs(est.input_delay - TAU) > TS / 2:
            off.append(seed)
    print(f"failures={len(failures)}/{args.seeds} off={len(off)}/{args.seeds} time={np.median(times):.3f}")


if __name__ == "__main__":
    main()
