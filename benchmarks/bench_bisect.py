"""How many hand-ins a student who games the verdicts needs to pin M within 1 %, under each feedback rule.

The student ignores the physics: they hand in guesses of M and keep every true value the verdicts
allow ("within ±tol" or not is a window around the truth, so each answer cuts the candidates). Each
next guess is the one whose answer best halves the candidates left (the most a yes/no answer can
tell). They stop when every candidate lies within 1 % of the middle one, or when the exercise's
rules refuse the next hand-in. The verdicts come from the real :class:`eha_core.exercise.Exercise`
(its ``verdicts``, ``refusal`` and ``shows_verdicts``); no server.

    python benchmarks/bench_bisect.py [--students 200] [--tolerance 0.05]

Last line: ``verdict_median=… verdict_max=… attempts3_pinned=…/N none_pinned=…/N after_deadline_pinned=…/N``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eha_core.exercise import Exercise

PIN = 0.01


def bisect(ex: Exercise, student: str, *, limit: int = 200) -> int | None:
    """Hand-ins until M is pinned within 1 % (None: the rules stop the student first)."""
    m0, vary = 4000.0, ex.vary
    cand = np.linspace(m0 * (1 - vary), m0 * (1 + vary), 20001)      # what the student knows at the start
    tol = ex.tolerance_of("M")
    count = 0
    while True:
        mid = np.median(cand)
        if np.all(np.abs(cand / mid - 1) <= PIN):
            return count
        if count >= limit or ex.refusal(count, now=time.time()) is not None:
            return None
        # the guess whose window [T(1 - tol), T(1 + tol)] holds half the candidates
        guesses = np.quantile(cand, np.linspace(0, 1, 41)) * (1 - tol)
        fractions = [np.mean(np.abs(g / cand - 1) <= tol) for g in guesses]
        g = guesses[int(np.argmin(np.abs(np.asarray(fractions) - 0.5)))]
        count += 1
        ok = ex.verdicts(student, {"M": g})["M"]
        if not ex.shows_verdicts(now=time.time()):
            continue                                  # the student learns nothing from this hand-in
        keep = (np.abs(g / cand - 1) <= tol) == ok
        cand = cand[keep]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--students", type=int, default=200)
    ap.add_argument("--tolerance", type=float, default=0.05)
    args = ap.parse_args()
    secret = "3e" * 32
    rules = {
        "verdict, no limit": Exercise.new(hide=("M",), tolerance=args.tolerance, secret=secret),
        "verdict, 3 attempts": Exercise.new(hide=("M",), tolerance=args.tolerance, secret=secret, attempts=3),
        "none": Exercise.new(hide=("M",), tolerance=args.tolerance, secret=secret, feedback="none", attempts=0),
        "after-deadline": Exercise.new(hide=("M",), tolerance=args.tolerance, secret=secret,
                                       feedback="after-deadline", deadline="2100-01-01T00:00"),
    }
    ids = [f"s{k}" for k in range(args.students)]
    out = {}
    t0 = time.perf_counter()
    for name, ex in rules.items():
        counts = [bisect(ex, sid, limit=60) for sid in ids]
        pinned = [c for c in counts if c is not None]
        out[name] = (pinned, len(ids))
        spread = (f"median {np.median(pinned):.0f}, max {max(pinned)} hand-ins" if pinned else "never")
        print(f"{name:22s} pinned {len(pinned)}/{len(ids)}: {spread}")
    v = out["verdict, no limit"][0]
    print(f"({time.perf_counter() - t0:.1f} s; tolerance ±{100 * args.tolerance:g} %, prior ±25 %, pin within 1 %)")
    print(f"verdict_median={np.median(v):.0f} verdict_max={max(v)} "
          f"attempts3_pinned={len(out['verdict, 3 attempts'][0])}/{len(ids)} "
          f"none_pinned={len(out['none'][0])}/{len(ids)} "
          f"after_deadline_pinned={len(out['after-deadline'][0])}/{len(ids)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
