"""One browser page's session: its state, its runner, its address, its exercise identity, its sections.

A :class:`Session` is made per page (``create_app``). It owns

- the student's :class:`~eha_app.session.state.AppState` (tab 1's parameters; in an
  exercise, the student and their hidden values),
- the :class:`~eha_app.runtime.tasks.SessionRunner` every computation of the page goes
  through (closed with the page),
- the page's address as it was opened (``query``: what a reload or a shared
  link restores) and the texts of sections not shown yet (from the address or
  a loaded settings file),
- its sections, made when first shown, in the order of the registry
  (:data:`~eha_app.session.section.SECTIONS`), and what sections post to one
  another (an estimate going to the model board before it was opened).

Settings files, the address and the session report iterate the registry:
nothing about a section is written here.
"""

from __future__ import annotations

import html
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import param

from eha_core.errors import FieldError

from ..runtime.tasks import SessionRunner, apply_locked, frozen_models, served_document
from .section import SECTIONS, Section, SectionRegistry, SectionSnapshot
from .state import AppState, shown_text, too_long

__all__ = ["Session", "SessionSnapshot", "SettingsError", "SETTINGS_FORMAT", "MAX_SETTINGS_BYTES"]

SETTINGS_FORMAT = "eha-settings/1"
#: A settings file is about 2 kB; a larger one is refused before it is read (in the page, before
#: it is even sent), so that no file can hold the server's thread or fill its log.
MAX_SETTINGS_BYTES = 100_000


class SettingsError(FieldError):
    """A settings file that cannot be loaded: its name and what is wrong (a FieldError of ``settings``)."""

    def __init__(self, filename: str, what: str):
        super().__init__("settings", filename, what, value_text=repr(filename))


@dataclass(frozen=True)
class SessionSnapshot:
    """The whole page at one moment (taken under its lock): read by the report in a worker."""

    sections: tuple[SectionSnapshot, ...]
    settings: Mapping[str, Any]
    hidden: tuple[str, ...] = ()
    exercise_title: str = ""
    student: str = ""

    def section(self, key: str) -> SectionSnapshot | None:
        return next((s for s in self.sections if s.key == key), None)


class Session(param.Parameterized):
    """One page's session (see the module docstring)."""

    state = param.ClassSelector(class_=AppState, doc="tab 1's parameters and, in an exercise, the student's")
    query = param.Dict(default={}, doc="the page's address as it was opened: field -> text")
    active_tab = param.Integer(default=0, doc="the main tab on show (0-based)")

    def __init__(self, state: AppState | None = None, *, query: Mapping | None = None,
                 runner: SessionRunner | None = None, registry: SectionRegistry | None = None, **params):
        state = state if state is not None else AppState()
        query = {str(k): shown_text(v, 10**6) for k, v in (query or {}).items()}
        super().__init__(state=state, query=query, **params)
        self.runner = runner if runner is not None else SessionRunner(state)
        self.registry = registry if registry is not None else SECTIONS
        self.doc = served_document()
        self._built: dict[str, Section] = {}
        self._pending: dict[str, dict[str, str]] = {}
        self._mail: dict[str, list] = {}
        self._on_built: list[Callable[[Section], None]] = []
        # which sections the student can see (set by the page; without one every section is in sight)
        self.sight: Callable[[str], bool] | None = None
        self._out_of_sight: dict[str, list[Callable[[], None]]] = {}
        # an exercise's hand-in boxes, and what the page last read of the lab: why hand-ins are refused now
        # (None: they are not), the hand-ins so far (None: not read yet), and what to do after a hand-in
        self.handin_boxes: list = []
        self.lab_refusal: str | None = None
        self.handins_used: int | None = None
        self.after_handin: list[Callable[[], None]] = []
        if not list(self.registry):
            raise RuntimeError("no section is registered: import eha_app.sections (the page's sections) first")

    def __repr__(self) -> str:
        return f"<Session {self.name}>"

    # -- the exercise identity ---------------------------------------------------------------------
    @property
    def hidden(self) -> tuple[str, ...]:
        return self.state.hidden

    @property
    def student(self) -> str:
        return self.state.student

    @property
    def exercise(self):
        return self.state.exercise

    # -- the page's lock -----------------------------------------------------------------------------
    def apply(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on this page under its lock (now without a server)."""
        apply_locked(fn, self.doc or served_document())

    # -- sections ---------------------------------------------------------------------------------
    def release(self) -> None:
        """Let go of every section (their results, figures and uploads): the page was given up (its id
        opened on another page). The session stays usable for nothing but its settings."""
        self._built.clear()
        self._mail.clear()
        self._on_built.clear()
        self._out_of_sight.clear()
        self.handin_boxes.clear()           # each holds its section
        self.after_handin.clear()
        # the sections watch the state: its watchers would keep every section (and its upload) alive
        for kinds in list(self.state.param.watchers.values()):
            for watchers in list(kinds.values()):
                for w in list(watchers):
                    self.state.param.unwatch(w)
        self.state.forget_secrets()

    # -- what is in sight --------------------------------------------------------------------------
    def in_sight(self, key: str) -> bool:
        """Is section ``key`` on show (its tab and sub-tab open)? Always, without a page."""
        return self.sight is None or self.sight(key)

    def when_in_sight(self, key: str, fn: Callable[[], None]) -> None:
        """Call ``fn`` (once, under the lock) when section ``key`` is next shown: work for a view no one
        is looking at waits until someone does (a change of tab 1 recomputes the board once it is shown,
        not at every keystroke while tab 1 is). Asking again for the same ``fn`` asks once."""
        waiting = self._out_of_sight.setdefault(key, [])
        if fn not in waiting:
            waiting.append(fn)

    def sight_changed(self) -> None:
        """The page showed another tab or sub-tab: what waited for a section now in sight runs."""
        for key in [k for k in self._out_of_sight if self.in_sight(k)]:
            for fn in self._out_of_sight.pop(key):
                fn()

    def section(self, key: str) -> Section | None:
        """The section ``key`` if it was made (shown), else None."""
        return self._built.get(key)

    def built(self) -> list[Section]:
        """The sections made so far, in page order."""
        return [self._built[p.key] for p in self.registry if p.key in self._built]

    def build(self, key: str) -> Section:
        """The section ``key``, made now (with the sections within it, or with the one it is within) if
        it never was. Call under the page's lock (it makes Bokeh models)."""
        section = self._built.get(key)
        if section is not None:
            return section
        placement = self.registry.get(key)
        if placement.within is not None and placement.within not in self._built:
            # a section within another is laid out (and given its settings) by that one: made with it
            self.build(placement.within)
            return self._built[key]
        with frozen_models():
            section = placement.cls(self)
            self._built[key] = section
            self._pending.pop(key, None)
            for inner in self.registry.within(key):
                self.build(inner.key)
            mail = self._mail.pop(key, [])
            if mail:
                section.receive_many(mail)
        for fn in list(self._on_built):
            fn(section)
        return section

    def when_built(self, fn: Callable[[Section], None]) -> None:
        """Call ``fn(section)`` for every section made from now on."""
        self._on_built.append(fn)

    def texts_for(self, key: str) -> dict[str, str]:
        """The texts a section's fields open with: its defaults, then the page's address, then what a
        settings file loaded for it before it was made."""
        defaults = self.registry.get(key).cls.defaults
        texts = dict(defaults)
        texts.update({k: v for k, v in self.query.items() if k in defaults})
        texts.update(self._pending.get(key, {}))
        return texts

    def post(self, key: str, item) -> None:
        """Hand ``item`` to section ``key`` (its ``receive``), now or when it is made. Under the lock."""
        section = self._built.get(key)
        if section is not None:
            section.receive(item)
            return
        waiting = self._mail.setdefault(key, [])
        limit = self.registry.get(key).cls.max_mail
        if limit is None or len(waiting) < limit:
            waiting.append(item)

    def keep_for(self, key: str, texts: Mapping[str, str]) -> None:
        """Texts for section ``key``'s fields when it is made (it was not shown yet)."""
        self._pending.setdefault(key, {}).update(texts)

    def mail(self, key: str) -> list:
        """What waits for section ``key`` (not made yet)."""
        return list(self._mail.get(key, []))

    # -- settings ------------------------------------------------------------------------------------
    def settings_of(self, key: str) -> dict[str, str]:
        section = self._built.get(key)
        return section.settings() if section is not None else self.registry.get(key).cls.unbuilt_settings(self)

    def settings(self) -> dict:
        """Every input of the session as a settings file holds it: texts as typed, by section."""
        out: dict[str, Any] = {"format": SETTINGS_FORMAT, "tab": self.active_tab + 1}
        for p in self.registry:
            # a text longer than a field may hold is refused where it is typed, and a file holding it is
            # refused whole: left out, the rest of the settings (and a student's kept work) still loads
            out[p.key] = {k: v for k, v in self.settings_of(p.key).items() if not too_long(str(v))}
        return out

    def settings_bytes(self) -> bytes:
        return json.dumps(self.settings(), indent=1, ensure_ascii=False).encode()

    def load_settings(self, data: bytes | str, filename: str = "settings.json") -> list[str]:
        """Type a settings file's values into the session; returns notes (what it does not know).
        :class:`SettingsError` for a file that is not one of this app's, before anything is typed."""
        doc = _read_settings(data, filename)
        notes, unknown = [], [k for k in doc if k not in ("format", "tab") and k not in self.registry]
        sections = {}
        for p in self.registry:
            given = _section_texts(doc, p.key, filename)
            sections[p.key] = {k: v for k, v in given.items() if k in p.cls.defaults}
            unknown += [f"{p.key}.{k}" for k in given if k not in p.cls.defaults]
        for key, texts in sections.items():
            if not texts:
                continue
            section = self._built.get(key)
            if section is not None:
                section.load(texts)
            else:                      # made later, with these
                self.registry.get(key).cls.load_unbuilt(self, texts)
        if unknown:
            shown = ", ".join(shown_text(u, 40) for u in unknown[:10]) + (f" and {len(unknown) - 10} more"
                                                                           if len(unknown) > 10 else "")
            notes.append(f"settings = {filename!r}: ignored what this app does not know: {shown}")
        return notes

    # -- the report -------------------------------------------------------------------------------------
    def snapshot(self) -> SessionSnapshot:
        """The whole page now, for a worker to read (call under the page's lock)."""
        snaps = []
        for p in self.registry:
            section = self._built.get(p.key)
            snaps.append(section.snapshot() if section is not None else p.cls.unbuilt_snapshot(self))
        ex = self.exercise
        return SessionSnapshot(tuple(snaps), self.settings(), self.hidden,
                               exercise_title=ex.title if ex is not None and self.hidden else "",
                               student=self.student)

    def report_sections(self, snapshot: SessionSnapshot):
        """Each section's report part, in page order (None where it has nothing to show)."""
        return [(s, self.registry.get(s.key).cls.report(s, snapshot.hidden)) for s in snapshot.sections]

    def describe(self) -> str:
        """One line for a person reading the page: the exercise and the student, if any."""
        if not self.hidden:
            return ""
        return (f"Exercise <b>{html.escape(self.exercise.title)}</b>, student <b>{html.escape(self.student)}</b>; "
                f"hidden: {html.escape(', '.join(self.hidden))}.")


def _read_settings(data: bytes | str, filename: str) -> dict:
    if len(data) > MAX_SETTINGS_BYTES:
        raise SettingsError(filename, f"it has {len(data) / 1e3:.1f} kB; at most {MAX_SETTINGS_BYTES / 1e3:g} kB "
                                      "(a saved settings file has about 2 kB)")
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SettingsError(filename, f"it is not JSON ({exc})") from None
    except RecursionError:
        raise SettingsError(filename, "it is nested too deeply to be a settings file; save one with “Save "
                                      "settings”") from None
    if not isinstance(doc, dict) or doc.get("format") != SETTINGS_FORMAT:
        raise SettingsError(filename, f"not a settings file of this app (format {SETTINGS_FORMAT!r} expected); "
                                      "save one with “Save settings”")
    return doc


def _section_texts(doc: dict, section: str, filename: str) -> dict[str, str]:
    """A section of the file as ``{field: text}``: texts (or numbers), each a field's worth."""
    given = doc.get(section) or {}
    if not isinstance(given, dict):
        raise SettingsError(filename, f"its {section!r} is not a list of fields")
    out = {}
    for name, value in given.items():
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise SettingsError(filename, f"{section}.{shown_text(name, 40)} is not a text or a number")
        text = str(value)
        if too_long(text):
            raise SettingsError(filename, f"{section}.{shown_text(name, 40)} = {shown_text(text)}: {too_long(text)}")
        out[str(name)] = text
    return out
