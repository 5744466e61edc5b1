"""``eha reproduce``: every figure and table of the paper in one report."""

from __future__ import annotations

import time
from pathlib import Path

from .common import refused, refused_file


def add_parser(sub) -> None:
    rp = sub.add_parser("reproduce", help="regenerate every figure and table of the paper in one report",
                        description="Write OUT/report.html (self-contained: opens offline, plots interactive) and "
                                    "the data behind it in OUT/data/ (CSV, and results.json with every number).")
    rp.add_argument("--out", default="eha-report", help="output folder (default ./eha-report)")
    rp.add_argument("--seed", type=int, default=0, help="seed of every random signal (default 0)")
    rp.set_defaults(handler=run)


def run(args) -> int:
    t0 = time.perf_counter()          # the wall time includes the imports below
    if args.seed < 0:
        raise refused("--seed", args.seed, "use a whole number >= 0")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise refused_file("--out", args.out, "it exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise refused_file("--out", args.out, f"{exc.strerror}") from None
    from eha_app.render.report import build_report

    result = build_report(out, seed=args.seed, started=t0)
    print(result.path)
    return 0
