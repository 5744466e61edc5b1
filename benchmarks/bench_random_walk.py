"""The long run: many students walking the app at random for a long time, every invariant checked.

Serves the app (``eha serve`` on a free port with ``EHA_STRICT=1``; or ``--url`` and ``--log`` for a
running one) and runs ``--sessions`` seeded random walks at once (benchmarks/walker.py: what a student
can do, in any order, each action followed by the checks of the server's log, tab 1's derived
values, the results' freshness, the run buttons and the connection), ``--actions`` actions each; walk
k has seed ``--seed + k``, so a failure replays with ``python -m benchmarks.walker --seed S``.

Printed: progress every 30 s (actions done, actions per second, failures so far); at the end the
actions by kind with their mean time, the failures grouped by sort (each with its first example in
full: seed, action index, action, the ten actions before, the page's address, the server's log
lines), the failures by kind, and a last line

    sessions=10 actions=20000 failures=N actions_per_s=X

    python benchmarks/bench_random_walk.py                        # 10 sessions x 2000 actions, seed 1
    python benchmarks/bench_random_walk.py --sessions 3 --actions 300 --seed 101
    python benchmarks/bench_random_walk.py --exercise --sessions 4
    python benchmarks/bench_random_walk.py --url http://127.0.0.1:5006/eha --log eha.log
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

# run as a script, this file's folder is on the path: the walker is a sibling module
if __package__:
    from .walker import LogMonitor, WalkOptions, WalkServer, format_failures, kinds_table, run_walks, shutdown_failures
else:
    from walker import LogMonitor, WalkOptions, WalkServer, format_failures, kinds_table, run_walks, shutdown_failures

HIDDEN = ("M", "B", "Af", "beta_e")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sessions", type=int, default=10, help="walks at once (default 10)")
    ap.add_argument("--actions", type=int, default=2000, help="actions per walk (default 2000)")
    ap.add_argument("--seed", type=int, default=1, help="walk k has seed SEED + k (default 1)")
    ap.add_argument("--url", help="a running server's app URL (default: start eha serve with EHA_STRICT=1)")
    ap.add_argument("--log", help="with --url: the server's log file (its problems are failures)")
    ap.add_argument("--procs", type=int, default=1, help="--num-procs for the server it starts (default 1)")
    ap.add_argument("--exercise", action="store_true", help="serve an exercise (hides M, B, Af, beta_e): every "
                    "walk starts with a student id and can hand in")
    ap.add_argument("--heavy", action="store_true", help="valid values of costly fields over their whole "
                    "range (studies of 500 seeds, 20000 samples)")
    ap.add_argument("--only", default="", help="comma-separated action kinds to walk (development)")
    ap.add_argument("--json", help="write the failures and the counts to this file")
    ap.add_argument("--save", metavar="FILE", help="write each walk's actions (as data) to this JSON file: "
                    "python -m benchmarks.walker --replay FILE [--shrink 300] does the first again")
    args = ap.parse_args(argv)
    if args.sessions < 1 or args.actions < 1:
        print("bench_random_walk: error: --sessions and --actions must be at least 1", file=sys.stderr)
        return 2
    if args.log and not args.url:
        print("bench_random_walk: error: --log is for --url", file=sys.stderr)
        return 2
    options = WalkOptions(light=not args.heavy, only=tuple(k for k in args.only.split(",") if k))
    server = None
    url, log = args.url, args.log
    extra = ["--num-procs", str(args.procs)] if args.procs != 1 else []
    if args.exercise:
        options.exercise_hidden = HIDDEN
        if url is None:
            exercise = os.path.join(tempfile.mkdtemp(prefix="eha-walk-"), "class.json")
            eha = Path(sys.executable).with_name("eha")
            subprocess.run([str(eha), "exercise", "new", "--hide", ",".join(HIDDEN), "--out", exercise],
                           check=True, capture_output=True)
            extra += ["--exercise", exercise]
    if url is None:
        server = WalkServer(*extra)
        url, log = server.url, server.log_path
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; server {url} (log {log}); "
          f"{args.sessions} sessions x {args.actions} actions, seeds {args.seed}..{args.seed + args.sessions - 1}",
          flush=True)
    monitor = LogMonitor(log) if log else None
    t0 = time.perf_counter()

    def progress(walkers):
        done = sum(w.actions_done for w in walkers)
        seconds = time.perf_counter() - t0
        failures = sum(len(w.failures) for w in walkers)
        print(f"  {seconds:6.0f} s: {done} actions ({done / seconds:.1f}/s), {failures} failures", flush=True)

    try:
        failures, walkers = asyncio.run(run_walks(url, [args.seed + k for k in range(args.sessions)], args.actions,
                                                  monitor=monitor, options=options, progress=progress,
                                                  progress_every_s=30))
        seconds = time.perf_counter() - t0
    finally:
        if server is not None:
            server.stop()
    if server is not None:
        failures += shutdown_failures(monitor)
    done = sum(w.actions_done for w in walkers)
    print()
    print(kinds_table(walkers))
    print()
    print(format_failures(failures))
    by_kind = Counter(f.kind for f in failures)
    print("\nfailures by kind: " + (", ".join(f"{k} {n}" for k, n in by_kind.most_common()) or "none"))
    if args.save:
        Path(args.save).write_text(json.dumps([{"seed": w.seed, "actions": w.specs} for w in walkers]))
    if args.json:
        counts = Counter()
        for w in walkers:
            counts.update(w.counts)
        Path(args.json).write_text(json.dumps({"failures": [f.to_json() for f in failures], "actions": dict(counts),
                                               "seconds": seconds}, indent=1, default=str))
    print(f"sessions={len(walkers)} actions={done} failures={len(failures)} actions_per_s={done / seconds:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
