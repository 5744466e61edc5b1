"""The exercise this server runs (``eha serve --exercise FILE`` sets EHA_EXERCISE, and ``--store URL``
EHA_STORE, where its lab's state is): read by the server only, once per change of the file, with its
secret registered to be kept out of every log line."""

from __future__ import annotations

import os
from functools import lru_cache

__all__ = ["current_exercise"]


@lru_cache(maxsize=4)
def _exercise_at(path: str, mtime: float, store: str):
    from eha_core.exercise import Exercise

    from .handins import HandIns
    from .redaction import keep_out_of_logs

    exercise = Exercise.load(path)
    keep_out_of_logs(exercise.secret)
    handins = HandIns(path, store=store or None)
    # the hand-ins this server's last run kept while the database was down: saved as soon as it answers
    from .extensions import lab_rules
    from .outbox import replay

    replay(exercise, handins, lambda rules: lab_rules(exercise, rules))
    return exercise, handins


def current_exercise():
    """The exercise this server runs (``eha serve --exercise FILE`` sets EHA_EXERCISE), as
    ``(Exercise, HandIns)``, or None. Read by the server only: nothing of it goes to a page
    but its title and the names of the hidden parameters."""
    path = os.environ.get("EHA_EXERCISE", "").strip()
    if not path:
        return None
    return _exercise_at(path, os.path.getmtime(path), os.environ.get("EHA_STORE", "").strip())
