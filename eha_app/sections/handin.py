"""The exercise's hand-in, one box for every route (least squares, the frequency domain's back-out).

A section gives the box its estimates, its settings and a word for its method; the box checks the
exercise's rules (open, deadline, attempts, the route allowed) inside the store's transaction, so
two pages of one student cannot both take the last attempt, stores the hand-in with the data's
conditions and the errors against the truth (the teacher's), and tells the student what the
exercise's feedback rule allows: the verdict per parameter, only that it was stored, or the
verdicts once the deadline has passed. The truth itself reaches the student only after the
teacher reveals it (:meth:`eha_app.app.Page` shows it then).
"""

from __future__ import annotations

import html
from collections.abc import Callable

import panel as pn

from eha_core.exercise import METHODS

from ..render.tables import SYMBOLS_HTML
from ..runtime.tasks import on_click

__all__ = ["HandInBox", "handin_status", "result_for_student"]


def handin_status(state) -> tuple[str | None, int]:
    """(why a hand-in is refused now or None, hand-ins so far) for the session's student; the
    teacher's switches are read from the store (a closed or extended exercise holds at once)."""
    ex, store = state.exercise, state.handins
    control = store.control()
    count = len(store.of(state.student))
    return ex.refusal(count, open_=control.get("open", "1") == "1", deadline=control.get("deadline"),
                      revealed=control.get("revealed") == "1"), count


class HandInBox:
    """A button and the verdict under it: ``estimates()`` gives ``({name: value}, settings)`` or
    None (nothing to hand in yet), ``tip()`` the button's tooltip as the section sees it."""

    def __init__(self, section, method: str, estimates: Callable[[], tuple[dict, dict] | None], *,
                 label: str = "Hand in these estimates", refusal: Callable[[], str | None] | None = None):
        self.section, self.method, self.estimates = section, method, estimates
        # why the section's result cannot be handed in (None: it can), e.g. an estimate that failed its checks
        self.refusal = refusal if refusal is not None else (lambda: None)
        self._refusal_shown = False
        state = section.state
        allowed = bool(state.hidden) and (state.exercise is None or method in state.exercise.conditions.methods)
        self.button = pn.widgets.Button(label=label, color="warning", width=260, css_classes=["eha-handin"],
                                        visible=allowed, disabled=True, description="run first")
        on_click(self.button, lambda _e: self.hand_in())
        self.verdict = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-verdict"])

    @property
    def takes_files(self) -> bool:
        """Does the exercise take hand-ins from an uploaded file (labelled so)?"""
        ex = self.section.state.exercise
        return ex is not None and bool(getattr(ex, "own_files", False))

    def set_tip(self, enabled: bool, tip: str) -> None:
        self.button.disabled = not enabled
        if self.button.description != tip:
            self.button.description = tip

    def show_refusal(self, why: str | None) -> None:
        """Say beside the button why the result cannot be handed in, and disable it (None: it can; a
        refusal shown before is taken away)."""
        if why:
            self.set_tip(False, why)
            self.verdict.object = (f"<div class='eha-verdict-box eha-handin-refused'><span class='eha-warn'>Cannot be "
                                   f"handed in: {html.escape(why)}.</span></div>")
            self.verdict.visible = True
            self._refusal_shown = True
        elif self._refusal_shown:
            self.verdict.visible = False
            self.verdict.object = ""
            self._refusal_shown = False

    def hand_in(self):
        """Store the section's estimates as a hand-in; show what the feedback rule allows."""
        s = self.section.state
        why = self.refusal()
        if why and s.hidden:
            self.show_refusal(why)
            return None
        got = self.estimates()
        if got is None or not s.hidden:
            return None
        estimates, settings = got
        exercise, student, store, method = s.exercise, s.student, s.handins, self.method
        settings = dict(settings)
        source = dict(settings.pop("_source", None) or {"kind": "simulated"})
        from_file = source.get("kind") == "file"
        # a file's data were not taken under the exercise's conditions: its hand-in says so, not the noise floors
        conditions = ({"data": "an uploaded file"} if from_file
                      else {**exercise.conditions.to_dict(), **settings.pop("_conditions", {})})
        settings.pop("_conditions", None)

        def compute(_token):
            from ..runtime.handins import Refused

            verdicts = exercise.verdicts(student, estimates)
            seen = {}

            def refusal(count, control):
                # the teacher's switches as the hand-in's own transaction reads them: a close, a
                # moved deadline or a reveal a moment ago holds
                seen.update(control)
                return exercise.refusal(count, open_=control.get("open", "1") == "1",
                                        deadline=control.get("deadline"), method=method,
                                        revealed=control.get("revealed") == "1", source=source.get("kind"))
            try:
                store.add(student, estimates, verdicts, method=method, settings=settings, conditions=conditions,
                          errors=exercise.errors(student, estimates), source=source, refusal=refusal)
            except Refused as exc:
                return None, str(exc), 0, False
            count = len(store.of(student))
            shows = exercise.shows_verdicts(deadline=seen.get("deadline"), revealed=seen.get("revealed") == "1")
            return verdicts, "", count, shows

        def show(out, _job):
            verdicts, refused, count, shows = out
            self._refusal_shown = False         # the verdict pane says this hand-in's outcome now
            if refused:
                self.verdict.object = (f"<div class='eha-verdict-box eha-handin-refused'><span class='eha-warn'>"
                                       f"Not handed in: {html.escape(refused)}.</span></div>")
                self.verdict.visible = True
                return
            limit = f" of {exercise.attempts} allowed" if exercise.attempts else ""
            origin = f" on your file {html.escape(source.get('name', ''))}" if from_file else ""
            head = (f"<b>Handed in</b> (hand-in {count}{limit}, from the "
                    f"{html.escape(METHODS[method].split(' (')[0])}{origin})")
            values = "".join(f"<li>{SYMBOLS_HTML.get(n, html.escape(n))} = {v:.5g}" for n, v in estimates.items())
            if shows:
                score = sum(verdicts.values())
                items = "".join(
                    f"<li>{SYMBOLS_HTML.get(n, html.escape(n))} "
                    + ("not handed in from this route ✗" if n not in estimates else
                       f"= {estimates[n]:.5g}: "
                       + (f"<span class='eha-ok'>within ±{100 * exercise.tolerance_of(n):g} % ✓</span>" if ok else
                          f"<span class='eha-warn'>not within ±{100 * exercise.tolerance_of(n):g} % ✗</span>"))
                    + "</li>" for n, ok in verdicts.items())
                body = f"{head}: {score} of {len(verdicts)} within tolerance.<ul>{items}</ul>"
            elif exercise.feedback == "after-deadline":
                body = (f"{head}.<ul>{values}</ul>The verdicts are shown after the deadline"
                        + (f" ({html.escape(exercise.deadline)})" if exercise.deadline else "") + ".")
            else:
                body = f"{head}.<ul>{values}</ul>Your teacher will tell you the result."
            self.verdict.object = f"<div class='eha-verdict-box'>{body}</div>"
            self.verdict.visible = True

        def fail(message):
            # nothing was stored (the class's database is damaged or gone): say so, not "identification failed"
            self.verdict.object = (f"<div class='eha-verdict-box'><span class='eha-warn'>Your hand-in was not "
                                   f"stored: {html.escape(message)}. Tell your teacher; your estimates stay "
                                   "here and you can hand in again.</span></div>")
            self.verdict.visible = True

        return self.section.runner.run("hand-in", compute, show, fail=fail, note=self.section._note)


def result_for_student(exercise, student: str, store, control: dict | None = None) -> str:
    """What the student may now see of their result ("" for nothing yet): after the teacher's reveal,
    their actuator's true hidden values and each hand-in's errors; after the deadline (feedback
    "after-deadline"), the verdicts of their hand-ins."""
    control = store.control() if control is None else control
    revealed = control.get("revealed") == "1"
    deadline = control.get("deadline")
    if not revealed and not (exercise.feedback == "after-deadline"
                             and exercise.shows_verdicts(deadline=deadline)):
        return ""
    handins = store.of(student)
    names = exercise.hide

    def sym(n):
        return SYMBOLS_HTML.get(n, html.escape(n))

    rows = []
    for k, h in enumerate(handins, start=1):
        cells = []
        for n in names:
            v, ok = h.estimates.get(n), h.verdicts.get(n)
            if v is None:
                cells.append("—")
                continue
            text = f"{v:.5g} {'✓' if ok else '✗'}"
            if revealed:
                err = exercise.errors(student, h.estimates).get(n)
                text += f" ({100 * err:+.2f} %)" if err is not None else ""
            cells.append(text)
        rows.append(f"<tr><td>{k}</td><td>{html.escape(METHODS.get(h.method, h.method).split(' (')[0])}</td>"
                    + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    head = "".join(f"<th>{sym(n)}</th>" for n in names)
    table = (f"<table class='eha-table'><tr><th>hand-in</th><th>route</th>{head}</tr>{''.join(rows)}</table>"
             if rows else "<p>You handed nothing in.</p>")
    score = exercise.score([h.verdicts for h in handins]) if handins else 0.0
    if revealed:
        truth = exercise.student_params(student)
        from eha_core.param_table import FIELD_INFO

        values = ", ".join(f"{sym(n)} = {getattr(truth, n) / FIELD_INFO[n].display_scale:.5g} "
                           f"{FIELD_INFO[n].display_unit}" for n in names)
        title = f"Your teacher has revealed your actuator: {values}."
    else:
        title = "The deadline has passed: your hand-ins' verdicts."
    return (f"<div class='eha-reveal'><b>{title}</b> Score ({exercise.score_rule} hand-in): "
            f"{100 * score:.0f} %.{table}</div>")
