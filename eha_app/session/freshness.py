"""Every result on screen is either computed from the current inputs or marked out of date.

A :class:`ResultView` wraps one result area of a tab (plots, a table, a
summary) and remembers the inputs its content was computed from, as a
hashable *key*. When an input changes, the tab computes the key of what the
inputs now say and calls :meth:`ResultView.inputs_changed`: a view whose key
differs is marked, in the page, either *updating* (a run with the new inputs
is on its way: it is re-run automatically) or *stale* (out of date: the
student has to run it again, the run being too long to start on every
keystroke). :meth:`ResultView.shown` records the key of freshly drawn content.

The mark is a class on the view's container (``eha-current``, ``eha-updating``,
``eha-out-of-date``; styled in :data:`eha_app.render.tables.CSS`: an updating view is
outlined, a stale one dimmed) and, for a stale one, a line of text above it
(:attr:`ResultView.banner`) that says why and what to do. Both are Panel objects of the
session's own document, changed from the session's callbacks.

Examples
--------
>>> import panel as pn
>>> view = ResultView("demo", pn.Column())
>>> view.status
'empty'
>>> view.shown(("M", 4000.0))
>>> view.inputs_changed(("M", 6000.0), why="M changed on tab 1")
>>> view.status, "eha-out-of-date" in view.container.css_classes
('stale', True)
>>> view.inputs_changed(("M", 4000.0))
>>> view.status
'current'
"""

from __future__ import annotations

import html
from collections.abc import Hashable

import panel as pn

__all__ = ["ResultView", "STATUS_CLASSES", "param_changes"]

#: the container's class for each status
STATUS_CLASSES = {"empty": "eha-empty", "current": "eha-current", "updating": "eha-updating",
                  "stale": "eha-out-of-date"}


def param_changes(before, after, *, limit: int = 3, hidden=()) -> str:
    """What differs between two actuators, in tab 1's labels and units ("M 4000 → 6000 kg, and 2 more");
    an exercise's ``hidden`` parameters are never named. Empty when nothing (shown) differs."""
    from eha_core.params import FIELD_INFO

    from .state import FIELD_LABELS

    changed = [n for n in FIELD_INFO if n not in hidden and getattr(before, n) != getattr(after, n)]
    parts = []
    for n in changed[:limit]:
        info = FIELD_INFO[n]
        a, b = getattr(before, n), getattr(after, n)
        a_text, b_text = (("force balance" if v is None else f"{v / info.display_scale:.6g}") for v in (a, b))
        parts.append(f"{FIELD_LABELS.get(n, n)} {a_text} → {b_text} {info.display_unit}")
    more = f" and {len(changed) - limit} more" if len(changed) > limit else ""
    return ", ".join(parts) + more


def _what_changed(old, new) -> str:
    """What differs between two keys, for a student: the parameters of tab 1 by name
    ("tab 1 changed since this run (M 4000 → 6000 kg)"), else the settings."""
    from eha_core.params import ActuatorParams

    def params_of(key):
        return key[0] if isinstance(key, tuple) and key and isinstance(key[0], ActuatorParams) else None

    before, after = params_of(old), params_of(new)
    if before is None or after is None or before == after:
        return "the settings changed since this run"
    return f"tab 1 changed since this run ({param_changes(before, after)})"


class ResultView:
    """One result area and the key of the inputs it shows."""

    def __init__(self, name: str, container: pn.layout.ListLike, *, run_hint: str = "Run it again to update.",
                 updating_marker=None):
        self.name = name
        self.container = container
        self.run_hint = run_hint
        # A view re-run while a slider is dragged says "updating" through
        # ``updating_marker(bool)`` (e.g. a word in its status line) instead of a class:
        # a class change re-lays out the tab, and Chromium then ends the drag.
        self.updating_marker = updating_marker
        self.computed_from: Hashable | None = None
        self.status = "empty"
        #: called with no argument after every :meth:`shown` (the guide offers "Next" once a result is there)
        self.on_shown: list = []
        self.banner = pn.pane.HTML("", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-stale-note", f"eha-stale-note-{name}"], margin=(0, 5))
        self._set_classes()

    # -- what the tab says --------------------------------------------------------------
    def shown(self, key: Hashable) -> None:
        """The view now shows results computed from ``key``."""
        self.computed_from = key
        self._set("current", "")
        for fn in list(self.on_shown):
            fn()

    def inputs_changed(self, key: Hashable | None, *, updating: bool = False, why: str = "") -> None:
        """The inputs now say ``key`` (None: they are not valid). ``updating``: a run with
        them is queued and will call :meth:`shown`. ``why``: what changed, for the
        out-of-date line (default: the parameters that differ, or the settings)."""
        if self.computed_from is None:
            return
        if key is not None and key == self.computed_from:
            self._set("current", "")
        elif updating:
            # no line of text: during a slider drag it would come and go with every run and
            # move the plots; the container's outline (or the marker) says it
            self._set("updating", "")
        else:
            reason = why or _what_changed(self.computed_from, key)
            self._set("stale", f"Out of date: {reason}. {self.run_hint}")

    @property
    def is_current(self) -> bool:
        return self.status == "current"

    # -- the page ------------------------------------------------------------------------
    def _set(self, status: str, text: str) -> None:
        was = self.status
        self.status = status
        if self.updating_marker is not None and (status == "updating") != (was == "updating"):
            self.updating_marker(status == "updating")
        if status != was:
            self._set_classes()
        if self.banner.object != text or self.banner.visible != bool(text):
            self.banner.object = (f"<span class='eha-stale-text'>{html.escape(text)}</span>" if text else "")
            self.banner.visible = bool(text)

    def _set_classes(self) -> None:
        status = self.status
        if status == "updating" and self.updating_marker is not None:
            status = "current"          # the marker says it; the classes stay (see __init__)
        keep = [c for c in self.container.css_classes if c not in STATUS_CLASSES.values()
                and not c.startswith("eha-view")]
        classes = [*keep, "eha-view", f"eha-view-{self.name}", STATUS_CLASSES[status]]
        if classes != list(self.container.css_classes):
            self.container.css_classes = classes
