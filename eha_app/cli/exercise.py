"""``eha exercise``: the teacher's exercise file, the class's results, one student's actuator."""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path

from eha_core.data import csv_cell
from eha_core.errors import FieldError

from .common import (
    NOISE_GRAMMAR,
    Parser,
    UsageError,
    add_store_option,
    as_option,
    check_input_file,
    check_output_file,
    open_store,
    parse_noise,
    refused,
    refused_file,
    terminal_text,
)


def add_parser(sub) -> None:
    ex = sub.add_parser("exercise", help="a class exercise with a hidden actuator per student (teacher's tools)",
                        description="Make an exercise file (it holds a secret: keep it on the server, never give it "
                                    "to students), print the students' join codes, list the results, reveal a "
                                    "student's actuator. Serve it with: eha serve --exercise FILE")
    cmds = ex.add_subparsers(dest="exercise_command", metavar="ACTION", parser_class=Parser)
    new = cmds.add_parser("new", help="make an exercise file")
    new.add_argument("--hide", default="M,B,Af,beta_e", metavar="NAMES",
                     help="comma-separated parameters to hide, any of the actuator's (default M,B,Af,beta_e)")
    new.add_argument("--roster", metavar="FILE.csv", help="the class: a CSV with columns id and name (more are "
                     "ignored); every student gets a join code of their own. Without it, any id typed is taken "
                     "as given (not checked)")
    new.add_argument("--vary", default="25%", help="how far each student's actuator varies around the paper's "
                     "values (default 25%%; at most 50%%)")
    new.add_argument("--tolerance", default=None, help="the precision asked of an answer: one for all (5%%) or per "
                     "parameter (M=3%%,beta_e=10%%; the others 5%%). Default 5%%, and 10%% for B (friction is the "
                     "parameter a 20 s record determines least: about ±6%% for the grey-box at 3 standard errors). "
                     "With --grading zscore, k standard errors of the student's record must lie within it; with "
                     "relative, the answer itself")
    new.add_argument("--grading", default="zscore", choices=("zscore", "relative"),
                     help="zscore (default): an answer counts within k standard errors of the truth, the standard "
                          "error of the student's own record (a better experiment earns a tighter acceptance), "
                          "when k standard errors are within the tolerance; relative: within the tolerance of the "
                          "truth, whatever the record")
    new.add_argument("--k", default="3", metavar="K", help="with --grading zscore: the standard errors an answer may "
                     "lie from the truth (default 3: an honest answer is refused about 0.3%% of the time; at least 1)")
    new.add_argument("--floor", default="0.5%", metavar="PERCENT", help="with --grading zscore: the narrowest "
                     "acceptance, a percentage of the truth (default 0.5%%)")
    new.add_argument("--deadline", default="", help="ISO-8601 date and time after which hand-ins are refused "
                     "(e.g. 2026-12-01T17:00; no zone: this machine's)")
    new.add_argument("--release-truth-at", default="", metavar="DATE",
                     help="ISO-8601 date and time from which every student sees their own true values on their page, "
                          "as after the dashboard's reveal (hand-ins close then for good); at or after --deadline")
    new.add_argument("--attempts", type=int, default=3, help="hand-ins allowed per student (default 3; 0: no limit)")
    new.add_argument("--feedback", default="verdict", choices=("verdict", "none", "after-deadline"),
                     help="what a student is told after a hand-in: the verdict per parameter (default), nothing "
                          "but that it was stored, or the verdicts once the deadline has passed (needs --deadline)")
    # eha_core.exercise.SCORE_RULES (not imported here: the parser is built for every command)
    new.add_argument("--score", default="last", choices=("last", "mean", "best-penalty", "best"),
                     help="which hand-ins count: last (default), mean, best-penalty (the best, less --attempt-penalty "
                          "for each hand-in before it: three sprayed guesses still beat one below about 85%%) or "
                          "best (the best of several rewards spraying guesses: 3 of B put 58%% of students within 5%%, "
                          "one guess 21%%)")
    new.add_argument("--attempt-penalty", default="25%", metavar="PERCENT",
                     help="with --score best-penalty: the points taken off a hand-in for each one before it "
                          "(default 25%%)")
    new.add_argument("--noise", default="x=0.01mm,v=1mm/s,p=0.05MPa", metavar="SIGNAL=SIGMA[UNIT],...",
                     help=f"the sensors' noise floor (students may raise it, not lower it), {NOISE_GRAMMAR}; "
                          "default x=0.01mm,v=1mm/s,p=0.05MPa")
    new.add_argument("--disturbance", default="none", metavar="SIGNAL",
                     help="a load force always acting, in the app's signal grammar (e.g. white:200, sine:500:3)")
    new.add_argument("--measured", default="x,v,p1,p2", help="the signals measured (x always; e.g. x,p1,p2: no "
                     "velocity sensor)")
    new.add_argument("--variants", default="paper", metavar="NAMES",
                     help="the pool each student's actuator is drawn from, comma-separated: paper (the paper's "
                          "model, default), spool (a valve spool that lags, 2nd order), leakage (internal leakage "
                          "past the piston), stribeck (Stribeck friction); e.g. paper,spool,leakage,stribeck gives "
                          "a quarter of the class each, so one shared script no longer fits everyone's actuator")
    new.add_argument("--methods", default="lse,frequency,greybox", help="the routes a hand-in may come from: lse "
                     "(the least squares), frequency (the back-out's βe), greybox (grey-box identification); "
                     "default all three")
    new.add_argument("--max-record", default="60", metavar="S", help="the longest record, in s (default 60)")
    new.add_argument("--own-files", action="store_true", help="take hand-ins from a file a student uploads "
                     "(labelled so on the dashboard and in the CSV); by default only estimates from the student's "
                     "own actuator's experiment count, since a file can be anyone's")
    new.add_argument("--ids-per-client", default="4", metavar="N", help="without a roster: new ids one network "
                     "address may start per hour (default 4; 0: no limit; this machine's own addresses are not "
                     "limited)")
    new.add_argument("--kept-uploads", default="1000", metavar="MB", help="disk the class's kept uploads may "
                     "take together, in MB (default 1000; each student's at most 20 MB; 0: none is kept)")
    new.add_argument("--title", default="EHA identification exercise", help="shown to the students")
    new.add_argument("--out", required=True, help="the exercise file to write (e.g. class.json)")
    new.add_argument("--force", action="store_true", help="overwrite an existing file (its secret is lost: "
                     "every student's actuator and code changes)")
    new.set_defaults(handler=run_new)
    codes = cmds.add_parser("codes", help="the students' join codes, one line each (hand them out)")
    codes.add_argument("exercise", help="the exercise file")
    add_store_option(codes)
    codes.add_argument("--csv", metavar="FILE", help="also write id, name, code as CSV (for a mail merge)")
    codes.set_defaults(handler=run_codes)
    res = cmds.add_parser("results", help="the class's table: joined, hand-ins, values, errors, verdicts, score")
    res.add_argument("exercise", help="the exercise file")
    add_store_option(res)
    res.add_argument("--csv", metavar="FILE", help="also write the table as CSV")
    res.add_argument("--format", choices=("csv", "moodle", "canvas"), default=None,
                     help="with --out: csv (the table, as --csv writes it), moodle (Moodle's Grades > Import > CSV "
                          "file: First name, Last name, ID number, Email address, 'ITEM (Real)'; map ID number to "
                          "useridnumber: the roster's ids must be the students' ID numbers in Moodle, which takes at "
                          "most 100 points unless the site allows more) or canvas (Canvas's Gradebook import: Student, "
                          "ID, SIS User ID, SIS Login ID, Section, ITEM and a Points Possible row; the roster's id is "
                          "written as SIS User ID, the Canvas ID left empty, so the students' SIS ids must be the "
                          "roster's). The grade is the counted score times --points; no hand-in scores 0")
    res.add_argument("--out", metavar="FILE", help="the file --format writes (UTF-8, no byte-order mark)")
    res.add_argument("--points", default="100", metavar="POINTS",
                     help="what a full score is worth in the gradebook (default 100)")
    res.add_argument("--item", default="", metavar="NAME",
                     help="the grade item's (Moodle) or assignment's (Canvas) name; default the exercise's title")
    res.set_defaults(handler=run_results)
    rev = cmds.add_parser("reveal", help="one student's true actuator (after the deadline)")
    rev.add_argument("exercise", help="the exercise file")
    add_store_option(rev)
    rev.add_argument("--student", required=True, help="the student's id (as in the roster, or as they typed it)")
    rev.set_defaults(handler=run_reveal)
    ext = cmds.add_parser("extend", help="a later deadline for one student (or --clear it)",
                          description="Give one student a deadline of their own, later than the class's: their "
                                      "hand-ins are taken until then, and their page says so. Kept in the class's "
                                      "database (every server of the exercise sees it at once).")
    ext.add_argument("exercise", help="the exercise file")
    add_store_option(ext)
    ext.add_argument("--student", required=True, help="the student's id (as in the roster, or as they typed it)")
    until = ext.add_mutually_exclusive_group(required=True)
    until.add_argument("--until", metavar="DATE", help="their deadline, ISO-8601 (e.g. 2026-12-08T17:00; no zone: "
                       "this machine's): later than the class's, not after --release-truth-at")
    until.add_argument("--clear", action="store_true", help="take their extension away (the class's deadline holds)")
    ext.set_defaults(handler=run_extend)
    tok = cmds.add_parser("token", help="the teacher's dashboard link: print it, or make a new one (--rotate)",
                          description="Print the link of the teacher's dashboard (a new one if it has expired). "
                                      "--rotate makes a new link now: the old one, and every browser logged in "
                                      "with it, stop working within seconds on every server of the exercise. "
                                      "No student's actuator or code changes.")
    tok.add_argument("exercise", help="the exercise file")
    add_store_option(tok)
    tok.add_argument("--rotate", action="store_true", help="make a new link now (the old one stops working)")
    tok.add_argument("--days", default=None, metavar="DAYS",
                     help="how long a new link lasts, in days (default 30; with --rotate or when the link expired)")
    tok.add_argument("--url", default="http://localhost:5006", metavar="URL",
                     help="the server's address as the teacher's browser reaches it (default http://localhost:5006)")
    tok.set_defaults(handler=run_token)
    ex.set_defaults(handler=_missing_action)
    cp = cmds.add_parser("copy-store", help="copy a lab's state (hand-ins, attempts, kept work, switches) from "
                         "one database to another: a lab outgrowing one machine, or a backup")
    cp.add_argument("exercise", help="the exercise file")
    cp.add_argument("--from", dest="source", default=None, metavar="URL",
                    help="the database to copy (default: the SQLite file beside the exercise)")
    cp.add_argument("--to", dest="target", required=True, metavar="URL",
                    help="an empty database: postgresql://USER@HOST:PORT/DATABASE, or sqlite:///PATH (relative to "
                         "here; sqlite:////PATH absolute)")
    cp.set_defaults(handler=run_copy_store)


def _missing_action(args) -> int:
    raise UsageError("exercise needs an ACTION: new, codes, results, reveal, extend, token or copy-store (eha "
                     "exercise --help tells more)")


def _fraction(option: str, text: str) -> float:
    t = str(text).strip()
    try:
        value = float(t[:-1]) / 100 if t.endswith("%") else float(t)
    except ValueError:
        raise refused(option, text, "give a percentage such as 25%", value_text=str(text)) from None
    return value


def _tolerances(text: str):
    """``5%`` (one for all) or ``M=3%,beta_e=10%`` (per parameter)."""
    if "=" not in text:
        return _fraction("--tolerance", text)
    out = {}
    for part in text.split(","):
        name, _, value = part.partition("=")
        if not name.strip() or not value.strip():
            raise refused("--tolerance", text, "give NAME=PERCENT pairs, e.g. M=3%,beta_e=10%")
        out[name.strip()] = _fraction("--tolerance", value)
    return out


def _whole(option: str, text: str) -> int:
    try:
        return int(str(text).strip())
    except ValueError:
        raise refused(option, text, "a whole number, e.g. 4") from None


def _names(option: str, text: str) -> tuple[str, ...]:
    return tuple(n.strip() for n in str(text).split(",") if n.strip())


def load_exercise(option: str, path: str):
    """The exercise file ``path`` given as ``option``; one that cannot be read, or is not an exercise file,
    is refused naming the option and the file."""
    from eha_core.exercise import Exercise

    check_input_file(option, path)
    try:
        return Exercise.load(path)
    except FieldError as exc:
        if exc.field != str(path):
            raise
        raise refused_file(option, path, exc.what) from None


def _load(path: str):
    return load_exercise("exercise", path)


def _check_deadline(args) -> None:
    """A deadline a student can meet, and one for feedback that waits for it."""
    import datetime
    import time

    from eha_core.exercise import parse_deadline

    if args.feedback == "after-deadline" and not args.deadline:
        raise refused("--feedback", args.feedback, "the verdicts wait for the deadline, and there is none: the "
                      "students would never see them; give --deadline, or use verdict or none",
                      context="without --deadline")
    if args.deadline:
        # (a deadline without a zone is this machine's time, as the exercise reads it)
        if datetime.datetime.fromisoformat(parse_deadline(args.deadline, name="--deadline")).timestamp() <= time.time():
            raise refused("--deadline", args.deadline, "it has passed: every hand-in would be refused; give a "
                                                       "later date and time")
    if args.release_truth_at:
        when = parse_deadline(args.release_truth_at, name="--release-truth-at")
        if datetime.datetime.fromisoformat(when).timestamp() <= time.time():
            raise refused("--release-truth-at", args.release_truth_at, "it has passed: every student would see "
                          "their true values at once and no hand-in would be taken; give a later date and time")


def _roster(path: str):
    """The class list of ``--roster``; a file that is not a CSV text, or has no students, is refused
    naming the file."""
    from eha_core.exercise import read_roster

    check_input_file("--roster", path)
    data = Path(path).read_bytes()
    if b"\0" in data:
        # a spreadsheet's own format, a picture: no text file holds a NUL byte
        raise refused_file("--roster", path, "not a CSV text file; save the class list as CSV UTF-8")
    try:
        # a CSV a spreadsheet saved in its local code page is still read (an accented letter shows as �)
        return read_roster(data.decode("utf-8-sig", errors="replace"), name="--roster")
    except FieldError as exc:
        raise refused_file("--roster", path, exc.what) from None


def run_new(args) -> int:
    from eha_core.exercise import Conditions, Exercise, parse_deadline

    hide = _names("--hide", args.hide)
    vary = _fraction("--vary", args.vary)
    if args.tolerance is None:
        tolerance = {"B": 0.10} if "B" in hide else 0.05
    else:
        tolerance = _tolerances(args.tolerance)
    try:
        k = float(args.k)
    except ValueError:
        raise refused("--k", args.k, "a number of standard errors in [1, 10], e.g. 3") from None
    floor = _fraction("--floor", args.floor)
    penalty = _fraction("--attempt-penalty", args.attempt_penalty)
    if not 0 <= penalty <= 1:
        raise refused("--attempt-penalty", args.attempt_penalty, "use a percentage in [0 %, 100 %]",
                      value_text=str(args.attempt_penalty))
    _check_deadline(args)
    check_output_file("--out", args.out)
    if Path(args.out).exists() and not args.force:
        raise refused_file("--out", args.out, "it exists (its secret defines every student's actuator and code); "
                                              "choose another name or add --force")
    roster = None
    options = {"hide": "--hide", "vary": "--vary", "tolerance": "--tolerance", "noise": "--noise",
               "measured": "--measured", "methods": "--methods", "max record": "--max-record",
               "variants": "--variants",
               "deadline": "--deadline", "attempts": "--attempts", "roster": "--roster",
               "ids per client": "--ids-per-client", "kept uploads": "--kept-uploads",
               "attempt penalty": "--attempt-penalty", "release truth at": "--release-truth-at", "k": "--k",
               "floor": "--floor", "grading": "--grading"}
    try:
        if args.roster:
            roster = _roster(args.roster)
        try:
            max_record = float(args.max_record)
        except ValueError:
            raise refused("--max-record", args.max_record, "a number of seconds, e.g. 60") from None
        from eha_core.signals import SignalSpecError, parse_signal

        try:
            parse_signal(args.disturbance, name="--disturbance", hold_s=1e-3)
        except SignalSpecError as exc:
            raise refused("--disturbance", args.disturbance, exc.what) from None
        ids_per_client = _whole("--ids-per-client", args.ids_per_client)
        kept_uploads = _whole("--kept-uploads", args.kept_uploads)
        conditions = Conditions(noise=parse_noise(args.noise), disturbance=args.disturbance,
                                measured=_names("--measured", args.measured),
                                methods=_names("--methods", args.methods), max_record_s=max_record)
        ex = Exercise.new(hide=hide, vary=vary, tolerance=tolerance, title=args.title, roster=roster,
                          conditions=conditions, deadline=parse_deadline(args.deadline) if args.deadline else "",
                          release_at=args.release_truth_at,
                          attempts=args.attempts, feedback=args.feedback, score_rule=args.score,
                          attempt_penalty=penalty, grading=args.grading, k=k, floor=floor,
                          variants=tuple(v.strip() for v in args.variants.split(",") if v.strip()),
                          own_files=args.own_files, ids_per_client=ids_per_client, kept_uploads_mb=kept_uploads)
    except FieldError as exc:
        raise as_option(exc, options) from None
    ex.save(args.out)
    tol = ", ".join(f"{n} ±{100 * ex.tolerance_of(n):g} %" for n in ex.hide)
    counts = (f"an answer counts within {tol}" if ex.grading == "relative" else
              f"an answer counts within {ex.k:g} standard errors of the student's record from the truth (at least "
              f"{100 * ex.floor:g} %), when {ex.k:g} standard errors are within {tol}")
    print(f"wrote {args.out}: hides {', '.join(ex.hide)}, each student's values vary by up to ±{100 * ex.vary:g} %; "
          f"{counts}. Keep this file on the server.")
    print(f"conditions: {ex.conditions.describe()}")
    if ex.variants != ("paper",):
        print(f"actuators: drawn from {', '.join(ex.variants)} (each student one; eha exercise reveal says whose is "
              "which)")
    print(f"hand-ins: {ex.attempts or 'no limit on the number of'} per student"
          + (f", until {ex.deadline}" if ex.deadline else ", no deadline")
          + (f"; every student sees their true values from {ex.release_at}" if ex.release_at else "")
          + f"; feedback: {ex.feedback}; score: {ex.score_text()}")
    print("hand-ins from an uploaded file: " + ("taken, and labelled so" if ex.own_files else
                                                "refused (only the student's own actuator's experiment counts; "
                                                "--own-files takes them)")
          + f"; kept uploads: up to {ex.kept_uploads_mb} MB for the class")
    if ex.has_roster:
        print(f"roster: {len(ex.roster)} students; print their join codes with:  eha exercise codes {args.out}")
    else:
        print("no roster: students type any id and it is taken as given (ids are not checked; anyone can type "
              "anyone's). Add --roster FILE.csv to give each student a join code"
              + (f"; one address may start {ex.ids_per_client} new ids an hour" if ex.ids_per_client else ""))
    print(f"serve it with:  eha serve --exercise {args.out} --address 0.0.0.0")
    return 0


def run_codes(args) -> int:
    ex = _load(args.exercise)
    if not ex.has_roster:
        raise refused_file("exercise", args.exercise, "it has no roster (make it with --roster FILE.csv): students "
                                                      "type their own id")
    if args.csv:
        check_output_file("--csv", args.csv)
    rows = [(e.id, e.name, ex.join_code(e.id)) for e in ex.roster]
    width = max(len(terminal_text(r[1])) for r in rows)
    for sid, name, code in rows:
        print(f"{code}  {terminal_text(name).ljust(width)}  {terminal_text(sid)}")
    if args.csv:
        buf = io.StringIO()
        csv.writer(buf).writerows([["id", "name", "code"], *[[csv_cell(c) for c in r] for r in rows]])
        _write_private(args.csv, buf.getvalue())
        print(f"wrote {args.csv}", file=sys.stderr)
    return 0


def _write_private(path: str, text: str) -> None:
    """Write a file readable by its owner only, from its first byte (every student's errors against the
    truth, or every student's join code)."""
    import os

    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.fchmod(fd, 0o600)                    # an existing file keeps its mode through O_CREAT
    with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
        f.write(text)


def _gradebook_file(args, ex, rows) -> str:
    """The text ``--format`` writes to ``--out``: the table as CSV, or a gradebook's import file."""
    from eha_app.runtime.classbook import results_csv
    from eha_app.runtime.gradebook import canvas_csv, moodle_csv

    if args.format == "moodle":
        return moodle_csv(ex, rows, points=args.points_value, item=args.item)
    if args.format == "canvas":
        return canvas_csv(ex, rows, points=args.points_value, item=args.item)
    return results_csv(ex, rows)


def _check_gradebook(args, ex) -> None:
    """--format, --out, --points and --item, checked before the database is read."""
    from eha_app.runtime.gradebook import check_item, check_points

    if args.format is not None and not args.out:
        raise refused("--format", args.format, "give --out FILE: the file to write it to")
    if args.out:
        args.format = args.format or "csv"
        check_output_file("--out", args.out)
    try:
        args.points_value = check_points(args.points, name="--points")
        if args.format in ("moodle", "canvas"):
            check_item(args.item or ex.title, args.format, name="--item")
    except FieldError as exc:
        raise UsageError(exc) from None


def run_results(args) -> int:
    from eha_app.runtime.classbook import class_rows, results_cells, results_csv, results_header

    ex = _load(args.exercise)
    if args.csv:
        check_output_file("--csv", args.csv)
    _check_gradebook(args, ex)
    rows = class_rows(ex, open_store(args.exercise, args.store))
    header = results_header(ex)
    # what students typed reaches the teacher's terminal and spreadsheet: neither may act on it
    shown = [[terminal_text(c) for c in results_cells(ex, row)] for row in rows]
    widths = [max(len(c) for c in col) for col in zip(header, *shown, strict=False)]
    handed = sum(1 for r in rows if r.count)
    print(f"{terminal_text(ex.title)}: {handed} student{'s' if handed != 1 else ''} handed in"
          + (f" of {len(ex.roster)} in the roster" if ex.has_roster else ""))
    for line in (header, *shown):
        print("  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip())
    if args.csv:
        _write_private(args.csv, results_csv(ex, rows))
        print(f"wrote {args.csv}", file=sys.stderr)
    if args.out:
        # every student's grade: the teacher's, like the table
        _write_private(args.out, _gradebook_file(args, ex, rows))
        what = {"csv": "the table as CSV", "moodle": "Moodle's grade import (Grades > Import > CSV file; map ID "
                "number to useridnumber)", "canvas": "Canvas's gradebook import (matched by SIS User ID)"}
        print(f"wrote {args.out}: {what[args.format]}", file=sys.stderr)
        if args.format == "moodle" and args.points_value > 100:
            print(f"note: Moodle refuses a grade above 100 (here up to {args.points_value:g}) unless the site allows "
                  "more (Site administration > Grades > General settings: unlimitedgrades, gradepointmax)",
                  file=sys.stderr)
    return 0


def run_extend(args) -> int:
    from eha_app.runtime.extensions import STUDENT_FIELD, UNTIL_FIELD, check_extension
    from eha_app.runtime.handins import StoreError

    ex = _load(args.exercise)
    store = open_store(args.exercise, args.store)
    options = {STUDENT_FIELD: "--student", UNTIL_FIELD: "--until"}
    try:
        class_deadline = store.control().get("deadline", "")
        student, until = check_extension(ex, args.student, "" if args.clear else args.until,
                                         class_deadline=class_deadline)
        if not args.clear and not until:
            raise refused("--until", args.until, "give an ISO-8601 date and time, e.g. 2026-12-08T17:00 (--clear "
                                                 "takes an extension away)")
        store.set_extension(student, until)
    except FieldError as exc:
        raise as_option(exc, options) from None
    except StoreError as exc:
        raise refused_file("exercise", args.exercise, f"{exc}") from None
    entry = ex.entry(student)
    who = terminal_text(f"{entry.name} ({student})" if entry else student)
    base = class_deadline or ex.deadline or "none"
    if until:
        print(f"{who} may hand in until {until} (the class's deadline: {base})")
    else:
        print(f"{who} has no extension now: the class's deadline holds ({base})")
    return 0


def run_token(args) -> int:
    import math

    from eha_app.runtime.teacher_access import TOKEN_DAYS, ensure_token, issue

    ex = _load(args.exercise)
    days = TOKEN_DAYS
    if args.days is not None:
        try:
            days = float(args.days)
        except ValueError:
            days = math.nan
        if not (math.isfinite(days) and 0 < days <= 3650):
            raise refused("--days", args.days, "a number of days in (0, 3650]")
    url = str(args.url).strip().rstrip("/")
    if not url.startswith(("http://", "https://")) or any(c.isspace() for c in url):
        raise refused("--url", args.url, "an address such as http://192.168.1.20:5006 (http:// or https://)")
    store = open_store(args.exercise, args.store)
    from eha_app.runtime.handins import StoreError

    try:
        if args.rotate:
            token, made = issue(ex, store, days), True
        else:
            token, made = ensure_token(ex, store, days)
    except StoreError as exc:
        raise refused_file("exercise", args.exercise, f"{exc}") from None
    what = "new link (the old one no longer works)" if args.rotate else "new link" if made else "current link"
    print(f"Teacher's dashboard, {what}, valid until {token.expires_text()} (for you only, do not show it to the "
          f"class):")
    print(f"{url}/teacher?token={token.token}")
    return 0


def run_reveal(args) -> int:
    from eha_core.exercise import normalize_id
    from eha_core.params import FIELD_INFO

    ex = _load(args.exercise)
    try:
        student = normalize_id(args.student)
    except FieldError as exc:
        raise as_option(exc, {"student id": "--student"}) from None
    if ex.has_roster:
        if ex.entry(student) is None:
            raise refused("--student", args.student, "no student with this id in the exercise's roster")
    elif student not in (store := open_store(args.exercise, args.store)).presence() and not store.of(student):
        raise refused("--student", args.student, "no student with this id has joined the exercise (ids are those "
                                                 "typed on the exercise's first page)")
    p = ex.student_params(student)
    entry = ex.entry(student)
    who = f"{entry.name} ({student})" if entry else student
    print(f"{terminal_text(who)}'s actuator in {terminal_text(repr(ex.title))}:")
    for n in ex.hide:
        info = FIELD_INFO[n]
        print(f"  {n} = {getattr(p, n):.6g} {info.unit}  ({info.description})")
    if ex.variants != ("paper",):
        from eha_core.variants import VARIANTS

        name = ex.variant_of(student)
        print(f"  variant: {name} ({VARIANTS[name].description})")
    return 0


def run_copy_store(args) -> int:
    """Copy the lab's state into an empty database (the teacher's move to PostgreSQL, or a backup)."""
    from eha_app.runtime.store_backend import StoreError, copy_lab, shown_url

    load_exercise("exercise", args.exercise)
    source = open_store(args.exercise, args.source, "--from")
    target = open_store(args.exercise, args.target, "--to")
    try:
        counts = copy_lab(source.backend, target.backend)
    except StoreError as exc:
        raise UsageError(f"--to: {exc}") from None
    rows = ", ".join(f"{n} {table}" for table, n in counts.items() if n)
    print(f"Copied {source.shown if args.source is None else shown_url(args.source)} to {shown_url(args.target)}: "
          f"{rows or 'nothing (the lab was empty)'}. Serve from it with: eha serve --exercise {args.exercise} "
          f"--store {shown_url(args.target)}", flush=True)
    return 0
