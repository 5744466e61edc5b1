"""A page closed during the largest run the server allows: how soon does the server stop using the CPU?

Serves the app (``eha serve``, one process, on a free port), opens a page at the protocol level
(``classroom_client.Student``), types the largest frequency experiment the limits allow (N = 20000
samples at Ts = 0.12 s: 2 x 2400 s of closed loop, 9.6 M integration steps, then tfest on 20000
samples) and presses "Run experiment and estimate". Measured from the server's CPU time, sampled
every 20 ms:

  kept     the page stays open: how long the server computes (the run's own length, the baseline)
  closed   the page's websocket is closed 0.5 s into the run: how long after the close the server
           still computes (until its CPU rate stays under 10 % of a core for 0.3 s)

The last line reads

    run_s=<kept> closed_stop_s=<closed, after the close> ratio=<run_s / closed_stop_s>

(target: closed_stop_s <= 0.5).

``--study KIND`` does the same with the largest study of that kind the app allows (500 seeds of
lse, tf or greybox; tab 3's "Study over seeds"), which runs in the server's child process for long
work: the server's CPU time counts its descendants.

Run:  python benchmarks/bench_closed_page.py [--repeat 3] [--study greybox]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import time

if __package__:
    from .bench_classroom import Server
    from .classroom_client import Student
else:
    from bench_classroom import Server
    from classroom_client import Student

LARGEST = {"n_samples": "20000", "ts": "0.12"}
IDLE_RATE = 0.10        # of one core
IDLE_FOR_S = 0.3
SAMPLE_S = 0.02
STUDY_SEEDS = 500       # the app's largest study
STUDY_KINDS = ("lse", "tf", "greybox")


async def _start_run(url: str, seed: int) -> Student:
    s = Student(url, name="student", timeout=120)
    await s.open(120)
    await s.show_frequency(120)
    form = s.form("eha-freq-form")
    # a seed of its own each time: the server computes a run once for everyone who asks for the same
    await s.set_property(form, "values", {**dict(form.attributes.get("values") or {}), **LARGEST,
                                          "freq_seed": str(seed)})
    await s.round_trip(30)
    await asyncio.sleep(0.5)             # the excitation's preview, after the new settings
    await s.click(s.button("Run experiment and estimate"))
    return s


async def _start_study(url: str, kind: str) -> Student:
    s = Student(url, name="student", timeout=120)
    await s.open(120)
    await s.start_study(STUDY_SEEDS, 120, kind=kind)
    return s


async def _busy_until_idle(tree, since: float, timeout: float = 120.0) -> float:
    """Seconds from ``since`` until the server's CPU rate stays under IDLE_RATE for IDLE_FOR_S."""
    last_cpu, last_t = tree.cpu_s(), time.perf_counter()
    idle_from = None
    while time.perf_counter() - since < timeout:
        await asyncio.sleep(SAMPLE_S)
        cpu, t = tree.cpu_s(), time.perf_counter()
        rate = (cpu - last_cpu) / (t - last_t)
        last_cpu, last_t = cpu, t
        if rate < IDLE_RATE:
            idle_from = idle_from if idle_from is not None else t - SAMPLE_S
            if t - idle_from >= IDLE_FOR_S:
                return max(0.0, idle_from - since)
        else:
            idle_from = None
    return float("nan")


async def _one(url: str, tree, close: bool, seed: int, study: str | None = None) -> float:
    s = await (_start_study(url, study) if study else _start_run(url, seed))
    t_click = time.perf_counter()
    if close:
        await asyncio.sleep(0.5)
        t_close = time.perf_counter()
        await s.close()
        return await _busy_until_idle(tree, t_close)
    took = await _busy_until_idle(tree, t_click)
    await s.close()
    return took


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--study", choices=STUDY_KINDS, help="a 500-seed study of this kind instead of the "
                    "frequency experiment")
    args = ap.parse_args(argv)
    server = Server(1)
    try:
        kept, closed = [], []
        for k in range(args.repeat):
            kept.append(asyncio.run(_one(server.url, server.tree, close=False, seed=100 + 2 * k, study=args.study)))
            time.sleep(1.0)
            closed.append(asyncio.run(_one(server.url, server.tree, close=True, seed=101 + 2 * k, study=args.study)))
            time.sleep(1.0)
            print(f"kept open: computed {kept[-1]:.2f} s; closed 0.5 s in: still computing {closed[-1]:.2f} s "
                  "after the close")
        problems = server.log_problems()
    finally:
        server.stop()
    run_s, stop_s = statistics.median(kept), statistics.median(closed)
    print(f"server log: {len(problems)} problem(s)" + (f", e.g. {problems[0][:200]}" if problems else ""))
    print(f"run_s={run_s:.2f} closed_stop_s={stop_s:.2f} ratio={run_s / max(stop_s, 1e-3):.1f}"
          + (f" study={args.study}" if args.study else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
