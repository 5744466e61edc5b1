"""Transfer-function estimation on the paper's closed-loop experiment, against a plain OE fit.

For each excitation seed: the paper's experiment (idinput sine reference,
Kp = 10 sampled at Ts = 0.01 s, nonlinear plant) is simulated once; then

* ours: eha_core.identify.tfest.tfest (SRIVC + output error), started also
  from the linearised H(s);
* the peer: a plain output-error fit, scipy.optimize.least_squares started
  from the linearised H(s) of eq. 24 (eha_core.identify.tfest.oe_fit);

both with the same initial-condition and input-offset settings, timed in the
same run. Two settings: the paper's model (zero initial state, no offset) and
ours (both estimated). The last line reads

    tfest_time=<median s> fit=<median %> plain_oe_fit=<median %> wins=<seeds where ours >= plain>

Run:  python benchmarks/bench_tfest.py [--seeds N]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from eha_core.experiments import PAPER_FIT_PERCENT, FrequencyExperiment
from eha_core.identify.tfest import oe_fit, tfest
from eha_core.linear import linearize
from eha_core.params import ActuatorParams


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    params = ActuatorParams()
    init = linearize(params).closed_loop_coeffs(10.0)
    for ic, off in (("zero", "zero"), ("estimate", "estimate")):
        cfg = FrequencyExperiment(initial_condition=ic, input_offset=off)
        times, fits, plain_fits, plain_times, s2 = [], [], [], [], []
        print(f"\ninitial condition {ic}, input offset {off}")
        print(f"{'seed':>4s} {'tfest [s]':>10s} {'fit %':>8s} {'s^2 coef':>9s} {'plain OE [s]':>13s} "
              f"{'plain fit %':>12s}")
        for seed in range(args.seeds):
            cfg_s = FrequencyExperiment(seed=seed, initial_condition=ic, input_offset=off)
            data = cfg_s.closed_loop(params, cfg_s.excitation())
            t0 = time.perf_counter()
            est = tfest(data.r, data.x, cfg.ts, 3, 0, initial_condition=ic, input_offset=off, init=init)
            times.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            plain = oe_fit(data.r, data.x, cfg.ts, *init, initial_condition=ic, input_offset=off)
            plain_times.append(time.perf_counter() - t0)
            fits.append(est.fit_percent)
            plain_fits.append(plain.fit_percent if np.isfinite(plain.fit_percent) else -np.inf)
            s2.append(est.den[1])
            print(f"{seed:4d} {times[-1]:10.3f} {fits[-1]:8.2f} {s2[-1]:9.3g} {plain_times[-1]:13.3f} "
                  f"{plain_fits[-1]:12.2f}")
        wins = sum(f >= p - 1e-6 for f, p in zip(fits, plain_fits, strict=True))
        print(f"median: tfest {np.median(times):.3f} s, fit {np.median(fits):.2f} %; "
              f"plain OE {np.median(plain_times):.3f} s, fit {np.median(plain_fits):.2f} %; "
              f"ours >= plain in {wins}/{args.seeds} (the paper: fit {PAPER_FIT_PERCENT} %)")
    print(f"tfest_time={np.median(times):.3f} fit={np.median(fits):.2f} plain_oe_fit={np.median(plain_fits):.2f} "
          f"wins={wins}/{args.seeds}")


if __name__ == "__main__":
    main()
