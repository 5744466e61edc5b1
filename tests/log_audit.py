"""After a test run: no exercise secret, no student's hidden value and no change made outside a
page's lock in any server log it wrote.

Every exercise file a test made (under pytest's temporary folder) names its
secret; its hand-in database names the students who worked. Every log the run's
servers wrote (their files under the same folder, and the browser tests' shared
server's log) is searched for the secret and for each of those students' hidden
values at 5 or more significant digits, and for the errors of a page changed
outside its lock (``RuntimeError: _pending_writes ...``, strict mode's
``UnlockedChange``).
"""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path

__all__ = ["exercises_under", "leaks_in_logs"]


def exercises_under(folder: Path) -> list[tuple[object, list[str]]]:
    """The exercises made under ``folder`` with the students of their hand-in databases."""
    from eha_app.runtime.handins import handins_path
    from eha_core.exercise import Exercise

    found = []
    for path in folder.rglob("*.json"):
        try:
            if '"eha-exercise/' not in path.read_text(encoding="utf-8", errors="replace")[:200]:
                continue
            ex = Exercise.load(path)
        except (OSError, ValueError):
            continue
        students = []
        db = handins_path(path)
        if db.exists():
            try:
                with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as con:
                    students = [r[0] for r in con.execute("SELECT DISTINCT student FROM handins")]
                    try:                # the students who joined, handed in or not
                        students += [r[0] for r in con.execute("SELECT student FROM presence")
                                     if r[0] not in students]
                    except sqlite3.Error:
                        pass
            except sqlite3.Error:
                pass
        found.append((ex, students))
    return found


def leaks_in_logs(logs: list[Path], exercises) -> list[str]:
    """``file: what`` for every secret or hidden value found in one of ``logs``."""
    from eha_app.runtime.redaction import number_forms

    needles: dict[str, str] = {}
    for ex, students in exercises:
        needles[ex.secret] = f"the secret of {ex.title!r}"
        for student in students:
            try:
                truth = ex.student_params(student)
            except ValueError:                  # an id the app refuses (a test stored it directly)
                continue
            for name in ex.hide:
                for form in number_forms(getattr(truth, name)):
                    needles[form] = f"{student}'s {name}"
    if not needles:
        return []
    pattern = re.compile(r"(?<![\w.])(" + "|".join(re.escape(n) for n in sorted(needles, key=len, reverse=True))
                         + r")(?![\w])")
    found = []
    for log in logs:
        text = log.read_text(encoding="utf-8", errors="replace")
        for m in pattern.finditer(text):
            found.append(f"{log}: {needles[m.group(1)]} ({m.group(1)!r})")
    return found


#: Lines no server log of the suite may hold: Bokeh's error for a page changed outside its lock,
#: and the strict mode's.
UNLOCKED = ("_pending_writes should be non-None", "UnlockedChange")


def unlocked_changes_in_logs(logs: list[Path]) -> list[str]:
    """``file: line`` for every line of a change made outside a page's lock."""
    found = []
    for log in logs:
        for line in log.read_text(encoding="utf-8", errors="replace").splitlines():
            if any(word in line for word in UNLOCKED):
                found.append(f"{log}: {line.strip()[:300]}")
    return found


def audit(basetemp: Path, extra_logs=()) -> list[str]:
    logs = [p for p in basetemp.rglob("*.log") if p.is_file()] + [Path(p) for p in extra_logs if Path(p).is_file()]
    return leaks_in_logs(logs, exercises_under(basetemp)) + unlocked_changes_in_logs(logs)


if __name__ == "__main__":
    import sys

    print(json.dumps(audit(Path(sys.argv[1])), indent=1))
