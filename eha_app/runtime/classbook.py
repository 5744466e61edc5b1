"""The class's results as the teacher sees them: one row per student, for the dashboard, the CSV
and ``eha exercise results`` alike (one table, three renderings).

A row holds the roster's id and name (or the id typed, in an open exercise), when the student
joined and was last seen, their hand-ins (count and the last one's time, method, values), the
error of each value against the truth and its verdict, and the score by the exercise's rule
(best or last hand-in). The errors are the teacher's: nothing here goes to a student's page.

>>> import tempfile, pathlib
>>> from eha_core.exercise import Exercise
>>> ex = Exercise.new(hide=("M",), roster=[("s1", "Ada")], secret="11" * 32)
>>> store = HandIns(pathlib.Path(tempfile.mkdtemp()) / "class.json").check()
>>> truth = ex.student_params("s1").M
>>> est = {"M": truth * 1.02}
>>> _ = store.add("s1", est, ex.verdicts("s1", est), errors=ex.errors("s1", est))
>>> [(r.id, r.name, r.count, r.score, round(r.errors["M"], 4)) for r in class_rows(ex, store)]
[('s1', 'Ada', 1, 1.0, 0.02)]
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field

from eha_core.data import csv_cell
from eha_core.exercise import METHODS

from .handins import HandIn, HandIns

__all__ = ["describe_conditions", "handin_errors", "ClassRow", "class_rows", "results_header", "results_cells",
           "results_csv"]


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


def class_rows(exercise, store: HandIns) -> list[ClassRow]:
    """Every student of the roster (in its order), then anyone else who joined or handed in."""
    handins: dict[str, list[HandIn]] = {}
    for h in store.all():
        handins.setdefault(h.student, []).append(h)
    presence = store.presence()
    names = {e.id: e.name for e in exercise.roster}
    ids = list(names) + sorted((set(presence) | set(handins)) - set(names))
    rows = []
    for sid in ids:
        hs = handins.get(sid, [])
        joined, seen = presence.get(sid, ("", ""))
        last = hs[-1] if hs else None
        rows.append(ClassRow(
            id=sid, name=names.get(sid, ""), joined=joined, last_seen=seen, count=len(hs),
            last_time=last.time if last else "", method=last.method if last else "",
            estimates=last.estimates if last else {},
            errors=last.errors if last and last.errors else handin_errors(exercise, sid, last),
            verdicts=last.verdicts if last else {}, score=exercise.score([h.verdicts for h in hs]),
            conditions=last.conditions if last else {}, settings=last.settings if last else {}))
    return rows


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
        cols += [n, f"{n} error %", f"{n} ok"]
    return cols + [f"score ({exercise.score_rule})", "conditions"]


def results_cells(exercise, row: ClassRow) -> list[str]:
    """A row as text (the terminal's and the CSV's)."""
    cells = [row.id, row.name, row.joined, row.last_seen, str(row.count), row.last_time,
             METHODS.get(row.method, row.method).split(" (")[0] if row.method else ""]
    for n in exercise.hide:
        v, e = row.estimates.get(n), row.errors.get(n)
        cells += [f"{v:.6g}" if isinstance(v, (int, float)) else "",
                  f"{100 * e:.2f}" if isinstance(e, (int, float)) else "",
                  ("yes" if row.verdicts.get(n) else "no") if row.count else ""]
    return cells + [f"{row.score:.2f}" if row.count else "", describe_conditions(row.conditions)]


def results_csv(exercise, rows: list[ClassRow]) -> str:
    """The results as CSV; every cell a spreadsheet would read as a formula is neutralised."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([csv_cell(c) for c in results_header(exercise)])
    for row in rows:
        w.writerow([csv_cell(c) for c in results_cells(exercise, row)])
    return buf.getvalue()
