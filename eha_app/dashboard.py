"""The teacher's dashboard (``/teacher``): the exercise's rules, the class's results live, the switches.

The page shows the rules of the running exercise (hidden parameters with their
tolerances, the conditions, the deadline with the teacher's extension, attempts,
feedback, score rule, open or closed, revealed or not), the class table of
:func:`~eha_app.runtime.classbook.class_rows` (the one ``eha exercise results``
prints, with each value's error against the truth: the teacher's only) and every
hand-in, newest first. It follows the class without a reload: every
:data:`POLL_MS` the page asks the hand-in database for its version (off the
event loop) and draws again only when it changed, or when the deadline passed.

Its buttons write through :meth:`~eha_app.runtime.handins.HandIns.set_control`,
so every server process (and ``eha exercise results``) sees the same switches:
open or close hand-ins, move the deadline, give one student a later deadline of
their own (:meth:`~eha_app.runtime.handins.HandIns.set_extension`, listed under the
form), reveal the verdicts to the students once the deadline (and every
extension) has passed; the rules say when the exercise file releases the true
values by itself (``release_at``). And it offers the results as CSV and, with a
roster, the join-code slips to print. A reveal is final: from then on every
student's page shows the truth, so no hand-in is taken whatever the deadline
or the open switch say, and the page says so beside both.

Nothing here waits on the database on the server's event loop: the reads are
made in a thread (:meth:`Dashboard.tick`), the switches are written by
:func:`~eha_app.runtime.store_calls.call`, and the CSV is made from the table
as last read.

Everything a student typed (an id) or the teacher's roster holds (a name) is
HTML-escaped before it is drawn. Nothing here reaches a student: the page is
served at /teacher, which answers the teacher's cookie only
(:mod:`eha_app.runtime.teacher_access`).
"""

from __future__ import annotations

import asyncio
import html
import io
import time

import panel as pn

from eha_core.errors import not_allowed
from eha_core.exercise import FEEDBACK, METHODS, parse_deadline

from .render.formatting import display_unit
from .render.tables import SYMBOLS_HTML, UNITS
from .runtime import store_calls
from .runtime.classbook import (
    ClassRow,
    class_rows,
    describe_conditions,
    describe_pages,
    describe_source,
    handin_errors,
    handin_judgements,
    results_csv,
)
from .runtime.extensions import STUDENT_FIELD, check_extension
from .runtime.handins import StoreError
from .runtime.tasks import held, on_click, served_document, watch

__all__ = ["Dashboard", "serve_dashboard", "POLL_MS", "join_slips_html"]

#: How often the page asks the database whether anything changed.
POLL_MS = 2000
EVERYONE = "(everyone)"

CSS = """
table { border-collapse: collapse; font-size: 13px; width: 100%; }
th, td { border-bottom: 1px solid #ddd; padding: 3px 6px; text-align: left; vertical-align: top; }
th { background: #f3f5f8; position: sticky; top: 0; white-space: nowrap; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.ok { color: #11703a; } .no { color: #b00020; } .dim { color: #777; }
.small { font-size: 11px; color: #555; font-weight: normal; }
dl { display: grid; grid-template-columns: max-content 1fr; gap: 3px 12px; margin: 0; font-size: 13px; }
dt { color: #555; } dd { margin: 0; }
.scroll { max-height: 360px; overflow-y: auto; }
.badge { padding: 1px 6px; border-radius: 3px; font-weight: 600; }
.badge.open { background: #dff3e6; color: #11703a; }
.badge.closed { background: #fbe3e6; color: #b00020; }
"""


def _esc(text) -> str:
    return html.escape(str(text), quote=True)


def _when(stamp: str, today: str) -> str:
    """A stored time (``YYYY-MM-DD HH:MM:SS``) as the table shows it: the time alone if it is today's."""
    if not stamp:
        return "<span class='dim'>—</span>"
    shown = stamp[11:] if stamp.startswith(today) else stamp
    return f"<span title='{_esc(stamp)}'>{_esc(shown)}</span>"


def _param_head(exercise, name: str) -> str:
    unit = display_unit(name, UNITS.get(name, "SI"))[0]
    return (f"{SYMBOLS_HTML.get(name, _esc(name))} <span class='small'>[{_esc(unit)}] "
            f"±{100 * exercise.tolerance_of(name):g} %</span>")


def _param_cell(name: str, value, error, verdict, count: int, z=None, reason: str = "") -> str:
    """A value (in the unit its column names, as the students' pages write it) with its error against
    the truth, its z-score (the error in standard errors of the student's record) and its verdict, in
    one cell."""
    if not count:
        return "<td class='num dim'>—</td>"
    scale = display_unit(name)[1]
    shown = f"{value / scale:.6g}" if isinstance(value, (int, float)) else "<span class='dim'>none</span>"
    err = f"{100 * error:+.2f} %" if isinstance(error, (int, float)) else "—"
    mark = "<span class='ok'>✓</span>" if verdict else "<span class='no'>✗</span>"
    zs = f" <span class='small'>z {z:+.1f}</span>" if isinstance(z, (int, float)) else ""
    if reason == "imprecise":
        zs += (" <span class='small no' title='k standard errors of the record exceed the tolerance'>not "
               "determined</span>")
    return f"<td class='num'>{shown} <span class='small {'ok' if verdict else 'no'}'>{err}</span>{zs} {mark}</td>"


def _variant_tag(exercise, student: str) -> str:
    try:
        name = exercise.variant_of(student)
    except ValueError:                  # an id the app now refuses (stored by an older version)
        return ""
    return f" <span class='small eha-dash-variant'>({_esc(name)})</span>"


def _method(method: str) -> str:
    return _esc(METHODS.get(method, method).split(" (")[0]) if method else ""


def _conditions(conditions: dict) -> str:
    if not conditions:
        return ""
    text = describe_conditions(conditions)
    cut = text if len(text) <= 80 else text[:79] + "…"
    return f"<span class='small' title='{_esc(text)}'>{_esc(cut)}</span>"


def _source(row) -> str:
    text = describe_source(row)
    if not text:
        return ""
    warn = row.source.get("kind") == "file" or row.damaged
    return f"<span class='small{' no' if warn else ''}' title='{_esc(text)}'>{_esc(text)}</span>"


def _one(handin) -> ClassRow:
    """One hand-in as a row of its own (where its data came from, in the history's terms)."""
    return ClassRow(handin.student, "", count=1, source=handin.source, damaged=int(handin.damaged))


def _pages(row) -> str:
    text = describe_pages(row)
    return f"<span class='{'no' if row.overlaps else 'small'}'>{_esc(text)}</span>" if text else ""


def join_slips_html(exercise, student_url: str) -> str:
    """A page of slips to print and cut: each student's name, id, join code and the app's address."""
    slips = "".join(
        f"<div class='slip'><div class='name'>{_esc(e.name)}</div><div>id: <b>{_esc(e.id)}</b></div>"
        f"<div>join code: <b class='code'>{_esc(exercise.join_code(e.id))}</b></div>"
        f"<div>open <b>{_esc(student_url)}</b></div></div>" for e in exercise.roster)
    return f"""<!DOCTYPE html><html><head><meta charset="utf-8"><title>{_esc(exercise.title)}: join codes</title>
<style>
body {{ font-family: sans-serif; margin: 10mm; }}
.slips {{ display: grid; grid-template-columns: 1fr 1fr; gap: 0; }}
.slip {{ border: 1px dashed #888; padding: 6mm; break-inside: avoid; font-size: 12pt; line-height: 1.6; }}
.name {{ font-size: 14pt; font-weight: bold; }}
.code {{ font-family: monospace; font-size: 15pt; letter-spacing: 1px; }}
</style></head><body><h3>{_esc(exercise.title)}: your join code (keep it to yourself)</h3>
<div class="slips">{slips}</div></body></html>
"""


class Dashboard(pn.viewable.Viewer):
    """The teacher's page for ``exercise`` and its hand-in ``store`` (see the module docstring).

    ``clock``: the time now (tests); ``student_url``: the app's address for the join-code slips.
    """

    def __init__(self, exercise, store, *, clock=time.time, student_url: str = "", **params):
        super().__init__(**params)
        self.exercise, self.store, self.clock, self.student_url = exercise, store, clock, student_url
        self._key = None            # what was drawn: the database's version and whether the deadline had passed
        self._busy = False
        self.control: dict[str, str] = {}
        self.rows = []
        self.handins = []
        self.refusals = []
        self.extensions: dict[str, tuple[str, str]] = {}        # student -> (their deadline, when it was set)
        self.rules = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-dash-rules"],
                                   stylesheets=[CSS])
        self.summary = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-dash-summary"],
                                   stylesheets=[CSS])
        self.roster = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-dash-roster"],
                                   stylesheets=[CSS])
        self.history = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-dash-history"],
                                   stylesheets=[CSS])
        self.who = pn.widgets.Select(label="Hand-ins of", options=[EVERYONE], value=EVERYONE, width=260,
                                     css_classes=["eha-dash-who"])
        self.open_button = pn.widgets.Button(label="Close hand-ins", width=170, css_classes=["eha-dash-open"])
        self.deadline_input = pn.widgets.TextInput(label="New deadline (ISO-8601; empty: the file's)",
                                                   placeholder="e.g. 2026-12-01T17:00", width=260,
                                                   css_classes=["eha-dash-deadline"])
        self.deadline_button = pn.widgets.Button(label="Set the deadline", width=150, align="end",
                                                 css_classes=["eha-dash-set-deadline"])
        self.deadline_message = pn.pane.HTML("", css_classes=["eha-error", "eha-error-deadline"], width=420,
                                             styles={"color": "#b00020", "font-size": "12px"})
        # one student's later deadline: "Extend the deadline for [id] until [date]", and the extensions granted
        self.extension_student = pn.widgets.TextInput(label="Extend the deadline for (student id)", width=200,
                                                      placeholder="e.g. s1234567",
                                                      css_classes=["eha-dash-extension-student"])
        self.extension_until = pn.widgets.TextInput(label="until (ISO-8601; empty: take it away)", width=220,
                                                    placeholder="e.g. 2026-12-08T17:00",
                                                    css_classes=["eha-dash-extension-until"])
        self.extension_button = pn.widgets.Button(label="Extend", width=90, align="end",
                                                  css_classes=["eha-dash-extend"])
        self.extension_student_message = pn.pane.HTML("", css_classes=["eha-error", "eha-error-extension-student"],
                                                      width=420, styles={"color": "#b00020", "font-size": "12px"})
        self.extension_until_message = pn.pane.HTML("", css_classes=["eha-error", "eha-error-extension-until"],
                                                    width=420, styles={"color": "#b00020", "font-size": "12px"})
        self.extensions_pane = pn.pane.HTML("", css_classes=["eha-dash-extensions"], width=540,
                                            styles={"font-size": "12px"})
        self.reveal_button = pn.widgets.Button(label="Reveal the verdicts to the students", width=270,
                                               css_classes=["eha-dash-reveal"])
        self.reveal_message = pn.pane.HTML("", css_classes=["eha-dash-reveal-message"], width=420,
                                           styles={"font-size": "12px"})
        self._read_failed = False
        self.note = pn.pane.HTML("", css_classes=["eha-dash-note"], styles={"font-size": "12px"},
                                 sizing_mode="stretch_width")
        self.csv = pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.csv_bytes()), filename="results.csv",
                                           label="Download the results (CSV)", width=230,
                                           css_classes=["eha-dash-csv"])
        self.slips = pn.widgets.FileDownload(callback=lambda: io.BytesIO(self.slips_bytes()),
                                             filename="join-codes.html", label="Join-code slips to print",
                                             width=230, visible=exercise.has_roster, css_classes=["eha-dash-slips"])
        on_click(self.open_button, lambda _e: self.toggle_open())
        on_click(self.deadline_button, lambda _e: self.set_deadline())
        on_click(self.reveal_button, lambda _e: self.reveal())
        on_click(self.extension_button, lambda _e: self.extend())
        watch(self.who, lambda _e: self._draw_history(), "value")
        actions = pn.Column(
            pn.pane.HTML("<h3 style='margin:4px 0'>Switches</h3>"),
            pn.Row(self.open_button, self.reveal_button), self.reveal_message,
            pn.Row(self.deadline_input, self.deadline_button), self.deadline_message,
            pn.Row(self.extension_student, self.extension_until, self.extension_button),
            self.extension_student_message, self.extension_until_message, self.extensions_pane,
            pn.Row(self.csv, self.slips), self.note, width=560, css_classes=["eha-dash-actions"])
        self.layout = pn.Column(
            pn.Row(self.rules, actions, sizing_mode="stretch_width"),
            self.summary, self.roster,
            pn.Row(pn.pane.HTML("<h3 style='margin:8px 0 0'>Every hand-in, newest first</h3>"), self.who),
            self.history, sizing_mode="stretch_width", margin=(0, 12), css_classes=["eha-dash"])
        self.doc = served_document()
        if self.doc is None:
            self.poll()             # no server: read now (a served page reads in its first tick, off the loop)
        else:
            self.summary.object = "<span class='small'>Reading the class's results…</span>"

    # -- reading and drawing --------------------------------------------------------------------------
    def _passed(self, control: dict | None = None) -> bool:
        due = self.exercise.deadline_at((control if control is not None else self.control).get("deadline") or None)
        return due is not None and self.clock() > due

    def _released(self) -> bool:
        return self.exercise.released(self.clock())

    def _key_now(self) -> tuple:
        # an extension's passing is drawn without a change, as the deadline's and the release's are
        return self.store.version(), self._passed(), self._released(), tuple(self._pending_extensions())

    def _read(self) -> tuple:
        control, extensions = self.store.control(), self.store.extensions()
        return (self.store.version(), self._passed(control), self._released(),
                tuple(self._pending_extensions(extensions, control))), control, \
            class_rows(self.exercise, self.store), self.store.all(), self.store.refusals(), extensions

    def poll(self) -> bool:
        """Read the database now and draw what changed (True: something did). The page's periodic
        callback does the same off the event loop (:meth:`tick`)."""
        try:
            key = self._key_now()
            self._answers_again()
            if self._key is not None and key == self._key:
                return False
            self._show(self._read())
        except StoreError as exc:
            self._failed(exc)
        return True

    async def tick(self) -> None:
        """The periodic callback: the database read in a thread, the drawing under the page's lock."""
        if self._busy:
            return
        self._busy = True
        try:
            key = await asyncio.to_thread(self._key_now)
            self._answers_again()
            if key != self._key:
                self._show(await asyncio.to_thread(self._read))
        except StoreError as exc:
            self._failed(exc)
        finally:
            self._busy = False

    def _answers_again(self) -> None:
        if self._read_failed:
            # the database answers again (PostgreSQL was restarting): its error is no longer news
            self._read_failed = False
            self.note.object = (f"<span class='small'>The class's database answers again "
                                f"({time.strftime('%H:%M:%S')}).</span>")

    def _failed(self, exc: Exception) -> None:
        self.note.object = f"<span style='color:#b00020'>{_esc(exc)}</span>"
        self._read_failed = True

    def refresh(self) -> None:
        """Read again now (after a switch): off the event loop when served."""
        if self.doc is None:
            self.poll()
            return
        self._key = None
        store_calls.call(self._read, self._show, fail=self._failed, doc=self.doc)

    def _show(self, data: tuple) -> None:
        self._key, self.control, self.rows, self.handins, self.refusals, self.extensions = data
        with held():
            self._draw_rules()
            self._draw_extensions()
            self._draw_roster()
            options = [EVERYONE] + [r.id for r in self.rows if r.count]
            if self.who.options != options:
                self.who.options = options
                if self.who.value not in options:
                    self.who.value = EVERYONE
            self._draw_history()

    @property
    def is_open(self) -> bool:
        return self.control.get("open", "1") != "0"

    @property
    def revealed(self) -> bool:
        return self.control.get("revealed", "0") == "1"

    def _deadline_text(self) -> str:
        ex, override = self.exercise, self.control.get("deadline", "")
        if not (override or ex.deadline):
            return "none"
        text = _esc(override or ex.deadline)
        if override and override != ex.deadline:
            text += f" <span class='small'>(moved by you; the file's: {_esc(ex.deadline or 'none')})</span>"
        return text + (" <span class='no'>— passed</span>" if self._passed() else "")

    def _draw_rules(self) -> None:
        ex = self.exercise
        hidden = ", ".join(f"{SYMBOLS_HTML.get(n, _esc(n))} ±{100 * ex.tolerance_of(n):g} %" for n in ex.hide)
        students = (f"a roster of {len(ex.roster)}, each with a join code" if ex.has_roster
                    else "an open exercise: any id typed is taken as given")
        status = ("<span class='badge open'>open</span>" if self.is_open
                  else "<span class='badge closed'>closed</span>")
        if self.revealed:
            status = ("<span class='badge closed'>closed for good</span> <span class='small'>(the true values "
                      "were revealed: no hand-in is taken, whatever the deadline or the open switch say)</span>")
        elif self._released():
            status = (f"<span class='badge closed'>closed for good</span> <span class='small'>(the true values were "
                      f"released at {_esc(ex.release_at)}: no hand-in is taken)</span>")
        elif self._passed():
            later = self._pending_extensions()
            status += (" <span class='small'>(the deadline has passed: no hand-in is taken"
                       + (f", except from {len(later)} student{'s' if len(later) > 1 else ''} with a later deadline "
                          "of their own" if later else "") + ")</span>")
        if ex.release_at:
            release = (f"{_esc(ex.release_at)}: every student sees their own true values from then on, and no hand-in "
                       "is taken" + (" <span class='no'>— released</span>" if self._released() else ""))
        else:
            release = "no date: only when you reveal them"
        self.rules.object = (
            f"<h2 style='margin:4px 0'>{_esc(ex.title)} <span class='small'>teacher's dashboard</span></h2><dl>"
            f"<dt>Hidden (tolerance)</dt><dd>{hidden}; each student's within ±{100 * ex.vary:g} % of the paper's</dd>"
            f"<dt>Conditions</dt><dd>{_esc(ex.conditions.describe())}</dd>"
            + (f"<dt>Actuators</dt><dd>each student's drawn from {_esc(', '.join(ex.variants))} (the class table "
               "says whose is which; students are not told)</dd>" if len(ex.variants) > 1 else "")
            + f"<dt>Deadline</dt><dd>{self._deadline_text()}</dd>"
            f"<dt>Truth released</dt><dd>{release}</dd>"
            f"<dt>Hand-ins allowed</dt><dd>{ex.attempts or 'no limit'}</dd>"
            f"<dt>Feedback</dt><dd>{_esc(FEEDBACK.get(ex.feedback, ex.feedback))}</dd>"
            f"<dt>Grading</dt><dd>{_esc(ex.grading_text())}</dd>"
            f"<dt>Score</dt><dd>{_esc(ex.score_text())}: its share of parameters accepted</dd>"
            f"<dt>Students</dt><dd>{students}</dd>"
            f"<dt>Hand-ins</dt><dd>{status}</dd>"
            f"<dt>Verdicts revealed</dt><dd>{'yes' if self.revealed else 'no'}</dd></dl>")
        self.open_button.label = "Close hand-ins" if self.is_open else "Open hand-ins"
        self.open_button.color = "danger" if self.is_open else "success"
        self.reveal_button.disabled = self.revealed
        self.reveal_button.label = ("Verdicts revealed" if self.revealed else "Reveal the verdicts to the students")
        # after a reveal neither switch can open hand-ins again: they say why before anyone tries
        self.open_button.disabled = self.deadline_button.disabled = self.deadline_input.disabled = self.revealed
        if self.revealed:
            self.open_button.label = "Hand-ins closed for good"
            self.deadline_message.object = ("The true values are revealed on every student's page: hand-ins are "
                                            "closed for good, and moving the deadline would reopen nothing.")
        self.reveal_button.description = ("Final: every student sees their true values, and no hand-in is taken "
                                          "after it, whatever the deadline says" if not self.revealed else None)

    def _draw_roster(self) -> None:
        ex, rows = self.exercise, self.rows
        today = time.strftime("%Y-%m-%d")
        joined = sum(1 for r in rows if r.joined)
        handed = sum(1 for r in rows if r.count)
        of = f" of {len(ex.roster)}" if ex.has_roster else ""
        self.summary.object = (f"<h3 style='margin:8px 0 2px'>The class</h3><span class='small'>{joined}{of} joined, "
                               f"{handed} handed in, {sum(r.count for r in rows)} hand-ins in all; updated "
                               f"{time.strftime('%H:%M:%S')}</span>")
        # two groups kept apart: the last hand-in (its time, route and values) and the score (the best and
        # the last hand-in's, the one the exercise's rule counts in bold)
        # the best and the last hand-in's scores, then the one the exercise's rule counts (in bold)
        counts = ("best", "last", "score")
        group = (f"<tr><th colspan='6'>student</th><th colspan='{2 + len(ex.hide)}' class='group'>last hand-in</th>"
                 f"<th colspan='3' class='group'>score ({_esc(ex.score_text())})</th>"
                 "<th colspan='3'></th></tr>")
        head = group + ("<tr><th>id</th><th>name</th><th>joined</th><th>last seen</th><th>hand-ins</th><th>refused</th>"
                        "<th>time</th><th>route</th>" + "".join(f"<th>{_param_head(ex, n)}</th>" for n in ex.hide)
                        + "<th>best</th><th>last</th><th><b>counted</b></th>"
                        + "<th>data</th><th>conditions</th><th>pages</th></tr>")
        body = []
        for r in rows:
            cells = "".join(_param_cell(n, r.estimates.get(n), r.errors.get(n), r.verdicts.get(n), r.count,
                                        r.zscores.get(n), r.reasons.get(n, ""))
                            for n in ex.hide)
            scores = "".join(
                ("<td class='num dim'>—</td>" if not r.count else
                 f"<td class='num'>{'<b>' if k == 'score' else ''}{getattr(r, k):.2f}"
                 f"{'</b>' if k == 'score' else ''}</td>") for k in counts)
            refused = (f"<td class='num no' title='{_esc('; '.join(r.refused))}'>{len(r.refused)}</td>" if r.refused
                       else "<td class='num dim'>0</td>")
            # the student's variant, when the pool has several (the teacher's: a student is never told)
            kind = _variant_tag(ex, r.id) if len(ex.variants) > 1 else ""
            body.append(f"<tr><td>{_esc(r.id)}</td><td>{_esc(r.name)}{kind}</td><td>{_when(r.joined, today)}</td>"
                        f"<td>{_when(r.last_seen, today)}</td><td class='num'>{r.count}</td>{refused}"
                        f"<td>{_when(r.last_time, today)}</td><td>{_method(r.method)}</td>{cells}"
                        f"{scores}<td>{_source(r)}</td><td>{_conditions(r.conditions)}</td>"
                        f"<td>{_pages(r)}</td></tr>")
        if not body:
            body.append(f"<tr><td colspan='{14 + len(ex.hide)}' class='dim'>Nobody has joined yet.</td></tr>")
        self.roster.object = f"<div class='scroll'><table>{head}{''.join(body)}</table></div>"

    def _draw_history(self) -> None:
        ex = self.exercise
        names = {e.id: e.name for e in ex.roster}
        who = self.who.value
        handins = [h for h in reversed(self.handins) if who in (EVERYONE, None) or h.student == who]
        today = time.strftime("%Y-%m-%d")
        counts: dict[str, int] = {}
        numbers: dict[int, int] = {}            # a hand-in's row id -> its number among its student's
        for h in self.handins:
            counts[h.student] = numbers[h.id] = counts.get(h.student, 0) + 1
        head = ("<tr><th>time</th><th>id</th><th>name</th><th>n°</th><th>method</th>"
                + "".join(f"<th>{_param_head(ex, n)}</th>" for n in ex.hide)
                + "<th>score</th><th>data</th><th>conditions</th></tr>")
        body = []
        for h in handins:
            errors = h.errors or handin_errors(ex, h.student, h)
            judged = handin_judgements(ex, h.student, h)
            cells = "".join(_param_cell(n, h.estimates.get(n), errors.get(n), h.verdicts.get(n), 1,
                                        getattr(judged.get(n), "z", None), getattr(judged.get(n), "reason", ""))
                            for n in ex.hide)
            body.append(f"<tr><td>{_when(h.time, today)}</td><td>{_esc(h.student)}</td>"
                        f"<td>{_esc(names.get(h.student, ''))}</td><td class='num'>{numbers[h.id]}</td>"
                        f"<td>{_method(h.method)}</td>{cells}<td class='num'>{h.score:.2f}</td>"
                        f"<td>{_source(_one(h))}</td><td>{_conditions(h.conditions)}</td></tr>")
        if not body:
            body.append(f"<tr><td colspan='{8 + len(ex.hide)}' class='dim'>No hand-in yet.</td></tr>")
        # the attempts the rules refused (too many, late, closed): nothing stored, but the teacher sees them
        refused = [r for r in reversed(self.refusals) if who in (EVERYONE, None) or r[1] == who]
        tried = ""
        if refused:
            rows = "".join(f"<tr><td>{_when(t, today)}</td><td>{_esc(s)}</td><td>{_esc(names.get(s, ''))}</td>"
                           f"<td>{_method(m)}</td><td class='no'>{_esc(why)}</td></tr>" for t, s, m, why in refused)
            tried = (f"<h4 style='margin:10px 0 2px'>Refused hand-ins ({len(refused)})</h4><div class='scroll'><table>"
                     f"<tr><th>time</th><th>id</th><th>name</th><th>method</th><th>why</th></tr>{rows}</table></div>")
        self.history.object = f"<div class='scroll'><table>{head}{''.join(body)}</table></div>{tried}"

    # -- the teacher's switches -------------------------------------------------------------------------
    def _switch(self, key: str, value: str, done: str, then=None) -> None:
        """Write a switch (off the event loop when served), then say so and read the class again."""
        store = self.store

        def written(_none) -> None:
            self.note.object = f"<span style='color:#11703a'>{_esc(done)} ({time.strftime('%H:%M:%S')})</span>"
            if then is not None:
                then()
            self.refresh()

        self.note.object = "<span class='small'>Saving…</span>"
        store_calls.call(lambda: store.set_control(key, value), written, fail=self._failed, doc=self.doc)

    def toggle_open(self) -> None:
        """Close hand-ins if they are open, else open them."""
        if self.is_open:
            self._switch("open", "0", "Hand-ins closed: students are told so when they hand in")
        else:
            self._switch("open", "1", "Hand-ins open")

    def set_deadline(self, text: str | None = None) -> None:
        """Move the deadline to ``text`` (by default the field's), an ISO-8601 date and time; empty: back to
        the exercise file's. A bad one is refused with its message beside the field."""
        if text is None:
            text = self.deadline_input.value_input or self.deadline_input.value or ""
        text = text.strip()
        if self.revealed:
            self.deadline_message.object = ("The true values are revealed: hand-ins are closed for good, and moving "
                                            "the deadline would reopen nothing.")
            return
        if text:
            try:
                text = parse_deadline(text)
                release = self.exercise.release_at
                if release and self.exercise.deadline_at(text) > self.exercise.deadline_at(release):
                    raise not_allowed("deadline", text, f"it is after the true values are released ({release}): no "
                                                        "hand-in is taken from then on; give one at or before it")
            except ValueError as exc:
                self.deadline_message.object = _esc(" ".join(str(exc).split()))
                return
        self.deadline_message.object = ""
        self._switch("deadline", text, f"Deadline set to {text}" if text else "Deadline back to the exercise file's")

    def reveal(self) -> None:
        """Show every student their verdicts: only once the deadline has passed."""
        due = self.exercise.deadline_at(self.control.get("deadline") or None)
        if due is None:
            why = ("This exercise has no deadline: set one (it may be now) before revealing, so that nobody "
                   "hands in after seeing the verdicts.")
        elif self.clock() <= due:
            why = (f"The deadline ({_esc(self.control.get('deadline') or self.exercise.deadline)}) has not passed: "
                   "students could still hand in after seeing the verdicts. Reveal after it, or move it to now.")
        elif self._pending_extensions():
            sid, until = self._pending_extensions()[0]
            why = (f"The deadline of {_esc(sid)}'s extension ({_esc(until)}) has not passed: they could still hand "
                   "in after seeing the verdicts. Reveal after it, or take the extension away.")
        else:
            why = ""
        if why:
            self.reveal_message.object = f"<span style='color:#b00020'>{why}</span>"
            return
        self._switch("revealed", "1", "Verdicts revealed to the students; hand-ins are closed for good",
                     then=lambda: setattr(self.reveal_message, "object", ""))

    # -- one student's later deadline ------------------------------------------------------------------
    def _pending_extensions(self, extensions: dict | None = None, control: dict | None = None) -> list[tuple[str, str]]:
        """(student, their deadline) of the ``extensions`` (default: as last read) still open now, later than the
        class's deadline under ``control``."""
        extensions = self.extensions if extensions is None else extensions
        control = self.control if control is None else control
        due = self.exercise.deadline_at(control.get("deadline") or None)
        out = []
        for sid, (until, _set) in sorted(extensions.items()):
            try:
                when = self.exercise.deadline_at(until)
            except ValueError:
                continue                    # a date no one can read (edited by hand) extends nothing
            if due is not None and when > due and when > self.clock():
                out.append((sid, until))
        return out

    def _draw_extensions(self) -> None:
        """The extensions granted: who, until when, and whether it still counts."""
        if not self.extensions:
            self.extensions_pane.object = "<span class='small'>No student has a later deadline of their own.</span>"
            return
        names = {e.id: e.name for e in self.exercise.roster}
        open_ = {sid for sid, _until in self._pending_extensions()}
        due = self.exercise.deadline_at(self.control.get("deadline") or None)
        items = []
        for sid, (until, when_set) in sorted(self.extensions.items()):
            who = f"{_esc(sid)}" + (f" ({_esc(names[sid])})" if names.get(sid) else "")
            try:
                later = due is not None and self.exercise.deadline_at(until) > due
            except ValueError:
                later = False
            state = ("" if sid in open_ else " <span class='dim'>— passed</span>" if later
                     else " <span class='dim'>— not later than the class's deadline: it changes nothing</span>")
            items.append(f"<li>{who} until {_esc(until)}{state} <span class='small'>(set {_esc(when_set)})</span></li>")
        self.extensions_pane.object = (f"<b>Later deadlines of their own</b><ul style='margin:2px 0'>{''.join(items)}"
                                       "</ul>")

    def extend(self, student: str | None = None, until: str | None = None) -> None:
        """Give ``student`` (by default the field's id) the deadline ``until`` (by default the field's, ISO-8601;
        empty: take their extension away). A refusal is said beside its field, naming the value as typed."""
        if student is None:
            student = self.extension_student.value_input or self.extension_student.value or ""
        if until is None:
            until = self.extension_until.value_input or self.extension_until.value or ""
        self.extension_student_message.object = self.extension_until_message.object = ""
        try:
            sid, deadline = check_extension(self.exercise, student, until, now=self.clock(),
                                            class_deadline=self.control.get("deadline", ""))
        except ValueError as exc:
            shown = _esc(" ".join(str(exc).split()))
            if getattr(exc, "field", "") == STUDENT_FIELD:
                self.extension_student_message.object = shown
            else:
                self.extension_until_message.object = shown
            return
        if not deadline and sid not in self.extensions:
            self.extension_until_message.object = _esc(str(not_allowed(
                "until", until, f"{sid} has no extension to take away; give an ISO-8601 date and time, e.g. "
                                "2026-12-08T17:00")))
            return
        store = self.store

        def written(_none) -> None:
            done = f"{sid} may hand in until {deadline}" if deadline else f"{sid}'s extension taken away"
            self.note.object = f"<span style='color:#11703a'>{_esc(done)} ({time.strftime('%H:%M:%S')})</span>"
            self.refresh()

        self.note.object = "<span class='small'>Saving…</span>"
        store_calls.call(lambda: store.set_extension(sid, deadline), written, fail=self._failed, doc=self.doc)

    def csv_bytes(self) -> bytes:
        """The results as ``eha exercise results --csv`` writes them (formula-like cells neutralised), from
        the table as last read (the download is made on the event loop: no database there)."""
        return results_csv(self.exercise, self.rows).encode("utf-8")

    def slips_bytes(self) -> bytes:
        return join_slips_html(self.exercise, self.student_url).encode("utf-8")

    def __panel__(self):
        return self.layout


def _student_url() -> str:
    """The app's address as the teacher's browser reached this server (behind nginx: nginx's)."""
    doc = pn.state.curdoc
    request = getattr(getattr(doc, "session_context", None), "request", None)
    headers = getattr(request, "headers", None) or {}
    host = headers.get("Host", "") or "localhost"
    proto = headers.get("X-Forwarded-Proto", "") or "http"
    return f"{proto}://{host}/eha"


def serve_dashboard() -> None:
    """Make this session's dashboard (the server runs :mod:`eha_app.teacher` for every teacher's page)."""
    from .app import _log_to_stderr, current_exercise
    from .runtime.connection import ConnectionWatch
    from .runtime.patches import apply_patches, strict_mode_on
    from .runtime.redaction import redact_server_logs
    from .runtime.serving import quiet_closed_websockets, use_local_resources
    from .runtime.tasks import note_loop_thread

    _log_to_stderr()
    redact_server_logs()
    note_loop_thread()
    if strict_mode_on():
        apply_patches(("strict",))
    quiet_closed_websockets()
    use_local_resources(pn.state.curdoc)
    pn.config.browser_info = False
    found = current_exercise()
    if found is None:           # not reached: /teacher answers 404 without an exercise
        pn.pane.HTML("<p>No exercise is running.</p>").servable(title="EHA: teacher")
        return
    exercise, store = found
    dashboard = Dashboard(exercise, store, student_url=_student_url())
    # only a page a browser shows follows the class (not the session Panel prepares for the next page)
    def follow() -> None:
        dashboard.refresh()
        pn.state.add_periodic_callback(dashboard.tick, period=POLL_MS)

    pn.state.onload(follow)
    pn.Column(ConnectionWatch(tabs_class="eha-none"), dashboard, sizing_mode="stretch_width").servable(
        title=f"EHA teacher: {exercise.title}", location=False)
