"""``eha reproduce``: every figure and table of the paper in one report."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from .common import refused, refused_file, require_app


def add_parser(sub) -> None:
    rp = sub.add_parser("reproduce", help="regenerate every figure and table of the paper in one report",
                        description="Write OUT/report.html (self-contained: opens offline, plots interactive) and "
                                    "the data behind it in OUT/data/ (CSV, and results.json with every number).")
    rp.add_argument("--out", default="eha-report", help="output folder (default ./eha-report)")
    rp.add_argument("--seed", type=int, default=0, help="seed of every random signal (default 0)")
    rp.set_defaults(handler=run)


def run(args) -> int:
    t0 = time.perf_counter()          # the wall time includes the imports below
    require_app("eha reproduce (its report is the web app's page)")
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

    stream = _LineKeeper(sys.stderr)
    try:
        result = build_report(out, seed=args.seed, started=t0, stream=stream)
    except KeyboardInterrupt:
        # Ctrl-C during a step ("[3/8] least squares ..."): the line that says so starts a line of its own
        if stream.open:
            stream.write("\n")
        raise
    print(result.path)
    return 0


class _LineKeeper:
    """A stream that knows whether its last line is open (a progress step waiting for its time)."""

    def __init__(self, stream):
        self.stream, self.open = stream, False

    def write(self, text: str) -> int:
        if text:
            self.open = not text.endswith("\n")
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()
