"""A later deadline for one student: the check the teacher's dashboard and ``eha exercise extend`` share.

The teacher grants a student a deadline of their own (kept in the class's database,
:meth:`~eha_app.runtime.handins.HandIns.set_extension`); the hand-in takes it when it is later than
the class's (:func:`own_deadline`). An extension is refused, naming the field
and the value as typed, for an id the roster does not hold, a date that is not ISO-8601, one that is
not later than the class's deadline or has passed (it would change nothing), one after the exercise
releases the true values (hand-ins close then, whatever the deadline), and in an exercise without a
deadline (there is nothing to extend).

>>> from eha_core.exercise import Exercise
>>> ex = Exercise.new(hide=("M",), roster=[("s1", "Ada")], deadline="2030-01-01T12:00", secret="00" * 32)
>>> check_extension(ex, " S1 ", "2030-01-08T12:00", now=0.0)
('s1', '2030-01-08T12:00')
>>> check_extension(ex, "s9", "2030-01-08T12:00", now=0.0)  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
eha_core._checks.FieldError: student id = s9 is not allowed: no student with this id in the exercise's roster...
"""

from __future__ import annotations

import time

from eha_core.errors import not_allowed
from eha_core.exercise import normalize_id, parse_deadline

__all__ = ["check_extension", "own_deadline", "lab_rules", "STUDENT_FIELD", "UNTIL_FIELD", "HANDIN_PATIENCE_S"]

#: The names a refusal gives the two fields (the command line's options replace them).
STUDENT_FIELD = "student id"
UNTIL_FIELD = "until"


def check_extension(exercise, student: str, until: str, *, class_deadline: str = "",
                    now: float | None = None) -> tuple[str, str]:
    """``(id, deadline)`` of an extension as typed: the student's normalised id and their deadline
    (ISO-8601, as typed once trimmed), or ``(id, "")`` for an empty ``until`` (the extension taken away).

    Parameters
    ----------
    exercise : Exercise
        The exercise: its roster, its deadline and its release date.
    student : str
        The student's id as typed.
    until : str
        The student's new deadline as typed (ISO-8601); empty: take their extension away.
    class_deadline : str
        The class's deadline as the teacher moved it (the store's control), "" for the exercise file's.
    now : float, optional
        The time [s, POSIX]; default the current time.

    A :class:`~eha_core.errors.FieldError` names :data:`STUDENT_FIELD` or :data:`UNTIL_FIELD`, the value
    as typed and what is allowed.
    """
    sid = normalize_id(student)
    if exercise.has_roster and exercise.entry(sid) is None:
        raise not_allowed(STUDENT_FIELD, student, "no student with this id in the exercise's roster (the ids of "
                                                  "the roster file, as `eha exercise codes` lists them)")
    typed = str(until).strip()
    if not typed:
        return sid, ""
    text = parse_deadline(typed, name=UNTIL_FIELD)
    base = class_deadline or exercise.deadline
    if not base:
        raise not_allowed(UNTIL_FIELD, typed, "this exercise has no deadline, so there is nothing to extend: every "
                                              "hand-in is taken until you close hand-ins")
    due = exercise.deadline_at(text)
    if due <= exercise.deadline_at(base):
        raise not_allowed(UNTIL_FIELD, typed, f"it is not later than the class's deadline ({base}): give a later "
                                              "date and time")
    if due <= (time.time() if now is None else now):
        raise not_allowed(UNTIL_FIELD, typed, "it has passed: the student could hand in nothing; give a later date "
                                              "and time")
    if exercise.release_at and due > exercise.deadline_at(exercise.release_at):
        raise not_allowed(UNTIL_FIELD, typed, f"it is after the true values are released ({exercise.release_at}): "
                                              "no hand-in is taken from then on; give one at or before it")
    return sid, text


#: How long a hand-in waits for the database before it waits to be saved (the database is down) [s].
HANDIN_PATIENCE_S = 8.0


def lab_rules(exercise, rules: dict, seen: dict | None = None):
    """The lab's rules for a hand-in as its own transaction judges them: ``refusal(count, control)`` with the
    teacher's switches as the transaction reads them (a close, a moved deadline or a reveal a moment ago
    holds), the hand-in's ``rules["method"]`` and ``rules["source"]``, and the time the student handed in
    (``rules["at"]``: a hand-in that waited for the database is not late for it). ``seen`` receives the
    switches read."""
    def refusal(count, control):
        if seen is not None:
            seen.update(control)
        return exercise.refusal(count, now=rules.get("at"), open_=control.get("open", "1") == "1",
                                deadline=own_deadline(exercise, control), method=rules.get("method"),
                                revealed=control.get("revealed") == "1", source=rules.get("source"))
    return refusal


def own_deadline(exercise, control: dict) -> str | None:
    """The student's deadline under the teacher's switches ``control`` (:meth:`HandIns.control_for`): their
    own extension when it is later than the class's deadline (the teacher's moved one, else the exercise
    file's), else the class's; None when the class has none (an extension extends nothing then)."""
    class_deadline = control.get("deadline") or exercise.deadline
    extension = control.get("extension") or ""
    if not class_deadline:
        return None
    try:
        later = bool(extension) and exercise.deadline_at(extension) > exercise.deadline_at(class_deadline)
    except ValueError:
        later = False                       # a stored date no one can read (edited by hand): the class's holds
    return extension if later else class_deadline
