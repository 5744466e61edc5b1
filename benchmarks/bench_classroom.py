"""A class at once: N students clicking each step of the app together, measured.

Serves the app (``eha serve`` on a free port, a fresh server for every class
size; or ``--url`` for a running deployment, e.g. nginx in front of several
processes) and drives N sessions at the protocol level (the Bokeh websocket,
as a browser would, without drawing; see ``classroom_client.py``) through the
workflow of a lab:

  open     open the page (GET, websocket, pull of the document; from the GET's start)
  param    type M = 6000 into tab 1; done when the derived values change
  tab2     show tab 2 (built when first shown; done when its content arrived)
  compare  "Compare both"; done when the status line shows the next "run N"
  tab3     show tab 3
  lse      "Run least squares"; done when the table arrived (an alert "... failed" is an error)
  freqtab  show tab 3's "Frequency domain: transfer function"
  freq     "Run experiment and estimate"; done when the summary shows Ĥ(s) (an alert is an error)
  retype   back to tab 1 and type M again, every tab now built with results; done when the derived
           values change

``--exercise`` runs the graded lab instead: for each class size a fresh exercise
(``eha exercise new --roster``, its defaults: M, B, Af and βe hidden, each
student's actuator their own, the default sensor noise, all three routes, 3
hand-ins) in a temporary folder with its hand-in database, served with ``eha
serve --exercise``. Every session (the observer too) has a roster entry and
joins with its own code. The steps:

  open     open the page, type the join code and press "Start"; done when tab 1's fields arrived
  param    type L0 (the chamber length; M is hidden, not on tab 1), each student a value of their own
  tab2 ... freq   as above
  gbtab    show tab 3's "Grey-box (nonlinear)"
  gb       "Run grey-box estimation" with the page's settings; done when the table arrived. An estimate
           that failed its checks (the red "may be wrong" box) is done, and counted: gb_ok=K/N passed
  board    show "Model board" (built then, with the estimates made before); done when the view it opens
           on, the fit on the validation record, shows every route's model in its table (LS1, H1, GB1
           when the grey-box passed its checks); its other views are computed when their tabs are opened
  handin   "Hand in the grey-box estimates"; when the grey-box failed its checks that button is off and
           the least squares' are handed in instead; done when the verdict shows. handin_ok=K/N: the
           hand-ins stored (the route and the verdicts "k of 4 accepted" are printed under the step)
  retype   back to tab 1, type L0 again

``--churn`` works with it too (a roster of K); ``--url`` does not (the benchmark makes the exercise and
serves it), nor ``--hog`` (an exercise offers no study).

Between steps a barrier: every student finishes (or times out, ``--timeout``,
an error) before the next step; within a step each starts at a random moment
of the first ``--spread`` seconds ("everyone clicks within a second"). One
more session, the observer, opened before the class and not counted, types
into M every 2 s throughout (alternating two values) and records how long
the page takes to answer: what a student feels while the others compute.

Printed per class size (1 student first): per step p50 / p95 / max [s],
successes, errors (the first few messages), the Bokeh messages and kB the
server sent per student, the server's CPU seconds, the observer's delays
during the step; the server's memory (peak VmHWM and RSS, summed over its
processes) and the client's own CPU time. The last line is

    sessions=N errors=E open_p95=… param_p95=… … retype_p95=… slowest=STEP typing_p95_worst_step=…
    peak_mb=… cpu_per_student=… freq_ok=K/N observer_p95=…

(with ``--exercise`` also gbtab_p95, gb_p95, board_p95 and handin_p95 among the steps, and gb_ok=K/N
handin_ok=K/N handin_lse=J before observer_p95: J of the hand-ins came from the least squares)

for the largest N (typing_p95_worst_step: the observer's p95 in the step where it was slowest;
cpu_per_student: the server's CPU seconds over the steps / N; E counts failed or timed-out steps, the server's ERROR
replies, broken connections and failed observer changes).

``--distinct`` gives each student values of M of their own: no two runs alike, nothing the
server can share (it computes a run once for the students with the same inputs). An exercise is
always so (each student's actuator and L0 their own).

``--hog study`` (or ``spam``) runs the largest class twice in the same run, without and then with
one more student who runs a 500-seed study throughout (or presses the study's run and cancel
buttons every 0.3 s), and prints the other students' p50 and p95 per step with / without.
``--hog-repeats K`` makes it K classes of each, alternating, their students pooled, and prints the
spread between the classes without the hog beside (two runs alike differ too: a short step's p95
of 30 students by 1.2-1.7x). The i-th class with the hog and the class without before it click at
the same moments (seed + i); the next pair at others: one coincidence (a pause of the server's
garbage collector landing in a burst of clicks) is not repeated in every class.

``--churn K`` instead opens and closes K sessions, 10 at a time, and prints
the server's memory every 50 sessions and after the server discarded them.

    python benchmarks/bench_classroom.py                        # 1, 10, 30 students
    python benchmarks/bench_classroom.py --sessions 1,10 --procs 2
    python benchmarks/bench_classroom.py --exercise --sessions 1,30
    python benchmarks/bench_classroom.py --exercise --sessions 30 --num-procs 2
    python benchmarks/bench_classroom.py --url http://127.0.0.1:8080/eha --sessions 30 --server-pid 1234
    python benchmarks/bench_classroom.py --sessions 30 --steps open,param,compare --json class.json
    python benchmarks/bench_classroom.py --sessions 30 --hog study --hog-repeats 3
    python benchmarks/bench_classroom.py --churn 200
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# run as a script (python benchmarks/bench_classroom.py) the project's folder is not on the path: put it there
if not __package__:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.classroom_client import (  # noqa: E402 - after the path is set
    EXERCISE_OBSERVER_VALUES,
    EXERCISE_PARAM,
    EXERCISE_STEPS,
    HOGS,
    STEP_NAMES,
    STEPS,
    ClassResult,
    Student,
    do_step,
    exercise_texts,
    run_class,
    wait_served,
)

ROOT = Path(__file__).resolve().parents[1]
_TICK = os.sysconf("SC_CLK_TCK")


# -- the server ------------------------------------------------------------------------------

def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ProcTree:
    """Processes and their descendants (e.g. the workers ``--num-procs`` forks), read from /proc:
    memory and CPU time."""

    def __init__(self, *pids: int):
        self.roots = list(pids)

    def pids(self) -> list[int]:
        out, todo = [], list(self.roots)
        while todo:
            pid = todo.pop()
            if pid in out or not os.path.exists(f"/proc/{pid}"):
                continue
            out.append(pid)
            try:
                for task in os.listdir(f"/proc/{pid}/task"):
                    with open(f"/proc/{pid}/task/{task}/children") as f:
                        todo += [int(c) for c in f.read().split()]
            except OSError:
                pass
        return out

    def memory_mb(self) -> tuple[float, float, int]:
        """(RSS now, peak RSS = VmHWM) summed over the processes, in MB, and how many processes."""
        rss = hwm = 0.0
        n = 0
        for pid in self.pids():
            try:
                with open(f"/proc/{pid}/status") as f:
                    for line in f:
                        if line.startswith("VmRSS:"):
                            rss += int(line.split()[1]) / 1024
                        elif line.startswith("VmHWM:"):
                            hwm += int(line.split()[1]) / 1024
                n += 1
            except OSError:
                pass
        return rss, hwm, n

    def cpu_s(self) -> float:
        """User + system CPU seconds of the processes (and their reaped children)."""
        total = 0
        for pid in self.pids():
            try:
                with open(f"/proc/{pid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                total += sum(int(x) for x in fields[11:15])     # utime stime cutime cstime
            except (OSError, IndexError, ValueError):
                pass
        return total / _TICK


class Server:
    """``eha serve`` in a subprocess on a free port.

    ``eha serve`` already passes ``--unused-session-lifetime 4000
    --check-unused-sessions 1000`` to Panel (eha_app/runtime/serving.py): a closed page's
    session is discarded about 5 s later, which the churn mode relies on.

    ``exercise``: an exercise file to serve (``--exercise``; its hand-in database is made beside it).
    """

    def __init__(self, procs: int = 1, exercise: str | Path | None = None):
        self.port = free_port()
        fd, self.log_path = tempfile.mkstemp(prefix="eha-serve-", suffix=".log")
        self.log = os.fdopen(fd, "w+")
        cmd = eha_command()
        cmd += ["serve", "--port", str(self.port), "--address", "127.0.0.1", "--num-procs", str(procs)]
        if exercise is not None:
            cmd += ["--exercise", str(Path(exercise).resolve())]
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT)
        self.tree = ProcTree(self.proc.pid)
        self.url = f"http://127.0.0.1:{self.port}/eha"
        wait_served(self.proc, self.url, 180, self.log_text, self.stop, poll_s=0.3)
        # every process serving before the class comes (each loads the kernels before it binds the port)
        deadline = time.monotonic() + 180
        while (len(set(re.findall(r"Starting Bokeh server with process id: (\d+)", self.log_text()))) < procs
               and time.monotonic() < deadline and self.proc.poll() is None):
            time.sleep(0.2)

    def log_text(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return Path(self.log_path).read_text(errors="replace")

    def log_problems(self) -> list[str]:
        """The first line of each traceback or error the server logged."""
        lines = self.log_text().splitlines()
        out = []
        for i, ln in enumerate(lines):
            if ln.startswith("Traceback"):
                j = i + 1
                while j < len(lines) and (lines[j].startswith(" ") or not lines[j].strip()):
                    j += 1
                out.append(lines[j] if j < len(lines) else ln)
            elif re.search(r"\b(ERROR|CRITICAL)\b", ln):
                out.append(ln)
        return out

    def stop(self, keep_log: bool = False) -> None:
        """Stop the server and the processes it forked (with --num-procs they outlive their parent);
        remove its log unless ``keep_log``."""
        children = [p for p in self.tree.pids() if p != self.proc.pid]
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        deadline = time.monotonic() + 10
        for pid in children:
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
        for pid in children:
            while os.path.exists(f"/proc/{pid}") and _ppid(pid) == 1 and time.monotonic() < deadline:
                time.sleep(0.1)
            if os.path.exists(f"/proc/{pid}") and _ppid(pid) == 1:
                os.kill(pid, signal.SIGKILL)
        self.log.close()
        if not keep_log:
            Path(self.log_path).unlink(missing_ok=True)


def eha_command() -> list[str]:
    """How to run ``eha`` from this Python (the venv's script, else the module)."""
    eha = Path(sys.executable).with_name("eha")
    return [str(eha)] if eha.exists() else [sys.executable, "-m", "eha_app.cli"]


def make_exercise(folder: Path, n: int, extra: tuple = ("observer",)) -> tuple[Path, dict]:
    """A class exercise in ``folder`` as a teacher makes one: ``eha exercise new --roster`` with its
    defaults, a roster of students s1..sN and the sessions ``extra`` (the observer). Returns the
    file and each session's join code by its name in :func:`run_class` ("student 1", ..., "observer")."""
    folder.mkdir(parents=True, exist_ok=True)
    ids = [(f"s{i + 1}", f"student {i + 1}") for i in range(n)] + [(e, e) for e in extra]
    roster = folder / "roster.csv"
    roster.write_text("id,name\n" + "".join(f"{sid},{name.title()}\n" for sid, name in ids), encoding="utf-8")
    path = folder / "class.json"
    out = subprocess.run([*eha_command(), "exercise", "new", "--roster", str(roster), "--out", str(path)],
                         cwd=ROOT, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"eha exercise new failed ({out.returncode}): {(out.stderr or out.stdout)[-1000:]}")
    from eha_core.exercise import Exercise

    ex = Exercise.load(path)
    return path, {name: ex.join_code(sid) for sid, name in ids}


def _ppid(pid: int) -> int | None:
    """The parent of ``pid`` (None if it is gone): an orphaned fork of ours is re-parented to 1."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return None


# -- figures -----------------------------------------------------------------------------------

def pct(values, q):
    if not values:
        return float("nan")
    v = sorted(values)
    k = (len(v) - 1) * q / 100
    lo, hi = int(k), min(int(k) + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


def fmt(x, width=6, digits=2):
    return f"{'-':>{width}s}" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:{width}.{digits}f}"


def client_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def step_label(step: str, param: str = "M") -> str:
    """The step's name in the table (the parameter typed named as it is)."""
    label = STEP_NAMES.get(step, step)
    return label.replace("change M", f"change {param}") if param != "M" else label


def _counted(values) -> str:
    """"a x3, b" from a list: each value once, with how often it came, the commonest first."""
    counts: dict = {}
    for v in values:
        counts[v] = counts.get(v, 0) + 1
    return ", ".join(f"{k}{f' x{c}' if c > 1 else ''}" for k, c in sorted(counts.items(), key=lambda kv: -kv[1]))


def report_details(r: ClassResult, step: str, out=print) -> dict:
    """What the exercise's steps noted beside their times (the grey-box's checks, the board's models, the
    hand-ins' routes and verdicts), printed under the step's row; returned as counts."""
    done = [o for o in r.steps.get(step, []) if o.seconds is not None]
    if step == "gb":
        failed = [o for o in done if o.detail.get("checks") == "failed"]
        out(f"    checks: {len(done) - len(failed)} passed, {len(failed)} failed (\"may be wrong\")")
        says = [re.sub(r"[-+]?\d[\d.,·e+-]*", "#", o.detail.get("says", ""))[:160] for o in failed]
        for k, line in enumerate(_counted(says).split(", ") if says else []):
            if k == 2:
                out("      ...")
                break
            out(f"      failed: {line}")
        return {"passed": len(done) - len(failed), "failed": len(failed),
                "failed_students": [o.student for o in failed]}
    if step == "board":
        models = [o.detail.get("models", "") for o in done]
        if models:
            out(f"    models on the board (* ticked): {_counted(models)[:300]}")
        return {"models": models}
    if step == "handin":
        routes = [o.detail.get("route", "?") for o in done]
        stored = sum(1 for o in done if o.detail.get("handed_in"))
        within = [o.detail.get("within", "-") for o in done if o.detail.get("handed_in")]
        missed = [name for o in done for name in o.detail.get("missed", [])]
        out(f"    handed in: {stored} of {len(done)} (from the {_counted(routes) or '-'}); "
            f"within tolerance: {_counted(within) or '-'}"
            + (f"; outside it: {_counted(missed)}" if missed else ""))
        for o in done:
            if not o.detail.get("handed_in"):
                out(f"      not handed in, e.g. {o.student}: {o.detail.get('says', '')[:200]}")
                break
        for o in done:
            if o.detail.get("route") == "lse":
                out(f"      the least squares', e.g. {o.student}: the grey-box's button said "
                    f"\"{o.detail.get('refused', '')[:200]}\"")
                break
        return {"handed_in": stored, "lse": routes.count("lse"), "greybox": routes.count("greybox"),
                "within": within, "missed": missed}
    return {}


def report(r: ClassResult, extra: dict, out=print) -> dict:
    n = r.sessions
    param = extra.get("param", "M")
    out(f"\n== {n} student{'s' if n != 1 else ''} ({extra['server']}) ==")
    out(f"{'step':22s} {'p50':>6s} {'p95':>6s} {'max':>6s} {'ok':>7s} {'err':>4s} {'msgs/st':>7s} "
        f"{'kB/st':>7s} {'srvCPU':>6s} {'obs95':>6s} {'wall':>6s}")
    summary = {"sessions": n, "steps": {}}
    obs_all = [o.delay for o in r.observer if o.delay is not None]
    for step, outs in r.steps.items():
        t = r.times(step)
        errs = r.errors(step)
        msgs = [o.messages for o in outs]
        kb = [o.bytes / 1e3 for o in outs]
        obs = [o.delay for o in r.observer if o.step == step and o.delay is not None]
        cpu = extra["server_cpu"].get(step)
        wall = r.step_wall.get(step, (0, 0))
        out(f"{step_label(step, param):22s} {fmt(pct(t, 50))} {fmt(pct(t, 95))} {fmt(max(t) if t else None)} "
            f"{r.ok(step):>3d}/{len(outs):<3d} {len(errs):>4d} {fmt(sum(msgs) / len(msgs) if msgs else None, 7, 1)} "
            f"{fmt(sum(kb) / len(kb) if kb else None, 7, 0)} {fmt(cpu, 6, 1)} {fmt(pct(obs, 95))} "
            f"{fmt(wall[1] - wall[0])}")
        shown = {}
        for e in errs:      # the first few, the same message once with a count
            key = re.sub(r"^student \d+: ", "", e)[:200]
            shown[key] = shown.get(key, 0) + 1
        for k, (msg, count) in enumerate(shown.items()):
            if k == 3:
                out(f"    ... and {len(shown) - 3} other message(s)")
                break
            out(f"    error{f' (x{count})' if count > 1 else ''}: {msg}")
        details = report_details(r, step, out)
        summary["steps"][step] = {"p50": pct(t, 50), "p95": pct(t, 95), "max": max(t) if t else None,
                                  "ok": r.ok(step), "n": len(outs), "errors": errs,
                                  "messages_per_student": sum(msgs) / len(msgs) if msgs else None,
                                  "kB_per_student": sum(kb) / len(kb) if kb else None, "server_cpu_s": cpu,
                                  "details": details}
    obs_err = [o for o in r.observer if o.error]
    if r.observer:
        out(f"{'observer typing ' + param:22s} {fmt(pct(obs_all, 50))} {fmt(pct(obs_all, 95))} "
            f"{fmt(max(obs_all) if obs_all else None)} {len(obs_all):>7d} {len(obs_err):>4d}   "
            f"(every 2 s, all steps)")
    if r.upstreams:
        out("backends (the proxy's X-Eha-Upstream): "
            + ", ".join(f"{k} x{v}" for k, v in sorted(r.upstreams.items())))
    for o in obs_err[:3]:
        out(f"    observer error during {o.step}: {o.error[:200]}")
    for e in r.session_errors[:3]:
        out(f"    session error: {e[:200]}")
    mem = extra.get("memory")
    if mem:
        out(f"server memory: peak (VmHWM) {mem['peak']:.0f} MB, RSS before {mem['before']:.0f} MB, "
            f"at the end {mem['end']:.0f} MB ({mem['procs']} process{'es' if mem['procs'] != 1 else ''})")
    else:
        out("server memory: not measured (--url without --server-pid)")
    if extra.get("log_problems") is not None:
        probs = extra["log_problems"]
        out(f"server log: {len(probs)} traceback(s)/error line(s)"
            + (f", e.g. {probs[0][:200]} (log kept: {extra['log_path']})" if probs else ""))
    out(f"client CPU: {extra['client_cpu']:.1f} s for {n} students + observer over {extra['wall']:.0f} s "
        f"({100 * extra['client_cpu'] / max(extra['wall'], 1e-9):.0f}% of one core)")
    errors = r.error_count()
    cpu = [v for v in extra["server_cpu"].values() if v is not None]
    summary.update(observer_p95_by_step={step: pct([o.delay for o in r.observer if o.step == step
                                                     and o.delay is not None], 95) for step in r.steps},
                   cpu_per_student=sum(cpu) / n if cpu else float("nan"))
    if r.hog_log:
        presses = [h for h in r.hog_log if h.split()[0] in ("run", "cancel")]
        out(f"hog: {len(presses)} press(es) of the study's buttons"
            + (f" ({', '.join(presses[:6])}{', ...' if len(presses) > 6 else ''})" if presses else "")
            + "".join(f"; {h}" for h in r.hog_log if h.startswith("error"))[:300])
    summary.update(errors=errors, observer_p50=pct(obs_all, 50), observer_p95=pct(obs_all, 95),
                   observer_max=max(obs_all) if obs_all else None, memory_mb=mem,
                   client_cpu_s=extra["client_cpu"], wall_s=extra["wall"])
    return summary


def summary_line(s: dict) -> str:
    """The last line: every step's p95, the slowest step, typing on tab 1 in the step where it waited most,
    the server's peak memory and CPU per student."""
    def p95(step):
        return s["steps"].get(step, {}).get("p95", float("nan"))
    freq = s["steps"].get("freq", {})
    steps = [k for k in s["steps"] if k != "param"]
    worst = max(steps, key=lambda k: p95(k) if not math.isnan(p95(k)) else -1) if steps else "-"
    typing = [v for v in s.get("observer_p95_by_step", {}).values() if v is not None and not math.isnan(v)]
    mem = (s.get("memory_mb") or {}).get("peak", float("nan"))
    exercise = ""
    if "gb" in s["steps"]:
        exercise += f"gb_ok={s['steps']['gb']['details'].get('passed', 0)}/{s['sessions']} "
    if "handin" in s["steps"]:
        handin = s["steps"]["handin"]["details"]
        exercise += f"handin_ok={handin.get('handed_in', 0)}/{s['sessions']} handin_lse={handin.get('lse', 0)} "
    return (f"sessions={s['sessions']} errors={s['errors']} "
            + " ".join(f"{k}_p95={p95(k):.2f}" for k in s["steps"])
            + f" slowest={worst} typing_p95_worst_step={max(typing) if typing else float('nan'):.2f} "
            f"peak_mb={mem:.0f} cpu_per_student={s.get('cpu_per_student', float('nan')):.2f} "
            f"freq_ok={freq.get('ok', 0)}/{s['sessions']} {exercise}observer_p95={s['observer_p95']:.2f}")


# -- modes -------------------------------------------------------------------------------------

def _pooled(runs: list, step: str) -> list:
    return [o["seconds"] for d in runs for o in d["raw"]["steps"][step] if o["seconds"] is not None]


def _ratios(a_runs: list, b_runs: list, steps, label_a: str, label_b: str, both_ways: bool = False) -> float:
    """Print p50 and p95 per step of the pooled students of ``b_runs`` against ``a_runs``; the worst
    ratio over the steps after open and param (``both_ways``: a ratio r counts as max(r, 1/r), for two
    groups alike, neither of which is the reference)."""
    worst = 0.0
    for s in steps:
        a, b = _pooled(a_runs, s), _pooled(b_runs, s)
        a50, a95, b50, b95 = pct(a, 50), pct(a, 95), pct(b, 50), pct(b, 95)
        r50 = b50 / a50 if a50 else float("nan")
        r95 = b95 / a95 if a95 else float("nan")
        if s not in ("open", "param"):
            worst = max(worst, r50, r95, *((1 / r50, 1 / r95) if both_ways and r50 and r95 else ()))
        print(f"  {step_label(s):28s} p50 {a50:.3f} -> {b50:.3f} ({r50:.2f}x)   "
              f"p95 {a95:.3f} -> {b95:.3f} ({r95:.2f}x)   [{label_a} -> {label_b}, {len(a)} / {len(b)} students]")
    return worst


def compare_hog(args, steps, largest: dict, largest_data: dict, raw: list) -> None:
    """The class at the largest size with the hog against without it: ``--hog-repeats`` classes of
    each, alternating (without, with, without, ...; the first without is the main run's)."""
    n, k = largest["sessions"], max(1, args.hog_repeats)
    without = [largest_data]
    hogged = []
    for i in range(k):
        # pair i (the class without, then with the hog) clicks at the moments of seed + i: the same
        # within a pair, other moments from pair to pair (one seed throughout repeated one
        # coincidence k times, e.g. a full collection of the server's garbage collector that the
        # hog's own allocations brought into a burst of clicks)
        hogged.append(run_one(n, args, steps, hog=args.hog, seed=args.seed + i)[1])
        raw.append(hogged[-1])
        if i + 1 < k:
            without.append(run_one(n, args, steps, seed=args.seed + i + 1)[1])
            raw.append(without[-1])
        if args.json:
            Path(args.json).write_text(json.dumps(raw, indent=1, default=str))
    print(f"\nwith the {args.hog} hog / without, {n} students, {k} class(es) of each "
          "(target: within 1.15):")
    worst = _ratios(without, hogged, steps, "without", "with")
    null = float("nan")
    if k >= 2:
        half = (k + 1) // 2
        print(f"the classes without the hog among themselves (runs 1-{half} / {half + 1}-{k}): the spread of "
              "two runs alike")
        null = _ratios(without[:half], without[half:], steps, "first", "second", both_ways=True)
    print(f"hog={args.hog} worst_ratio={worst:.2f} null_worst_ratio={null:.2f} repeats={k} "
          "(steps after open and param; null: the classes without among themselves, either way)")


def run_one(n: int, args, steps, hog: str | None = None, seed: int | None = None) -> tuple[dict, dict]:
    folder, path, exercise = None, None, {}
    if getattr(args, "exercise", False):
        # a fresh exercise (roster, secret, hand-in database) for every class: nothing of one class in the next
        folder = Path(tempfile.mkdtemp(prefix="eha-bench-exercise-"))
        path, codes = make_exercise(folder, n, ("observer",))
        exercise = {"codes": codes, "param": EXERCISE_PARAM, "texts": exercise_texts,
                    "observer_values": EXERCISE_OBSERVER_VALUES}
    try:
        server = None if args.url else Server(args.procs, exercise=path)
    except BaseException:
        if folder:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    tree = server.tree if server else _tree_of(args.server_pid)
    problems = None
    try:
        url = args.url or server.url
        before = tree.memory_mb()[0] if tree else None
        cpu_marks: dict = {}
        server_cpu: dict = {}

        def on_step(step, when):
            if tree is None:
                return
            if when == "start":
                cpu_marks[step] = tree.cpu_s()
            else:
                server_cpu[step] = tree.cpu_s() - cpu_marks[step]

        c0, w0 = client_cpu(), time.perf_counter()
        result = asyncio.run(run_class(url, n, steps, spread=args.spread, timeout=args.timeout,
                                       observer=not args.no_observer, seed=args.seed if seed is None else seed,
                                       on_step=on_step,
                                       observer_period=args.observer_period, distinct=args.distinct, hog=hog,
                                       **exercise))
        c1, w1 = client_cpu(), time.perf_counter()
        memory = None
        if tree:
            rss, hwm, nproc = tree.memory_mb()
            memory = {"before": before, "peak": hwm, "end": rss, "procs": nproc}
        problems = server.log_problems() if server else None
    finally:
        if server:
            server.stop(keep_log=bool(problems))
        if folder:
            shutil.rmtree(folder, ignore_errors=True)
    label = args.url or f"eha serve --num-procs {args.procs}"
    if folder:
        label += f" --exercise (a roster of {n} + the observer, each their own code, actuator and {EXERCISE_PARAM})"
    else:
        label += ", each student their own M" if args.distinct else ""
    label += f", with a {hog} hog" if hog else ""
    extra = {"server": label, "server_cpu": server_cpu, "param": exercise.get("param", "M"),
             "memory": memory, "log_problems": problems, "client_cpu": c1 - c0, "wall": w1 - w0,
             "log_path": server.log_path if server else None}
    summary = report(result, extra)
    return summary, {"summary": summary, "raw": result.to_json(), "server_cpu_s": server_cpu,
                     "log_problems": problems}


async def churn(url: str, tree: ProcTree | None, k: int, steps, timeout: float, codes: dict | None = None) -> list:
    """Open and close ``k`` sessions, 10 at a time; the server's RSS as it goes. ``codes``: an exercise's
    join codes by name ("student 1", ...: one each, since a code opened again closes its first page)."""
    def rss():
        return tree.memory_mb()[0] if tree else float("nan")
    rows = []
    print(f"\n== {k} sessions opened ({', '.join(steps)}) and closed, 10 at a time ==")
    print(f"server RSS at the start: {rss():.1f} MB")
    errors = 0
    done = 0
    t0 = time.perf_counter()
    while done < k:
        batch = [Student(url, name=f"s{done + i + 1}", timeout=timeout,
                         **({"code": codes[f"student {done + i + 1}"], "param_name": EXERCISE_PARAM} if codes else {}))
                 for i in range(min(10, k - done))]
        for i, st in enumerate(batch):
            if codes:
                st.param_text, st.retype_text = exercise_texts(done + i)
        for step in steps:
            outs = await asyncio.gather(*(do_step(s, step, timeout) for s in batch), return_exceptions=True)
            errors += sum(isinstance(o, BaseException) for o in outs)
        await asyncio.gather(*(s.close() for s in batch))
        done += len(batch)
        if done % 50 == 0 or done == k:
            rows.append((done, rss()))
            print(f"after {done:4d} sessions: RSS {rows[-1][1]:7.1f} MB   ({time.perf_counter() - t0:.0f} s, "
                  f"{errors} error(s))")
    # eha serve discards a closed page's session 4 s after its websocket closed, checking every 1 s
    for wait in (8, 15):
        await asyncio.sleep(wait)
        rows.append((f"+{wait}s", rss()))
        print(f"{wait:2d} s after the last close (sessions discarded): RSS {rows[-1][1]:7.1f} MB")
    first = next((m for d, m in rows if d == 50), rows[0][1])
    last = rows[-1][1]
    print(f"growth from 50 sessions to the end: {last - first:+.1f} MB "
          f"({(last - first) / max(k - 50, 1) * 100:+.2f} MB per 100 sessions); errors {errors}")
    return rows


def _tree_of(server_pid: str | None) -> ProcTree | None:
    return ProcTree(*(int(p) for p in server_pid.split(",") if p.strip())) if server_pid else None


def _sizes_and_steps(args) -> tuple[list[int], list[str]]:
    """The class sizes and steps asked for; ValueError with the message of a bad option."""
    try:
        sizes = [int(x) for x in args.sessions.split(",") if x.strip()]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1:
        raise ValueError(f"--sessions = {args.sessions} is not allowed: use e.g. 1,10,30")
    exercise = getattr(args, "exercise", False)
    # the grey-box, the board and their tab need no exercise; a hand-in does
    allowed = EXERCISE_STEPS if exercise else (*STEPS, *(s for s in EXERCISE_STEPS if s not in STEPS + ("handin",)))
    steps = [s.strip() for s in (args.steps or ",".join(EXERCISE_STEPS if exercise else STEPS)).split(",")
             if s.strip()]
    if not steps or any(s not in allowed for s in steps) or steps[0] != "open":
        raise ValueError(f"--steps = {args.steps} is not allowed: start with open, then any of "
                         f"{','.join(s for s in allowed if s != 'open')}"
                         + ("" if exercise else " (handin: with --exercise)"))
    if exercise and getattr(args, "hog", None):
        raise ValueError(f"--hog = {args.hog} is not allowed with --exercise: an exercise offers no study (its "
                         "estimates would be drawn against the true values)")
    if exercise and args.url:
        raise ValueError(f"--url = {args.url} is not allowed with --exercise: it serves a fresh exercise of its own "
                         "for every class size")
    if args.server_pid and not args.url:
        raise ValueError(f"--server-pid = {args.server_pid} is not allowed: it is only for --url")
    if args.server_pid and not re.fullmatch(r"\d+(,\d+)*", args.server_pid.replace(" ", "")):
        raise ValueError(f"--server-pid = {args.server_pid} is not allowed: use e.g. 1234 or 1234,1240")
    return sizes, steps


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sessions", default="1,10,30", help="class sizes, run in this order (default 1,10,30; "
                    "1 is added first if missing)")
    ap.add_argument("--url", help="a running server's app URL, e.g. http://host/eha (default: start "
                    "eha serve, fresh for each size)")
    ap.add_argument("--server-pid", help="with --url: the server's pid(s), comma-separated (e.g. each backend "
                    "behind nginx), for memory and CPU; their children are counted too")
    ap.add_argument("--procs", "--num-procs", dest="procs", type=int, default=1, help="--num-procs for eha serve "
                    "(default 1)")
    ap.add_argument("--exercise", action="store_true", help="the graded lab: a fresh exercise per class size (eha "
                    "exercise new's defaults, a roster of the students and the observer), served with eha serve "
                    f"--exercise; each session joins with its own code; steps {','.join(EXERCISE_STEPS)}")
    ap.add_argument("--spread", type=float, default=1.0, help="students start a step within this many "
                    "seconds (default 1)")
    ap.add_argument("--timeout", type=float, default=180.0, help="a step not done after this is an error "
                    "[s] (default 180)")
    ap.add_argument("--steps", default=None, help=f"subset of {','.join(STEPS)} (starting with "
                    "open; a run step shows its tab itself); also gbtab,gb,board, and with --exercise handin "
                    "(default there: all of those)")
    ap.add_argument("--no-observer", action="store_true", help="no observer session")
    ap.add_argument("--seed", type=int, default=0, help="of the random start offsets")
    ap.add_argument("--json", help="write every raw timing to this file")
    ap.add_argument("--distinct", action="store_true", help="each student types values of M of their own: no two "
                    "runs alike, nothing the server can share between students")
    ap.add_argument("--hog", choices=HOGS, help="at the largest size, run the class twice in this run: without, "
                    "then with one more student who runs a 500-seed study (study) or presses the study's buttons "
                    "every 0.3 s (spam); prints the others' p50 and p95 with / without")
    ap.add_argument("--hog-repeats", type=int, default=1, metavar="K", help="with --hog: K classes without "
                    "and K with the hog, alternating, their students pooled (30K per step): a short step's p95 "
                    "from 30 students moves 1.2-1.7x between two runs alike; K >= 2 also prints that spread "
                    "between the classes without (default 1)")
    ap.add_argument("--observer-period", type=float, default=2.0, help="the observer types every this many "
                    "seconds (default 2)")
    ap.add_argument("--churn", type=int, default=0, metavar="K", help="instead: open and close K sessions, "
                    "10 at a time (steps: --steps, default open,param,tab2)")
    args = ap.parse_args(argv)
    try:
        sizes, steps = _sizes_and_steps(args)
    except ValueError as exc:
        print(f"bench_classroom: error: {exc}", file=sys.stderr)
        return 2
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; server: "
          f"{args.url or f'eha serve --num-procs {args.procs}'}{' --exercise' if args.exercise else ''}; "
          f"spread {args.spread:g} s, timeout {args.timeout:g} s")
    if not args.churn:
        print("columns: seconds per student (p50 p95 max); ok/students; errors; Bokeh messages and kB the server "
              "sent each student during the step;\n         the server's CPU seconds; the observer's p95 delay "
              "during the step; the step's duration (spread included)")

    if args.churn:
        churn_steps = steps if args.steps else ["open", "param", "tab2"]
        folder, path, codes = None, None, None
        if args.exercise:
            folder = Path(tempfile.mkdtemp(prefix="eha-bench-exercise-"))
            path, codes = make_exercise(folder, args.churn, ())
        server = None
        try:
            server = None if args.url else Server(args.procs, exercise=path)
            tree = server.tree if server else _tree_of(args.server_pid)
            c0 = client_cpu()
            rows = asyncio.run(churn(args.url or server.url, tree, args.churn, churn_steps, args.timeout, codes))
        finally:
            if server:
                server.stop()
            if folder:
                shutil.rmtree(folder, ignore_errors=True)
        print(f"client CPU: {client_cpu() - c0:.1f} s")
        if args.json:
            Path(args.json).write_text(json.dumps({"churn": rows}, indent=1, default=str))
        return 0

    if 1 not in sizes:
        sizes = [1, *sizes]
    summaries, raw = [], []
    for n in sizes:
        summary, data = run_one(n, args, steps)
        summaries.append(summary)
        raw.append(data)
        if args.json:       # after every size: a crash later keeps what was measured
            Path(args.json).write_text(json.dumps(raw, indent=1, default=str))
    base = summaries[0]
    largest = max(summaries, key=lambda s: s["sessions"])
    if args.hog:
        compare_hog(args, steps, largest, raw[summaries.index(largest)], raw)
    if largest is not base:
        ratios = []
        for s in steps:
            b, last = base["steps"][s]["p95"], largest["steps"][s]["p95"]
            if not math.isnan(b) and not math.isnan(last) and b > 0:
                ratios.append(f"{s} {last / b:.1f}x")
        print(f"\np95 with {largest['sessions']} students / with 1: " + ", ".join(ratios))
    print(summary_line(largest))
    return 0


if __name__ == "__main__":
    sys.exit(main())
