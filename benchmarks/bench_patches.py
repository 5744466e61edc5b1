"""Each library patch of the server (eha_app/runtime/patches.py) with and without it, in one run.

Every patch that only makes the server faster must show its gain here, measured with the patch
turned off (``EHA_PATCHES_OFF=<name>``) against all patches on, in the same run on the same machine.
A patch that fixes behaviour (the component and teacher guards, the shared port, a widget enabled
before it is drawn, the lock check) is justified by the test named in ``PATCHES[name].gain`` instead.

Part 1, in a process of its own per configuration (no server):

  page_build_ms   build one student's page with every tab shown and serialise its document (what a
                  server does for a page), median of 6 pages
  page_kb         memory a page keeps (tracemalloc), mean of 3 pages
  update_ms       a result shown on a page with every tab built: one text changed in a frozen
                  document (the model graph recomputed, or not), median of 40
  graph_ms        a change that adds a model (a new figure, tooltip or pane) on a page with every tab
                  built, in a frozen document: the document's models found again, median of 40
  gc_pause_max_ms building 24 pages kept open (a class): the longest pause of the garbage
                  collector (and gc_full_total_ms, the sum of the full collections' pauses)

Each configuration runs once per round (``--rounds``, default 3), the rounds one after the other;
the median of the rounds is printed.

Part 2, a served class of ``--students`` (``bench_classroom.py --distinct``) per configuration:
every step's p95, the observer's typing p95 and the server's CPU per student; and
``bench_closed_page.py`` for the closed page (``disconnects``). "all off" leaves the two security
guards on (``EHA_PATCHES_OFF`` never turns them off).

The last line gives each figure with every patch on, then with the patch (or group) it justifies
turned off (and, for part 1, their ratio):

    page_build_ms=<on> page_build_ms_model_patches_off=<off> ratio=<off/on> page_kb_... update_ms_...
    gc_pause_max_ms_... open_p95=<on> open_p95_all_off=<off> ... closed_stop_s_disconnects_off=<off>

Run:  python benchmarks/bench_patches.py [--students 10] [--part 1|2|all] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: The patches that only make Bokeh's models cheaper to make and serialise.
MODEL_PATCHES = ("stable_defaults", "fast_themed_values", "settled_settings", "lazy_containers")

IN_PROCESS = r"""
import gc, json, statistics, sys, time, tracemalloc
import panel as pn
from bokeh.document import Document
from bokeh.models import Column, Div
from panel.io.state import set_curdoc
from eha_app.runtime.patches import AFTER_LOAD_PATCHES, SERVER_PATCHES, apply_patches, lazy_freeze
from eha_app.app import create_app, warm_up

apply_patches([n for n in SERVER_PATCHES if n not in ("component_guard", "teacher_routes")])
warm_up()
apply_patches(AFTER_LOAD_PATCHES)
SHOWN = ("simulation", "least_squares", "frequency", "greybox", "board", "study")

def page():
    doc = Document()
    with set_curdoc(doc):
        app = create_app()
        doc.add_root(pn.panel(app).get_root(doc))
        for key in SHOWN:
            app.show(key)
        doc.to_json()
    return doc, app

page(); page()                                  # warm: imports, caches, numba
build = []
for _ in range(6):
    t0 = time.perf_counter(); page(); build.append(time.perf_counter() - t0)

tracemalloc.start()
kept = []
gc.collect(); before = tracemalloc.get_traced_memory()[0]
for _ in range(3):
    kept.append(page())
gc.collect(); page_kb = (tracemalloc.get_traced_memory()[0] - before) / 3 / 1024
tracemalloc.stop()

doc, app = kept[0]
div = Div(text="0")
doc.add_root(div)
update = []
for k in range(40):
    t0 = time.perf_counter()
    with lazy_freeze(doc):
        div.text = str(k + 1)
    update.append(time.perf_counter() - t0)
column = Column()
doc.add_root(column)
graph = []
for k in range(40):
    t0 = time.perf_counter()
    with lazy_freeze(doc):
        column.children = [Div(text=str(k))]
    graph.append(time.perf_counter() - t0)
kept.clear()

pauses, full = [], []
started = {}
def timing(phase, info):
    if phase == "start":
        started["t"] = time.perf_counter()
    elif "t" in started:
        d = time.perf_counter() - started.pop("t")
        pauses.append(d)
        if info.get("generation") == 2:
            full.append(d)
gc.callbacks.insert(0, timing)
klass = [page() for _ in range(24)]
gc.callbacks.remove(timing)
print(json.dumps({"page_build_ms": 1000 * statistics.median(build), "page_kb": page_kb,
                  "update_ms": 1000 * statistics.median(update),
                  "graph_ms": 1000 * statistics.median(graph), "gc_pause_max_ms": 1000 * max(pauses or [0]),
                  "gc_full_total_ms": 1000 * sum(full)}))
"""


def in_process(off: str) -> dict:
    env = {**os.environ, "EHA_PATCHES_OFF": off}
    done = subprocess.run([sys.executable, "-c", IN_PROCESS], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def fields(line: str) -> dict:
    return {k: v for k, v in re.findall(r"(\w+)=(\S+)", line)}


def served(script: str, args: list[str], off: str) -> dict:
    env = {**os.environ, "EHA_PATCHES_OFF": off}
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=3600)
    lines = [ln for ln in done.stdout.strip().splitlines() if "=" in ln]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"{script} {off}: {done.stdout[-2000:]}{done.stderr[-2000:]}")
    return fields(lines[-1])


def part1(rounds: int) -> dict:
    """Every configuration once per round, the rounds one after the other (a machine's drift falls on
    every configuration alike); the median of the rounds."""
    configs = {"all on": "", **{f"{n} off": n for n in (*MODEL_PATCHES, "lazy_freeze", "incremental_graph", "gc_freeze",
                                                     "gc_often")},
               "model patches off": ",".join(MODEL_PATCHES), "gc patches off": "gc_freeze,gc_often"}
    runs: dict[str, list[dict]] = {label: [] for label in configs}
    for _ in range(rounds):
        for label, off in configs.items():
            runs[label].append(in_process(off))
    out = {}
    print(f"{'configuration':28s} {'page_build_ms':>13s} {'page_kb':>8s} {'update_ms':>9s} {'graph_ms':>8s} "
          f"{'gc_pause_max_ms':>15s} "
          f"{'gc_full_total_ms':>16s}   (median of {rounds} rounds)", flush=True)
    for label, results in runs.items():
        r = out[label] = {k: statistics.median(x[k] for x in results) for k in results[0]}
        print(f"{label:28s} {r['page_build_ms']:13.1f} {r['page_kb']:8.0f} {r['update_ms']:9.2f} {r['graph_ms']:8.2f} "
              f"{r['gc_pause_max_ms']:15.1f} {r['gc_full_total_ms']:16.1f}", flush=True)
    return out


CLASS_STEPS = ("open", "param", "tab2", "compare", "tab3", "lse", "freqtab", "freq", "retype")


def part2(students: int) -> dict:
    configs = {"all on": "", "loop_has_work off": "loop_has_work",
               "model patches off": ",".join(MODEL_PATCHES), "all off": "all"}
    out = {}
    keys = [f"{s}_p95" for s in CLASS_STEPS] + ["observer_p95", "cpu_per_student", "peak_mb", "errors"]
    print("\nconfiguration          " + " ".join(f"{k:>15s}" for k in keys), flush=True)
    for label, off in configs.items():
        r = out[label] = served("bench_classroom.py", ["--sessions", str(students), "--distinct"], off)
        print(f"{label:22s} " + " ".join(f"{r.get(k, '-'):>15s}" for k in keys), flush=True)
    for label, off in {"all on": "", "disconnects off": "disconnects"}.items():
        r = out[f"closed page, {label}"] = served("bench_closed_page.py", ["--repeat", "2"], off)
        print(f"closed page, {label:18s} run_s={r.get('run_s')} closed_stop_s={r.get('closed_stop_s')}", flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--students", type=int, default=10)
    ap.add_argument("--part", choices=("1", "2", "all"), default="all")
    ap.add_argument("--rounds", type=int, default=3, help="part 1: rounds over every configuration (default 3)")
    args = ap.parse_args(argv)
    last = []
    if args.part in ("1", "all"):
        p1 = part1(args.rounds)
        on = p1["all on"]
        last.append(f"page_build_ms={on['page_build_ms']:.1f}")
        for key, config in (("page_build_ms", "model patches off"), ("page_kb", "lazy_containers off"),
                            ("update_ms", "lazy_freeze off"), ("graph_ms", "incremental_graph off"),
                            ("gc_pause_max_ms", "gc patches off")):
            off = p1[config][key]
            last.append(f"{key}_{config.replace(' ', '_')}={off:.2f} ratio={off / max(on[key], 1e-9):.2f}")
    if args.part in ("2", "all"):
        p2 = part2(args.students)
        for key, config in (("open_p95", "all off"), ("retype_p95", "all off"), ("cpu_per_student", "all off"),
                            ("open_p95", "model patches off"), ("observer_p95", "loop_has_work off"),
                            ("closed_stop_s", "disconnects off")):
            on = p2["closed page, all on" if key == "closed_stop_s" else "all on"].get(key)
            off = p2[f"closed page, {config}" if key == "closed_stop_s" else config].get(key)
            last.append(f"{key}={on} {key}_{config.replace(' ', '_')}={off}")
    print(" ".join(last))
    return 0


if __name__ == "__main__":
    sys.exit(main())
