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
import secrets
import time
from collections.abc import Callable

import panel as pn

from eha_core.cancel import Cancelled
from eha_core.exercise import FEEDBACK, METHODS

from ..render.formatting import display_unit, num_html
from ..render.layout import BUTTON_CONTRAST
from ..render.tables import SYMBOLS_HTML
from ..runtime.extensions import HANDIN_PATIENCE_S, lab_rules, own_deadline
from ..runtime.outbox import RETRY_S, outbox
from ..runtime.tasks import apply_locked, on_click, served_document

__all__ = ["HandInBox", "handin_status", "result_for_student", "lab_rules_html", "lab_refusal", "impossible_estimates",
           "verdict_words", "own_deadline"]


def shown_value(name: str, value: float) -> str:
    """A handed-in value as every page writes it: in tab 1's unit (βe in GPa), five digits."""
    unit, scale = display_unit(name)
    return f"{num_html(float(value) / scale, 5)} {html.escape(unit)}".rstrip()


def impossible_estimates(estimates: dict) -> list[str]:
    """The estimates that break their parameter's physical bound (M, βe > 0; B, Af >= 0), each as the
    student reads it ("B = -1626 N s/m: must be ≥ 0"), in display units."""
    from eha_core.param_table import FIELD_INFO, physically_possible

    out = []
    for name, value in estimates.items():
        info = FIELD_INFO.get(name)
        if info is None or info.bound not in (">", ">=") or physically_possible(name, value):
            continue
        out.append(f"{SYMBOLS_HTML.get(name, html.escape(name))} = {float(value) / info.display_scale:.4g} "
                   f"{html.escape(info.display_unit)}: must be {'> 0' if info.bound == '>' else '≥ 0'}")
    return out


def route_model_errors(reference, estimates: dict, token) -> dict:
    """The route's own error on the student's experiment at the truth (``reference(cancel=token)``, a
    function of :mod:`eha_core.grading`), for the parameters handed in; {} without one, or when it
    cannot be computed (then the hand-in is judged against the truth alone, and the teacher sees
    that no model error was kept)."""
    if reference is None:
        return {}
    try:
        return {n: float(v) for n, v in reference(cancel=token).items() if n in estimates}
    except Cancelled:
        raise
    except (ValueError, ArithmeticError, RuntimeError):
        return {}


def verdict_words(exercise, name: str, judgement) -> str:
    """The verdict on one value as the student reads it: accepted or not, and the acceptance their
    record earned (k standard errors, from their own data: it says nothing of the truth)."""
    tol = f"±{100 * exercise.tolerance_of(name):g} %"
    band = "" if judgement.band is None else f"±{100 * judgement.band:.2g} %"
    if exercise.grading == "relative":
        return (f"<span class='eha-ok'>within {tol} ✓</span>" if judgement.ok else
                f"<span class='eha-warn'>not within {tol} ✗</span>")
    k = f"{exercise.k:g}"
    if judgement.ok:
        return f"<span class='eha-ok'>accepted ✓</span> (your record's acceptance: {k} standard errors, {band})"
    if judgement.reason == "imprecise":
        return (f"<span class='eha-warn'>not determined well enough ✗</span>: {k} standard errors of your record are "
                f"{band}, the lab asks for {tol}; a longer record or a richer input narrows it")
    if judgement.reason == "no-error":
        return "<span class='eha-warn'>no standard error ✗</span>: the route gave none, so it cannot be judged"
    return (f"<span class='eha-warn'>not accepted ✗</span>: further from the truth than {k} standard errors of your "
            f"record ({band})")


def lab_refusal(exercise, control: dict, count: int, *, now: float | None = None) -> str | None:
    """Why the student, with ``count`` hand-ins, may hand in nothing now under the teacher's switches
    ``control`` (None: they may)."""
    return exercise.refusal(count, now=now, open_=control.get("open", "1") == "1",
                            deadline=own_deadline(exercise, control), revealed=control.get("revealed") == "1")


def lab_rules_html(exercise, control: dict, count: int, *, now: float | None = None, why: str | None = None) -> str:
    """The lab's rules as they stand for this student, always on their page: the deadline (the teacher's
    extension if any), the hand-ins used and left, the tolerances, what feedback they get and when, and
    the routes taken; and ``why`` hand-ins are refused now (default :func:`lab_refusal`), if they are."""
    import time as _time

    now = _time.time() if now is None else now
    deadline = own_deadline(exercise, control)
    due = exercise.deadline_at(deadline)
    if due is None:
        when = "no deadline"
    else:
        left = due - now
        rel = ("passed" if left <= 0 else f"in {left / 86400:.0f} days" if left >= 2 * 86400
               else f"in {left / 3600:.0f} h" if left >= 2 * 3600 else f"in {max(left / 60, 1):.0f} min")
        own = " extended for you" if deadline == control.get("extension") else ""
        when = f"deadline{own} {_time.strftime('%Y-%m-%d %H:%M UTC', _time.gmtime(due))} ({rel})"
    if exercise.release_at:
        at = _time.strftime('%Y-%m-%d %H:%M UTC', _time.gmtime(exercise.deadline_at(exercise.release_at)))
        when += (f"; your true values were released at {at}" if exercise.released(now)
                 else f"; your true values are shown from {at}")
    if exercise.attempts:
        used = f"hand-ins: {count} of {exercise.attempts} used, {max(exercise.attempts - count, 0)} left"
    else:
        used = f"hand-ins: {count} so far, no limit"
    score = exercise.score_text()
    tols = {exercise.tolerance_of(n) for n in exercise.hide}
    names = ", ".join(SYMBOLS_HTML.get(n, html.escape(n)) for n in exercise.hide)
    if len(tols) == 1:
        one = f"±{100 * tols.pop():g} %"
        each, within = f"{one} ({names})", f"each of {names} within {one}"
    else:
        each = within = ", ".join(f"{SYMBOLS_HTML.get(n, html.escape(n))} ±{100 * exercise.tolerance_of(n):g} %"
                                  for n in exercise.hide)
    if exercise.grading == "zscore":
        label = "grading"
        tol = (f"a value counts within {exercise.k:g} standard errors of your record from the truth (at least "
               f"{100 * exercise.floor:g} % of it), when {exercise.k:g} standard errors are at most {each}: a "
               "better experiment earns a tighter acceptance")
    else:
        label, tol = "tolerance", within
    routes = ", ".join(html.escape(METHODS[m].split(" (")[0]) for m in exercise.conditions.methods if m in METHODS)
    feedback = html.escape(FEEDBACK.get(exercise.feedback, exercise.feedback))
    why = lab_refusal(exercise, control, count, now=now) if why is None else why
    closed = f" <b class='eha-warn'>Hand-ins are refused now: {html.escape(why)}.</b>" if why else ""
    return (f"<div class='eha-lab-rules' role='status'><b>The lab's rules:</b> {when}; {used} ({score}); "
            f"{label}: {tol}; feedback: {feedback}; routes taken: {routes}.{closed}</div>")


def handin_status(state) -> tuple[str | None, int]:
    """(why a hand-in is refused now or None, hand-ins so far) for the session's student; the
    teacher's switches are read from the store (a closed or extended exercise holds at once)."""
    ex, store = state.exercise, state.handins
    control = store.control_for(state.student)
    count = len(store.of(state.student))
    return lab_refusal(ex, control, count), count


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
                                        visible=allowed, disabled=True, description="run first",
                                        stylesheets=[BUTTON_CONTRAST])
        on_click(self.button, lambda _e: self.hand_in())
        self.verdict = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-verdict"])
        # the section's own view of the button (a result to hand in, and its tip), before the lab's rules
        self._enabled, self._tip = False, "run first"
        # the question asked before an impossible estimate uses an attempt (made when first asked)
        self.confirm = pn.Column(visible=False, width=270, css_classes=["eha-handin-confirm"])
        self._asked: dict | None = None
        section.session.handin_boxes.append(self)

    @property
    def takes_files(self) -> bool:
        """Does the exercise take hand-ins from an uploaded file (labelled so)?"""
        ex = self.section.state.exercise
        return ex is not None and bool(getattr(ex, "own_files", False))

    def set_tip(self, enabled: bool, tip: str) -> None:
        """The section's say: is there a result to hand in, and the button's tip. The lab's rules come
        on top: when hand-ins are refused now (no attempt left, the deadline passed, closed), the
        button is off and its tip says why."""
        self._enabled, self._tip = enabled, tip
        why = self.section.session.lab_refusal
        self.button.disabled = not enabled or bool(why)
        tip = f"no hand-in now: {why}" if why else tip
        if self.button.description != tip:
            self.button.description = tip

    def rules_changed(self) -> None:
        """The page read the lab's rules again (:attr:`Session.lab_refusal`): the button follows."""
        self.set_tip(self._enabled, self._tip)
        if self.section.session.lab_refusal and self.confirm.visible:
            self.confirm.visible = False

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

    def _ask(self, estimates: dict, impossible: list[str]) -> None:
        """Ask before an impossible estimate uses an attempt: what is impossible, the attempt it would
        use, and two buttons (hand in anyway, or not)."""
        session, exercise = self.section.session, self.section.state.exercise
        used = session.handins_used
        attempt = ("" if not exercise.attempts or used is None else
                   f" It would use hand-in {used + 1} of {exercise.attempts}.")
        if not self.confirm.objects:
            yes = pn.widgets.Button(label="Hand in anyway", color="danger", width=130,
                                    css_classes=["eha-handin-anyway"], stylesheets=[BUTTON_CONTRAST])
            no = pn.widgets.Button(label="Keep it", width=110, css_classes=["eha-handin-keep"])
            on_click(yes, lambda _e: self._answered(True))
            on_click(no, lambda _e: self._answered(False))
            self.confirm.objects = [pn.pane.HTML("", sizing_mode="stretch_width"), pn.Row(yes, no)]
        items = "".join(f"<li>{text}</li>" for text in impossible)
        self.confirm[0].object = (f"<div class='eha-verdict-box' role='alert'><b class='eha-warn'>Physically "
                                  f"impossible:</b><ul>{items}</ul>No actuator has such a value: it cannot be "
                                  f"accepted.{attempt} Hand it in anyway?</div>")
        self._asked = dict(estimates)
        self.confirm.visible = True

    def _answered(self, yes: bool) -> None:
        asked, self._asked = self._asked, None
        self.confirm.visible = False
        if yes and asked is not None:
            self.hand_in(confirmed=asked)

    def hand_in(self, confirmed: dict | None = None):
        """Store the section's estimates as a hand-in; show what the feedback rule allows. An estimate
        that breaks a physical bound is asked about first (``confirmed``: the estimates the student
        said yes to; the hand-in goes ahead only if they are still the section's)."""
        s = self.section.state
        why = self.refusal()
        if why and s.hidden:
            self.show_refusal(why)
            return None
        if s.hidden and outbox().waiting(s.student):
            # one waits to be saved (the database is down): a second would take another attempt unseen
            self.verdict.object = ("<div class='eha-verdict-box eha-handin-waiting' role='status'>Your last hand-in "
                                   "is still waiting to be saved; hand in again once it is (this box says so).</div>")
            self.verdict.visible = True
            return None
        got = self.estimates()
        if got is None or not s.hidden:
            return None
        estimates, settings = got
        impossible = impossible_estimates(estimates)
        if impossible and confirmed != estimates:
            self._ask(estimates, impossible)
            return None
        self.confirm.visible = False
        exercise, student, store, method = s.exercise, s.student, s.handins, self.method
        settings = dict(settings)
        source = dict(settings.pop("_source", None) or {"kind": "simulated"})
        # the standard errors this server computed on the student's record (zscore grading), kept with
        # the hand-in so the teacher's table can show each value's z-score
        std_errors = {n: float(v) for n, v in dict(settings.pop("_se", None) or {}).items()}
        settings["std_errors"] = std_errors
        # the route's own error on the student's experiment, at the truth: computed in the worker below
        reference = settings.pop("_model_error", None)
        from_file = source.get("kind") == "file"
        # a file's data were not taken under the exercise's conditions: its hand-in says so, not the noise floors
        conditions = ({"data": "an uploaded file"} if from_file
                      else {**exercise.conditions.to_dict(), **settings.pop("_conditions", {})})
        settings.pop("_conditions", None)

        # the hand-in's own key: sent again (a lost connection, a database that was down), it is stored once
        key = secrets.token_hex(12)
        rules = {"method": method, "source": source.get("kind"), "at": time.time()}

        def compute(_token):
            from ..runtime.handins import WRITE_PATIENCE_S, Refused, StoreUnavailable

            model_errors = route_model_errors(reference, estimates, _token)
            settings["model_errors"] = model_errors
            judged = exercise.judge(student, estimates, std_errors, model_errors)
            verdicts = {n: j.ok for n, j in judged.items()}
            seen = {}
            refusal = lab_rules(exercise, rules, seen)
            handin = dict(student=student, estimates=estimates, verdicts=verdicts, method=method, settings=settings,
                          conditions=conditions, errors=exercise.errors(student, estimates), source=source,
                          refusal=refusal, key=key)
            # a database that is down is waited for a few seconds before the hand-in waits in the outbox; a
            # SQLite file locked by another program keeps the whole patience of a write
            patience = HANDIN_PATIENCE_S if store.backend.kind == "postgresql" else WRITE_PATIENCE_S
            try:
                store.add(**handin, patience=patience)
            except Refused as exc:
                return None, str(exc), 0, False
            except StoreUnavailable as exc:
                # the database is down: this server keeps the hand-in and saves it when it answers
                outbox().put(store, handin, on_done=lambda row, why: saved_later(judged, row, why, seen),
                             refusal_spec=rules)
                return judged, "", -1, str(exc)
            count = len(store.of(student))
            shows = exercise.shows_verdicts(deadline=own_deadline(exercise, seen), revealed=seen.get("revealed") == "1")
            return judged, "", count, shows

        def saved_later(judged, row, why, seen):
            def show_saved():
                if why:
                    show((None, why, 0, False), None)
                    return
                try:
                    count = len(store.of(student))
                except Exception:  # noqa: BLE001 - read again at the page's next look
                    count = 0
                shows = exercise.shows_verdicts(deadline=own_deadline(exercise, seen),
                                                revealed=seen.get("revealed") == "1")
                show((judged, "", count, shows), None)
            apply_locked(show_saved, doc)

        session = self.section.session
        doc = served_document()

        def show(out, _job):
            self._show_outcome(out, exercise, method, estimates, source, session)

        def fail(message):
            # nothing was stored (the class's database is damaged or gone): say so, not "identification failed"
            self.verdict.object = (f"<div class='eha-verdict-box'><span class='eha-warn'>Your hand-in was not "
                                   f"stored: {html.escape(message)}. Tell your teacher; your estimates stay "
                                   "here and you can hand in again.</span></div>")
            self.verdict.visible = True

        return self.section.runner.run("hand-in", compute, show, fail=fail, note=self.section._note)

    def _show_outcome(self, out, exercise, method: str, estimates: dict, source: dict, session) -> None:
        """What became of a hand-in: stored (with what the feedback rule allows), refused, or waiting to be
        saved (``count`` -1: the database was down)."""
        judged, refused, count, shows = out
        self._refusal_shown = False         # the verdict pane says this hand-in's outcome now
        if count == -1:
            self.verdict.object = (
                "<div class='eha-verdict-box eha-handin-waiting' role='status'><b>Your hand-in is waiting to be "
                "saved.</b> The class's database cannot be reached just now; this server keeps your hand-in and "
                f"tries again every {RETRY_S:.0f} s, and it is saved as soon as the database answers (it counts "
                "once, however often it is tried, and the deadline is the time you handed in). Keep working; no "
                "need to hand in again.</div>")
            self.verdict.visible = True
            return
        for fn in list(session.after_handin):
            fn()                            # the page reads the lab's rules again (attempts left)
        if refused:
            self.verdict.object = (f"<div class='eha-verdict-box eha-handin-refused'><span class='eha-warn'>"
                                   f"Not handed in: {html.escape(refused)}.</span></div>")
            self.verdict.visible = True
            return
        limit = f" of {exercise.attempts} allowed" if exercise.attempts else ""
        origin = f" on your file {html.escape(source.get('name', ''))}" if source.get('kind') == 'file' else ""
        head = (f"<b>Handed in</b> (hand-in {count}{limit}, from the "
                f"{html.escape(METHODS[method].split(' (')[0])}{origin})")
        values = "".join(f"<li>{SYMBOLS_HTML.get(n, html.escape(n))} = {shown_value(n, v)}"
                         for n, v in estimates.items())
        if shows:
            score = sum(j.ok for j in judged.values())
            items = "".join(
                f"<li>{SYMBOLS_HTML.get(n, html.escape(n))} "
                + ("not handed in from this route ✗" if n not in estimates else
                   f"= {shown_value(n, estimates[n])}: " + verdict_words(exercise, n, j))
                + "</li>" for n, j in judged.items())
            body = f"{head}: {score} of {len(judged)} accepted.<ul>{items}</ul>"
        elif exercise.feedback == "after-deadline":
            body = (f"{head}.<ul>{values}</ul>The verdicts are shown after the deadline"
                    + (f" ({html.escape(exercise.deadline)})" if exercise.deadline else "") + ".")
        else:
            body = f"{head}.<ul>{values}</ul>Your teacher will tell you the result."
        self.verdict.object = f"<div class='eha-verdict-box'>{body}</div>"
        self.verdict.visible = True


def result_for_student(exercise, student: str, store, control: dict | None = None) -> str:
    """What the student may now see of their result ("" for nothing yet): after the teacher's reveal (or
    once the exercise's release date has come), their actuator's true hidden values and each hand-in's
    errors; after their deadline (feedback "after-deadline"), the verdicts of their hand-ins."""
    control = store.control_for(student) if control is None else control
    released = exercise.released()
    revealed = control.get("revealed") == "1" or released
    deadline = own_deadline(exercise, control)
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
            text = f"{shown_value(n, v)} {'✓' if ok else '✗'}"
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
        values = ", ".join(f"{sym(n)} = {shown_value(n, getattr(truth, n))}" for n in names)
        title = (f"Your actuator, released at {html.escape(exercise.release_at)}: {values}." if released
                 and control.get("revealed") != "1" else f"Your teacher has revealed your actuator: {values}.")
    else:
        title = "The deadline has passed: your hand-ins' verdicts."
    return (f"<div class='eha-reveal'><b>{title}</b> Score ({html.escape(exercise.score_text())}): "
            f"{100 * score:.0f} %.{table}</div>")
