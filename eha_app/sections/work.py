"""A student's work in an exercise, kept for their id and given back when they join again.

A reload, a closed laptop or a restart of the server must not cost a student their afternoon:
in an exercise (only there: outside one nothing is stored), a page's :class:`WorkKeeper` saves
the session's settings and what each section keeps of its last run (its
:meth:`~eha_app.session.section.Section.kept_work`: which results were on the page, the record
the student gave it) in the exercise's database (:mod:`eha_app.runtime.work_store`). When the
student joins again with the same id, it types the settings back in, and each section takes the
steps that bring its work back (its :meth:`~eha_app.session.section.Section.restore_work`: read
its record again, run again what had a result), in page order. The runs are deterministic (the
same inputs and seeds give the same numbers) and go through the session's runner like a click:
a restored student waits their turn in the fair queue like everyone else. They run one after
another, each once the previous one is on the page: the session's runner keeps one waiting job
per session, and a second request would replace the first.

Saves follow the page's changes without costing it: a run that ends or an input that changes
starts a timer, and the page is read (under its lock) and written (on the store's own thread)
at most once per :attr:`WorkKeeper.SAVE_DELAY_S`, not once per keystroke. A database that cannot
be used is said once on the page and in the server's log; the page goes on without it.
"""

from __future__ import annotations

import dataclasses
import html
import json
import logging
import threading
from collections.abc import Callable
from functools import partial

import panel as pn

from ..runtime.handins import StoreError, StoreUnavailable
from ..runtime.jobs import JobState
from ..runtime.tasks import apply_locked, served_document
from ..runtime.work_store import MAX_WORK_FILE_BYTES, RETRY_UNAVAILABLE_S, Work, WorkStore, submit
from ..session import KeptWork, SettingsError
from ..session.form import Form

__all__ = ["WorkKeeper", "keep_work"]

log = logging.getLogger("eha_app")

#: The name a restored settings file goes by in the page's notes.
_SAVED = "your saved work"


def keep_work(session, note: Callable[[str], None]) -> WorkKeeper | None:
    """Restore and keep the work of the session's student (in an exercise; else None). ``note(html)``
    tells the student, on the page, what was restored (or that the database could not be read).
    Call under the page's lock, once the student has joined."""
    state = session.state
    if not session.student or state.exercise is None or state.handins is None:
        return None
    keeper = WorkKeeper(session, note)
    keeper.restore()
    return keeper


class WorkKeeper:
    """One page's saving and restoring of its student's work (see the module docstring)."""

    #: Seconds between a change and its save: a burst of typing is one write.
    SAVE_DELAY_S = 2.0

    def __init__(self, session, note: Callable[[str], None]):
        self.session = session
        self.student = session.student
        exercise = session.state.exercise
        quota = getattr(exercise, "kept_uploads_mb", None)
        self.store = WorkStore(session.state.handins, quota_bytes=None if quota is None else quota * 10**6)
        self._quota_told: set[str] = set()
        self.note = note
        self.doc = served_document()
        self.restoring = True           # nothing is saved before what was kept is back on the page
        self.restored: list[str] = []   # what was restored, for the page's note
        self._dirty = False
        self._timer = False
        self._closed = False
        self._stopped = False           # the page gave way to another of the same id: nothing more is saved
        self._last = None               # what was last saved, to skip a save of the same
        self._told = False
        self._waited: set[str] = set()  # what waits for the database ("restore", "save"), told once
        self._watched: set[int] = set()
        self._changed_sections: list[str] | None = None     # set when kept work was put back
        self._planned: list[str] = []                       # the results being computed again

    # -- threads ------------------------------------------------------------------------------------
    def _off_page(self, key, fn: Callable[[], None]) -> None:
        """``fn()`` on the store's thread (at once without a server)."""
        if self.doc is None:
            try:
                fn()
            except StoreUnavailable:
                pass                    # (without a server there is no store thread to try it again)
        else:
            submit(key, fn)

    def _on_page(self, fn: Callable[[], None]) -> None:
        apply_locked(fn, self.doc)

    @property
    def _key(self):
        return "work", self.store.handins.shown, self.student

    # -- restoring ----------------------------------------------------------------------------------
    def restore(self) -> None:
        """Read the student's kept work (off the page), then put it back on the page."""
        store, student = self.store, self.student

        def read():
            try:
                work, error = store.load(student), None
            except StoreUnavailable as exc:
                # the database is down (PostgreSQL restarting): the page waits for the work rather than start
                # afresh, which its first save would then write over the kept work
                if not self._stopped and not self._closed:
                    self._on_page(partial(self._tell_once, "restore", (
                        f"Your earlier work is on its way: the class's database cannot be reached just now "
                        f"({exc}). This page tries again every {RETRY_UNAVAILABLE_S:.0f} s and puts it back as soon "
                        "as it answers; nothing you do meanwhile replaces it.")))
                    timer = threading.Timer(RETRY_UNAVAILABLE_S, self._off_page, args=(("read", id(self)), read))
                    timer.daemon = True
                    timer.start()
                return
            except StoreError as exc:
                work, error = None, exc
            self._on_page(lambda: self._put_back(work, error))

        self._off_page(("read", id(self)), read)

    def _put_back(self, work: Work | None, error: StoreError | None) -> None:
        if self._stopped:
            return                      # the page gave way meanwhile
        self._watch()
        if error is not None:
            log.warning("a student's saved work could not be read: %s", error)
            self._tell(f"Your earlier work could not be read ({error}); you start afresh. Tell your teacher.")
            self._done()
            return
        if work is None:
            self._done()
            return
        session = self.session
        # A page opened with fields in its address (a reload keeps every field that differs from its
        # default, and a missing one means the default) shows those: the kept settings, saved a couple
        # of seconds after a change, may lag what the student last typed. The kept ones come back on an
        # address without fields (the class's plain link, another computer, after a restart). Either
        # way a section's result is run again only if its fields are those it was computed with, and
        # none if tab 1's are not.
        try:
            settings = json.loads(work.settings)
        except ValueError:
            settings = {}
        if any(k != "tab" for k in session.query):
            current = session.settings()
            contradicted = {key for key, texts in settings.items()
                            if isinstance(texts, dict) and {k: str(v) for k, v in texts.items()}
                            != {k: str(v) for k, v in (current.get(key) or {}).items() if k in texts}}
            settings = {}
        else:
            contradicted = set()
            try:
                session.load_settings(json.dumps(settings), _SAVED)
            except SettingsError as exc:
                log.warning("a student's saved settings could not be loaded: %s", exc)
                self._done()
                return
        if "parameters" in contradicted:
            contradicted |= {p.key for p in session.registry}
        work = dataclasses.replace(work, runs={k: v for k, v in work.runs.items() if k not in contradicted})
        changed = [p.cls.title for p in session.registry
                   if any(str(v) != str(p.cls.defaults.get(k, v)) for k, v in (settings.get(p.key) or {}).items())]
        steps = self._steps(work, settings)
        self._changed_sections = changed
        self._planned = [title for title, _ in steps if title]
        self._restored_note(changed, running=bool(self._planned))
        self._next(steps)

    def _steps(self, work: Work, settings: dict) -> list[tuple[str, Callable]]:
        """What brings the kept results back, in page order: each section's steps (its ``restore_work``),
        as ``(title, step)``, a step returning the job it started (None: nothing to wait for)."""
        session, runs = self.session, work.runs
        files = {f.slot: f for f in work.files}
        steps: list[tuple[str, Callable]] = []
        for p in session.registry:
            run, upload = runs.get(p.key), files.get(p.key)
            if not run and upload is None:
                continue
            texts = settings.get(p.key)
            if not isinstance(texts, dict):
                texts = session.settings_of(p.key)      # the page's own (its address won over the kept ones)
            kept = KeptWork(run if isinstance(run, dict) else None, upload)
            for step in p.cls.restore_work(kept, {k: str(v) for k, v in texts.items()}):
                steps.append((step.title, partial(self._take, p.key, step.do)))
        return steps

    def _take(self, key: str, do: Callable) -> object:
        """One step of a section's restoring, on the section (made now if it never was)."""
        return do(self.session.build(key))

    def _next(self, steps: list) -> None:
        """Take the steps in turn, each once the previous one's job is handled on the page."""
        while steps and not self._stopped:
            title, step = steps.pop(0)
            try:
                job = step()
            except Exception as exc:  # noqa: BLE001 - a step that cannot be taken: the others still are
                log.warning("restoring a student's work: a step failed: %s", exc, exc_info=exc)
                continue
            if job is not None:
                self.session.runner.then(job, partial(self._step_done, title, steps))
                return
        self._done()

    def _step_done(self, title: str, steps: list, job) -> None:
        if title and job.state == JobState.DONE:        # a run that failed is not said to be restored
            self.restored.append(title)
        self._next(steps)

    def _done(self) -> None:
        if self.restoring and self._changed_sections is not None:
            self._restored_note(self._changed_sections, running=False)
        self.restoring = False
        if self._dirty:
            self.changed()

    def _restored_note(self, changed: list[str], running: bool) -> None:
        parts = []
        if changed:
            parts.append("settings of " + ", ".join(changed))
        if running:
            parts.append("computing again the results of " + ", ".join(dict.fromkeys(self._planned)))
        elif self.restored:
            parts.append("results of " + ", ".join(dict.fromkeys(self.restored)))
        what = f" ({'; '.join(parts)})" if parts else ""
        self.note(f"<span class='eha-ok eha-work-restored'>Your work was restored{html.escape(what)}.</span>")

    def _tell(self, text: str) -> None:
        self.note(f"<span class='eha-warn eha-work-problem'>{html.escape(text)}</span>")

    # -- saving ---------------------------------------------------------------------------------------
    def _watch(self) -> None:
        """Save after every run of the session and every change of its inputs (debounced)."""
        session = self.session
        session.runner.after_each(lambda _job: self.changed())
        session.state.param.watch(lambda _e: self.changed(), ["texts"])
        for section in session.built():
            self._watch_section(section)
        session.when_built(self._watch_section)
        if self.doc is not None:
            self.doc.on_session_destroyed(lambda _context: self._closing())

    def _watch_section(self, section) -> None:
        if id(section) in self._watched:
            return
        self._watched.add(id(section))
        for obj in list(vars(section).values()):
            if isinstance(obj, Form):
                obj.param.watch(lambda _e: self.changed(), ["values"])
            elif isinstance(obj, pn.widgets.Select):
                obj.param.watch(lambda _e: self.changed(), ["value"])

    def changed(self) -> None:
        """Something to save: in :attr:`SAVE_DELAY_S` (at once without a server)."""
        if self._stopped:
            return
        if self.restoring:
            self._dirty = True
            return
        if self.doc is None:
            self.save()
            return
        if self._timer or self._closed:
            return
        self._timer = True
        try:
            self.doc.add_timeout_callback(self._due, int(self.SAVE_DELAY_S * 1000))
        except Exception:  # noqa: BLE001 - the page is closing
            self._timer = False

    def _due(self) -> None:
        self._timer = False
        self.save()

    def stop(self) -> None:
        """Save nothing more from this page (its id is live on another page, whose work is the student's)."""
        self._stopped = True
        self._closed = True
        self._timer = False

    def _closing(self) -> None:
        self._closed = True
        if self._timer:             # a change not saved yet: saved now, before the page goes
            self._timer = False
            self.save()

    def collect(self) -> Work:
        """The session's work now (read under the page's lock)."""
        session = self.session
        runs, files, size = {}, [], 0
        for section in session.built():
            kept = section.kept_work()
            if kept is None:
                continue
            upload = kept.file
            if upload is not None:
                upload = dataclasses.replace(upload, slot=section.key)     # one file per section, under its key
                if size + len(upload.data) > MAX_WORK_FILE_BYTES:
                    log.info("a student's upload %r is not kept: their uploads pass %d MB", upload.name,
                             MAX_WORK_FILE_BYTES // 10**6)
                else:
                    size += len(upload.data)
                    files.append(upload)
            if kept.run is not None:
                runs[section.key] = dict(kept.run)
        return Work(self.student, session.settings_bytes(), runs, tuple(files))

    def save(self) -> None:
        """Write the session's work (on the store's thread), unless it is what was written last."""
        if self._stopped:
            return
        if self.restoring:
            self._dirty = True
            return
        work = self.collect()
        mark = (work.settings, json.dumps(work.runs, sort_keys=True),
                tuple((f.slot, f.name, id(f.data), repr(f.mapping)) for f in work.files))
        if mark == self._last:
            return
        self._last = mark
        store = self.store

        def write():
            try:
                refused = store.save(work)
            except StoreUnavailable as exc:
                # the store's thread keeps this save (the latest of the student's) and tries it again
                self._on_page(partial(self._tell_once, "save", (
                    f"Your work waits to be kept: the class's database cannot be reached just now ({exc}). This "
                    "server tries again and keeps it as soon as it answers; go on working.")))
                raise
            except StoreError as exc:
                log.warning("a student's work could not be saved: %s", exc)
                self._on_page(partial(self._not_saved, exc))
                return
            if "save" in self._waited:
                self._waited.discard("save")
                self._on_page(partial(self._tell, "Your work is kept again: the class's database answers."))
            if refused:
                log.warning("the class's kept uploads are at their limit (%s MB): a student's upload is not kept",
                            store.quota_bytes // 10**6 if store.quota_bytes is not None else "?")
                self._on_page(partial(self._not_kept, refused))

        self._off_page(self._key, write)

    def _tell_once(self, what: str, text: str) -> None:
        if what not in self._waited:
            self._waited.add(what)
            self._tell(text)

    def _not_kept(self, names: list[str]) -> None:
        new = [n for n in names if n not in self._quota_told]
        if not new:
            return
        self._quota_told.update(new)
        mb = self.store.quota_bytes // 10**6 if self.store.quota_bytes is not None else 0
        self._tell(f"Your file {', '.join(new)} is used on this page but not kept for a reload: the class's space "
                   f"for kept files ({mb} MB) is full. Tell your teacher; your settings and results are kept.")

    def _not_saved(self, error: StoreError) -> None:
        self._last = None               # tried again at the next change
        if not self._told:
            self._told = True
            self._tell(f"Your work is not being kept for a reload ({error}). Tell your teacher; you can "
                       "go on working, and “Save settings” keeps your inputs.")
