"""The class's results as the teacher sees them: one row per student, for the dashboard, the CSV
and ``eha exercise results`` alike (one table, three renderings).

A row holds the roster's id and name (or the id typed, in an open exercise), when the student
joined and was last seen, their hand-ins (count and the last one's time, method, values), the
error of each value against the truth and its verdict, the score by the exercise's rule (best or
last hand-in), where the last hand-in's data came from (their actuator's experiment, or an
uploaded file: its name, its digest, and the classmates who handed in from the same file) and
how many pages the student opened (and how many of those while another was live: a code used
twice). The errors are the teacher's: nothing here goes to a student's page.

>>> import tempfile, pathlib
>>> from eha_core.exercise import Exercise
>>> ex = Exercise.new(hide=("M",), roster=[("s1", "Ada")], secret="11" * 32)
>>> store = HandIns(pathlib.Path(tempfile.mkdtemp()) / "class.json").check()
>>> truth = ex.student_params("s1").M
>>> est = {"M": truth * 1.02}
>>> se = {"M": truth * 0.01}          # the standard error of the student's record: 2 of them off, accepted
>>> _ = store.add("s1", est, ex.verdicts("s1", est, se), errors=ex.errors("s1", est), settings={"std_errors": se})
>>> [(r.id, r.name, r.count, r.score, round(r.errors["M"], 4)) for r in class_rows(ex, store)]
[('s1', 'Ada', 1, 1.0, 0.02)]
>>> round(class_rows(ex, store)[0].zscores["M"], 2)
2.0
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field

from eha_core.data import csv_cell
from eha_core.exercise import METHODS

from .handins import HandIn, HandIns

__all__ = ["describe_conditions", "describe_source", "describe_pages", "handin_errors", "ClassRow", "class_rows",
           "results_header", "results_cells", "results_csv"]


@dataclass(frozen=True)
class ClassRow:
    id: str
    name: str
    joined: str = ""
    last_seen: str = ""
    count: int = 0
    last_time: str = ""
    method: str = ""
    estimates: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)
    verdicts: dict = field(default_factory=dict)
    score: float = 0.0
    conditions: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    source: dict = field(default_factory=dict)
    same_file: tuple[str, ...] = ()     # others who handed in from a file with the same digest
    pages: int = 0
    overlaps: int = 0
    damaged: int = 0                    # hand-ins whose stored values could not be read
    refused: tuple[str, ...] = ()       # the hand-ins the rules refused (too many, late, closed): why, each
    best: float = 0.0                   # the best hand-in's score and the last's (``score``: the rule's)
    last: float = 0.0
    zscores: dict = field(default_factory=dict)     # the last hand-in's (estimate - truth) / standard error
    reasons: dict = field(default_factory=dict)     # ... and why each value counts or not (Judgement.reason)


def class_rows(exercise, store: HandIns) -> list[ClassRow]:
    """Every student of the roster (in its order), then anyone else who joined or handed in."""
    handins: dict[str, list[HandIn]] = {}
    files: dict[str, set[str]] = {}                 # a file's digest -> who handed in from it
    for h in store.all():
        handins.setdefault(h.student, []).append(h)
        if h.source.get("kind") == "file" and h.source.get("sha256"):
            files.setdefault(str(h.source["sha256"]), set()).add(h.student)
    presence = store.presences()
    refused: dict[str, list[str]] = {}
    for _time, sid, _method, why in store.refusals():
        refused.setdefault(sid, []).append(why)
    names = {e.id: e.name for e in exercise.roster}
    ids = list(names) + sorted((set(presence) | set(handins) | set(refused)) - set(names))
    rows = []
    for sid in ids:
        hs = handins.get(sid, [])
        here = presence.get(sid)
        last = hs[-1] if hs else None
        judged = handin_judgements(exercise, sid, last)
        mine = {str(h.source.get("sha256")) for h in hs if h.source.get("kind") == "file"}
        same = sorted(set().union(*(files.get(d, set()) for d in mine)) - {sid}) if mine else []
        rows.append(ClassRow(
            id=sid, name=names.get(sid, ""), joined=here.joined if here else "", last_seen=here.last_seen if here
            else "", count=len(hs), last_time=last.time if last else "", method=last.method if last else "",
            estimates=last.estimates if last else {},
            errors=last.errors if last and last.errors else handin_errors(exercise, sid, last),
            verdicts=last.verdicts if last else {}, score=exercise.score([h.verdicts for h in hs]),
            conditions=last.conditions if last else {}, settings=last.settings if last else {},
            source=last.source if last else {}, same_file=tuple(same), pages=here.pages if here else 0,
            overlaps=here.overlaps if here else 0, damaged=sum(h.damaged for h in hs),
            refused=tuple(refused.get(sid, ())), best=max((h.score for h in hs), default=0.0),
            last=last.score if last else 0.0, zscores={n: j.z for n, j in judged.items()},
            reasons={n: j.reason for n, j in judged.items()}))
    return rows


def handin_judgements(exercise, sid: str, handin: HandIn | None) -> dict:
    """Per parameter of ``handin``: its :class:`~eha_core.exercise.Judgement` by the exercise's grading,
    from the standard errors and the route's model errors kept with it ({} for none)."""
    if handin is None:
        return {}
    try:
        return exercise.judge(sid, handin.estimates, handin.settings.get("std_errors") or {},
                              handin.settings.get("model_errors") or {})
    except (ValueError, TypeError, AttributeError):
        return {}




def describe_source(row) -> str:
    """Where a hand-in's data came from, in a few words (the dashboard's and the CSV's column).

    >>> describe_source(ClassRow("s1", "", count=1, source={"kind": "file", "name": "run.csv", "sha256": "ab12cd"},
    ...                          same_file=("s2",)))
    'uploaded file run.csv (sha256 ab12cd), also handed in by s2'
    >>> describe_source(ClassRow("s1", "", count=1, source={"kind": "simulated"}))
    "own actuator's experiment"
    """
    if not row.count:
        return ""
    src = row.source or {}
    if src.get("kind") != "file":
        text = "own actuator's experiment"
    else:
        text = f"uploaded file {src.get('name', '?')} (sha256 {src.get('sha256', '?')})"
        if row.same_file:
            text += f", also handed in by {', '.join(row.same_file)}"
    if row.damaged:
        text += f"; {row.damaged} stored hand-in{'s' if row.damaged > 1 else ''} could not be read"
    return text


def describe_pages(row) -> str:
    """How many pages the student opened, and how many while another of theirs was live.

    >>> describe_pages(ClassRow("s1", "", pages=3, overlaps=1))
    '3 (1 while another was open)'
    """
    if not row.pages:
        return ""
    return f"{row.pages}" + (f" ({row.overlaps} while another was open)" if row.overlaps else "")


def handin_errors(exercise, sid: str, last: HandIn | None) -> dict:
    """The errors of a hand-in stored before they were kept (none for an id the app now refuses)."""
    if last is None:
        return {}
    try:
        return exercise.errors(sid, last.estimates)
    except ValueError:
        return {}


_NOISE_SHOWN = {"x": ("mm", 1e-3), "v": ("mm/s", 1e-3), "p1": ("MPa", 1e6), "p2": ("MPa", 1e6)}


def describe_conditions(conditions: dict) -> str:
    """A hand-in's data conditions in a few words: the sensors' σ as used (display units), the load
    disturbance applied, where v came from (the dashboard's and the CSV's column).

    >>> describe_conditions({"noise": {"x": 1e-5, "v": 0.001, "p1": 5e4, "p2": 5e4}, "v": "measured",
    ...                      "disturbance_applied": "none"})
    'σ x 0.01 mm, v 1 mm/s, p1 0.05 MPa, p2 0.05 MPa; d(t) none'
    """
    if not conditions:
        return ""
    if conditions.get("data"):             # an uploaded file: not taken under the exercise's conditions
        return f"{conditions['data']}: not the exercise's conditions"
    parts = []
    noise = conditions.get("noise") or {}
    if isinstance(noise, dict):
        shown = [f"{k} {v / _NOISE_SHOWN[k][1]:g} {_NOISE_SHOWN[k][0]}" for k, v in noise.items()
                 if k in _NOISE_SHOWN and isinstance(v, (int, float)) and v > 0]
        parts.append("σ " + ", ".join(shown) if shown else "no sensor noise")
    d = conditions.get("disturbance_applied", conditions.get("disturbance"))
    if d:
        parts.append(f"d(t) {d}")
    if conditions.get("v") and conditions["v"] != "measured":
        parts.append(f"v = {conditions['v']}")
    return "; ".join(parts)


def results_header(exercise) -> list[str]:
    cols = ["id", "name", "joined", "last seen", "hand-ins", "last hand-in", "method"]
    for n in exercise.hide:
        cols += [n, f"{n} error %", f"{n} z", f"{n} ok"]
    return cols + [f"score ({exercise.score_rule})", "data", "conditions", "pages"]


def results_cells(exercise, row: ClassRow) -> list[str]:
    """A row as text (the terminal's and the CSV's)."""
    cells = [row.id, row.name, row.joined, row.last_seen, str(row.count), row.last_time,
             METHODS.get(row.method, row.method).split(" (")[0] if row.method else ""]
    for n in exercise.hide:
        v, e = row.estimates.get(n), row.errors.get(n)
        z = row.zscores.get(n)
        cells += [f"{v:.6g}" if isinstance(v, (int, float)) else "",
                  f"{100 * e:.2f}" if isinstance(e, (int, float)) else "",
                  f"{z:+.2f}" if isinstance(z, (int, float)) else "",
                  ("yes" if row.verdicts.get(n) else "no") if row.count else ""]
    return cells + [f"{row.score:.2f}" if row.count else "", describe_source(row), describe_conditions(row.conditions),
                    describe_pages(row)]


def results_csv(exercise, rows: list[ClassRow]) -> str:
    """The results as CSV; every cell a spreadsheet would read as a formula is neutralised."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([csv_cell(c) for c in results_header(exercise)])
    for row in rows:
        w.writerow([csv_cell(c) for c in results_cells(exercise, row)])
    return buf.getvalue()
