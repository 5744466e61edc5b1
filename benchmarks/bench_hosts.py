"""A class on two "hosts": two ``eha serve`` behind nginx, the lab's state in PostgreSQL, measured against one server.

Each host (:class:`benchmarks.hosts.Host`) is a process group of its own (``start_new_session``) in a
working directory of its own (a copy of the exercise file) on a port of its own, running ``eha serve
--exercise class.json --store postgresql://... --behind-proxy --workers 1``; nginx
(:class:`benchmarks.hosts.Nginx`: :func:`eha_app.runtime.serving.nginx_standalone_config`, an affinity
cookie hashed consistently over the hosts) in front, a throwaway PostgreSQL (tests/postgres.py) behind. On
one machine the "hosts" share its cores: this measures what the second server, nginx and PostgreSQL cost and
bring, not a second machine's cores.

N students of a roster (``eha exercise new --roster``: 3 hand-ins each, M, B, Af and βe hidden) join with
their codes through nginx and go through the exercise's steps together, as ``bench_classroom.py --exercise``
drives them (:func:`benchmarks.classroom_client.run_class`, a barrier between steps, each student starting a
step within ``--spread`` s, an observer typing every 2 s):

  open     open the page, type the join code, press "Start"; done when tab 1's fields arrived
  param    type L0, each student a value of their own
  tab3     show tab 3
  lse      "Run least squares"
  freqtab  show the frequency-domain sub-tab
  freq     "Run experiment and estimate"
  handin   hand in (the least squares' estimates: no grey-box was run); done when the verdict shows

The baseline, in the same run and first: the same N students and steps on one ``eha serve --exercise``
(default workers, the default SQLite store beside the exercise file). Printed: each run's table as
bench_classroom prints it (p50 / p95 / max per step, errors, the servers' CPU seconds, the observer), the
hand-ins the database holds against those the pages confirmed, the students per host, then the ratios two
hosts / one server per step, and last

    sessions=N errors=E open_p95=… param_p95=… tab3_p95=… lse_p95=… freqtab_p95=… freq_p95=… handin_p95=… …
    peak_mb=… … hosts=2 stored=K/N worst_p95_ratio=…

for the two hosts (peak_mb: the two servers' peak RSS summed; PostgreSQL and nginx are printed apart).

    python benchmarks/bench_hosts.py                  # 60 students
    python benchmarks/bench_hosts.py --quick          # 10 students: a check that it works
    python benchmarks/bench_hosts.py --students 30 --no-baseline --json hosts.json
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

if not __package__:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_classroom import (  # noqa: E402 - after the path is set
    ProcTree,
    Server,
    client_cpu,
    fmt,
    free_port,
    make_exercise,
    report,
    step_label,
    summary_line,
)
from benchmarks.classroom_client import (  # noqa: E402
    EXERCISE_OBSERVER_VALUES,
    EXERCISE_PARAM,
    run_class,
    wait_served,
)
from benchmarks.hosts import NGINX, Host, Nginx  # noqa: E402

STEPS = ("open", "param", "tab3", "lse", "freqtab", "freq", "handin")


def texts(i: int) -> tuple[str, str]:
    """What student i (from 0) types into L0 [mm]: values of their own (up to 300 students)."""
    return f"{305 + 0.1 * i:.1f}", f"{275 - 0.1 * i:.1f}"


def _confirmed(result) -> int:
    return sum(1 for o in result.steps.get("handin", []) if o.seconds is not None and o.detail.get("handed_in"))


def _class(url: str, n: int, codes: dict, args, trees: list[ProcTree]):
    """The class through ``url``; the servers' CPU seconds per step summed over ``trees``."""
    marks, cpu = {}, {}

    def on_step(step, when):
        now = sum(t.cpu_s() for t in trees)
        if when == "start":
            marks[step] = now
        else:
            cpu[step] = now - marks[step]

    before = sum(t.memory_mb()[0] for t in trees)
    c0, w0 = client_cpu(), time.perf_counter()
    result = asyncio.run(run_class(url, n, STEPS, spread=args.spread, timeout=args.timeout,
                                   observer=not args.no_observer, seed=args.seed, on_step=on_step, codes=codes,
                                   param=EXERCISE_PARAM, texts=texts, observer_values=EXERCISE_OBSERVER_VALUES))
    c1, w1 = client_cpu(), time.perf_counter()
    mems = [t.memory_mb() for t in trees]
    memory = {"before": before, "peak": sum(m[1] for m in mems), "end": sum(m[0] for m in mems),
              "procs": sum(m[2] for m in mems)}
    return result, {"server_cpu": cpu, "memory": memory, "client_cpu": c1 - c0, "wall": w1 - w0}


def one_server(n: int, args) -> tuple[dict, object]:
    """The baseline: one ``eha serve --exercise`` (default workers), SQLite beside the exercise file."""
    folder = Path(tempfile.mkdtemp(prefix="eha-bench-hosts-one-"))
    server = None
    try:
        path, codes = make_exercise(folder, n)
        server = Server(1, exercise=path)
        result, extra = _class(server.url, n, codes, args, [server.tree])
        from eha_app.runtime.handins import HandIns

        stored = len(HandIns(path).all())
        problems = server.log_problems()
    finally:
        if server is not None:
            server.stop(keep_log=False)
        shutil.rmtree(folder, ignore_errors=True)
    extra.update(server="one eha serve --exercise, default workers, SQLite", param=EXERCISE_PARAM,
                 log_problems=problems, log_path=None)
    summary = report(result, extra)
    print(f"hand-ins in the database: {stored}; confirmed on the pages: {_confirmed(result)}")
    summary["stored"] = stored
    return summary, result


def two_hosts(n: int, args) -> tuple[dict, object]:
    """Two hosts behind nginx, PostgreSQL behind them."""
    from tests.postgres import PostgresServer

    folder = Path(tempfile.mkdtemp(prefix="eha-bench-hosts-two-"))
    pg = front = None
    hosts: list[Host] = []
    try:
        pg = PostgresServer().start()
        url = pg.create_database("bench_hosts")
        path, codes = make_exercise(folder / "exercise", n)
        listen = free_port()
        origin = f"127.0.0.1:{listen}"
        # host 2 once host 1 has issued the dashboard's link (two at once on an empty database would each issue one)
        hosts.append(Host(folder / "host1", path, url, origin))
        hosts[0].wait_for_link(timeout=180)
        hosts.append(Host(folder / "host2", path, url, origin))
        for h in hosts:
            h.wait()
        front = Nginx(folder / "nginx", listen, [h.address for h in hosts])
        wait_served(front.proc, front.url, 30)
        pg_tree = ProcTree(pg.pid)
        pg_cpu0 = pg_tree.cpu_s()
        result, extra = _class(front.url, n, codes, args, [h.tree for h in hosts])
        pg_cpu = pg_tree.cpu_s() - pg_cpu0
        pg_mem = pg_tree.memory_mb()
        nginx_mem = front.tree.memory_mb()
        from eha_app.runtime.handins import HandIns

        stored = len(HandIns(path, store=url).all())
        problems = [f"{h.address}: {p}" for h in hosts for p in h.problems()] + front.errors()
    finally:
        if front is not None:
            front.stop()
        for h in hosts:
            h.stop()
        if pg is not None:
            pg.stop()
        shutil.rmtree(folder, ignore_errors=True)
    extra.update(server="2 hosts (eha serve --workers 1 each) behind nginx, PostgreSQL", param=EXERCISE_PARAM,
                 log_problems=problems, log_path=None)
    summary = report(result, extra)
    print(f"hand-ins in the database: {stored}; confirmed on the pages: {_confirmed(result)}")
    print(f"PostgreSQL: {pg_cpu:.2f} CPU-s over the class, RSS {pg_mem[0]:.0f} MB ({pg_mem[2]} processes); "
          f"nginx: RSS {nginx_mem[0]:.0f} MB")
    summary["stored"] = stored
    summary["hosts"] = {h: result.upstreams.get(h, 0) for h in (x.address for x in hosts)}
    return summary, result


def ratios(base: dict, hosts: dict) -> float:
    """Print p50 and p95 per step, two hosts / one server; the worst p95 ratio."""
    worst = 0.0
    print(f"\ntwo hosts / one server, {hosts['sessions']} students:")
    for s in STEPS:
        a, b = base["steps"].get(s, {}), hosts["steps"].get(s, {})
        a50, a95, b50, b95 = (x.get(k, float("nan")) for x in (a, b) for k in ("p50", "p95"))
        r50 = b50 / a50 if a50 else float("nan")
        r95 = b95 / a95 if a95 else float("nan")
        if not math.isnan(r95):
            worst = max(worst, r95)
        print(f"  {step_label(s, EXERCISE_PARAM):28s} p50 {fmt(a50, 5, 3)} -> {fmt(b50, 5, 3)} ({r50:.2f}x)   "
              f"p95 {fmt(a95, 5, 3)} -> {fmt(b95, 5, 3)} ({r95:.2f}x)")
    return worst


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--students", type=int, default=60, help="the class's size (default 60)")
    ap.add_argument("--quick", action="store_true", help="a check that it works: 10 students")
    ap.add_argument("--no-baseline", action="store_true", help="only the two hosts")
    ap.add_argument("--spread", type=float, default=1.0, help="students start a step within this many seconds")
    ap.add_argument("--timeout", type=float, default=300.0, help="a step not done after this is an error [s]")
    ap.add_argument("--no-observer", action="store_true", help="no observer session")
    ap.add_argument("--seed", type=int, default=0, help="of the random start offsets")
    ap.add_argument("--json", help="write both runs' raw timings to this file")
    args = ap.parse_args(argv)
    n = 10 if args.quick else args.students
    if not 1 <= n <= 300:
        print("bench_hosts: error: --students must be 1-300", file=sys.stderr)
        return 2
    if NGINX is None:
        print("bench_hosts: error: nginx not found (apt-get install -y nginx)", file=sys.stderr)
        return 2
    from tests.postgres import find_pg_bin

    if find_pg_bin() is None:
        print("bench_hosts: error: PostgreSQL not found (apt-get install -y postgresql)", file=sys.stderr)
        return 2
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; {n} students, steps {','.join(STEPS)}; "
          f"spread {args.spread:g} s, timeout {args.timeout:g} s")
    print("columns: seconds per student (p50 p95 max); ok/students; errors; Bokeh messages and kB the servers "
          "sent each student during the step;\n         the servers' CPU seconds; the observer's p95 delay during "
          "the step; the step's duration (spread included)")
    raw = {}
    base = None
    if not args.no_baseline:
        base, r = one_server(n, args)
        raw["one_server"] = r.to_json()
    hosts, r = two_hosts(n, args)
    raw["two_hosts"] = r.to_json()
    if args.json:
        Path(args.json).write_text(json.dumps(raw, indent=1, default=str))
    worst = ratios(base, hosts) if base is not None else float("nan")
    if base is not None:
        print("one server: " + summary_line(base) + f" stored={base['stored']}/{n}")
    split = "/".join(str(v) for v in hosts["hosts"].values())
    print(summary_line(hosts) + f" hosts=2 split={split} stored={hosts['stored']}/{n} worst_p95_ratio={worst:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
