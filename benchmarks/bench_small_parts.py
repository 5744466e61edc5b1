"""Two small parts of the core that the app calls on every run, timed against a plain baseline.

* The paper's reference signal (``idinput`` sine, 1000 samples, 100 sinusoids: eq. 21's
  excitation), against the same sum of cosines written out with numpy (an outer product of
  the sample times and the frequencies). Target: under 0.05 s.
* The residual tests' verdicts (``assess_residuals`` on 1000 samples), against computing only
  the residuals' autocorrelation with ``numpy.correlate``. Target: under 0.01 s a call.

Both were once wall-clock assertions of the test suite; a test must not fail because a shared
machine is slow, so they are figures here. Best of a few repetitions after a warm-up. The last
line reads

    idinput_s=<s> idinput_target=0.05 idinput_ratio=<baseline / ours> assess_s=<s> assess_target=0.01 \\
    assess_ratio=<baseline / ours>

Run:  python benchmarks/bench_small_parts.py
"""

from __future__ import annotations

import time

import numpy as np


def best_of(fn, repeat: int = 5) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    from eha_core.excitation import idinput
    from eha_core.identify.assessment import assess_residuals
    from eha_core.identify.validate import residual_analysis

    ours_idinput = best_of(lambda: idinput([1000, 1, 1], "sine", [0, 1], [-1, 1], [100, 50, 1], seed=0))
    t = np.arange(1000)
    freqs = np.linspace(0.0, np.pi, 100)
    phases = np.random.default_rng(0).uniform(0, 2 * np.pi, 100)
    plain_idinput = best_of(lambda: np.cos(np.outer(t, freqs) + phases).sum(axis=1))
    print(f"idinput sine (1000 samples, 100 sinusoids): {ours_idinput * 1e3:.2f} ms; "
          f"a plain numpy sum of cosines: {plain_idinput * 1e3:.2f} ms")

    res = residual_analysis(np.random.default_rng(0).standard_normal(1000), np.random.default_rng(1).random(1000))
    e = np.random.default_rng(0).standard_normal(1000)
    ours_assess = best_of(lambda: [assess_residuals(res) for _ in range(100)]) / 100
    plain_assess = best_of(lambda: [np.correlate(e, e, "full") for _ in range(100)]) / 100
    print(f"assess_residuals (1000 samples): {ours_assess * 1e6:.0f} us a call; "
          f"numpy.correlate alone: {plain_assess * 1e6:.0f} us")
    print(f"idinput_s={ours_idinput:.4f} idinput_target=0.05 idinput_ratio={plain_idinput / ours_idinput:.2f} "
          f"assess_s={ours_assess:.5f} assess_target=0.01 assess_ratio={plain_assess / ours_assess:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
