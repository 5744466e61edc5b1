"""``eha exercise``: the teacher's exercise file, the class's results, one student's actuator."""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path

from eha_core.errors import FieldError

from .common import (
    Parser,
    as_option,
    check_input_file,
    check_output_file,
    refused,
    refused_file,
    terminal_text,
)


def add_parser(sub) -> None:
    ex = sub.add_parser("exercise", help="a class exercise with a hidden actuator per student (teacher's tools)",
                        description="Make an exercise file (it holds a secret: keep it on the server, never give it "
                                    "to students), list the hand-ins, reveal a student's actuator after the "
                                    "deadline. Serve it with: eha serve --exercise FILE")
    cmds = ex.add_subparsers(dest="exercise_command", metavar="ACTION", parser_class=Parser)
    new = cmds.add_parser("new", help="make an exercise file")
    new.add_argument("--hide", required=True, metavar="NAMES",
                     help="comma-separated parameters to hide, of M, B, Af, beta_e (e.g. M,B,Af,beta_e)")
    new.add_argument("--vary", default="25%", help="how far each student's actuator varies around the paper's "
                     "values (default 25%%; at most 50%%)")
    new.add_argument("--tolerance", default="5%", help="relative error of a correct answer (default 5%%)")
    new.add_argument("--title", default="EHA identification exercise", help="shown to the students")
    new.add_argument("--out", required=True, help="the exercise file to write (e.g. class.json)")
    new.add_argument("--force", action="store_true", help="overwrite an existing file (its secret is lost: "
                     "every student's actuator changes)")
    new.set_defaults(handler=run_new)
    res = cmds.add_parser("results", help="the class's table: id, last hand-in, verdicts, score")
    res.add_argument("exercise", help="the exercise file")
    res.add_argument("--csv", metavar="FILE", help="also write the table as CSV")
    res.set_defaults(handler=run_results)
    rev = cmds.add_parser("reveal", help="one student's true actuator (after the deadline)")
    rev.add_argument("exercise", help="the exercise file")
    rev.add_argument("--student", required=True, help="the student's name or id, as they typed it")
    rev.set_defaults(handler=run_reveal)
    ex.set_defaults(handler=lambda args: (ex.print_help(), 2)[1])


def _fraction(option: str, text: str) -> float:
    t = str(text).strip()
    try:
        value = float(t[:-1]) / 100 if t.endswith("%") else float(t)
    except ValueError:
        raise refused(option, text, "give a percentage such as 25%", value_text=str(text)) from None
    return value


def _load(path: str):
    from eha_core.exercise import Exercise

    check_input_file("exercise", path)
    return Exercise.load(path)


def run_new(args) -> int:
    from eha_core.exercise import Exercise

    hide = tuple(n.strip() for n in args.hide.split(",") if n.strip())
    vary, tolerance = _fraction("--vary", args.vary), _fraction("--tolerance", args.tolerance)
    check_output_file("--out", args.out)
    if Path(args.out).exists() and not args.force:
        raise refused_file("--out", args.out, "it exists (its secret defines every student's actuator); choose "
                                              "another name or add --force")
    try:
        ex = Exercise.new(hide=hide, vary=vary, tolerance=tolerance, title=args.title)
    except FieldError as exc:
        raise as_option(exc, {"hide": "--hide", "vary": "--vary", "tolerance": "--tolerance"}) from None
    ex.save(args.out)
    print(f"wrote {args.out}: hides {', '.join(ex.hide)}, each student's values vary by up to ±{100 * ex.vary:g} %, "
          f"an answer within ±{100 * ex.tolerance:g} % counts. Keep this file on the server.")
    print(f"serve it with:  eha serve --exercise {args.out} --address 0.0.0.0")
    return 0


def _table(ex, handins) -> tuple[list[str], list[list[str]]]:
    header = ["student", "last hand-in", "hand-ins", *[f"{n} ok" for n in ex.hide], "score"]
    rows = [[h.student, h.time, str(h.count), *["yes" if h.verdicts.get(n) else "no" for n in ex.hide],
             f"{h.score:.2f}"] for h in handins]
    return header, rows


def _store(path: str):
    """The exercise's hand-ins, checked: a damaged database is one line and exit code 2."""
    from eha_app.runtime.handins import HandIns, StoreError

    try:
        return HandIns(path).check()
    except StoreError as exc:
        raise refused_file("exercise", path, f"{exc}") from None


def run_results(args) -> int:
    from eha_app.runtime.handins import handins_path
    from eha_core.data import csv_cell

    ex = _load(args.exercise)
    if args.csv:
        check_output_file("--csv", args.csv)
    handins = _store(args.exercise).latest() if handins_path(args.exercise).exists() else []
    header, rows = _table(ex, handins)
    # what students typed reaches the teacher's terminal and spreadsheet: neither may act on it
    shown = [[terminal_text(c) for c in row] for row in rows]
    widths = [max(len(c) for c in col) for col in zip(header, *shown, strict=False)]
    print(f"{terminal_text(ex.title)}: {len(rows)} student{'s' if len(rows) != 1 else ''} handed in")
    for line in (header, *shown):
        print("  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip())
    if args.csv:
        buf = io.StringIO()
        csv.writer(buf).writerows([[csv_cell(c) for c in row] for row in (header, *rows)])
        Path(args.csv).write_text(buf.getvalue(), encoding="utf-8")
        print(f"wrote {args.csv}", file=sys.stderr)
    return 0


def run_reveal(args) -> int:
    from eha_core.exercise import normalize_id
    from eha_core.params import FIELD_INFO

    ex = _load(args.exercise)
    try:
        student = normalize_id(args.student)
    except FieldError as exc:
        raise as_option(exc, {"student id": "--student"}) from None
    p = ex.student_params(student)
    print(f"{terminal_text(student)}'s actuator in {terminal_text(repr(ex.title))}:")
    for n in ex.hide:
        info = FIELD_INFO[n]
        print(f"  {n} = {getattr(p, n):.6g} {info.unit}  ({info.description})")
    return 0
