"""The parts of a page (tabs and panels), what each offers the session, and the ordered registry.

A :class:`Section` is one tab or one panel of a tab: the least squares, the
model board, the study... It declares its inputs (:attr:`Section.defaults`: its
fields and their texts as they open, which are its part of the page's address
and of a settings file) and its results (the ``result`` parameter), and offers
the session a small protocol:

- :meth:`Section.settings` and :meth:`Section.load`: its fields' texts, saved
  and loaded again (a settings file, the page's address);
- :meth:`Section.snapshot`: what it shows, taken under the page's lock, as an
  immutable :class:`SectionSnapshot` that a worker may read;
- :meth:`Section.report`: its part of the session report, drawn from a
  snapshot (in a worker, off the page);
- :attr:`Section.guide_step`: its stop on the guide's way through the steps
  (None: the guide passes it by);
- :meth:`Section.kept_work` and :meth:`Section.restore_work`: what an exercise
  keeps of its last run for a student who joins again (a reload, a restart of the
  server), and the steps that compute it again (:mod:`eha_app.sections.work`);
- :meth:`Section.run_cost`: what the run its inputs describe would cost the
  server, checked against the server's limits before it is queued
  (:meth:`Section.check_cost`);
- :attr:`Section.form_css`, :attr:`Section.content_css` and
  :attr:`Section.run_buttons`: how its form, its content and its run buttons are
  found on the page (a browser test, the random walk of ``benchmarks/walker.py``).

The registry (:data:`SECTIONS`) holds every section in page order with where it
goes: a main tab, a sub-tab of one, or inside another section. Settings, the
address, the report, the guide, the kept work and the random walk iterate it: a
new panel is one module and one ``SECTIONS.register(...)`` line (see
``eha_app/sections/__init__.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, ClassVar

import panel as pn
import param

from eha_core.errors import not_allowed

from ..runtime.limits import RunCost, check_run
from ..runtime.work_store import StoredFile

__all__ = ["Section", "SectionSnapshot", "ReportPart", "GuideStep", "KeptWork", "RestoreStep", "Placement",
           "SectionRegistry", "SECTIONS", "stale_note"]


@dataclass(frozen=True)
class SectionSnapshot:
    """What a section shows at one moment: its settings, whether its results are out of date, and
    whatever its report needs (``content``: immutable results of the core, copies of lists)."""

    key: str
    title: str
    settings: Mapping[str, str]
    built: bool = True
    stale: bool = False
    content: Any = None


@dataclass(frozen=True)
class ReportPart:
    """A section's part of the session report: HTML with ``{{name}}`` where each of ``figures``
    (Bokeh layouts, made for the report alone) goes."""

    title: str
    html: str
    figures: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class GuideStep:
    """A section's stop on the guide's way through the steps: its short name in the guide's trail,
    what is done there (HTML, the guide line's sentence), the label of the button that leads to it
    ("Next: ..."), ``press``: what to do there, naming the button (HTML; the guide says it until
    the step is done, :meth:`Section.guide_done`), and ``runs``: False for a step with no run of its
    own (it says ``press`` throughout). The guide (:mod:`eha_app.guide`) stops at every section that
    has one, in page order."""

    short: str
    what: str
    go: str
    press: str = ""
    runs: bool = True


@dataclass(frozen=True)
class KeptWork:
    """What a section keeps of its last run for a student who joins an exercise again: ``run``, what its
    :meth:`Section.restore_work` needs to compute the results again (JSON: ``{"views": [...], ...}``;
    None: no result, only the file), and ``file``, the file the student gave it (its bytes, name and
    column mapping; its ``slot`` is the section's key)."""

    run: Mapping[str, Any] | None = None
    file: StoredFile | None = None


@dataclass(frozen=True)
class RestoreStep:
    """One step that brings a section's kept work back: ``do(section)`` (the section, made when the step
    is taken) returns the job it started (None: nothing to wait for); ``title`` names the result it
    brings back in the page's note ("" for a step on the way, such as reading a file)."""

    title: str
    do: Callable[[Any], Any]


def run_off_notice(label: str, *, tab1_valid: bool, errors: Mapping[str, str], waiting: bool,
                   buttons: str = "The button is") -> str:
    """Why a run button (``label``) is off, as the note under it says it ("" when it is on): tab 1, the
    first invalid field, or a file that waits for its columns (it would otherwise run quietly on the
    simulated sensors, or on the previous file)."""
    import html

    if not tab1_valid:
        return (f'<span class="eha-warn">{buttons} off: a parameter on tab 1 is not valid; fix it to run the '
                'identification.</span>')
    if errors:
        return (f'<span class="eha-warn">“{label}” is off until this input is fixed: '
                f'{html.escape(next(iter(errors.values())))}</span>')
    if waiting:
        return (f"<span class='eha-note'>“{label}” waits for your file's columns: choose them below, or go back "
                "to simulated data.</span>")
    return ""


def stale_note(snapshot: SectionSnapshot) -> str:
    """The report's line above results the inputs no longer describe (as the page marks them)."""
    if not snapshot.stale:
        return ""
    return ("<p class='eha-warn'>Out of date: the inputs changed after this run; it shows the run's "
            "results.</p>")


class Section(pn.viewable.Viewer):
    """One tab or panel of the page, made by the session when first shown (see the module docstring).

    Subclasses set :attr:`key` (its name in settings files and the report),
    :attr:`title` and :attr:`defaults`, build their widgets in ``__init__(session)``
    from :meth:`initial_texts`, and override :meth:`snapshot` and
    :meth:`report` to show their results in the session report.
    """

    key: ClassVar[str] = ""
    title: ClassVar[str] = ""
    #: The section's fields and the texts they open with (display units, as typed).
    defaults: ClassVar[Mapping[str, str]] = {}
    #: At most this many posts wait for the section before it is made (None: no limit).
    max_mail: ClassVar[int | None] = None
    #: Its stop on the guide's way through the steps (None: the guide passes it by).
    guide_step: ClassVar[GuideStep | None] = None
    #: The CSS class of its form (the one that holds its :attr:`defaults`' fields; None: no form) and of
    #: what shows its content has arrived (None: its form): how a test or a random walk finds them.
    form_css: ClassVar[str | None] = None
    content_css: ClassVar[str | None] = None
    #: The labels of the buttons that compute its results.
    run_buttons: ClassVar[tuple[str, ...]] = ()

    result = param.Parameter(default=None, doc="the section's last result (an immutable result of the core)")

    def __init__(self, session, **params):
        super().__init__(**params)
        self.session = session

    @property
    def state(self):
        return self.session.state

    @property
    def runner(self):
        return self.session.runner

    def _note(self, text: str) -> None:
        """The runner's note (queued, waiting) beside the run button, for a section with a ``queue_note``."""
        self.queue_note.object = text
        self.queue_note.visible = bool(text)

    def initial_texts(self) -> dict[str, str]:
        """The texts the section's fields open with: defaults, the page's address, loaded settings."""
        return self.session.texts_for(self.key)

    # -- the protocol --------------------------------------------------------------------------
    def settings(self) -> dict[str, str]:
        """The section's fields as typed (by default its form's ``values``)."""
        form = getattr(self, "form", None)
        values = form.values if form is not None else {}
        return {k: str(values.get(k, v)) for k, v in self.defaults.items()}

    def load(self, texts: Mapping[str, str]) -> None:
        """Type ``texts`` into the section's fields (a settings file, a restored address)."""
        form = getattr(self, "form", None)
        if form is not None and texts:
            form.set_values(**texts)

    def is_stale(self) -> bool:
        """Are the section's results out of date with its inputs? (Its views say so on the page.)"""
        return any(getattr(v, "status", "") == "stale" for v in self.result_views())

    def result_views(self) -> list:
        """The section's :class:`~eha_app.session.freshness.ResultView`s (none by default)."""
        return []

    def guide_done(self) -> bool:
        """Is the guide's step here done, its result on the page? (The guide offers "Next" then.) By
        default: a result was shown in one of its views, or it has one; a section whose step asks for
        no run says True."""
        return self.result is not None or any(getattr(v, "computed_from", None) is not None
                                               for v in self.result_views())

    def snapshot(self) -> SectionSnapshot:
        """What the section shows now; call under the page's lock. Subclasses add ``content``."""
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale())

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden: tuple[str, ...] = ()) -> ReportPart | None:
        """The section's part of the session report, from ``snapshot`` (None: nothing to report)."""
        return None

    def receive(self, item) -> None:
        """Take what another section posted to this one (:meth:`Session.post`)."""
        raise TypeError(f"section {self.key!r} takes nothing from other sections (got {type(item).__name__})")

    def receive_many(self, items: list) -> None:
        """Take what was posted before the section was made, all at once (a section whose every
        :meth:`receive` starts work may start it once for all)."""
        for item in items:
            self.receive(item)

    # -- the work kept for a student who joins again (an exercise) ----------------------------------
    def kept_work(self) -> KeptWork | None:
        """What to keep of the section's last run (None: nothing); read under the page's lock after each
        run and change. A result is worth keeping only while it is current: its inputs are then the
        settings kept beside it, and computing it again gives the same numbers."""
        return None

    @classmethod
    def restore_work(cls, kept: KeptWork, texts: Mapping[str, str]) -> list[RestoreStep]:
        """The steps that bring ``kept`` back, in order, on a page whose settings were typed in already
        (``texts``: the section's own). Each step runs once the job of the one before is on the page."""
        return []

    # -- what a run costs the server -------------------------------------------------------------------
    def run_cost(self, **how) -> RunCost | None:
        """What the run its inputs describe would cost the server (``how``: which of its runs, for a
        section with several; None: nothing worth pricing, or inputs that do not make a run)."""
        return None

    def check_cost(self, **how) -> None:
        """A :class:`~eha_core.errors.FieldError` that says what to change when the run is beyond the
        server's limits (:mod:`eha_app.runtime.limits`): checked before it is queued."""
        check_run(self.run_cost(**how))

    # -- before it is made ---------------------------------------------------------------------
    @classmethod
    def unbuilt_settings(cls, session) -> dict[str, str]:
        """The section's settings while it was never shown: its opening texts."""
        return session.texts_for(cls.key)

    @classmethod
    def load_unbuilt(cls, session, texts: Mapping[str, str]) -> None:
        """Settings loaded before the section was made: it opens with them."""
        session.keep_for(cls.key, texts)

    @classmethod
    def unbuilt_snapshot(cls, session) -> SectionSnapshot:
        """A section never shown: only its settings."""
        return SectionSnapshot(cls.key, cls.title, cls.unbuilt_settings(session), built=False)


@dataclass(frozen=True)
class Placement:
    """Where a section goes: on a main ``tab`` (as one of its sub-tabs when the tab holds several,
    titled ``subtab``), or ``within`` another section, which lays it out."""

    cls: type
    tab: str | None = None
    subtab: str | None = None
    within: str | None = None

    @property
    def key(self) -> str:
        return self.cls.key


class SectionRegistry:
    """The page's sections in order, each with its :class:`Placement`."""

    def __init__(self):
        self._placements: list[Placement] = []

    def register(self, cls: type, *, tab: str | None = None, subtab: str | None = None,
                 within: str | None = None) -> type:
        """Add ``cls`` (a :class:`Section`) to the page; returns it (usable as a decorator's result)."""
        if not cls.key:
            raise not_allowed("section", cls.__name__, "it has no key")
        if (tab is None) == (within is None):
            raise not_allowed("section", cls.key, "give a tab or the section it is within")
        if any(p.key == cls.key for p in self._placements):
            raise not_allowed("section", cls.key, "a section of that key is registered")
        clash = set(cls.defaults) & {f for p in self._placements for f in p.cls.defaults}
        if clash:
            # every field is one argument of the page's address: names must not collide
            raise not_allowed("section", cls.key, f"fields {', '.join(sorted(clash))} are another section's")
        self._placements.append(Placement(cls, tab, subtab, within))
        return cls

    def unregister(self, key: str) -> None:
        self._placements = [p for p in self._placements if p.key != key]

    @contextmanager
    def added(self, cls: type, **where) -> Iterator[type]:
        """``cls`` registered for the duration of a block (tests)."""
        self.register(cls, **where)
        try:
            yield cls
        finally:
            self.unregister(cls.key)

    def __iter__(self) -> Iterator[Placement]:
        return iter(list(self._placements))

    def __contains__(self, key: str) -> bool:
        return any(p.key == key for p in self._placements)

    def get(self, key: str) -> Placement:
        for p in self._placements:
            if p.key == key:
                return p
        raise KeyError(key)

    def tabs(self) -> list[str]:
        """The main tabs, in order."""
        return list(dict.fromkeys(p.tab for p in self._placements if p.tab is not None))

    def on_tab(self, tab: str) -> list[Placement]:
        return [p for p in self._placements if p.tab == tab]

    def within(self, key: str) -> list[Placement]:
        return [p for p in self._placements if p.within == key]

    def owner_of(self, field_name: str) -> str | None:
        """The key of the section a field of the page's address belongs to."""
        return next((p.key for p in self._placements if field_name in p.cls.defaults), None)


#: The page's sections (filled by ``eha_app.sections``).
SECTIONS = SectionRegistry()
