"""The log's redaction with many students: registering one more, and a log line, against the former expression.

Each student's four hidden values (M, B, Af, beta_e of a real exercise, ~97 printed forms) are
registered with :func:`eha_app.runtime.redaction.SecretRegistry.register_student`, in a registry of
this run's own. At each number of students already registered it measures

  register  registering one more student (median over ``--repeat`` new ids, each released after)
  line      one record of the server's log through :class:`RedactingFilter` (a Tornado access line,
            ~120 characters with five numbers): without a hidden number, and with one of a student's
  memory    tracemalloc's growth per student, and what is left once every student is released (the
            dicts' tables, which Python never shrinks: sized for the largest class, not growing with the
            next one, which the last column shows)

The baseline, measured in the same run, is the former algorithm (copied below from git history):
every form of every student in one set, and one expression of the whole set compiled again at
each registration that adds a form. Its registries of N students are filled at once (one compile),
then one more registration is timed, as the server did it at its N+1st. Its memory counts the one
expression; the server also kept its every former expression in ``re``'s cache of 512.

Run:  python benchmarks/bench_redaction.py [--sizes 1 10 100 500] [--old-sizes 1 10 60 100] [--repeat 20]

Last line: ``register_<N>_ms=… line_<N>_ms=… line_target_ms=0.05 register_growth=<at the largest N /
at 1> register_ratio_<N>=<former / ours> line_ratio_<N>=… kb_per_student=… kb_left_after_release=…
kb_left_after_two_classes=…``.
"""

from __future__ import annotations

import argparse
import logging
import re
import statistics
import time
import tracemalloc

from eha_app.runtime.redaction import HIDDEN, RedactingFilter, SecretRegistry, number_forms
from eha_core.exercise import Exercise

HIDE = ("M", "B", "Af", "beta_e")
LINE = "200 GET /eha/ws?bokeh-session-id=%s&student=s%d (10.0.3.%d) %.2fms, M = %s kg, queue %d/%d"
SESSION_ID = "Xq3p8Lr2mZ0kTbN1"
LINE_TARGET_MS = 0.05


def _records(value: str, n: int) -> list[logging.LogRecord]:
    """``n`` records of the access line, with ``value`` as its M."""
    return [logging.LogRecord("tornado.access", logging.INFO, __file__, 1, LINE,
                              (SESSION_ID, 17, 42, 12.34, value, 3, 40), None) for _ in range(n)]


def _per_line_s(filter_: logging.Filter, value: str, n: int = 2000) -> float:
    """Seconds per record through ``filter_``, best of 5 (the records are made outside the timing)."""
    best = float("inf")
    for _ in range(5):
        records = _records(value, n)
        t0 = time.perf_counter()
        for record in records:
            filter_.filter(record)
        best = min(best, (time.perf_counter() - t0) / n)
    return best


class _OneExpression:
    """The former registry (``git show b8ff5a4:eha_app/runtime/redaction.py``), as its own object:
    one set of every form, one expression of the whole set, compiled again when the set grows."""

    def __init__(self) -> None:
        self.secrets: set[str] = set()
        self.pattern: re.Pattern | None = None

    def _compile(self) -> None:
        # longest first, so that 4500.2913 is hidden whole rather than as [hidden]13
        alternatives = "|".join(re.escape(s) for s in sorted(self.secrets, key=len, reverse=True))
        self.pattern = re.compile(rf"(?<![\w.])(?:{alternatives})(?![\w])")

    def preload(self, values_list) -> None:
        """The state after registering each of ``values_list``: filled at once, compiled once."""
        for values in values_list:
            for v in values:
                self.secrets |= number_forms(v)
        self._compile()

    def keep_out_of_logs(self, *values) -> None:
        new = set()
        for v in values:
            new |= number_forms(float(v))
        if new <= self.secrets:
            return
        self.secrets.update(new)
        self._compile()

    def redact(self, text: str) -> str:
        return self.pattern.sub(HIDDEN, text) if self.pattern is not None and text else text


class _OldFilter(logging.Filter):
    """The former :class:`RedactingFilter`'s message path, on a :class:`_OneExpression`."""

    def __init__(self, old: _OneExpression) -> None:
        super().__init__()
        self.old = old

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg, record.args = self.old.redact(record.getMessage()), None
        return True


def _memory_ours(n: int, students: list[tuple[float, ...]]) -> tuple[float, float, float]:
    """Bytes per student with ``n`` registered, and bytes left once all are released, after one class
    and after a second one of as many other students (the dicts' tables stay sized for the largest)."""
    registry = SecretRegistry()
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    left = []
    for name in ("s", "t"):
        pages = [registry.register_student("lab-3", f"{name}{k}", values) for k, values in enumerate(students[:n])]
        if name == "s":
            held = tracemalloc.get_traced_memory()[0] - before
        for page in pages:
            page.release()
        del pages
        left.append(tracemalloc.get_traced_memory()[0] - before)
    tracemalloc.stop()
    return held / n, left[0], left[1]


def _measure_ours(n: int, students: list[tuple[float, ...]], repeat: int) -> dict:
    per_student_b, left_b, left2_b = _memory_ours(n, students)
    registry = SecretRegistry()
    pages = [registry.register_student("lab-3", f"s{k}", values) for k, values in enumerate(students[:n])]
    times = []
    for r in range(repeat):
        values = students[n + r]
        t0 = time.perf_counter()
        page = registry.register_student("lab-3", f"s{n + r}", values)
        times.append(time.perf_counter() - t0)
        page.release()
    filter_ = RedactingFilter(registry)
    hidden_value = f"{students[n - 1][0]:.6g}"
    check = _records(hidden_value, 1)[0]
    filter_.filter(check)
    if HIDDEN not in check.getMessage():
        raise SystemExit(f"the hidden value was not hidden at {n} students: {check.getMessage()}")
    line_plain = _per_line_s(filter_, "4500.29")
    line_hidden = _per_line_s(filter_, hidden_value)
    for page in pages:
        page.release()
    return {"register": statistics.median(times), "line_plain": line_plain, "line_hidden": line_hidden,
            "per_student_b": per_student_b, "left_b": left_b, "left2_b": left2_b}


def _measure_old(n: int, students: list[tuple[float, ...]], repeat: int) -> dict:
    old = _OneExpression()
    re.purge()
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    old.preload(students[:n])
    re.purge()                                  # the expression itself, not re's cached copy of it
    per_student_b = (tracemalloc.get_traced_memory()[0] - before) / n
    tracemalloc.stop()
    times = []
    for r in range(repeat):
        t0 = time.perf_counter()
        old.keep_out_of_logs(*students[n + r])
        times.append(time.perf_counter() - t0)
    filter_ = _OldFilter(old)
    return {"register": statistics.median(times), "line_plain": _per_line_s(filter_, "4500.29", 200),
            "line_hidden": _per_line_s(filter_, f"{students[n - 1][0]:.6g}", 200), "per_student_b": per_student_b}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 100, 500])
    ap.add_argument("--old-sizes", type=int, nargs="+", default=[1, 10, 60, 100])
    ap.add_argument("--repeat", type=int, default=20, help="new students timed at each size (the former: 3)")
    args = ap.parse_args()
    ex = Exercise.new(hide=HIDE, secret="3e" * 32)
    count = max(args.sizes + args.old_sizes) + args.repeat
    students = [tuple(getattr(ex.student_params(f"s{k}"), n) for n in HIDE) for k in range(count)]
    forms = statistics.mean(len(set().union(*(number_forms(v) for v in s))) for s in students[:50])
    print(f"{len(HIDE)} hidden values a student, {forms:.0f} printed forms; a log line of "
          f"{len(_records('4500.29', 1)[0].getMessage())} characters")

    ours = {}
    print("\nours (a dict of forms, one fixed expression for numbers):")
    print(f"{'students':>8} {'register ms':>12} {'line ms':>8} {'line+hidden ms':>15} {'KB/student':>11} "
          f"{'KB left after release':>22} {'after a 2nd class':>18}")
    for n in args.sizes:
        ours[n] = m = _measure_ours(n, students, args.repeat)
        print(f"{n:8d} {m['register'] * 1e3:12.3f} {m['line_plain'] * 1e3:8.4f} {m['line_hidden'] * 1e3:15.4f} "
              f"{m['per_student_b'] / 1e3:11.1f} {m['left_b'] / 1e3:22.1f} {m['left2_b'] / 1e3:18.1f}")

    old = {}
    print("\nformer (one expression of every form, compiled at each registration):")
    print(f"{'students':>8} {'register ms':>12} {'line ms':>8} {'line+hidden ms':>15} {'KB/student':>11}")
    for n in args.old_sizes:
        old[n] = m = _measure_old(n, students, min(args.repeat, 3))
        print(f"{n:8d} {m['register'] * 1e3:12.3f} {m['line_plain'] * 1e3:8.4f} {m['line_hidden'] * 1e3:15.4f} "
              f"{m['per_student_b'] / 1e3:11.1f}")

    print("\nformer / ours:")
    both = [n for n in args.sizes if n in old]
    for n in both:
        print(f"{n:8d} students: register x{old[n]['register'] / ours[n]['register']:.0f}, "
              f"line x{old[n]['line_plain'] / ours[n]['line_plain']:.1f}, "
              f"line with a hidden number x{old[n]['line_hidden'] / ours[n]['line_hidden']:.1f}, "
              f"memory x{old[n]['per_student_b'] / ours[n]['per_student_b']:.1f}")
    top, low = max(args.sizes), min(args.sizes)
    growth = ours[top]["register"] / ours[low]["register"]
    print(f"ours, registering at {top} students / at {low}: x{growth:.2f}; "
          f"a line at {top}: {max(ours[top]['line_plain'], ours[top]['line_hidden']) * 1e3:.4f} ms "
          f"(target {LINE_TARGET_MS} ms)")
    last = [f"register_{n}_ms={ours[n]['register'] * 1e3:.3f}" for n in args.sizes]
    last += [f"line_{top}_ms={max(ours[top]['line_plain'], ours[top]['line_hidden']) * 1e3:.4f}",
             f"line_target_ms={LINE_TARGET_MS}", f"register_growth={growth:.2f}"]
    last += [f"register_ratio_{n}={old[n]['register'] / ours[n]['register']:.0f}" for n in both]
    last += [f"line_ratio_{n}={old[n]['line_hidden'] / ours[n]['line_hidden']:.1f}" for n in both]
    last += [f"kb_per_student={ours[top]['per_student_b'] / 1e3:.1f}",
             f"kb_left_after_release={ours[top]['left_b'] / 1e3:.1f}",
             f"kb_left_after_two_classes={ours[top]['left2_b'] / 1e3:.1f}"]
    print(" ".join(last))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
