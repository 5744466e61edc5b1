"""A random walk through the app at the protocol level, with the page's invariants checked after
every action.

A :class:`Walker` is one student's browser session (a :class:`WalkStudent`, the classroom client's
:class:`~benchmarks.classroom_client.Student` with a few more eyes) doing, in a seeded random order,
what a student can do: type any field of any form (valid values and not: in and out of range, text,
blank, 1e308, negative), show any tab and sub-tab, press every button that is there and enabled,
tick, untick, rename and delete models on the model board, choose files (the least squares' and the
own record's uploads, a settings file) and reload the page from its address. After each action,
once the page has settled (the action's visible effect, or a short quiet spell with no message and
no run in progress), it checks:

``log``          the server's log has nothing at WARNING or above and no traceback (a problem is
                 put on the action whose time it fell in; with several sessions at once, the one
                 begun last, the others named beside it);
``server-error`` the server answered no message of the session with an ERROR;
``connection``   the websocket is open and answers a round trip (an empty PATCH-DOC);
``derived``      tab 1's derived values (``.eha-derived``) are what the app's own code makes of the
                 typed texts (``AppState.set_text`` for each, then ``tables.derived_html``);
``freshness``    every result view (``.eha-view-NAME``) is current with its inputs or marked: it
                 does not stay ``eha-current`` after an input it depends on changed value, is never
                 current while its inputs are not valid, and becomes current only with the inputs of
                 a run (or those it showed before); ``eha-updating`` does not last;
``banner``       a view's out-of-date line (``.eha-stale-note-NAME``) shows exactly when it is out
                 of date;
``buttons``      run buttons are enabled exactly when their inputs are valid (tab 1 and the
                 button's own form; see :meth:`Walker.expected_buttons`);
``action``       the action's own effect came (a tab's content arrived, the student could start).

A failure records the seed, the session, the action's index, the action, the invariant, what was
seen and what was expected, and the last ten actions (:class:`Failure`). The walk is a function of
the seed as far as the server's timing allows: every choice comes from the seeded generator and the
page's state after it settled.

The page's sections (its tabs, sub-tabs and panels) are read from the app's registry
(``eha_app.sections``: :func:`page_sections`): where each is, its form and its run buttons (each
section declares them), so that a section registered with one line is walked too: typed into
(``type-KEY``), run (``run-KEY``), reached through its tab and sub-tab, and in the settings files
the walk loads. What a view depends on, and a few actions of their own (uploads, the board's list),
are known here for the sections the app has now:

- ``simulation`` (tab 2): tab 1's parameters and the simulation form's shown fields; re-runs by
  itself when short (its status line says "updating", the view's class stays current);
- ``lse``: tab 1's parameters, the least-squares form, the student's data file and its time range;
  ``table4``: tab 1's parameters and the noise seed;
- ``freq-*`` (data, fit, bode, validation, residuals, summary): tab 1's parameters and Kp and the
  frequency form; ``freq-excitation`` only the form's excitation fields (a preview, re-run by itself);
- ``freq-record``: the student's record, its range and trend, and the form's model settings;
- ``bb`` (black-box models): tab 1's parameters (not Kp: the form has its own) and the black-box form's shown
  fields;
- ``board-record``: tab 1's parameters and Kp and the board's form (re-run by itself; its step height only
  once the board's step view was opened on the page: the board computes steps from then on).

Run it against a running server, or let it start one::

    python -m benchmarks.walker --seed 3 --actions 300 --sessions 3
    python benchmarks/walker.py --url http://127.0.0.1:5006/eha --log /tmp/eha.log --seed 1
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import csv
import io
import json
import math
import os
import random
import re
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from urllib.parse import urlencode

if __package__:
    from . import classroom_client as _client
else:  # run as a script: this file's folder is on the path
    import classroom_client as _client

Model, ProtocolError, StepTimeout, Student, StudentSession = (
    _client.Model, _client.ProtocolError, _client.StepTimeout, _client.Student, _client.StudentSession)
_plain, _refs, stop_server, wait_served = _client._plain, _client._refs, _client.stop_server, _client.wait_served

__all__ = ["Failure", "LogMonitor", "WalkServer", "WalkStudent", "Walker", "WalkOptions", "run_walks",
           "format_failures", "main"]

ROOT = Path(__file__).resolve().parents[1]

# -- the page's vocabulary (css classes, labels, field names) ----------------------------------------

MAIN_TABS, IDENT_TABS = "eha-main-tabs", "eha-ident-tabs"
FREQ_FIGURES, BOARD_VIEWS = "eha-freq-figures", "eha-board-views"
PARAM_FORM, SIM_FORM, LSE_FORM, FREQ_FORM = "eha-param-form", "eha-sim-form", "eha-lse-form", "eha-freq-form"
BOARD_FORM, STUDY_FORM, GB_FORM, BB_FORM = "eha-board-form", "eha-study-form", "eha-gb-form", "eha-bb-form"
LSE_WINDOW, RECORD_WINDOW = "eha-lse-window", "eha-freq-record-window"
STATUS_CLASSES = {"eha-empty": "empty", "eha-current": "current", "eha-updating": "updating",
                  "eha-out-of-date": "stale"}
SIM_BUTTONS = ("Case 1", "Case 2", "Case 3", "Case 4", "All four cases", "Run nonlinear", "Run linearised",
               "Compare both")
LSE_RUN, TABLE4_RUN, HANDIN = "Run least squares", "Run all four scenarios (Table 4)", "Hand in these estimates"
FREQ_RUN, RECORD_RUN = "Run experiment and estimate", "Estimate from your record"
GB_RUN, GB_CANCEL = "Run grey-box estimation", "Cancel the estimation"
BB_RUN = "Run black-box estimation"
STUDY_RUN, STUDY_CANCEL = "Run the study", "Cancel"
RESET, REPORT, BACK_TO_SIMULATED, USE_COLUMNS = ("Reset to paper defaults", "Report of this session",
                                                  "Back to simulated data", "Use these columns")
#: the frequency form's fields the excitation preview (Fig. 8) is made from
EXCITATION_FIELDS = ("signal_type", "n_samples", "freq_seed", "band_lo", "band_hi", "range_lo", "range_hi",
                     "n_sines", "n_trials", "grid_skip", "ts")
#: the frequency form's fields an estimate from the student's own record uses
ORDER_FIELDS = ("n_poles", "n_zeros", "initial_condition", "input_offset", "input_delay")
FREQ_VIEWS = ("freq-data", "freq-fit", "freq-bode", "freq-validation", "freq-residuals", "freq-summary")
#: views that re-run by themselves (the others wait for their button)
AUTO_VIEWS = ("simulation", "freq-excitation", "board-record")
#: Views whose inputs are tab 1's (with Kp or not) and one form's.
_FORM_VIEWS = {"simulation": (SIM_FORM, False), "gb": (GB_FORM, False), "bb": (BB_FORM, False),
               "board-record": (BOARD_FORM, True)}
#: the run button (label) whose press computes each manual view
VIEW_BUTTON = {"lse": LSE_RUN, "table4": TABLE4_RUN, "freq-record": RECORD_RUN, "gb": GB_RUN, "bb": BB_RUN,
               **{v: FREQ_RUN for v in FREQ_VIEWS}}

_LOG_LINE = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) (DEBUG|INFO|WARNING|ERROR|CRITICAL) (.*)$")
_BARE_LEVEL = re.compile(r"^(WARNING|ERROR|CRITICAL)\b[: ]")
#: a Python warning as a log line holds it ("file.py:12: UserWarning: ..."), its source line below
_WARNING_NOTE = re.compile(r"\.py:\d+: \w*Warning: ")
#: what ``eha serve`` itself prints when it starts and stops (anything else unformatted is a problem:
#: a library writing to stderr, warnings printed as notes)
_BENIGN = re.compile(r"^(EHA app:|Pages may connect|Preparing the simulation|Starting the server|Ready: |for the class|"
                     r"Received signal|Exercise )")
_RUN_COUNT = re.compile(r"run (\d+)")


def _app(name: str, *modules: str):
    """``name`` from the first of ``modules`` that has it: the app's modules move (eha_app.state became
    eha_app.session.state); what the walk uses of them (AppState, derived_html) does not."""
    import importlib

    for module in modules:
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            continue
    raise ImportError(f"{name} is in none of {', '.join(modules)}")


def _app_state():
    return _app("AppState", "eha_app.session.state", "eha_app.state")


def _derived_html():
    return _app("derived_html", "eha_app.render.tables", "eha_app.tables")


def _strip_tags(text: str, limit: int = 300) -> str:
    out = " ".join(re.sub(r"<[^>]+>", " ", text or "").split())
    return out if len(out) <= limit else out[:limit] + "…"


def _first_difference(seen: str, expected: str, width: int = 14) -> tuple[str, str]:
    """The two texts (tags stripped) around the first word where they differ."""
    a, b = _strip_tags(seen, 100000).split(), _strip_tags(expected, 100000).split()
    k = next((i for i, (x, y) in enumerate(zip(a, b, strict=False)) if x != y), min(len(a), len(b)))
    lo = max(0, k - 4)
    return ("…" + " ".join(a[lo:lo + width]) + "…", "…" + " ".join(b[lo:lo + width]) + "…")


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "…"


def normalized(name: str, text) -> object:
    """A field's text as the app compares it: numbers by value ("5", "5.0", " 5,0 " alike), the input
    delay's words, other texts trimmed. Never finer than the app's own comparison: two texts the app
    takes for the same input are the same here."""
    t = "" if text is None else str(text).strip()
    if name == "input_delay":
        if t.lower() in ("", "0", "none"):
            return 0.0
        if t.lower() in ("estimate", "est"):
            return "estimate"
    try:
        v = float(t.replace(",", "."))
    except ValueError:
        return t
    return v if math.isfinite(v) else t


# -- the page's sections, as the app registers them ------------------------------------------------------

@dataclass(frozen=True)
class PageSection:
    """A section of the page as the walk finds it: its key and title, the css classes of its form and of
    what shows its content has arrived, the labels of its run buttons, and where it is (its main tab,
    its sub-tab of that tab or None; a section within another is where that one is)."""

    key: str
    title: str
    form_css: str | None
    content_css: str | None
    run_buttons: tuple
    tab: int
    subtab: int | None = None
    within: str | None = None


def page_sections() -> tuple[PageSection, ...]:
    """The page's sections in page order, read from the app's registry (``eha_app.sections.SECTIONS``):
    what the served page is made of, the sections registered after the walker was written included."""
    registry = _app("SECTIONS", "eha_app.sections")
    tabs = registry.tabs()
    out = []
    for p in registry:
        top = p
        while top.within is not None:
            top = registry.get(top.within)
        on_tab = [q.key for q in registry.on_tab(top.tab)]
        form_css = getattr(p.cls, "form_css", None)
        out.append(PageSection(p.key, p.cls.title, form_css, getattr(p.cls, "content_css", None) or form_css,
                               tuple(getattr(p.cls, "run_buttons", ())), tabs.index(top.tab),
                               on_tab.index(top.key) if len(on_tab) > 1 else None, p.within))
    return tuple(out)


# -- the server and its log ---------------------------------------------------------------------------

def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class WalkServer:
    """``eha serve`` in a subprocess on a free port, its log in a file (``EHA_STRICT=1`` set)."""

    def __init__(self, *args: str, env: dict | None = None, log_dir: str | None = None, timeout: float = 180):
        self.port = free_port()
        fd, self.log_path = tempfile.mkstemp(prefix=f"eha-walk-{self.port}-", suffix=".log", dir=log_dir)
        self.log = os.fdopen(fd, "w")
        eha = Path(sys.executable).with_name("eha")
        cmd = [str(eha)] if eha.exists() else [sys.executable, "-m", "eha_app.cli"]
        cmd += ["serve", "--port", str(self.port), "--address", "127.0.0.1", *args]
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT,
                                     env={**os.environ, "EHA_STRICT": "1", **(env or {})}, start_new_session=True)
        self.url = f"http://127.0.0.1:{self.port}/eha"
        wait_served(self.proc, self.url, timeout, self.log_text, self.stop)

    def log_text(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return Path(self.log_path).read_text(errors="replace")

    def stop(self) -> None:
        stop_server(self.proc)
        self.log.close()


@dataclass
class LogProblem:
    """A WARNING/ERROR/CRITICAL line of the server's log, or a traceback, with the lines that follow it."""

    at: float                   # its time (the line's own, or when it was read)
    lines: list

    @property
    def head(self) -> str:
        """The line that says what happened: a traceback's last line, else the first."""
        if any(ln.startswith("Traceback") for ln in self.lines):
            for ln in reversed(self.lines):
                if ln.strip() and not ln.startswith(" "):
                    return ln.strip()
        return self.lines[0].strip()


class LogMonitor:
    """Reads the server's log as it grows and hands each problem to the walk that was acting then.

    Walkers register; :meth:`dispatch` (called by any of them) reads what is new and puts each
    problem on the action whose time window holds the problem's time (several: the one begun last,
    the others named), or, in a gap, on the latest action that ended before it.
    """

    def __init__(self, path: str):
        self.path = path
        self._offset = 0
        self._partial = ""
        self._open: LogProblem | None = None     # the entry being read (continuation lines join it)
        self._open_is_problem = False
        self.problems: list[LogProblem] = []
        self.walkers: list = []
        self.unclaimed: list[LogProblem] = []

    def _read(self) -> None:
        try:
            with open(self.path, errors="replace") as f:
                f.seek(self._offset)
                chunk = f.read()
                self._offset = f.tell()
        except OSError:
            return
        text = self._partial + chunk
        lines = text.split("\n")
        self._partial = lines.pop()          # an unfinished line waits for the rest
        # a line without a time of its own was written since the last read: say, half-way
        now = time.time()
        now, self._last_read = (now + getattr(self, "_last_read", now)) / 2, now
        for ln in lines:
            m = _LOG_LINE.match(ln)
            if m:
                self._close()
                at = datetime.strptime(m.group(1), "%Y-%m-%d %H:%M:%S,%f").timestamp()
                self._open = LogProblem(at, [ln])
                self._open_is_problem = m.group(2) in ("WARNING", "ERROR", "CRITICAL")
            elif _BARE_LEVEL.match(ln) or ln.startswith("Traceback"):
                if self._open is not None and ln.startswith("Traceback"):
                    self._open.lines.append(ln)          # the traceback of the line before
                    self._open_is_problem = True
                else:
                    self._close()
                    self._open = LogProblem(now, [ln])
                    self._open_is_problem = True
            elif not ln.strip() or _BENIGN.match(ln):
                continue
            elif self._open is not None and self._open_is_problem:
                if len(self._open.lines) < 1000:
                    self._open.lines.append(ln)      # a problem's traceback, its further lines
            elif (self._open is not None and len(self._open.lines) == 1 and ln.startswith("  ")
                  and _WARNING_NOTE.search(self._open.lines[0])):
                self._open.lines.append(ln)          # a Python warning's source line, under its note
            else:
                self._close()                        # a line of its own: printed, not logged
                self._open, self._open_is_problem = LogProblem(now, [ln]), True
        # an entry is complete when the next one starts; a problem's first lines are enough to
        # report it now, its traceback is kept growing on the same object
        if self._open is not None and self._open_is_problem and self._open not in self.problems:
            self.problems.append(self._open)
            self.unclaimed.append(self._open)

    def _close(self) -> None:
        if self._open is not None and self._open_is_problem and self._open not in self.problems:
            self.problems.append(self._open)
            self.unclaimed.append(self._open)
        self._open, self._open_is_problem = None, False

    def dispatch(self, settle_s: float = 0.0) -> None:
        """Read the log; put every new problem older than ``settle_s`` seconds on its action."""
        self._read()
        now = time.time()
        keep = []
        for problem in self.unclaimed:
            if problem.at > now - settle_s:
                keep.append(problem)
                continue
            self._assign(problem)
        self.unclaimed = keep

    _JOB = re.compile(r"job '([^']+)'")

    def _by_job(self, problem: LogProblem):
        """A failed job's line names the job ("job 'Table 4' of session ..."): the latest action, of any
        walk, begun before the line whose description shares the most words with the job's name."""
        m = self._JOB.search(" ".join(problem.lines[:2]))
        if not m:
            return None
        words = {w for w in re.findall(r"[a-z0-9]+", m.group(1).lower()) if len(w) >= 4} - {"your", "from"}
        best = None
        for w in self.walkers:
            for act in reversed(w.windows):
                if act["t0"] > problem.at + 0.05:
                    continue
                if problem.at - act["t0"] > 120:
                    break
                overlap = len(words & set(re.findall(r"[a-z0-9]+", act["desc"].lower())))
                if overlap and (best is None or (overlap, act["t0"]) > (best[0], best[1])):
                    best = (overlap, act["t0"], w, act)
        return best

    def _assign(self, problem: LogProblem) -> None:
        by_job = self._by_job(problem)
        if by_job is not None:
            _, _, owner, act = by_job
            owner.log_problem(problem, act, ["(a job's failure: put on the action that asked for that job)"])
            return
        inside, before = [], []
        slack = 0.05
        for w in self.walkers:
            for act in reversed(w.windows):
                t0, t1 = act["t0"], act["t1"]
                if t0 - slack <= problem.at and (t1 is None or problem.at <= t1 + slack):
                    inside.append((t0, w, act))
                    break
                if t1 is not None and t1 < problem.at:
                    before.append((t1, w, act))
                    break
        if inside:
            inside.sort(key=lambda x: x[0])
            _, owner, act = inside[-1]
            others = [f"{w.name} #{a['index']} {a['desc']}" for _, w, a in inside[:-1]]
        elif before:
            before.sort(key=lambda x: x[0])
            _, owner, act = before[-1]
            others = ["(between actions: put on the session that acted last)"]
        else:
            return
        owner.log_problem(problem, act, others)


# -- one browser session, with eyes for the walk ---------------------------------------------------------

class WalkStudent(Student):
    """A :class:`Student` that also notes what the walk needs between its looks at the page: when the
    last message came, and every status a result view passed through."""

    def __init__(self, url: str, **kwargs):
        super().__init__(url, **kwargs)
        self.last_message_at = time.perf_counter()
        self.view_passes: dict[str, list] = {}       # view name -> statuses set since the last check
        self._parents: dict | None = None

    def _handle(self, msg: dict) -> None:
        self.last_message_at = time.perf_counter()
        super()._handle(msg)

    def _apply(self, event: dict) -> None:
        super()._apply(event)
        self._parents = None
        if event.get("kind") == "ModelChanged" and event.get("attr") == "css_classes":
            classes = _plain(event.get("new")) or []
            status = next((STATUS_CLASSES[c] for c in classes if c in STATUS_CLASSES), None)
            for c in classes:
                if isinstance(c, str) and c.startswith("eha-view-"):
                    self.view_passes.setdefault(c[len("eha-view-"):], []).append(status)

    # -- what is on the page ---------------------------------------------------------------------------
    def _indexes(self) -> tuple[dict, dict]:
        """The live models by css class and by type name, made again after every message that changed
        the page (a walk looks things up dozens of times between two messages)."""
        live = self.live_ids()
        if getattr(self, "_index_of", None) is not live:
            by_css: dict = {}
            by_type: dict = {}
            for m in self.models.values():
                if m.id not in live:
                    continue
                for c in m.css:
                    by_css.setdefault(c, []).append(m)
                by_type.setdefault(m.type, []).append(m)
            self._index_of, self._by_css, self._by_type = live, by_css, by_type
        return self._by_css, self._by_type

    def find(self, type_suffix: str | None = None, *, css: str | None = None, label: str | None = None,
             where=None, live: bool = True) -> list[Model]:
        """:meth:`Student.find`, from an index of the live models."""
        if not live or (css is None and type_suffix is None):
            return super().find(type_suffix, css=css, label=label, where=where, live=live)
        by_css, by_type = self._indexes()
        if css is not None:
            found = by_css.get(css, [])
        else:
            found = [m for t, ms in by_type.items() if t.endswith(type_suffix) for m in ms]
        return [m for m in found if (type_suffix is None or m.type.endswith(type_suffix))
                and (label is None or m.attributes.get("label") == label) and (where is None or where(m))]

    def parents(self) -> dict:
        """Each live model's parent (the model that refers to it first)."""
        if self._parents is None:
            out: dict = {}
            live = self.live_ids()
            for mid in live:
                refs: list = []
                _refs(self.models[mid].attributes, refs)
                for r in refs:
                    if r in live and r not in out and r != mid:
                        out[r] = mid
            self._parents = out
        return self._parents

    def shown(self, model: Model, *, tabs: bool = True) -> bool:
        """Is ``model`` on screen: live, neither it nor a parent invisible, every tab on its way open
        (``tabs=False``: whichever tab it is on)?"""
        parents = self.parents()
        if model.id not in self.live_ids():
            return False
        node, child = model, None
        for _ in range(200):
            if node.attributes.get("visible") is False:
                return False
            if tabs and node.type.endswith("Tabs") and child is not None:
                tabs = node.attributes.get("tabs") or []
                ids = [t.get("id") for t in tabs if isinstance(t, dict)]
                if child.id in ids and ids.index(child.id) != (node.attributes.get("active") or 0):
                    return False
            pid = parents.get(node.id)
            if pid is None:
                return True
            node, child = self.models[pid], node
        return True

    def one(self, type_suffix: str | None = None, **kwargs) -> Model | None:
        found = self.find(type_suffix, **kwargs)
        return found[0] if found else None

    def descendants(self, model: Model) -> list[Model]:
        seen, todo, out = set(), [model.id], []
        while todo:
            mid = todo.pop()
            if mid in seen or mid not in self.models:
                continue
            seen.add(mid)
            out.append(self.models[mid])
            refs: list = []
            _refs(self.models[mid].attributes, refs)
            todo.extend(refs)
        return out

    def form_model(self, css: str) -> Model | None:
        return self.component_data(css) if self.find(css=css) else None

    #: views found updating for too long (reported stuck): waiting for them would wait for ever
    stuck: frozenset = frozenset()

    def busy(self) -> str:
        """What is still in progress on the page ('' when nothing): a loading indicator, a queue note, a
        view updating (but not one known to be stuck), tab 2's "updating" word."""
        by_css, _ = self._indexes()
        if by_css.get("pn-loading"):
            return "loading"
        if any(m.attributes.get("visible") and m.text().strip() for m in by_css.get("eha-queue-note", [])):
            return "queued"
        if any(not any(c[len("eha-view-"):] in self.stuck for c in m.css if c.startswith("eha-view-"))
               for m in by_css.get("eha-updating", [])):
            return "updating"
        if "simulation" not in self.stuck and any("eha-sim-updating" in m.text()
                                                  for m in by_css.get("eha-sim-info", [])):
            return "simulation updating"
        return ""

    async def sync(self, timeout: float = 5.0) -> None:
        """A round trip after an action: Panel answers a client's change on the next tick of the
        server's loop, not while it reads the message, so a quiet spell alone can end before a busy
        server (other students' work under their locks) has even begun on it. The round trip's
        ``OK`` comes after the change was handled (the loop runs its callbacks in order)."""
        if self._broken:
            return
        try:
            await self.round_trip(timeout)
        except (ProtocolError, ConnectionError, OSError, asyncio.TimeoutError):
            pass        # the connection invariant reports it

    async def settle(self, quiet_s: float, cap_s: float, *, wait_busy: bool = True) -> bool:
        """Wait until no message came for ``quiet_s`` and (``wait_busy``) nothing is in progress, at most
        ``cap_s``; True if it settled."""
        deadline = time.perf_counter() + cap_s
        while True:
            now = time.perf_counter()
            since = now - self.last_message_at
            if since >= quiet_s and not (wait_busy and self.busy()):
                return True
            if self._broken:
                return False
            left = deadline - now
            if left <= 0:
                return False
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), min(left, max(quiet_s - since, 0.02)))
            except asyncio.TimeoutError:
                pass


# -- what a walk finds ---------------------------------------------------------------------------------

@dataclass
class Failure:
    """One broken invariant, with where the walk was."""

    kind: str
    seed: int
    session: str
    index: int
    action: str
    invariant: str
    seen: str
    expected: str
    last_actions: list = field(default_factory=list)
    log: list = field(default_factory=list)
    page: str = ""          # the page's address then (its fields that differ from the defaults)
    problem: object = field(default=None, repr=False)   # a log problem (its traceback may still grow)

    @property
    def what(self) -> str:
        """What was seen (a log problem's line that says what happened, read when asked)."""
        return self.problem.head[:300] if self.problem is not None else self.seen

    def text(self) -> str:
        lines = [f"[{self.kind}] seed {self.seed}, {self.session}, action #{self.index}: {self.action}",
                 f"    invariant: {self.invariant}", f"    seen:      {self.what}", f"    expected:  {self.expected}"]
        if self.page:
            lines.append(f"    page:      {self.page}")
        log = list(self.problem.lines) if self.problem is not None else self.log
        if log:
            lines.append("    server log:")
            if len(log) <= 16:
                lines += [f"      {ln}" for ln in log]
            else:
                lines += [f"      {ln}" for ln in log[:8]]
                lines.append(f"      ... ({len(log) - 14} lines)")
                lines += [f"      {ln}" for ln in log[-6:]]
        lines.append("    last actions: " + " | ".join(self.last_actions))
        return "\n".join(lines)

    def to_json(self) -> dict:
        out = {k: v for k, v in self.__dict__.items() if k != "problem"}
        out["seen"] = self.what
        if self.problem is not None:
            out["log"] = list(self.problem.lines)
        return out


def failure_sort(f: Failure) -> tuple[str, str]:
    """Failures of one sort: same kind and invariant (a log problem: same message), numbers aside."""
    what = f.what if f.kind == "log" else f.invariant
    return f.kind, re.sub(r"0x[0-9a-f]+|\d+(\.\d+)?", "N", what)[:120]


def format_failures(failures: list, limit: int = 40) -> str:
    """Failures grouped by kind and invariant, each group with its first example in full."""
    if not failures:
        return "no failures"
    groups: dict = {}
    for f in failures:
        groups.setdefault(failure_sort(f), []).append(f)
    out = [f"{len(failures)} failure(s) of {len(groups)} sort(s):"]
    for k, ((kind, _), items) in enumerate(groups.items()):
        if k == limit:
            out.append(f"... and {len(groups) - limit} more sorts")
            break
        out.append(f"\n{len(items)} x {kind}:\n" + items[0].text())
    return "\n".join(out)


@dataclass
class WalkOptions:
    quiet_s: float = 0.05           # a page is settled after this long without a message ...
    run_quiet_s: float = 0.22       # ... after a run button, longer: the loading indicator comes at 0.2 s
    settle_cap_s: float = 2.5       # ... or after this long anyway (a run may go on: the checks hold mid-run)
    consistency_s: float = 1.0      # an invariant broken after settling has this long to mend itself
    derived_s: float = 3.0          # tab 1's derived values must follow within this
    tab_s: float = 20.0             # a tab's content must arrive within this
    stuck_s: float = 20.0           # a view may be "updating" this long
    light: bool = True              # valid values of costly fields kept small (seeds, samples)
    stay: float = 0.6               # how often the next action is one on the tab the student is on
    wait_busy: bool = True          # after typing too, wait for the re-runs it started (not only after a run button)
    exercise_hidden: tuple = ()     # an exercise's hidden parameters (the server runs one)
    only: tuple = ()                # restrict the walk to these action kinds (development)
    trace: bool = False             # print every action as it is done
    exclude: tuple = ()             # or leave these out


@dataclass
class ViewTrack:
    """What the walk knows of one result view."""

    snapshot: object = None         # the inputs it was last computed from (None: not known yet)
    known: bool = False
    last_status: str | None = None
    runs: list = field(default_factory=list)   # inputs at each press of its button since the snapshot
    run_count: int = -1             # tab 2's "run N" at the snapshot
    updating_since: float | None = None
    reported: bool = False          # a failure was reported and not mended since


# -- test data ------------------------------------------------------------------------------------------

_CASE_CACHE: dict = {}


def _case_csv() -> bytes:
    """A real record for the least squares: ``eha simulate --case 1 --t-end 2`` (t, x, v, p1, p2, u, d),
    made once per process."""
    if "lse" not in _CASE_CACHE:
        data = b""
        eha = Path(sys.executable).with_name("eha")
        try:
            out = subprocess.run([str(eha) if eha.exists() else sys.executable, *([] if eha.exists() else
                                  ["-m", "eha_app.cli"]), "simulate", "--case", "1", "--t-end", "2"],
                                 capture_output=True, timeout=120, cwd=ROOT)
            data = out.stdout if out.returncode == 0 else b""
        except (OSError, subprocess.SubprocessError):
            data = b""
        if not data:                # a synthetic one, should the command be missing
            rows = ["t,x,v,p1,p2,u,d"]
            for k in range(2001):
                t = k * 1e-3
                u = 6 * math.sin(4 * math.pi * t)
                rows.append(f"{t:g},{0.01 * math.sin(4 * math.pi * t):.6g},{0.12 * math.cos(4 * math.pi * t):.6g},"
                            f"{12e6 + 1e6 * u / 6:.8g},{18.2e6 - 1e6 * u / 6:.8g},{u:.6g},0")
            data = ("\n".join(rows) + "\n").encode()
        _CASE_CACHE["lse"] = data
    return _CASE_CACHE["lse"]


def _table(data: bytes) -> tuple[list, list]:
    rows = list(csv.reader(io.StringIO(data.decode())))
    return rows[0], rows[1:]


def _write_csv(header: list, rows: list) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue().encode()


def _mat(columns: dict) -> bytes | None:
    try:
        import numpy as np
        from scipy.io import savemat
    except ImportError:
        return None
    buf = io.BytesIO()
    savemat(buf, {k: np.asarray(v, dtype=float) for k, v in columns.items()})
    return buf.getvalue()


def _record(rng: random.Random, n: int, names=("t", "u", "y")) -> bytes:
    """A closed-loop-like record: a first-order system driven by a random binary input, with noise."""
    ts = rng.choice([0.01, 0.005, 0.02])
    u = [rng.choice([-1.0, 1.0]) * 0.01 for _ in range(n)]
    y, state = [], 0.0
    a = math.exp(-ts / rng.choice([0.05, 0.1, 0.3]))
    for k in range(n):
        state = a * state + (1 - a) * u[k]
        y.append(state + rng.gauss(0, 1e-5))
    return _write_csv(list(names), [[f"{k * ts:.6g}", f"{u[k]:.6g}", f"{y[k]:.6g}"] for k in range(n)])


# -- the walk ----------------------------------------------------------------------------------------

@dataclass
class Action:
    kind: str
    desc: str
    run: object                      # async callable
    settle: str = "quiet"            # "quiet", "run" (a run button), "none" (the action waited itself)
    runs: tuple = ()                 # views whose button this is (their inputs are noted at the press)
    spec: dict = field(default_factory=dict)    # the action as data: Walker.replay does it again


class Walker:
    """One session's seeded random walk (see the module docstring)."""

    def __init__(self, url: str, seed: int, *, name: str | None = None, monitor: LogMonitor | None = None,
                 options: WalkOptions | None = None, timeout: float = 60.0):
        self.url = url
        self.seed = seed
        self.name = name or f"session {seed}"
        self.rng = random.Random(seed)
        self.monitor = monitor
        self.o = options or WalkOptions()
        self.timeout = timeout
        self.failures: list[Failure] = []
        self.history: list[str] = []
        self.specs: list[dict] = []                # each action as data (Walker.replay does them again)
        self.windows: list[dict] = []              # each action's time window, for the log's problems
        self.counts: Counter = Counter()
        self.seconds: Counter = Counter()          # wall time by action kind (action, settling, checks)
        self.s: WalkStudent | None = None
        self.query: dict = {}
        self.shadow = None
        self.views: dict[str, ViewTrack] = {}
        self.reported: dict = {}
        self.sorts: set = set()
        self.derived_bad = False
        self.errors_seen = 0
        self.walker_errors = 0
        self.uploads = 0
        self.index = -1
        self.pending: Action | None = None        # an action that waits for its tab to be shown first
        self.in_gate = False
        self.joined_as = ""             # the id typed at the gate when the app was shown (an exercise)
        self.student_id = f"s{seed:07d}"
        self.actions_done = 0
        self.sections = page_sections()
        self._plan()
        if monitor is not None:
            monitor.walkers.append(self)

    # -- reporting ------------------------------------------------------------------------------------
    def _current(self) -> tuple[int, str]:
        return self.index, (self.history[-1] if self.history else "(opening the page)")

    def fail(self, kind: str, invariant: str, seen: str, expected: str, *, log: list | None = None,
             index: int | None = None, action: str | None = None, problem: LogProblem | None = None) -> None:
        i, desc = self._current()
        if index is not None:
            i, desc = index, action or desc
        last = self.history[max(0, i - 9):i + 1] if i >= 0 else []
        try:
            page = "?" + urlencode(self.page_query()) if self.s is not None else ""
        except Exception:  # noqa: BLE001 - the address is a help, not a must
            page = ""
        self.failures.append(Failure(kind, self.seed, self.name, i, desc, invariant, seen, expected,
                                     [f"#{max(0, i - 9) + k} {a}" for k, a in enumerate(last)], log or [],
                                     page if page != "?" else "", problem))

    def log_problem(self, problem: LogProblem, act: dict, others: list) -> None:
        extra = f" (also acting then: {'; '.join(others)})" if others else ""
        self.fail("log", "nothing at WARNING or above, no traceback, in the server's log" + extra,
                  problem.head[:300], "no such line", log=problem.lines, index=act["index"], action=act["desc"],
                  problem=problem)

    # -- shadow of tab 1 -------------------------------------------------------------------------------
    def _new_shadow(self) -> None:
        from eha_core.params import ActuatorParams

        state = _app_state()()
        if self.o.exercise_hidden:
            defaults = ActuatorParams()
            state.secret = {n: getattr(defaults, n) for n in self.o.exercise_hidden}
            state.reset_defaults()
        self.shadow = state

    def _shadow_type(self, name: str, text: str) -> None:
        """Type into the shadow of tab 1 (the app's own AppState). If that raises, the app's does too: a
        finding (once per sort), and the shadow goes on as the app's state would."""
        if name in self.shadow.secret:
            return
        try:
            self.shadow.set_text(name, text)
        except Exception as exc:  # noqa: BLE001 - the app's own state class fails on this input
            what = f"{type(exc).__name__}: {exc}"
            if what not in self.reported.setdefault("state-raises", set()):
                self.reported["state-raises"].add(what)
                self.fail("derived", "tab 1 takes any text in any field (eha_app's AppState.set_text)",
                          f"AppState.set_text({name!r}, {_short(text)}) raises {what[:200]}",
                          "a value, or a message beside the field")

    def _tab1_texts(self) -> dict:
        s = self.shadow
        return {**{k: v for k, v in s.texts.items() if k not in s.hidden}, "kp": s.kp_text}

    _derived_cache: dict = {}

    def expected_derived(self) -> str | Exception:
        """What tab 1's derived values must show, by the app's own code; the exception if that code
        raises for these inputs (then the page cannot show them either)."""
        derived_html = _derived_html()
        s = self.shadow
        key = (s.params, s.kp, not s.valid, s.hidden)
        if key not in Walker._derived_cache:
            if len(Walker._derived_cache) > 512:
                Walker._derived_cache.clear()
            try:
                Walker._derived_cache[key] = derived_html(s.params, s.kp, stale=not s.valid, hidden=s.hidden)
            except Exception as exc:  # noqa: BLE001 - the app's code fails here too: a finding
                Walker._derived_cache[key] = exc
        return Walker._derived_cache[key]

    # -- the session -----------------------------------------------------------------------------------
    async def open(self, query: dict | None = None) -> None:
        self.query = dict(query or {})
        url = self.url + (("?" + urlencode(self.query)) if self.query else "")
        self.s = WalkStudent(url, name=self.name, timeout=self.timeout)
        self.errors_seen = 0
        self.views = {}
        self.reported = {}
        self.derived_bad = False
        self.pending = None
        self.pending_steps = 0
        self._lse_data = self._record = None
        self._new_shadow()
        if self.o.exercise_hidden:
            await super(Student, self.s).open(self.timeout)
            await self.s.wait_for_model(css="eha-gate", timeout=self.o.tab_s)
            self.in_gate = True
            return
        await super(Student, self.s).open(self.timeout)
        # the open tab is built first (a link with tab=3 builds tab 3, not tab 1)
        tab = self.query.get("tab", "").strip()
        first = int(tab) - 1 if tab.isdigit() and 1 <= int(tab) <= len(self.tab_ready) else 0
        await self.s.wait_for(lambda: self.s.find(css=self.tab_ready[first]), self.o.tab_s,
                              f"tab {first + 1}'s content")
        self._apply_query()

    def _apply_query(self) -> None:
        from eha_core.params import PARAM_NAMES

        for name in (*PARAM_NAMES, "kp"):
            if name in self.query and name not in self.o.exercise_hidden:
                self._shadow_type(name, self.query[name])

    async def close(self) -> None:
        if self.s is not None:
            await self.s.close()

    def page_query(self) -> dict:
        """The page's address as the browser keeps it: the fields of every form that writes them (those
        that differ from its defaults, at most 200 characters) and the open tab."""
        q = dict(self.query)
        for m in self.s.find():
            defaults = m.attributes.get("url_defaults")
            if not isinstance(defaults, dict) or "spec" not in m.attributes:
                continue
            values = m.attributes.get("values") or {}
            for group in m.attributes.get("spec") or []:
                for f in group.get("fields", []):
                    name = f.get("name")
                    text = values.get(name)
                    if text is None or str(text) == str(defaults.get(name, "")) or len(str(text)) > 200:
                        q.pop(name, None)
                    else:
                        q[name] = str(text)
        tabs = self.s.one("Tabs", css=MAIN_TABS)
        if tabs is not None:
            active = tabs.attributes.get("active") or 0
            if active:
                q["tab"] = str(active + 1)
            else:
                q.pop("tab", None)
        return q

    # -- the walk --------------------------------------------------------------------------------------
    async def walk(self, n_actions: int) -> list[Failure]:
        """``n_actions`` actions chosen at random (see :meth:`choose`), each checked."""
        return await self._run(n_actions, self.choose)

    async def replay(self, specs: list[dict]) -> list[Failure]:
        """The actions ``specs`` (each an :attr:`Action.spec`, e.g. from :attr:`specs` of another walk),
        in order, each checked as in a walk; one not possible now is passed over (and said so)."""
        todo = iter(specs)

        def next_action():
            spec = next(todo)
            action = self._from_spec(spec)
            if action is None:
                async def nothing():
                    return None
                return Action("skipped", f"(not possible now: {json.dumps(spec)[:80]})", nothing, spec=spec)
            return action
        return await self._run(len(specs), next_action)

    def _from_spec(self, spec: dict) -> Action | None:
        """The action a spec describes, on the page as it is now (None: not possible now)."""
        def typed():
            form = self.s.form_model(spec["css"])
            return None if form is None else self._typing(spec["css"], form, {"name": spec["field"]}, spec["text"],
                                                          spec["kind"], spec["label"])
        build = {
            "tab": lambda: self._make_tab(spec["index"]),
            "subtab": lambda: self._make_subtab(spec["index"], tab=spec.get("tab")),
            "figure-tab": lambda: self._figure_tab(spec["css"], spec["index"]),
            "type": typed,
            "reset": self._make_reset_tab1,
            "press": lambda: self._press(spec["label"], spec["kind"], nth=spec.get("nth", 0),
                                         settle=spec.get("settle", "run")),
            "download": lambda: self._download(spec["label"], spec.get("nth", 0)),
            "tick": lambda: self._tick(spec["nth"], spec["value"]),
            "bands": lambda: self._bands(spec["value"]),
            "rename": lambda: self._rename(spec["nth"], spec["text"]),
            "upload": lambda: self._upload_file(spec["css"], spec["kind"], spec["label"], spec["filename"],
                                                base64.b64decode(spec["data"]), spec["what"]),
            "mapping": lambda: self._map_columns(spec["panel"], spec["kind"], spec["label"],
                                                 [tuple(c) for c in spec["choices"]]),
            "detrend": lambda: self._detrend(spec["value"]),
            "settings": lambda: self._load_settings(spec["filename"], base64.b64decode(spec["data"]), spec["what"]),
            "reload": lambda: self._reload(spec["query"]),
            "other-page": lambda: self._other_page(spec["query"]),
            "gate-id": lambda: self._gate_id(spec["text"]),
            "gate-start": self._gate_start,
        }
        if spec.get("do") not in build:
            raise ValueError(f"spec = {spec!r} is not allowed: unknown action {spec.get('do')!r}")
        return build[spec["do"]]()

    async def _run(self, n_actions: int, next_action) -> list[Failure]:
        try:
            await self.open()
        except Exception as exc:  # noqa: BLE001 - the walk cannot start: that is its finding
            self._walker_error(exc, "connection", "the page opens", "the page")
            return self.failures
        for i in range(n_actions):
            self.index = i
            try:
                action = next_action()
            except StopIteration:
                break
            except Exception as exc:  # noqa: BLE001 - the walker's own defect: reported, the walk goes on
                self.history.append("(choosing an action)")
                self._walker_error(exc)
                action = self._make_tab(self.rng.randrange(len(self.tab_ready)))
                self.history.pop()
            await self._do(i, action)
        return self.failures

    def _walker_error(self, exc: BaseException, kind: str = "walker", invariant: str = "the walker itself works",
                      expected: str = "no exception") -> None:
        import traceback

        if kind == "walker":
            self.walker_errors += 1
        self.fail(kind, invariant, f"{type(exc).__name__}: {exc}"[:400], expected,
                  log=traceback.format_exception(exc)[-14:])

    async def _do(self, i: int, action: Action) -> None:
        """One action: do it, let the page settle, check every invariant."""
        self.history.append(action.desc)
        self.specs.append(action.spec)
        self.counts[action.kind] += 1
        if self.o.trace:
            print(f"{self.name} #{i} {action.desc}", flush=True)
        window = {"t0": time.time(), "t1": None, "index": i, "desc": action.desc}
        self.windows.append(window)
        if len(self.windows) > 50:
            del self.windows[:-50]
        try:
            await action.run()
            # a round trip: its answer says the server has read the action (and done what it does at
            # once); the quiet spell is counted from it
            answer = asyncio.ensure_future(self.s.round_trip(10))
            await asyncio.wait([answer], timeout=10)
            if action.settle == "run":
                await self.s.settle(self.o.run_quiet_s, self.o.settle_cap_s)
            elif action.settle == "quiet":
                await self.s.settle(self.o.quiet_s, self.o.settle_cap_s, wait_busy=self.o.wait_busy)
            await self.check(answer)
        except (ProtocolError, ConnectionError, OSError) as exc:
            self.fail("connection", "the websocket stays open and answers", f"{type(exc).__name__}: {exc}",
                      "an open connection")
            await self._reopen()
        except (StepTimeout, asyncio.TimeoutError) as exc:
            self.fail("action", "the action's effect comes", f"{type(exc).__name__}: {exc}"[:400],
                      "its effect in time")
            if self.s._broken:
                await self._reopen()
        except LookupError as exc:
            self.fail("action", "what the action needs is on the page", f"{type(exc).__name__}: {exc}"[:400],
                      "it there")
        except Exception as exc:  # noqa: BLE001 - the walker's own defect: reported, the walk goes on
            self._walker_error(exc)
        window["t1"] = time.time()
        self.seconds[action.kind] += window["t1"] - window["t0"]
        if self.o.trace:
            print(f"{self.name} #{i} took {window['t1'] - window['t0']:.2f} s", flush=True)
        self.actions_done += 1
        if self.monitor is not None:
            self.monitor.dispatch(settle_s=0.3)

    async def _reopen(self, query: dict | None = None, *, why: str = "a new page opens after a lost one") -> None:
        """A new page (with ``query``, else the last address); if it does not open, one without an address
        (the student clears it), so that one page that cannot open does not end the walk."""
        self.board_step_opened = False          # a new page: the board's step view not opened yet
        for attempt in (self.query if query is None else query, {}):
            try:
                await self.s.close()
            except Exception:  # noqa: BLE001, S110 - it is broken anyway
                pass
            try:
                await self.open(attempt)
                return
            except Exception as exc:  # noqa: BLE001 - reported; then without the address
                shown = "?" + urlencode(attempt) if attempt else "(no address)"
                self.fail("connection", why, f"{type(exc).__name__}: {exc}"[:300], f"the page {shown[:300]}")
                if not attempt:
                    return

    # -- choosing --------------------------------------------------------------------------------------
    #: relative weights of the action kinds; each section's typing (``type-KEY``) and run buttons (``run-KEY``)
    #: are kinds of their own, weighted here or by the defaults below
    WEIGHTS = {
        "tab": 4, "subtab": 3.5, "figure-tab": 2, "type-tab1": 16, "reset-tab1": 0.8,
        "type-simulation": 7, "run-simulation": 6,
        "type-least_squares": 4.5, "run-least_squares": 4.2, "lse-upload": 2, "lse-window": 1.5, "lse-back": 0.6,
        "lse-mapping": 1.2, "handin": 1.5,
        "type-frequency": 5, "run-frequency": 2.2, "record-upload": 2, "type-record": 1.5, "detrend": 1,
        "run-record": 1.5, "record-mapping": 1.2,
        "type-greybox": 3, "run-greybox": 1.5, "gb-cancel": 1.2,
        "type-board": 2, "board-tick": 3, "board-rename": 1.5, "board-delete": 0.7, "board-bands": 0.5,
        "type-study": 2, "run-study": 1, "study-cancel": 1.5,
        "download": 0.8, "any-button": 2, "settings": 1.5, "report": 0.6, "reload": 1.3, "other-page": 0.5,
    }
    #: a section's kinds not weighted above
    TYPE_WEIGHT, RUN_WEIGHT = 3.0, 1.5
    #: how often a run button is pressed beside its section's others (1 unless said)
    BUTTON_WEIGHTS = {TABLE4_RUN: 0.4}
    #: the actions of one section's own parts (its upload, the board's list), by the section they act in
    #: (tab 1 is the section whose form is PARAM_FORM)
    SECTION_OF = {**{k: "least_squares" for k in ("lse-upload", "lse-window", "lse-back", "lse-mapping", "handin")},
                  **{k: "record" for k in ("record-upload", "detrend", "record-mapping")},
                  **{k: "board" for k in ("board-tick", "board-rename", "board-delete", "board-bands")},
                  "study-cancel": "study", "gb-cancel": "greybox"}

    def _plan(self) -> None:
        """The walk's kinds of action, their weights and where each acts, from the page's sections."""
        sections, table = self.sections, type(self).WEIGHTS      # the class's weights (this walk's are set below)
        tab1 = next((p for p in sections if p.form_css == PARAM_FORM), None)
        self.tab1_key = tab1.key if tab1 is not None else "parameters"
        #: what shows that a main tab, or a sub-tab, has been built (a tab opens on its first sub-tab)
        self.tab_ready = {}
        self.subtab_ready: dict[tuple, tuple] = {}
        for p in sections:
            if p.within is None:
                self.tab_ready.setdefault(p.tab, p.content_css)
                if p.subtab is not None:
                    self.subtab_ready[(p.tab, p.subtab)] = (p.content_css, p.title)
        place = {p.key: (p.tab, p.subtab) for p in sections}
        weights = {k: w for k, w in table.items() if not k.startswith(("type-", "run-"))}
        where = {k: place[key] for k, key in self.SECTION_OF.items() if key in place}
        weights = {k: w for k, w in weights.items() if k not in self.SECTION_OF or k in where}
        self.makers = {}
        for p in sections:
            if p.key == self.tab1_key:
                weights["type-tab1"] = table["type-tab1"]
                where["type-tab1"] = where["reset-tab1"] = place[p.key]
                continue
            if p.form_css:
                kind = f"type-{p.key}"
                weights[kind], where[kind] = table.get(kind, self.TYPE_WEIGHT), place[p.key]
                self.makers[kind] = (lambda p=p: self._type_section(p))
            if p.run_buttons:
                kind = f"run-{p.key}"
                weights[kind], where[kind] = table.get(kind, self.RUN_WEIGHT), place[p.key]
                self.makers[kind] = (lambda p=p: self._run_section(p))
        if tab1 is None:
            weights.pop("type-tab1", None)
            weights.pop("reset-tab1", None)
        self.WEIGHTS, self.WHERE = weights, where
        #: the kinds that press a run button
        self.RUNS = tuple(k for k in weights if k.startswith("run-")) + ("handin",)
        #: the sections of a settings file, each a table of texts
        self.settings_sections = tuple(p.key for p in sections)

    def _kinds(self) -> list[str]:
        kinds = [k for k in self.WEIGHTS if (not self.o.only or k in self.o.only) and k not in self.o.exclude]
        if not self.o.exercise_hidden:
            kinds = [k for k in kinds if k not in ("handin", "other-page")]
        return kinds

    def choose(self) -> Action:
        if self.in_gate:
            return self._gate_action()
        if self.pending is not None:
            where = self.WHERE.get(self.pending.kind)
            if self._at(where):
                action, self.pending = self.pending, None
                return action
            if self.pending_steps < 3:
                self.pending_steps += 1
                return self._navigate(where)
            self.pending = None
        kinds = self._kinds()
        places = {where: self._at(where) for where in set(self.WHERE.values())}
        here = [k for k in kinds if places.get(self.WHERE.get(k), True)]
        for attempt in range(30):
            # mostly what can be done where the student is; now and then anything (going there first)
            pool = here if attempt < 10 and self.rng.random() < self.o.stay else kinds
            kind = self.rng.choices(pool, weights=[self.WEIGHTS[k] for k in pool])[0]
            action = self._make(kind)
            if action is None and kind in self.RUNS and not self.shadow.valid and self.rng.random() < 0.5:
                # the run button is off because of tab 1: a student goes back and mends it
                action, kind = self._type_in(PARAM_FORM, "type-tab1", "tab 1", shown_only=False, mend=True), \
                    "type-tab1"
            if action is None:
                continue
            where = self.WHERE.get(kind)
            if where is not None and not self._at(where):
                self.pending, self.pending_steps = action, 1
                return self._navigate(where)
            return action
        return self._make_tab(self.rng.randrange(len(self.tab_ready)))

    def _at(self, where) -> bool:
        if where is None:
            return True
        tab, sub = where
        tabs = self.s.one("Tabs", css=MAIN_TABS)
        if tabs is None or (tabs.attributes.get("active") or 0) != tab or tab not in self._built_tabs():
            return False
        if sub is None:
            return True
        ident = self._subtabs()
        return (ident is not None and (ident.attributes.get("active") or 0) == sub
                and self.s.find(css=self.subtab_ready[(tab, sub)][0]))

    def _subtabs(self) -> Model | None:
        """The sub-tabs of the main tab shown now (None: it has none, or they are not built)."""
        return next((m for m in self.s.find("Tabs", css=IDENT_TABS) if self.s.shown(m)), None)

    def _built_tabs(self) -> set:
        return {i for i, css in self.tab_ready.items() if self.s.find(css=css)}

    def _navigate(self, where) -> Action:
        tab, sub = where
        tabs = self.s.one("Tabs", css=MAIN_TABS)
        if tabs is None or (tabs.attributes.get("active") or 0) != tab or tab not in self._built_tabs():
            return self._make_tab(tab)
        return self._make_subtab(sub, tab=tab)

    # -- actions ---------------------------------------------------------------------------------------
    def _make(self, kind: str) -> Action | None:
        maker = self.makers.get(kind) or getattr(self, "_make_" + kind.replace("-", "_"))
        return maker()

    def _app_shown(self):
        return any(self.s.find(css=css) for css in self.tab_ready.values())

    def _gate_action(self) -> Action:
        s = self.s
        box = s.one("TextInput", css="eha-student-id")
        if box is None and self._app_shown():
            self.in_gate = False
            return self.choose()
        typed = (box.attributes.get("value_input") or box.attributes.get("value") or "") if box else ""
        if (typed.strip() and self.rng.random() < 0.8) or box is None:
            return self._gate_start()
        text = self.rng.choice([self.student_id] * 6 + ["", "   ", "Ada\x1b[2J", "s" * 300, "<b>x</b>"])
        return self._gate_id(text)

    def _gate_start(self) -> Action | None:
        s = self.s
        if s.one("Button", css="eha-start") is None:
            return None

        box = s.one("TextInput", css="eha-student-id")
        typed = (box.attributes.get("value_input") or box.attributes.get("value") or "") if box else ""

        async def start():
            await s.click(s.one("Button", css="eha-start"))
            await s.round_trip(10)
            await s.settle(self.o.run_quiet_s, self.o.settle_cap_s)
            # the app (its open tab: tab=3 in the address builds tab 3 first), or the gate's message
            # (the same one again, for the same refused id: no change to wait for)
            await s.wait_for(lambda: self._app_shown() or self._gate_message().strip(), self.o.tab_s,
                             "the app after Start")
            if self._app_shown():
                self.in_gate = False
                self.joined_as = typed
                self._apply_query()
                if not any(k != "tab" for k in self.query):
                    # an address without fields gives the student their kept work back (the app types
                    # their last settings in): tab 1 is what the page now shows
                    await s.settle(self.o.run_quiet_s, self.o.settle_cap_s)
                    self._shadow_from_page()
        return Action("gate-start", "press Start", start, settle="quiet", spec={"do": "gate-start"})

    def _shadow_from_page(self) -> None:
        from eha_core.params import PARAM_NAMES

        form = self.s.form_model(PARAM_FORM)
        values = (form.attributes.get("values") or {}) if form is not None else {}
        for name in (*PARAM_NAMES, "kp"):
            if name in values and str(values[name]) != self._tab1_texts().get(name):
                self._shadow_type(name, str(values[name]))

    def _gate_id(self, text: str) -> Action | None:
        s = self.s
        box = s.one("TextInput", css="eha-student-id")
        if box is None:
            return None

        async def type_id():
            await s.set_property(box, "value_input", text)
            await s.set_property(box, "value", text)
        return Action("gate-id", f"type student id = {_short(text)}", type_id, spec={"do": "gate-id", "text": text})

    def _gate_message(self) -> str:
        m = self.s.one(css="eha-error-student")
        return m.text() if m is not None else ""

    def _make_tab(self, index: int | None = None) -> Action:
        if index is None:
            index = self.rng.randrange(len(self.tab_ready))
        s = self.s

        async def show():
            tabs = s.one("Tabs", css=MAIN_TABS)
            if tabs is None:
                raise LookupError("no main tabs")
            if (tabs.attributes.get("active") or 0) != index:
                await s.set_property(tabs, "active", index)
            await s.wait_for(lambda: s.find(css=self.tab_ready[index]), self.o.tab_s, f"tab {index + 1}'s content")
        return Action("tab", f"show tab {index + 1}", show, spec={"do": "tab", "index": index})

    def _make_subtab(self, index: int | None = None, *, tab: int | None = None) -> Action | None:
        places = sorted(self.subtab_ready)
        if not places:
            return None
        if index is None:
            tab, index = self.rng.choice(places)
        elif tab is None:
            tab = places[0][0]          # an action saved before sub-tabs said their tab: the only such tab
        if (tab, index) not in self.subtab_ready:
            return None
        s = self.s
        ready, title = self.subtab_ready[(tab, index)]

        async def show():
            ident = self._subtabs()
            if ident is None or not self._at((tab, None)):
                await self._make_tab(tab).run()
                await s.wait_for(self._subtabs, self.o.tab_s, f"tab {tab + 1}'s sub-tabs")
                ident = self._subtabs()
            if (ident.attributes.get("active") or 0) != index:
                await s.set_property(ident, "active", index)
            await s.wait_for(lambda: s.find(css=ready), self.o.tab_s, f"tab {tab + 1}'s {title}")
        return Action("subtab", f"show tab {tab + 1} / {title}", show,
                      spec={"do": "subtab", "index": index, "tab": tab})

    def _make_figure_tab(self) -> Action | None:
        options = [(css, n) for css, n in ((FREQ_FIGURES, 6), (BOARD_VIEWS, 4))
                   if any(self.s.shown(m) for m in self.s.find("Tabs", css=css))]
        if not options:
            return self._make_subtab()
        css, n = self.rng.choice(options)
        return self._figure_tab(css, self.rng.randrange(n))

    def _figure_tab(self, css: str, index: int) -> Action | None:
        s = self.s
        tabs = s.one("Tabs", css=css)
        if tabs is None:
            return None

        async def show():
            await s.set_property(tabs, "active", index)
            if css == BOARD_VIEWS and index == 2:
                self.board_step_opened = True   # the board computes its steps from now on (see signature)
        return Action("figure-tab", f"show {css.replace('eha-', '')} tab {index + 1}", show,
                      spec={"do": "figure-tab", "css": css, "index": index})

    # typing --------------------------------------------------------------------------------------------
    def _fields(self, form: Model) -> list[dict]:
        return [f for g in form.attributes.get("spec") or [] for f in g.get("fields", [])]

    def _type_in(self, css: str, kind: str, label: str, *, shown_only: bool = True,
                 mend: bool = False) -> Action | None:
        s = self.s
        form = s.form_model(css)
        if form is None:
            return None
        fields = self._fields(form)
        hidden = set(form.attributes.get("hidden") or [])
        errors = form.attributes.get("errors") or {}
        choices = [f for f in fields if f["name"] not in hidden] if shown_only else fields
        if not choices:
            return None
        defaults = self._default_texts() if css == PARAM_FORM else (form.attributes.get("url_defaults") or {})
        if errors and (mend or self.rng.random() < 0.7):      # mend a field in error, as a student would
            bad = [f for f in choices if f["name"] in errors]
            if bad:
                f = self.rng.choice(bad)
                return self._typing(css, form, f, self._valid(f, defaults.get(f["name"]), mend=True), kind, label)
        f = self.rng.choice(choices)
        return self._typing(css, form, f, self._value(f, defaults.get(f["name"])), kind, label)

    def _typing(self, css: str, form: Model, f: dict, text: str, kind: str, label: str) -> Action:
        s = self.s
        name = f["name"]

        async def type_it():
            target = s.form_model(css)
            values = dict(target.attributes.get("values") or {})
            await s.set_property(target, "values", {**values, name: text})
            await s.sync()
            if css == PARAM_FORM:
                self._shadow_type(name, text)
                await self._wait_derived()
        return Action(kind, f"{label}: {name} = {_short(text)}", type_it,
                      settle="none" if css == PARAM_FORM else "quiet",
                      spec={"do": "type", "css": css, "field": name, "text": text, "kind": kind, "label": label})

    async def _wait_derived(self) -> None:
        """Tab 1's answer to typing: the derived values as expected (checked properly afterwards)."""
        pane = self.s.one(css="eha-derived")
        if pane is None:
            return
        expected = self.expected_derived()
        if isinstance(expected, Exception):
            await self.s.settle(self.o.quiet_s, self.o.settle_cap_s, wait_busy=self.o.wait_busy)
            return
        timeout = 0.4 if self.derived_bad else self.o.derived_s
        try:
            await self.s.wait_for(lambda: pane.text() == expected, timeout, "tab 1's derived values")
        except StepTimeout:
            pass
        await self.s.settle(self.o.quiet_s, self.o.settle_cap_s, wait_busy=self.o.wait_busy)

    #: texts a field is not meant to take (a few that parse: "1e3", " 42 ", "٣" is an Arabic-Indic 3)
    _EDGE = ("", " ", "abc", "1e308", "-1e308", "1e309", "-1", "0", "nan", "inf", "-inf", "1,5", "1e-308", "9" * 201,
             "½", "12 mm", "0x1A", "  42  ", "-0", "1e3", "5e-324", "٣", "1_000")

    #: fields whose large valid values cost the server much: at most this in a light walk
    _COSTLY = {"study_seeds": 12, "n_samples": 2000, "n_trials": 5, "n_sines": 60}

    def _value(self, f: dict, default: str | None) -> str:
        """Any text for field ``f``: mostly a valid one near its default, else out of range or not a number."""
        r = self.rng.random()
        if f.get("kind") == "select":
            options = [o[0] for o in f.get("options") or []]
            if r < 0.85 and options:
                return self.rng.choice(options)
            return self.rng.choice(["", "xyz", (options or ["x"])[0].upper(), " " + (options or ["x"])[0]])
        if r < 0.65:
            return self._valid(f, default)
        special = self._special(f["name"])
        if special and r < 0.8:
            return self.rng.choice(special)
        if r < 0.82 and f.get("lo") is not None:
            return f"{f['lo'] - max(abs(f['lo']) * 0.5, 1):.6g}"
        if r < 0.84 and f.get("hi") is not None:
            return f"{f['hi'] * 2 + 1:.6g}"
        return self.rng.choice(self._EDGE)

    def _special(self, name: str) -> list:
        """Texts that mean something to one field (its first ones valid)."""
        return {
            "lse_custom": ["sine:1000:3", "none", "white:500", "sine:500:2+noise:100:1", "step:2000:1",
                           "chirp:500:1:5", "bogus:1", "sine:abc", "noise:1e308", "const:1e6", "sine:1e308:1"],
            "lse_freq": ["", "3", "0.5", "2.5", "-1", "1e308", "25", "1e-9"],
            "input_delay": ["0", "", "estimate", "est", "0.01", "0.05", "-0.1", "1e308", "none", "EST"],
            "own_from": ["", "0", "0.5", "1", "-1", "5", "1.99"], "own_to": ["", "1", "1.5", "2", "0.02", "99"],
            "rec_from": ["", "0", "1", "2", "-1", "1e308"], "rec_to": ["", "1", "3", "5", "0.1", "99"],
        }.get(name, [])

    def _valid(self, f: dict, default: str | None, *, mend: bool = False) -> str:
        """A text the field takes: its default (always when ``mend``), or a value near it or in its range.
        Forms do not send their bounds (only sliders'), so the default is the guide."""
        name, kind = f["name"], f.get("kind")
        if kind == "select":
            options = [o[0] for o in f.get("options") or []]
            return default if (mend and default in options) or not options else self.rng.choice(options)
        special = self._special(name)
        if special:
            return special[0] if mend else self.rng.choice(special[:4])
        base = "" if default is None else str(default)
        if mend or self.rng.random() < 0.25:
            return base
        cap = self._COSTLY.get(name) if self.o.light else None
        lo, hi = f.get("lo"), f.get("hi")
        if lo is not None and hi is not None:           # a slider: anywhere on it
            hi = min(hi, cap) if cap is not None else hi
            v = (math.exp(self.rng.uniform(math.log(lo), math.log(hi))) if lo > 0 and hi / lo > 100
                 else self.rng.uniform(lo, hi))
            return f"{v:.3g}"
        try:
            v = float(base)
        except ValueError:
            return base
        if kind == "text":              # tab 1: the paper's value scaled a little (p2(0) blank: force balance)
            if name == "p2_0" and self.rng.random() < 0.5:
                return ""
            return f"{v * self.rng.choice([0.5, 0.8, 0.9, 1.1, 1.25, 2]):.4g}"
        if kind == "integer" or (v == int(v) and abs(v) < 1e6 and "." not in base and "e" not in base.lower()):
            n = int(v) + self.rng.choice([0, 1, 2, 5, -1]) if v else self.rng.choice([0, 1, 2, 7, 42])
            n = max(n, 0) if v >= 0 else n
            return str(min(n, cap) if cap is not None else n)
        if v == 0:
            return self.rng.choice(["0", "0.1", "0.5", "2"])
        return f"{v * self.rng.choice([0.5, 0.8, 0.9, 1.1, 1.25, 2]):.4g}"

    _defaults: dict = {}

    def _default_texts(self) -> dict:
        """Tab 1's fields as a page opens: the paper's values in display units."""
        if not Walker._defaults:
            fresh = _app_state()()
            Walker._defaults.update({**fresh.texts, "kp": fresh.kp_text})
        return Walker._defaults

    def _make_type_tab1(self) -> Action | None:
        return self._type_in(PARAM_FORM, "type-tab1", "tab 1", shown_only=False)

    def _make_reset_tab1(self) -> Action | None:
        s = self.s
        button = s.one("Button", label=RESET)
        if button is None:
            return None

        async def reset():
            await s.click(button)
            self.shadow.reset_defaults()
            await self._wait_derived()
        return Action("reset-tab1", "press “Reset to paper defaults”", reset, settle="none", spec={"do": "reset"})

    def _type_section(self, p: PageSection) -> Action | None:
        """Type into section ``p``'s form, once it is there and shown on its tab (the own record's range
        only once a record is read)."""
        return self._visible_form(p.form_css, f"type-{p.key}", p.title, tabs=False)

    def _run_section(self, p: PageSection) -> Action | None:
        """Press one of section ``p``'s run buttons that is there and enabled."""
        labels = [label for label in p.run_buttons if self._buttons(label)]
        if not labels:
            return None
        label = self.rng.choices(labels, weights=[self.BUTTON_WEIGHTS.get(x, 1.0) for x in labels])[0]
        return self._press(label, f"run-{p.key}")

    def _make_lse_window(self):
        return self._visible_form(LSE_WINDOW, "lse-window", "least squares' range")

    def _visible_form(self, css: str, kind: str, label: str, *, tabs: bool = True):
        component = self.s.one(css=css)
        if component is None or not self.s.shown(component, tabs=tabs):
            return None
        return self._type_in(css, kind, label)

    # buttons --------------------------------------------------------------------------------------------
    @staticmethod
    def _order(m: Model):
        """Models in the order they were made (ids are "p" and a counter)."""
        return (len(m.id), m.id)

    def _buttons(self, label: str, type_suffix: str = "Button") -> list[Model]:
        """The enabled buttons labelled ``label`` that are on the page (whichever tab they are on)."""
        s = self.s
        found = [b for b in s.find(type_suffix, label=label)
                 if s.shown(b, tabs=False) and not b.attributes.get("disabled")
                 and (type_suffix != "Button" or not b.type.endswith("FileDownload"))]
        return sorted(found, key=self._order)

    def _press(self, label: str, kind: str, *, nth: int = 0, settle: str = "run",
               desc: str | None = None) -> Action | None:
        """Press the ``nth`` enabled button labelled ``label`` (the inputs of the views it runs noted first)."""
        s = self.s
        found = self._buttons(label)
        if len(found) <= nth:
            return None
        button = found[nth]
        desc = desc or f"press “{label}”" + (" (any button)" if kind == "any-button" else "")
        runs = tuple(v for v, lab in VIEW_BUTTON.items() if lab == label)

        async def press():
            if runs:
                await s.sync()      # the inputs as the server has them when the button is pressed
            if button.attributes.get("disabled") or not s.shown(button):
                # it went off (or away) while the walk went to its tab: a student cannot press it
                self.history[-1] = desc + " (not pressed: it is off now)"
                return
            for view in runs:
                self.views.setdefault(view, ViewTrack()).runs.append(self.signature(view))
            await s.click(button)
            if label == RESET:
                self.shadow.reset_defaults()
                await self._wait_derived()
            elif label == REPORT:
                # the report takes a second or two of a worker, with no indicator: its download button
                # (or a message) is its effect; waiting for it keeps the walk the same from run to run
                await self._wait_report()
        return Action(kind, desc, press, settle=settle, runs=runs,
                      spec={"do": "press", "label": label, "nth": nth, "kind": kind, "settle": settle})

    async def _wait_report(self) -> None:
        s = self.s

        def ready():
            button = s.one(css="eha-session-report-download")
            note = s.one(css="eha-settings-note")
            return ((button is not None and button.attributes.get("visible"))
                    or (note is not None and "could not be made" in note.text()))
        await s.round_trip(10)
        try:
            await s.wait_for(ready, 15, "the session report")
        except StepTimeout:
            pass

    def _make_handin(self):
        return self._press(HANDIN, "handin")

    def _make_lse_back(self):
        return self._press(BACK_TO_SIMULATED, "lse-back", settle="quiet")

    def _make_study_cancel(self):
        return self._press(STUDY_CANCEL, "study-cancel")

    def _make_gb_cancel(self):
        return self._press(GB_CANCEL, "gb-cancel")

    def _make_report(self):
        return self._press(REPORT, "report")

    def _make_any_button(self):
        """Any button on screen that is enabled (whatever its label: buttons added later are pressed too)."""
        s = self.s
        buttons = [b for b in s.find("Button") if s.shown(b) and not b.attributes.get("disabled")
                   and not b.type.endswith("FileDownload")]
        if not buttons:
            return None
        buttons.sort(key=lambda b: (str(b.attributes.get("label")), self._order(b)))
        label = str(self.rng.choice(buttons).attributes.get("label"))
        same = [b for b in self._buttons(label) if s.shown(b)]
        if not same:
            return None
        nth = self._buttons(label).index(self.rng.choice(same))
        return self._press(label, "any-button", nth=nth)

    def _make_download(self):
        found = [b for b in self.s.find("FileDownload") if self.s.shown(b) and not b.attributes.get("disabled")]
        if not found:
            return None
        label = str(self.rng.choice(sorted(found, key=self._order)).attributes.get("label"))
        return self._download(label, 0)

    def _download(self, label: str, nth: int) -> Action | None:
        s = self.s
        found = self._buttons(label, "FileDownload")
        if len(found) <= nth:
            return None
        button = found[nth]

        async def press():
            clicks = int(button.attributes.get("clicks") or 0) + 1
            await s.set_property(button, "clicks", clicks)
        return Action("download", f"press download “{label}”", press, settle="run",
                      spec={"do": "download", "label": label, "nth": nth})

    # the model board -----------------------------------------------------------------------------------
    def _board_items(self, css: str, type_suffix: str) -> list[Model]:
        items = [m for m in self.s.find(type_suffix, css=css) if self.s.shown(m, tabs=False)]
        return sorted(items, key=self._order)

    def _make_board_tick(self):
        boxes = self._board_items("eha-board-tick", "Checkbox")
        if not boxes:
            return None
        nth = self.rng.randrange(len(boxes))
        return self._tick(nth, not bool(boxes[nth].attributes.get("active")))

    def _tick(self, nth: int, value: bool) -> Action | None:
        boxes = self._board_items("eha-board-tick", "Checkbox")
        if len(boxes) <= nth:
            return None
        box = boxes[nth]
        name = next((c for c in box.css if c.startswith("eha-board-tick-")), "eha-board-tick-?")

        async def tick():
            await self.s.set_property(box, "active", value)
        return Action("board-tick", f"{'tick' if value else 'untick'} board model {name[15:]}", tick,
                      spec={"do": "tick", "nth": nth, "value": value})

    def _make_board_bands(self):
        box = self.s.one("Checkbox", css="eha-board-bands")
        if box is None or not self.s.shown(box, tabs=False):
            return None
        return self._bands(not bool(box.attributes.get("active", True)))

    def _bands(self, value: bool) -> Action | None:
        box = self.s.one("Checkbox", css="eha-board-bands")
        if box is None:
            return None

        async def tick():
            await self.s.set_property(box, "active", value)
        return Action("board-bands", f"{'tick' if value else 'untick'} the 95 % bands", tick,
                      spec={"do": "bands", "value": value})

    def _make_board_rename(self):
        names = self._board_items("eha-board-name", "TextInput")
        if not names:
            return None
        text = self.rng.choice(["H1 mine", "", "   ", "x" * 60, "<b>bold</b>", "Ĥ(s) ✓", "model\nwith newline",
                                "a", "LS1"])
        return self._rename(self.rng.randrange(len(names)), text)

    def _rename(self, nth: int, text: str) -> Action | None:
        names = self._board_items("eha-board-name", "TextInput")
        if len(names) <= nth:
            return None
        box = names[nth]

        async def rename():
            await self.s.set_property(box, "value_input", text)
            await self.s.set_property(box, "value", text)
        return Action("board-rename", f"rename board model {nth + 1} to {_short(text)}", rename,
                      spec={"do": "rename", "nth": nth, "text": text})

    def _make_board_delete(self):
        drops = self._buttons("✕")
        if not drops:
            return None
        nth = self.rng.randrange(len(drops))
        return self._press("✕", "board-delete", nth=nth, settle="quiet",
                           desc=f"delete board model ({drops[nth].attributes.get('description', '')})")

    # files ------------------------------------------------------------------------------------------
    def _upload(self, css: str, kind: str, label: str, make) -> Action | None:
        component = self.s.one(css=css)
        if component is None or not self.s.shown(component):
            return None
        data_model = self.s.component_data(css)
        limit = int(data_model.attributes.get("max_bytes") or 20_000_000)
        self.uploads += 1
        filename, data, what = make(self.uploads)
        if len(data) > limit:       # the page refuses it before sending a byte
            data = data[:limit]
            what += " (cut to the chooser's limit)"
        return self._upload_file(css, kind, label, filename, data, what)

    def _upload_file(self, css: str, kind: str, label: str, filename: str, data: bytes, what: str) -> Action | None:
        if self.s.one(css=css) is None:
            return None

        async def upload():
            await self.s.upload(css, filename, data)
        return Action(kind, f"{label}: choose {filename} ({what}, {len(data)} bytes)", upload, settle="run",
                      spec={"do": "upload", "css": css, "kind": kind, "label": label, "filename": filename,
                            "data": base64.b64encode(data).decode(), "what": what})

    def _lse_file(self, k: int) -> tuple[str, bytes, str]:
        header, rows = _table(_case_csv())
        tag = f"{self.seed}_{k}"
        r = self.rng.random()
        if r < 0.35:
            n = self.rng.choice([len(rows), 1000, 300, 60])
            return f"data_{tag}.csv", _write_csv(header, rows[:n]), f"simulated case 1, {n} rows"
        if r < 0.45:
            cols = {h: [float(row[i]) for row in rows[:800]] for i, h in enumerate(header)}
            data = _mat(cols)
            if data is not None:
                return f"data_{tag}.mat", data, "MATLAB file, 800 rows"
        if r < 0.55:
            new = ["time", "pos", "vel", "pA", "pB", "cmd", "dist"]
            return f"data_{tag}.csv", _write_csv(new, rows[:500]), "columns to map"
        if r < 0.62:
            new = [h if h not in ("p1", "p2") else f"{h}[MPa]" for h in header]
            scaled = [[c if header[i] not in ("p1", "p2") else f"{float(c) / 1e6:.8g}" for i, c in enumerate(row)]
                      for row in rows[:600]]
            return f"data_{tag}.csv", _write_csv(new, scaled), "pressures in MPa"
        bad = self.rng.choice([
            (b"", "empty"), (b"t,x,v,p1,p2,u\n" + b"1,2,3,4,5,6\n" * 10, "10 rows"),
            (bytes(self.rng.randrange(256) for _ in range(3000)), "random bytes"),
            (_write_csv(header, [r[:3] + ["abc"] + r[4:] for r in rows[:200]]), "a text cell"),
            (_write_csv(header, rows[200:100:-1]), "time running backwards"),
            (b"\xef\xbb\xbf" + _write_csv(header, rows[:300]), "with a byte-order mark"),
            (_write_csv(header, [[c if j != 1 else "nan" for j, c in enumerate(r)] for r in rows[:300]]), "NaN x"),
        ])
        return f"bad_{tag}.{self.rng.choice(['csv', 'mat', 'txt'])}", bad[0], bad[1]

    def _record_file(self, k: int) -> tuple[str, bytes, str]:
        tag = f"{self.seed}_{k}"
        r = self.rng.random()
        if r < 0.4:
            n = self.rng.choice([200, 600, 1200])
            return f"record_{tag}.csv", _record(self.rng, n), f"t, u, y, {n} rows"
        if r < 0.5:
            return f"record_{tag}.csv", _record(self.rng, 500, ("t", "r", "x")), "t, r, x"
        if r < 0.6:
            return f"record_{tag}.csv", _record(self.rng, 400, ("time", "in", "out")), "columns to map"
        if r < 0.68:
            header, rows = _table(_record(self.rng, 400))
            data = _mat({h: [float(row[i]) for row in rows] for i, h in enumerate(header)})
            if data is not None:
                return f"record_{tag}.mat", data, "MATLAB file"
        bad = self.rng.choice([(b"", "empty"), (b"t,u,y\n0,1,2\n", "one row"),
                               (bytes(self.rng.randrange(256) for _ in range(2000)), "random bytes"),
                               (_record(self.rng, 300).replace(b"\n1", b"\nx", 3), "text cells"),
                               (b"t,u,y\n" + b"0,0,0\n" * 100, "constant")])
        return f"bad_record_{tag}.{self.rng.choice(['csv', 'mat'])}", bad[0], bad[1]

    def _make_lse_upload(self):
        return self._upload("eha-lse-upload", "lse-upload", "least squares' file", self._lse_file)

    def _make_record_upload(self):
        return self._upload("eha-freq-upload", "record-upload", "own record", self._record_file)

    def _mapping(self, panel_css: str, kind: str, label: str) -> Action | None:
        s = self.s
        panel = s.one(css=panel_css)
        if panel is None or not s.shown(panel):
            return None
        inside = s.descendants(panel)
        selects = sorted([m for m in inside if m.type.endswith("Select") and any(c.startswith("eha-map-")
                                                                                 for c in m.css)],
                         key=lambda m: m.id)
        button = next((m for m in inside if m.type.endswith("Button") and "eha-map-go" in m.css), None)
        if button is None:
            return None
        choices = []
        for sel in selects:
            options = [o[0] if isinstance(o, list) else o for o in sel.attributes.get("options") or []]
            if options and self.rng.random() < 0.5:
                choices.append((next(c for c in sel.css if c.startswith("eha-map-")), self.rng.choice(options)))
        return self._map_columns(panel_css, kind, label, choices)

    def _map_columns(self, panel_css: str, kind: str, label: str, choices: list) -> Action | None:
        s = self.s
        panel = s.one(css=panel_css)
        if panel is None:
            return None
        inside = s.descendants(panel)
        button = next((m for m in inside if m.type.endswith("Button") and "eha-map-go" in m.css), None)
        if button is None:
            return None
        selects = {c: m for m in inside if m.type.endswith("Select") for c in m.css if c.startswith("eha-map-")}

        async def choose():
            for css, value in choices:
                if css in selects:
                    await s.set_property(selects[css], "value", value)
            await s.settle(self.o.quiet_s, self.o.settle_cap_s)
            await s.click(button)
        what = ", ".join(f"{c[8:]}={v}" for c, v in choices)
        return Action(kind, f"{label}: columns {what or 'as guessed'}, “Use these columns”", choose, settle="run",
                      spec={"do": "mapping", "panel": panel_css, "kind": kind, "label": label,
                            "choices": [list(c) for c in choices]})

    def _make_lse_mapping(self):
        return self._mapping("eha-lse-mapping", "lse-mapping", "least squares' file")

    def _make_record_mapping(self):
        return self._mapping("eha-freq-record-mapping", "record-mapping", "own record")

    def _make_detrend(self):
        sel = self.s.one(css="eha-freq-record-detrend")
        if sel is None or not self.s.shown(sel):
            return None
        options = [o[0] if isinstance(o, list) else o for o in sel.attributes.get("options") or []]
        return self._detrend(self.rng.choice(options or ["none"]))

    def _detrend(self, value: str) -> Action | None:
        sel = self.s.one(css="eha-freq-record-detrend")
        if sel is None:
            return None

        async def choose():
            await self.s.set_property(sel, "value", value)
        return Action("detrend", f"record: remove {value}", choose, spec={"do": "detrend", "value": value})

    # settings and the address ---------------------------------------------------------------------
    def _settings_doc(self) -> dict:
        """The page's settings as “Save settings” writes them (eha_app/settings.py's format)."""
        doc = {"format": "eha-settings/1", self.tab1_key: dict(self._tab1_texts())}
        tabs = self.s.one("Tabs", css=MAIN_TABS)
        doc["tab"] = int((tabs.attributes.get("active") or 0) if tabs else 0) + 1
        for p in self.sections:
            form = self.s.form_model(p.form_css) if p.form_css and p.key != self.tab1_key else None
            if form is not None:
                doc[p.key] = {k: str(v) for k, v in (form.attributes.get("values") or {}).items()}
        return doc

    def _make_settings(self) -> Action | None:
        doc = self._settings_doc()
        r = self.rng.random()
        what = "saved settings"
        if r < 0.6:
            sections = [k for k in doc if isinstance(doc[k], dict)]
            for _ in range(self.rng.randint(1, 4)):
                section = self.rng.choice(sections)
                if not doc[section]:
                    continue
                name = self.rng.choice(sorted(doc[section]))
                if section == self.tab1_key:
                    value = self.rng.choice([self._valid({"name": name, "kind": "text"},
                                                         self._default_texts().get(name))] * 2 + list(self._EDGE[:8]))
                else:
                    value = self.rng.choice(["0", "1", "5", "abc", "", "1e308", "-1"])
                doc[section][name] = value
            what = "changed settings"
            data = json.dumps(doc).encode()
        elif r < 0.7:
            data, what = b"{not json", "not JSON"
        elif r < 0.78:
            doc["format"] = "something-else/2"
            data, what = json.dumps(doc).encode(), "another format"
        elif r < 0.85:
            doc[self.tab1_key] = ["M", 1]
            data, what = json.dumps(doc).encode(), "parameters as a list"
        elif r < 0.9:
            doc[self.tab1_key]["M"] = "9" * 300
            data, what = json.dumps(doc).encode(), "a 300-character value"
        elif r < 0.95:
            doc[self.tab1_key]["unknown_field"] = "1"
            doc["extra"] = {"a": 1}
            data, what = json.dumps(doc).encode(), "unknown fields"
        else:
            data, what = ("[" * 5000 + "]" * 5000).encode(), "nested deeply"
        self.uploads += 1
        return self._load_settings(f"settings_{self.seed}_{self.uploads}.json", data, what)

    def _load_settings(self, filename: str, data: bytes, what: str) -> Action | None:
        doc = self._settings_file(data)
        s = self.s
        if s.one(css="eha-load-settings") is None:
            return None

        async def load():
            await s.upload("eha-load-settings", filename, data)
            self._shadow_settings(doc)
            await s.round_trip(10)
            await self._wait_derived()
        verdict = "a file it takes" if doc is not None else "a file it refuses"
        return Action("settings", f"load {filename} ({what}: {verdict})", load, settle="run",
                      spec={"do": "settings", "filename": filename, "data": base64.b64encode(data).decode(),
                            "what": what})

    def _settings_file(self, data: bytes) -> dict | None:
        """The settings file as the app should take it (its format: "Save settings"), or None if it
        should refuse the whole file: at most 100 kB, JSON, this format, every section a table of texts
        or numbers of at most 200 characters. A refused file changes nothing."""
        if len(data) > 100_000:
            return None
        try:
            doc = json.loads(data)
        except (ValueError, RecursionError):
            return None
        if not isinstance(doc, dict) or doc.get("format") != "eha-settings/1":
            return None
        for section in self.settings_sections:
            given = doc.get(section) or {}
            if not isinstance(given, dict):
                return None
            for value in given.values():
                if isinstance(value, bool) or not isinstance(value, (str, int, float)) or len(str(value)) > 200:
                    return None
        return doc

    def _shadow_settings(self, doc) -> None:
        """Tab 1 as the app types a loaded settings file into it (eha_app.settings.apply): each field in the
        file's order, then the form's changed fields again in the form's order (its watcher types them)."""
        from eha_core.params import PARAM_NAMES

        if doc is None:
            return
        params = doc.get(self.tab1_key) or {}
        before = self._tab1_texts()
        for name, text in params.items():
            if name in (*PARAM_NAMES, "kp"):
                self._shadow_type(name, str(text))
        after = self._tab1_texts()
        for name in (*PARAM_NAMES, "kp"):
            if name in after and before.get(name) != after.get(name):
                self._shadow_type(name, after[name])

    def _make_reload(self) -> Action:
        return self._reload(self.page_query())

    def _make_other_page(self) -> Action | None:
        return self._other_page(self.page_query())

    def _other_page(self, query: dict) -> Action | None:
        """An exercise: the student opens the app in another browser tab with the same id (one id, one live
        page: this page gives way and says so), closes that tab, and reloads this one."""
        who = self.joined_as
        if not who:
            return None

        async def other_page():
            other = StudentSession(self.url, name=f"{self.name}-other", timeout=self.timeout)
            try:
                await other.open(self.timeout)
                box = await other.wait_for_model("TextInput", css="eha-student-id", timeout=self.o.tab_s)
                await other.set_property(box, "value_input", who)
                await other.set_property(box, "value", who)
                await other.click(other.find("Button", css="eha-start")[0])
                await other.wait_for(lambda: any(other.find(css=c) for c in self.tab_ready.values()), self.o.tab_s,
                                     "the other page's app")
                try:
                    await self.s.wait_for(lambda: self.s.find(css="eha-given-way"), 10, "the first page giving way")
                except Exception:  # noqa: BLE001 - reported as the invariant it breaks
                    self.fail("invariant", "a page gives way when its id is opened on another page",
                              "no notice on the first page within 10 s", "Your code was opened on another page")
                await other.round_trip(10)
            finally:
                await other.close()
            await self._reopen(query, why="the first page opens again after the other closed")
        shown = _short(who, 20)
        return Action("other-page", f"open the app with id {shown} in another tab, close it, reload this one",
                      other_page, spec={"do": "other-page", "query": dict(query)})

    def _reload(self, query: dict) -> Action:
        async def reload():
            await self._reopen(query, why="the page opens again from its address")
        shown = "&".join(f"{k}={_short(v, 20)}" for k, v in query.items())
        return Action("reload", f"reload the page ?{shown}", reload, spec={"do": "reload", "query": dict(query)})

    # -- checking ------------------------------------------------------------------------------------
    async def check(self, answer: asyncio.Future | None = None) -> None:
        s = self.s
        try:
            await (answer if answer is not None else s.round_trip(10))
        except asyncio.TimeoutError:
            self.fail("connection", "the session answers a round trip", "no answer in 10 s", "an OK")
        for e in s.errors[self.errors_seen:]:
            kind = "connection" if e.startswith("connection") else "server-error"
            self.fail(kind, "the server accepts every message of the session", e[:400], "no ERROR reply")
        self.errors_seen = len(s.errors)
        if s._broken:
            raise ProtocolError(s._broken)
        if self.in_gate:
            return
        await self._check_derived()
        await self._eventually(self._button_problems, "buttons")
        await self._eventually(self._freshness_problems, "freshness")
        self._note_views()

    async def _eventually(self, problems, group: str) -> None:
        """Report what ``problems()`` finds unless it mends within the consistency time; a problem that
        lasts is reported once, until it mends."""
        found = problems()
        known = self.reported.get(group, set())
        # a new one gets time to mend (the page may be a moment behind); a sort this walk already
        # reported does not (the defect is known: no need to wait for it every time)
        if any(key not in known and key[:2] not in self.sorts for _, key, _, _, _ in found):
            try:
                await self.s.wait_for(lambda: not problems(), self.o.consistency_s, group)
                found = []
            except StepTimeout:
                found = problems()
        keys = set()
        for kind, key, invariant, seen, expected in found:
            keys.add(key)
            self.sorts.add(key[:2])
            if key not in known:
                self.fail(kind, invariant, seen, expected)
        self.reported[group] = keys

    async def _check_derived(self) -> None:
        pane = self.s.one(css="eha-derived")
        if pane is None:
            return
        expected = self.expected_derived()
        if isinstance(expected, Exception):
            what = f"{type(expected).__name__}: {expected}"
            if what not in self.reported.setdefault("derived-raises", set()):
                self.reported["derived-raises"].add(what)
                s = self.shadow
                self.fail("derived", "tab 1's derived values can be made for every input tab 1 takes as valid "
                          "(eha_app's derived_html)", f"derived_html raises {what[:200]}",
                          "the derived values" if s.valid else "the last valid ones, marked out of date")
            self.derived_bad = True
            return
        if pane.text() != expected:
            try:
                await self.s.wait_for(lambda: pane.text() == expected, 0.3 if self.derived_bad else 1.0,
                                      "tab 1's derived values")
            except StepTimeout:
                if not self.derived_bad:
                    s = self.shadow
                    seen, wanted = _first_difference(pane.text(), expected)
                    self.fail("derived", "tab 1's derived values (.eha-derived) follow its fields (within "
                              f"{self.o.derived_s:g} s)", seen,
                              f"{wanted} (tab 1 {'valid' if s.valid else 'not valid: marked out of date'})")
                self.derived_bad = True
                return
        self.derived_bad = False

    # buttons ---------------------------------------------------------------------------------------
    def _tab1_valid(self) -> bool:
        return bool(self.shadow.valid)

    def _form_errors(self, css: str) -> dict | None:
        form = self.s.form_model(css)
        return None if form is None else dict(form.attributes.get("errors") or {})

    def expected_buttons(self) -> dict:
        """Each run button's expected state: label -> (enabled?, why). Only buttons on the page."""
        s, valid = self.s, self._tab1_valid()
        out = {}
        why_tab1 = "tab 1 is valid" if valid else "tab 1 has an invalid field"
        sim = self._form_errors(SIM_FORM)
        if sim is not None:
            for label in SIM_BUTTONS:
                out[label] = (valid and not sim, f"{why_tab1}, tab 2's form {'has errors' if sim else 'is valid'}")
        lse = self._form_errors(LSE_FORM)
        if lse is not None:
            window = self._form_errors(LSE_WINDOW) or {}
            # a file waiting for its columns holds the run (it would otherwise use the simulated sensors)
            mapping = s.one(css="eha-lse-mapping")
            waiting = bool(mapping is not None and s.shown(mapping, tabs=False))
            out[LSE_RUN] = (valid and not lse and not window and not waiting,
                            f"{why_tab1}, the least squares' form {'has errors' if lse or window else 'is valid'}"
                            + (", a file waits for its columns" if waiting else ""))
            out[TABLE4_RUN] = (valid and "lse_seed" not in lse,
                               f"{why_tab1}, its noise seed {'is not' if 'lse_seed' in lse else 'is'} valid")
            if self.o.exercise_hidden:
                view = s.one(css="eha-view-lse")
                has = view is not None and "eha-empty" not in view.css
                # a hand-in comes from the student's actuator, not from a file of theirs
                table = s.one(css="eha-lse-table")
                own = has and table is not None and "Your data (" in table.text()
                out[HANDIN] = (has and not own, "the least squares ran on your own file" if own else
                               "the least squares ran" if has else "no least-squares result yet")
        freq = self._form_errors(FREQ_FORM)
        if freq is not None:
            pane = s.one(css="eha-error-freq")
            config_error = bool(pane is not None and pane.attributes.get("visible") and valid)
            out[FREQ_RUN] = (valid and not freq and not config_error,
                             f"{why_tab1}, the frequency form {'has errors' if freq or config_error else 'is valid'}")
            record = self._record_token()
            window = self._form_errors(RECORD_WINDOW) or {}
            # the record's estimate uses no parameter of tab 1: only the record and the form's model settings
            # (a message of the form as a whole shows in the panel's error line; with tab 1 invalid that
            # line speaks of tab 1 instead, and whether the form is whole cannot be told: not checked)
            mapping = s.one(css="eha-freq-record-mapping")
            waiting = bool(mapping is not None and s.shown(mapping, tabs=False))
            if valid or not (pane is not None and pane.attributes.get("visible")):
                out[RECORD_RUN] = (bool(record) and not freq and not window and not config_error and not waiting,
                                   ("a record is loaded" if record else "no record loaded")
                                   + (", a file waits for its columns" if waiting else ""))
        study = self._form_errors(STUDY_FORM)
        if study is not None:
            progress = s.one(css="eha-study-progress")
            running = bool(progress is not None and progress.attributes.get("visible"))
            out[STUDY_RUN] = (valid and not study and not running and not self.o.exercise_hidden,
                              f"{why_tab1}, the study form {'has errors' if study else 'is valid'}, "
                              f"{'a study is running' if running else 'no study running'}")
            out[STUDY_CANCEL] = (running, "a study is running" if running else "no study running")
        gb_bar = s.one(css="eha-gb-progress-bar")
        if gb_bar is not None:
            running = bool(gb_bar.attributes.get("visible"))
            out[GB_CANCEL] = (running, "a grey-box estimate is running" if running else "no grey-box estimate running")
        for label in (RESET, REPORT):
            out[label] = (True, "always")
        return out

    def _button_problems(self) -> list:
        out = []
        s = self.s
        for label, (enabled, why) in self.expected_buttons().items():
            for b in s.find("Button", label=label):
                disabled = bool(b.attributes.get("disabled"))
                if disabled == (not enabled):
                    continue
                out.append(("buttons", ("buttons", label, enabled),
                            f"“{label}” is enabled exactly when its inputs are valid ({why})",
                            "disabled" if disabled else "enabled", "enabled" if enabled else "disabled"))
        return out

    # freshness -------------------------------------------------------------------------------------
    def _values(self, css: str, names=None, *, shown_only: bool = True) -> dict | None:
        """The shown fields of a form (``shown_only`` False: every field), as the app compares them (None: no
        such form)."""
        form = self.s.form_model(css)
        if form is None:
            return None
        hidden = set(form.attributes.get("hidden") or []) if shown_only else set()
        values = form.attributes.get("values") or {}
        return {k: normalized(k, v) for k, v in sorted(values.items())
                if k not in hidden and (names is None or k in names)}

    def _tab1_key(self, with_kp: bool):
        s = self.shadow
        if not s.valid:
            return None
        return (s.params, s.kp) if with_kp else s.params

    def _note_text(self, css: str) -> str:
        m = self.s.one(css=css)
        return _strip_tags(m.text(), 500) if m is not None else ""

    def _lse_token(self):
        text = self._note_text("eha-lse-upload-note")
        m = re.search(r"Using your data: (.+?), \d+ samples", text)
        if m:
            self._lse_data = m.group(1)
        elif "Using the simulated sensors again" in text or "Or use your own" in text:
            self._lse_data = None
        return getattr(self, "_lse_data", None)

    def _record_token(self):
        text = self._note_text("eha-freq-record-note")
        m = re.search(r"Your record: (.+?), \d+ samples", text)
        if m:
            self._record = m.group(1)
        elif "Or estimate H(s) from your own record" in text:
            self._record = None
        return getattr(self, "_record", None)

    def signature(self, view: str):
        """The inputs ``view`` depends on now, as the app compares them; None when they are not valid."""
        if view in _FORM_VIEWS:
            # tab 1 (with Kp or not) and one form: tab 2's runs, the grey-box estimate (a file of the
            # student's is not chosen by the walk), the board's record
            form, with_kp = _FORM_VIEWS[view]
            tab1, values = self._tab1_key(with_kp), self._values(form)
            if tab1 is None or values is None or self._form_errors(form):
                return None
            if view == "board-record" and not getattr(self, "board_step_opened", False):
                # the board computes the steps (of board_step's height) once its step view was opened
                values = {k: v for k, v in values.items() if k != "board_step"}
            return tab1, tuple(values.items())
        if view == "lse":
            tab1, values = self._tab1_key(False), self._values(LSE_FORM)
            own = self._lse_token()
            window = self._values(LSE_WINDOW) if own else None
            if tab1 is None or values is None or self._form_errors(LSE_FORM) or (own and self._form_errors(LSE_WINDOW)):
                return None
            return tab1, tuple(values.items()), own, tuple((window or {}).items())
        if view == "table4":
            tab1, errors = self._tab1_key(False), self._form_errors(LSE_FORM)
            if tab1 is None or errors is None or "lse_seed" in errors:
                return None
            # its seed whether shown or not (hidden while the student's own file is in use, which Table 4
            # does not read)
            return tab1, (self._values(LSE_FORM, shown_only=False) or {}).get("lse_seed")
        if view in FREQ_VIEWS:
            tab1, values = self._tab1_key(True), self._values(FREQ_FORM)
            if tab1 is None or values is None or self._form_errors(FREQ_FORM):
                return None
            return tab1, tuple(values.items())
        if view == "freq-excitation":
            values = self._values(FREQ_FORM, EXCITATION_FIELDS)
            if values is None or self._form_errors(FREQ_FORM):
                return None
            return tuple(values.items())
        if view == "freq-record":
            record, values = self._record_token(), self._values(FREQ_FORM, ORDER_FIELDS)
            if not record or values is None or self._form_errors(FREQ_FORM) or self._form_errors(RECORD_WINDOW):
                return None
            detrend = self.s.one(css="eha-freq-record-detrend")
            return (record, tuple(values.items()), tuple((self._values(RECORD_WINDOW) or {}).items()),
                    detrend.attributes.get("value") if detrend is not None else None)
        return ("unknown view", view)

    def _views_on_page(self) -> dict[str, Model]:
        out = {}
        for m in self.s.find(css="eha-view"):
            name = next((c[len("eha-view-"):] for c in m.css if c.startswith("eha-view-")), None)
            if name:
                out[name] = m
        return out

    @staticmethod
    def _status(model: Model) -> str | None:
        return next((STATUS_CLASSES[c] for c in model.css if c in STATUS_CLASSES), None)

    def _describe_change(self, before, now) -> str:
        def flat(sig, prefix=""):
            out = {}
            if isinstance(sig, tuple) and sig and all(isinstance(x, tuple) and len(x) == 2 and isinstance(x[0], str)
                                                      for x in sig):
                for k, v in sig:
                    out[prefix + k] = v
                return out
            if isinstance(sig, tuple):
                for i, x in enumerate(sig):
                    out.update(flat(x, f"{prefix}{i}."))
                return out
            out[prefix or "value"] = sig
            return out
        if now is None:
            return "inputs not valid"
        a, b = flat(before), flat(now)
        diffs = [f"{k}: {_short(a.get(k), 40)} → {_short(b.get(k), 40)}" for k in sorted(set(a) | set(b))
                 if a.get(k) != b.get(k)]
        if not diffs:
            return "(no difference)"
        diffs = [d if not d.startswith("0:") else "tab 1's parameters changed" for d in diffs]
        return "; ".join(dict.fromkeys(diffs))[:400]

    def _freshness_problems(self) -> list:
        """Views that say current while their inputs say otherwise (evaluated without side effects)."""
        out = []
        now = time.perf_counter()
        for name, model in self._views_on_page().items():
            status = self._status(model)
            track = self.views.get(name)
            banner = self.s.one(css=f"eha-stale-note-{name}")
            if banner is not None and bool(banner.attributes.get("visible")) != (status == "stale"):
                line = "shown" if banner.attributes.get("visible") else "hidden"
                out.append(("banner", ("banner", name, status), f"view {name}: its out-of-date line shows exactly "
                            "when it is out of date", f"status {status}, line {line}",
                            f"line {'shown' if status == 'stale' else 'hidden'}"))
            if track is None or not track.known:
                if status == "current" and self.signature(name) is None:      # at first sight too
                    out.append(("freshness", ("invalid", name, "None"), f"view {name}: not current while its "
                                "inputs are not valid", "eha-current", "eha-out-of-date"))
                continue
            since = track.updating_since
            info = self.s.one(css="eha-sim-info") if name == "simulation" else None
            marked = info is not None and "eha-sim-updating" in info.text()
            if since is not None and now - since > self.o.stuck_s and (status == "updating" or marked):
                out.append(("freshness", ("stuck", name), f"view {name}: 'updating' ends (a re-run comes)",
                            f"updating for {now - track.updating_since:.0f} s", "current or out of date"))
            if status != "current":
                continue
            sig = self.signature(name)
            passes = self.s.view_passes.get(name, [])
            went_away = track.last_status != "current" or any(p != "current" for p in passes)
            if sig is None:
                out.append(("freshness", ("invalid", name, repr(sig)), f"view {name}: not current while its inputs "
                            "are not valid", "eha-current", "eha-out-of-date"))
                continue
            if name == "simulation":
                info = self.s.one(css="eha-sim-info")
                text = info.text() if info is not None else ""
                m = _RUN_COUNT.search(text)
                count = int(m.group(1)) if m else 0
                if "eha-sim-updating" in text or count != track.run_count or went_away:
                    continue
            elif went_away:
                if name not in AUTO_VIEWS and sig != track.snapshot and sig not in track.runs:
                    last = track.runs[-1] if track.runs else track.snapshot
                    out.append(("freshness", ("unrun", name, repr(sig)[:200]), f"view {name}: becomes current only "
                                "with the inputs of a run (or those it showed)",
                                f"eha-current with {self._describe_change(last, sig)}"
                                + (" (against the last run's inputs)" if track.runs else ""),
                                "eha-out-of-date"))
                continue
            if sig != track.snapshot and track.snapshot is not None:
                # (a snapshot of None: the view was found current with invalid inputs, reported then)
                out.append(("freshness", ("stayed", name, repr(sig)[:200]), f"view {name}: does not stay current "
                            "after an input it depends on changed", f"eha-current after "
                            f"{self._describe_change(track.snapshot, sig)}",
                            "eha-out-of-date, or updating then current" if name in AUTO_VIEWS else "eha-out-of-date"))
        return out

    def _note_views(self) -> None:
        """After the checks: what each view now shows becomes the walk's knowledge of it."""
        now = time.perf_counter()
        present = self._views_on_page()
        for name in list(self.views):
            if name not in present and self.views[name].known:
                self.views.pop(name)
        for name, model in present.items():
            status = self._status(model)
            track = self.views.setdefault(name, ViewTrack())
            passes = self.s.view_passes.pop(name, [])
            sig = self.signature(name)
            info = self.s.one(css="eha-sim-info") if name == "simulation" else None
            marked = info is not None and "eha-sim-updating" in info.text()      # tab 2 says "updating"
            if status == "updating" or marked:
                if track.updating_since is None:
                    track.updating_since = now
            else:
                track.updating_since = None
            if status == "current":
                info_count = None
                if name == "simulation":
                    info = self.s.one(css="eha-sim-info")
                    text = info.text() if info is not None else ""
                    m = _RUN_COUNT.search(text)
                    info_count = int(m.group(1)) if m else 0
                    if "eha-sim-updating" in text:
                        track.last_status = "updating"
                        continue
                fresh = (not track.known or track.last_status != "current" or any(p != "current" for p in passes)
                         or (info_count is not None and info_count != track.run_count))
                if fresh or sig != track.snapshot:
                    # a new result, or one already reported: the walk resyncs on what is shown
                    track.snapshot, track.runs = sig, []
                if info_count is not None:
                    track.run_count = info_count
            track.known = True
            track.last_status = status
        self.s.stuck = frozenset(n for n, t in self.views.items()
                                 if t.updating_since is not None and now - t.updating_since > 5.0)


# -- many walks at once ----------------------------------------------------------------------------------

async def run_walks(url: str, seeds: list[int], n_actions: int, *, log_path: str | None = None,
                    monitor: LogMonitor | None = None, options: WalkOptions | None = None, timeout: float = 60.0,
                    progress=None, progress_every_s: float = 10.0) -> tuple[list[Failure], list[Walker]]:
    """One walk per seed on ``url``, all at once; returns every failure and the walkers. The server's log
    (``log_path``, or a ``monitor`` of it to read more after the server stopped) is watched too."""
    if monitor is None and log_path:
        monitor = LogMonitor(log_path)
    if monitor is not None:
        monitor._read()                   # what the log held before the walks is not theirs
        monitor.unclaimed.clear()
    walkers = [Walker(url, seed, name=f"session {k + 1} (seed {seed})", monitor=monitor, options=options,
                      timeout=timeout) for k, seed in enumerate(seeds)]

    async def one(w: Walker):
        try:
            await w.walk(n_actions)
        finally:
            await w.close()

    ticker = None
    if progress is not None:
        async def tick():
            while True:
                await asyncio.sleep(progress_every_s)
                progress(walkers)
        ticker = asyncio.ensure_future(tick())
    try:
        await asyncio.gather(*(one(w) for w in walkers))
    finally:
        if ticker is not None:
            ticker.cancel()
    if monitor is not None:
        await asyncio.sleep(0.5)
        monitor.dispatch()
        for w in walkers:                 # what came after the last action: the session that acted last
            if w.windows:
                w.windows[-1]["t1"] = time.time()
        monitor.dispatch()
    failures = [f for w in walkers for f in w.failures]
    return failures, walkers


async def replay_failures(url: str, monitor: LogMonitor | None, specs: list[dict], *, seed: int = 0,
                          options: WalkOptions | None = None) -> list[Failure]:
    """Do ``specs`` again in a new session of ``url`` (one at a time on the server: its log's problems
    are this replay's); the failures found."""
    w = Walker(url, seed, name="replay", monitor=None, options=options)
    if monitor is not None:
        monitor._read()
        monitor.unclaimed.clear()
        monitor.walkers = [w]
        w.monitor = monitor
    try:
        await w.replay(specs)
    finally:
        await w.close()
    if monitor is not None:
        await asyncio.sleep(0.5)
        monitor.dispatch()
        if w.windows:
            w.windows[-1]["t1"] = time.time()
        monitor.dispatch()
    return w.failures


async def shrink(url: str, monitor: LogMonitor | None, specs: list[dict], sort: tuple, *, seed: int = 0,
                 options: WalkOptions | None = None, budget_s: float = 600.0, say=None) -> list[dict]:
    """A short list of actions that still breaks the invariant of ``sort`` (:func:`failure_sort`): delta
    debugging (Zeller's ddmin) over ``specs``, each try a replay in a new session, for at most
    ``budget_s`` seconds. What it returns reproduced when it was last tried (the server's timing may
    make a failure come and go)."""
    deadline = time.monotonic() + budget_s
    tries = [0]

    async def fails(subset: list[dict]) -> bool:
        tries[0] += 1
        found = await replay_failures(url, monitor, subset, seed=seed, options=options)
        hit = any(failure_sort(f) == sort for f in found)
        if say is not None:
            say(f"    try {tries[0]}: {len(subset)} actions: {'fails' if hit else 'passes'}")
        return hit

    current = list(specs)
    n = 2
    while len(current) >= 2 and time.monotonic() < deadline:
        size = math.ceil(len(current) / n)
        chunks = [current[i:i + size] for i in range(0, len(current), size)]
        reduced = False
        for k, chunk in enumerate(chunks):           # a part alone, then everything but a part
            if time.monotonic() > deadline:
                break
            if len(chunks) > 2 and await fails(chunk):
                current, n, reduced = chunk, 2, True
                break
            rest = [x for j, c in enumerate(chunks) if j != k for x in c]
            if await fails(rest):
                current, n, reduced = rest, max(n - 1, 2), True
                break
        if not reduced:
            if n >= len(current):
                break
            n = min(2 * n, len(current))
    return current


def describe_specs(specs: list[dict]) -> list[str]:
    """Actions as a person reads them (uploads without their bytes)."""
    out = []
    for spec in specs:
        spec = {k: (f"<{len(base64.b64decode(v))} bytes>" if k == "data" else v) for k, v in spec.items()}
        out.append(json.dumps(spec, ensure_ascii=False))
    return out


def kinds_table(walkers: list) -> str:
    """Actions by kind over all walks: how many, and their mean wall time (action, settling, checks)."""
    counts, seconds = Counter(), Counter()
    for w in walkers:
        counts.update(w.counts)
        seconds.update(w.seconds)
    width = max([16, *map(len, counts)])        # a section's kinds are named after its key
    rows = [f"{'action kind':{width}s} {'count':>6s} {'s/action':>9s} {'total s':>8s}"]
    for kind, n in counts.most_common():
        rows.append(f"{kind:{width}s} {n:6d} {seconds[kind] / n:9.2f} {seconds[kind]:8.1f}")
    return "\n".join(rows)


def shutdown_failures(monitor: LogMonitor | None) -> list[Failure]:
    """What the server printed while it stopped (warnings it held until then, say): call after stopping it."""
    if monitor is None:
        return []
    monitor.walkers = []
    monitor._read()
    monitor._close()
    out = []
    for problem in monitor.unclaimed:
        out.append(Failure("log", -1, "server", -1, "(the server stopping)", "nothing at WARNING or above, no "
                           "traceback, in the server's log (printed when it stopped)", problem.head[:300],
                           "no such line", [], problem.lines, "", problem))
    monitor.unclaimed = []
    return out


def _shrink_all(url, monitor, failures, walkers, options, budget_s) -> None:
    """Shrink the first failure of each sort (a failure of the server's stopping cannot be)."""
    by_name = {w.name: w for w in walkers}
    done = set()
    for f in failures:
        sort = failure_sort(f)
        if sort in done or f.session not in by_name or f.index < 0:
            continue
        done.add(sort)
        w = by_name[f.session]
        print(f"\nshrinking [{f.kind}] {f.what[:100]} (seed {f.seed}, action #{f.index}) ...", flush=True)
        specs = asyncio.run(shrink(url, monitor, w.specs[:f.index + 1], sort, seed=w.seed, options=options,
                                   budget_s=budget_s, say=lambda text: print(text, flush=True)))
        print(f"  {len(specs)} action(s) still break it:")
        for line in describe_specs(specs):
            print(f"    {line}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", help="a running server's app URL (default: start eha serve with EHA_STRICT=1)")
    ap.add_argument("--log", help="with --url: the server's log file, for the log invariant")
    ap.add_argument("--seed", type=int, default=1, help="first seed (session k walks seed + k)")
    ap.add_argument("--sessions", type=int, default=1)
    ap.add_argument("--actions", type=int, default=100)
    ap.add_argument("--only", default="", help="comma-separated action kinds to walk (development)")
    ap.add_argument("--exclude", default="", help="comma-separated action kinds to leave out")
    ap.add_argument("--exercise", action="store_true", help="serve an exercise (hides M,B,Af,beta_e)")
    ap.add_argument("--heavy", action="store_true", help="valid values of costly fields over their whole range")
    ap.add_argument("--json", help="write the failures here")
    ap.add_argument("--trace", action="store_true", help="print every action as it is done")
    ap.add_argument("--save", metavar="FILE", help="write each walk's actions (as data) to this JSON file")
    ap.add_argument("--replay", metavar="FILE", help="instead of walking: do the actions of this JSON file (a "
                    "list of actions, or --save's file: its first walk) in one session")
    ap.add_argument("--no-wait-busy", action="store_true", help="after typing, do not wait for the re-runs it "
                    "started (faster, less repeatable)")
    ap.add_argument("--shrink", type=float, default=0, metavar="SECONDS", help="after the walk, look for the "
                    "shortest actions that still break each invariant found broken (at most SECONDS each), on the "
                    "same server, one session at a time")
    args = ap.parse_args(argv)
    options = WalkOptions(light=not args.heavy, only=tuple(k for k in args.only.split(",") if k),
                          exclude=tuple(k for k in args.exclude.split(",") if k), trace=args.trace,
                          wait_busy=not args.no_wait_busy)
    server, tmp = None, None
    url, log = args.url, args.log
    try:
        if url is None:
            extra = []
            if args.exercise:
                tmp = tempfile.mkdtemp(prefix="eha-walk-")
                exercise = os.path.join(tmp, "class.json")
                eha = Path(sys.executable).with_name("eha")
                # every kind of actuator a lab may give (the student's id draws one of them)
                subprocess.run([str(eha), "exercise", "new", "--hide", "M,B,Af,beta_e", "--variants",
                                "paper,spool,leakage,stribeck", "--out", exercise], check=True, capture_output=True)
                extra = ["--exercise", exercise]
                options.exercise_hidden = ("M", "B", "Af", "beta_e")
            server = WalkServer(*extra)
            url, log = server.url, server.log_path
            print(f"server: {url}, log {log}", flush=True)
        t0 = time.perf_counter()
        monitor = LogMonitor(log) if log else None
        if args.replay:
            specs = json.loads(Path(args.replay).read_text())
            specs = specs[0]["actions"] if specs and isinstance(specs[0], dict) and "actions" in specs[0] else specs
            walker = Walker(url, args.seed, name="replay", options=options)
            failures = asyncio.run(replay_failures(url, monitor, specs, seed=args.seed, options=options))
            walkers = [walker]
            walker.actions_done, walker.specs = len(specs), specs
        else:
            failures, walkers = asyncio.run(run_walks(url, [args.seed + k for k in range(args.sessions)],
                                                      args.actions, monitor=monitor, options=options))
        seconds = time.perf_counter() - t0
        if args.save:
            Path(args.save).write_text(json.dumps([{"seed": w.seed, "actions": w.specs} for w in walkers]))
        if args.shrink > 0:
            _shrink_all(url, monitor, failures, walkers, options, args.shrink)
    finally:
        if server is not None:
            server.stop()
    failures += shutdown_failures(monitor)
    print(kinds_table(walkers))
    print(format_failures(failures))
    done = sum(w.actions_done for w in walkers)
    print(f"\nsessions={len(walkers)} actions={done} failures={len(failures)} seconds={seconds:.1f} "
          f"actions_per_s={done / seconds:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps([f.to_json() for f in failures], indent=1, default=str))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
