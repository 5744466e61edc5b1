"""The class's grades as the teacher's gradebook imports them: Moodle's and Canvas's CSV files.

Each student's grade is the exercise's counted score (:meth:`~eha_core.exercise.Exercise.score` over
their hand-ins, oldest first: the ``score`` of :func:`~eha_app.runtime.classbook.class_rows`, the
dashboard's "counted") times ``points``. One row per student of the roster, in its order (an open
exercise: every id that joined or handed in). A student who handed nothing in gets 0: the exercise's
rule scores no hand-in 0, and both importers read an empty cell (or "-") as "no grade", which Moodle
writes over a grade imported before and Canvas leaves ungraded; a lab that was not handed in is a 0.

**Moodle** ("Grade import", docs.moodle.org: "the import file format is the same as the corresponding
export format"; Grades > Import > CSV file). The columns of Moodle's own plain-text export:
``First name``, ``Last name``, ``ID number``, ``Email address``, then one column per grade item named
``ITEM (Real)``. The roster has an id and a name only: the id goes to ``ID number`` (map "ID number" to
"useridnumber" on import: the students' ID number field in Moodle must hold the roster's ids), the name
is split the simple way (its last word is the last name, the words before it the first name: "Ada King
Lovelace" -> "Ada King", "Lovelace"; a name written "Turing, Alan" is split at its comma), and the email
address stays empty. Grades are written with two
decimals, as Moodle exports them; Moodle takes at most 100 unless the site allows more
("unlimitedgrades"). Moodle's export also writes a "Last downloaded from this course" column: it is left
out, since on import Moodle compares it with each grade's last change, and no such download happened.
No feedback column: Moodle's documentation warns that a feedback column mapped without its grade column
overwrites the grades.

**Canvas** ("How do I import grades in the Gradebook?", Instructure; the importer of Canvas's source,
``GradebookImporter``): the header ``Student``, ``ID``, ``SIS User ID``, ``SIS Login ID``, ``Section``,
then one column per assignment, ``NAME (assignment id)`` for an existing one or just ``NAME`` for a new
one (an existing assignment of exactly that name is matched too); the second row, ``Points Possible``,
gives each assignment's points. Canvas matches a row to a student by ``ID`` (its own user id, which the
exercise does not know: left empty), then by ``SIS User ID`` (the roster's id is written there), then
``SIS Login ID``, then by the name in ``Student``. Grades have two decimals, as Canvas exports them.

Both files are UTF-8 without a byte-order mark (Instructure: "All text should be UTF-8 encoded";
Moodle's import form asks for the encoding, UTF-8 by default): a mark is not needed by either importer,
and without one the header's first cell is exactly ``First name`` or ``Student``. Text cells a
spreadsheet would run as a formula are neutralised as in every CSV of the project
(:func:`eha_core.data.csv_cell`); the csv module quotes a name holding a comma or a quote.

>>> from eha_core.exercise import Exercise
>>> from eha_app.runtime.classbook import ClassRow
>>> ex = Exercise.new(hide=("M",), title="Lab 3", roster=[("s1", "Ada King Lovelace")], secret="00" * 32)
>>> rows = [ClassRow("s1", "Ada King Lovelace", count=1, score=0.5)]
>>> print(moodle_csv(ex, rows), end="")  # doctest: +NORMALIZE_WHITESPACE
First name,Last name,ID number,Email address,Lab 3 (Real)
Ada King,Lovelace,s1,,50.00
>>> print(canvas_csv(ex, rows, points=10), end="")  # doctest: +NORMALIZE_WHITESPACE
Student,ID,SIS User ID,SIS Login ID,Section,Lab 3
Points Possible,,,,,10.00
Ada King Lovelace,,s1,,,5.00
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass

from eha_core.data import csv_cell
from eha_core.errors import not_allowed

__all__ = ["FORMATS", "MOODLE_HEADER", "CANVAS_HEADER", "Grade", "grades", "split_name", "moodle_csv", "canvas_csv",
           "check_points", "check_item"]

#: What ``eha exercise results --format`` writes: the results table as CSV, or a gradebook's import file.
FORMATS = ("csv", "moodle", "canvas")
#: The user columns of Moodle's CSV export (the grade items follow, each ``NAME (Real)``).
MOODLE_HEADER = ("First name", "Last name", "ID number", "Email address")
#: The student columns of Canvas's gradebook CSV (the assignments follow).
CANVAS_HEADER = ("Student", "ID", "SIS User ID", "SIS Login ID", "Section")
#: Canvas reads a column named ``NAME (123)`` as the assignment whose id is 123.
_CANVAS_ID = re.compile(r"\s\(\d+\)\s*$")
#: Columns Canvas's importer drops as its own read-only totals (and everything that holds their names).
_CANVAS_TOTALS = ("Current Score", "Current Points", "Current Grade", "Final Score", "Final Points", "Final Grade",
                  "Override Score", "Override Grade", "Override Status")


@dataclass(frozen=True)
class Grade:
    """One student's line: the id the gradebook matches, the name, the counted score (0-1) and the
    points it is worth."""

    id: str
    name: str
    score: float
    points: float


def check_points(points, name: str = "points") -> float:
    """The points a full score is worth: a finite number > 0 (at most 100000); a refusal names ``name``."""
    try:
        value = float(str(points).strip())
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0 < value <= 100_000):
        raise not_allowed(name, points, "a number of points > 0 (at most 100000), e.g. 100")
    return value


def check_item(item: str, fmt: str, name: str = "item") -> str:
    """The grade item's (Moodle) or assignment's (Canvas) name: one line of printable text, which Canvas
    must not read as an assignment id or as one of its own total columns; a refusal names ``name``."""
    text = " ".join(str(item).split())
    if not text or not text.isprintable() or len(text) > 255:
        raise not_allowed(name, item, "a name of 1-255 printable characters (the grade item's or assignment's)")
    if fmt == "canvas" and _CANVAS_ID.search(text):
        raise not_allowed(name, text, "Canvas reads a name ending in a number in brackets as the id of an existing "
                                      "assignment; give another name (e.g. without the brackets)")
    if fmt == "canvas" and any(t in text for t in _CANVAS_TOTALS):
        raise not_allowed(name, text, "Canvas drops a column holding the name of one of its totals (Current Score, "
                                      "Final Grade, ...); give another name")
    return text


def grades(exercise, rows, *, points: float = 100.0) -> list[Grade]:
    """The grade of every student of the roster, in its order, from the class's ``rows``
    (:func:`~eha_app.runtime.classbook.class_rows`); an open exercise: every row's id.
    A student without a row (or without a hand-in) scores 0."""
    by_id = {r.id: r for r in rows}
    if exercise.has_roster:
        people = [(e.id, e.name) for e in exercise.roster]
    else:
        people = [(r.id, r.name) for r in rows]
    out = []
    for sid, name in people:
        row = by_id.get(sid)
        score = float(row.score) if row is not None and row.count else 0.0
        out.append(Grade(sid, name, score, score * points))
    return out


def split_name(name: str) -> tuple[str, str]:
    """``(first name, last name)`` the simple way: the last word is the last name, the words before it the
    first name (a one-word name is a last name); a name written "Last, First" (as Canvas sorts names) is
    split at its comma.

    >>> split_name("Ada King Lovelace"), split_name("Hypatia"), split_name("Turing, Alan"), split_name("")
    (('Ada King', 'Lovelace'), ('', 'Hypatia'), ('Alan', 'Turing'), ('', ''))
    """
    if "," in str(name):
        last, _, first = str(name).partition(",")
        return " ".join(first.split()), " ".join(last.split())
    words = str(name).split()
    if not words:
        return "", ""
    return " ".join(words[:-1]), words[-1]


def _csv(lines) -> str:
    buf = io.StringIO()
    csv.writer(buf).writerows([[csv_cell(c) for c in line] for line in lines])
    return buf.getvalue()


def moodle_csv(exercise, rows, *, points: float = 100.0, item: str = "") -> str:
    """Moodle's CSV grade import (see the module docstring): one grade item, ``item`` (default the
    exercise's title), worth ``points``."""
    name = check_item(item or exercise.title, "moodle")
    lines = [[*MOODLE_HEADER, f"{name} (Real)"]]
    for g in grades(exercise, rows, points=points):
        lines.append([*split_name(g.name), g.id, "", f"{g.points:.2f}"])
    return _csv(lines)


def canvas_csv(exercise, rows, *, points: float = 100.0, item: str = "") -> str:
    """Canvas's gradebook CSV import (see the module docstring): one assignment, ``item`` (default the
    exercise's title, a new assignment unless one of that name exists), worth ``points``."""
    name = check_item(item or exercise.title, "canvas")
    lines = [[*CANVAS_HEADER, name], ["Points Possible", "", "", "", "", f"{points:.2f}"]]
    for g in grades(exercise, rows, points=points):
        lines.append([g.name, "", g.id, "", "", f"{g.points:.2f}"])
    return _csv(lines)
