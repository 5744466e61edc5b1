"""Where the server changes a library's behaviour beyond its public API, in one place; and the
strict mode of the test suite.

Every change is a :class:`Patch` in :data:`PATCHES`: the library and minor versions it was
written for, the names it replaces or reads, a check of their shape, and the figure that justifies
it (``benchmarks/bench_patches.py`` measures each speed patch with and without it in one run;
a fix names the test that fails without it). When ``eha serve`` starts, :func:`apply_patches`
applies each one only if the installed version is one it was written for and what it replaces is
there with the shape it expects; otherwise it logs one line naming it and why, and the app works
without it (slower; a feature that needs a fix is refused; the server does not start without its
two security guards, which use public Tornado hooks and so are checked by shape, not version).
``eha serve`` prints one line of what it applied. ``EHA_PATCHES_OFF=name,name`` (or ``all``)
turns patches off, for the benchmarks. A test fakes a newer Panel and Bokeh and drives a page
without the patches (``tests/serve/test_newer_libraries.py``); each patch also has a test that it
takes effect (``tests/app/test_patches.py``, ``tests/serve/test_hardening.py``).

Component resources (Panel 1.9, ``panel.io.server.ComponentResourceHandler``)
    Panel serves ``/components/<module>/<class>/<attribute>/<path>`` for
    custom components' CSS and JavaScript, and resolves the URL by importing
    ``<module>``: any module on the server's path, named by anyone who can
    reach the server (an ``<img>`` on any page a student opens will do).
    ``/components/eha_app.cli.__main__/x/_css/a`` once made the server re-read
    its own command line and exit; ``/components/this/...`` printed into the
    log. :func:`refuse_foreign_components` makes the route answer 404 unless
    the module is already loaded, belongs to Panel or to this app, and the
    name is a Parameterized class (every Panel component is one); the
    component's own checks (listed attribute, listed file) still apply.

One layout per message (BokehJS 3.9, ``Document._apply_json_patch`` and ``LayoutDOMView.invalidate_layout``)
    BokehJS lays the whole page out again, synchronously, for every changed
    property that can move something (a class, a visibility, a size): 60-150 ms
    each on tab 3, and a frequency-domain result clears twelve out-of-date
    marks. :data:`LAYOUT_ONCE_JS` (run by every page's
    :class:`~eha_app.runtime.connection.ConnectionWatch` when it renders) notes
    the layouts invalidated while one message from the server is applied and
    does each root's once, when the message is applied. The page reports
    whether it found those internals (``ConnectionWatch.patches``, and
    ``window.__eha_patches`` for the browser tests); the server logs a warning
    when a page reports it did not (the page still works, only slower).
    No public API lays out once per message.

A widget enabled before it is drawn (BokehJS 3.9, ``ControlView.connect_signals``)
    BokehJS connects a new widget's signals when it builds its view and draws it
    (``render``) only once the whole new part of the page is built, which waits
    for the page's components' modules. A message from the server that enables
    or disables the widget meanwhile (a download offered once a result is
    shown, sent 20 ms after the tab that holds it) made BokehJS set an
    attribute on an element that did not exist yet: an exception inside the
    patch, and the rest of the tab was never drawn ("Drawing the paper's
    Fig. 2…" for good, in 5 of 12 pages opened from a link on a fast server).
    :data:`CONTROLS_BEFORE_RENDER_JS` skips the widget's elements that are not
    drawn yet (drawing them takes the widget's state then). The page reports
    it in ``ConnectionWatch.patches`` like the one layout per message.

Tabs and checkboxes for the keyboard and screen readers (BokehJS 3.9, ``TabsView._update_headers``,
``TabsView.update_active``, ``CheckboxView.render``; Panel 1.9's ``TabsView.update_active``)
    BokehJS draws a tab header as a ``div`` that only a click opens: a student without a mouse
    could reach a header with Tab but not open it, and a screen reader heard no tab, no tab list,
    and not which tab is open. A ``Checkbox``'s text is a ``div`` beside its input, which names
    nothing (axe-core's ``label`` rule; the model board's ticks and its band checkbox had no name).
    :data:`ACCESSIBLE_WIDGETS_JS` gives the headers the ARIA tab roles (``tablist``, ``tab`` with
    ``aria-selected``, ``tabpanel``), one Tab stop per list (the open tab), the arrow keys, Home
    and End between headers and Enter or Space to open one (the WAI-ARIA tabs pattern, activated
    by hand: a tab is built when first opened, which the arrow keys alone should not do), and
    each checkbox input its text as ``aria-label``. Installed before the page's widgets are drawn
    (like the guard below) and reported by the page like the layout patch; Bokeh has no API
    for an element's attributes inside a widget.

Is the event loop busy? (CPython 3.10-3.13 ``asyncio.BaseEventLoop._ready``)
    The page updates wait until nothing else is ready to run
    (:class:`~eha_app.runtime.tasks.PageUpdates`): a student typing goes
    first. asyncio has no public way to ask; :func:`loop_has_work` reads the
    queue of CPython's own loops, chosen by the loop's type, and calls any
    other loop (uvloop) idle, which only makes the page updates less polite.

One port, several processes (Bokeh 3.9, ``bokeh.server.server.bind_sockets``)
    ``eha serve --num-procs N`` runs N processes on one port with
    ``SO_REUSEPORT``, so that Linux spreads the students evenly (Bokeh's own
    forked processes put 28 of 30 students in one of two). Bokeh's ``Server``
    binds its sockets itself, through a function of its module and without
    that option; :func:`bind_port_shared` replaces that function. The
    public route, ``BaseServer`` with sockets of our own, would mean building
    Panel's server by hand instead of running ``panel serve``.

The teacher's pages (Tornado 6.5-6.6 ``Application.find_handler``, on Bokeh 3.9's ``BokehTornado``)
    The dashboard's app at ``/teacher`` must answer nobody but the teacher:
    not its page, nor its websocket, autoload script or metadata, which
    Bokeh routes to handlers of its own and Panel's. :func:`guard_paths`
    puts a function in front of every route (``find_handler`` and
    ``get_handler_delegate`` are public Tornado methods; overriding them on
    Bokeh's application class is what no API offers):
    :func:`eha_app.runtime.teacher_access.route` answers 403 without the
    teacher's cookie, before any Bokeh code runs.

Stable property defaults (Bokeh 3.9, ``PropertyDescriptor._get_default``)
    Bokeh builds an unset property's default again on every read (overrides looked up, the
    default copied and validated): a quarter of the event loop's time under a class of thirty,
    most of it while serialising new models. :func:`cache_stable_defaults` keeps each class's
    stable (immutable, not per-instance) defaults once computed; themed instances and unstable
    defaults take Bokeh's path. A page's models and their JSON are unchanged (a test compares
    them with Bokeh's own); serialising a page with every tab built takes 42 ms instead of 160.

Theme values, settings, empty containers (Bokeh 3.9, ``HasProps.themed_values``, ``HasProps.__init__``,
``HasProps.query_properties_with_values``, ``bokeh.model.util.visit_immediate_value_references``)
    :func:`fast_themed_values` reads a model's theme values without a failed attribute lookup,
    :func:`settle_settings` fixes the settings Bokeh resolves for every model (and turns its
    error diagnostics off), :func:`lazy_container_defaults` makes an empty list or dict default
    only when it is read (each function says what it saved). The page's JSON is unchanged
    (``tests/app/test_stable_defaults.py``).

The document's models (Bokeh 3.9, ``DocumentModelManager.recompute``, ``Model.trigger``)
    After a change that adds or removes a model, Bokeh finds the document's models again by a walk
    over every property of every model of the page. :func:`incremental_model_graph` keeps each
    model's references and reads again only the models that changed and the new ones
    (``tests/app/test_incremental_graph.py`` compares it with Bokeh's walk after every step of a
    student's path).

The collector (CPython's ``gc``; Panel 1.9's ``_garbage_collect`` and ``_destroy_document``)
    :func:`tune_garbage_collector` freezes what outlives each full collection (no pause of the
    event loop over 30 ms while a class works) and unfreezes it when Panel discards a session;
    :func:`collect_often` makes a full collection after three young ones instead of ten (2-7 ms
    each, wherever in a burst of clicks it falls).

A closed page (Bokeh 3.9, ``ServerSession.unsubscribe``)
    Panel hears that a page was closed only when it discards the session, about 5 s later; the
    page's largest run used a core meanwhile. :func:`notice_disconnects` calls the session's
    :func:`on_disconnect` functions when its last websocket closes: its runs are cancelled then.

The strict mode (Bokeh 3.9, ``DocumentCallbackManager.trigger_on_change``)
    Every change to a served page must be made under its document's lock, on
    the server's event loop: from a locked callback (a click, a next-tick or
    timeout callback, :func:`eha_app.runtime.tasks.apply_locked`). A change made
    elsewhere (a worker thread, Panel's lock-free handling of a priority
    change) sometimes works and sometimes raises later, somewhere else: a
    student who had shown tab 2 could no longer update tab 1. With
    ``EHA_STRICT=1`` (the test suite sets it) :func:`strict_page_changes`
    makes such a change raise at once, naming the line of the app that made it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass

__all__ = ["COMPONENT_PACKAGES", "WRITTEN_FOR", "component_allowed", "refuse_foreign_components",
           "strict_page_changes", "UnlockedChange", "strict_mode_on", "VIEW_CLASS_JS", "LAYOUT_ONCE_JS",
           "CONTROLS_BEFORE_RENDER_JS", "ACCESSIBLE_WIDGETS_JS", "loop_has_work",
           "bind_port_shared", "guard_paths", "cache_stable_defaults", "fast_themed_values", "settle_settings",
           "SETTLED_SETTINGS", "lazy_container_defaults", "incremental_model_graph",
           "tune_garbage_collector", "collect_often", "on_disconnect",
           "notice_disconnects", "note_loop_thread", "holds_lock", "lazy_freeze", "Patch",
           "PATCHES", "SERVER_PATCHES", "AFTER_LOAD_PATCHES", "READ_PATCHES", "GUARDS", "apply_patches",
           "unknown_turned_off", "usable", "why_not",
           "installed_version", "turned_off", "forget_status"]

#: The library versions these changes were written against (pyproject.toml admits these minor
#: versions only: tests/app/test_patches.py checks both).
WRITTEN_FOR = {"panel": "1.9", "bokeh": "3.9"}
#: The Pythons whose asyncio loop :func:`loop_has_work` reads (``BaseEventLoop._ready``).
PYTHONS = ((3, 10), (3, 11), (3, 12), (3, 13))

#: Top-level packages whose components' resources the server may serve.
COMPONENT_PACKAGES = ("panel", "eha_app")


def component_allowed(path: str) -> bool:
    """May ``/components/<path>`` be resolved? Only for a Parameterized class of a module of
    :data:`COMPONENT_PACKAGES` that is already loaded: a request never imports anything.

    >>> component_allowed("panel.template.vanilla/VanillaTemplate/_css/vanilla.css")
    True
    >>> component_allowed("eha_app.cli.__main__/x/_css/a"), component_allowed("this/x/_css/a")
    (False, False)
    """
    import param

    module_name, _, rest = path.partition("/")
    cls_name = rest.partition("/")[0]
    if module_name.split(".")[0] not in COMPONENT_PACKAGES:
        return False
    module = sys.modules.get(module_name)
    component = getattr(module, cls_name, None) if module is not None and cls_name else None
    return isinstance(component, type) and issubclass(component, param.Parameterized)


def refuse_foreign_components() -> None:
    """Answer 404 to every ``/components/`` request :func:`component_allowed` refuses.

    Call before the server builds its routes (``panel serve`` does so when it
    starts): Panel looks ``ComponentResourceHandler`` up in its module then.
    Calling it again does nothing.
    """
    import panel.io.server as panel_server
    from tornado.web import HTTPError

    base = panel_server.ComponentResourceHandler
    if getattr(base, "eha_guarded", False):
        return

    class GuardedComponentResourceHandler(base):
        eha_guarded = True

        def parse_url_path(self, path: str) -> str:
            if not component_allowed(path):
                raise HTTPError(404, "Not found")
            try:
                return super().parse_url_path(path)
            except HTTPError:
                raise
            except Exception:  # noqa: BLE001 - a resource attribute Panel cannot list (None, ...): not found
                raise HTTPError(404, "Not found") from None

        def write_error(self, status_code, **kwargs):
            # a short answer: no traceback, no echo of the path asked for
            self.finish(f"{status_code}: not found" if status_code == 404 else str(status_code))

    panel_server.ComponentResourceHandler = GuardedComponentResourceHandler


#: BokehJS: ``ehaViewClass(model, name)``, the prototype of the view class called ``name`` among the
#: ancestors of model ``model``'s view (null if BokehJS has none): the internals the two changes
#: below take. Pasted once before them.
VIEW_CLASS_JS = """
function ehaViewClass(modelName, viewName) {
  try {
    const model = Bokeh.Models.get(modelName);
    let proto = model != null ? model.prototype.default_view.prototype : null;
    while (proto != null && proto.constructor.__name__ !== viewName) { proto = Object.getPrototypeOf(proto); }
    return proto;
  } catch (e) { return null; }
}
"""

#: BokehJS: ``ehaLayoutOncePerMessage(doc)`` installs one layout per message on ``doc`` and returns
#: whether it found the internals it needs (see the module docstring). Pasted, after
#: :data:`VIEW_CLASS_JS`, into the ESM of :class:`~eha_app.runtime.connection.ConnectionWatch`.
LAYOUT_ONCE_JS = """
function ehaLayoutOncePerMessage(doc) {
  if (doc == null || typeof doc._apply_json_patch !== "function") { return false; }
  if (doc.__eha_layout_once) { return true; }
  const proto = ehaViewClass("Column", "LayoutDOMView");
  if (proto == null || typeof proto.invalidate_layout !== "function") { return false; }
  doc.__eha_layout_once = true;
  const LayoutDOMView = proto.constructor;
  const invalidate = proto.invalidate_layout;
  if (!invalidate.__eha_deferring) {
    const deferring = function () {
      const pending = window.__eha_layout_pending;
      if (pending != null && !(this.parent instanceof LayoutDOMView)) { pending.add(this); return; }
      return invalidate.call(this);
    };
    deferring.__eha_deferring = true;
    proto.invalidate_layout = deferring;
  }
  const apply = doc._apply_json_patch;
  doc._apply_json_patch = function (...args) {
    if (window.__eha_layout_pending != null) { return apply.apply(this, args); }
    const pending = window.__eha_layout_pending = new Set();
    try {
      return apply.apply(this, args);
    } finally {
      window.__eha_layout_pending = null;
      for (const view of pending) {
        try { view.invalidate_layout(); } catch (e) { console.error(e); }
      }
    }
  };
  return true;
}
"""


#: A widget told it is enabled or disabled before it was drawn (BokehJS 3.9, ``ControlView``; see the
#: module docstring): ``ehaControlsBeforeRender()``, after :data:`VIEW_CLASS_JS`.
CONTROLS_BEFORE_RENDER_JS = """
function ehaControlsBeforeRender() {
  const proto = ehaViewClass("Button", "ControlView");
  if (proto == null || typeof proto.connect_signals !== "function") { return false; }
  if (proto.connect_signals.__eha_before_render) { return true; }
  const base = Object.getPrototypeOf(proto);
  if (base == null || typeof base.connect_signals !== "function") { return false; }
  const connect = function () {
    base.connect_signals.call(this);
    this.connect(this.disabled, (disabled) => {
      for (const el of this.controls()) {
        // not drawn yet: render() takes the model's state
        if (el == null) { continue; }
        if (disabled) { el.setAttribute("disabled", ""); } else { el.removeAttribute("disabled"); }
      }
    });
  };
  connect.__eha_before_render = true;
  proto.connect_signals = connect;
  return true;
}
"""


#: Tab headers a keyboard can use and a screen reader can name, and named checkboxes (BokehJS 3.9,
#: ``TabsView._update_headers``/``update_active``, Panel 1.9's ``TabsView.update_active``,
#: ``CheckboxView.render``/``_update_label``; see the module docstring): ``ehaAccessibleWidgets()``,
#: after :data:`VIEW_CLASS_JS`.
ACCESSIBLE_WIDGETS_JS = """
function ehaTabKey(view, i, event) {
  const headers = view.header_els;
  const n = headers.length;
  let next = null;
  switch (event.key) {
    case "ArrowRight": next = (i + 1) % n; break;
    case "ArrowLeft": next = (i - 1 + n) % n; break;
    case "Home": next = 0; break;
    case "End": next = n - 1; break;
    case "Enter": case " ":
      event.preventDefault();
      if (!view.model.disabled && !view.model.tabs[i].disabled) { view.change_active(i); }
      return;
    default: return;
  }
  event.preventDefault();
  headers[next].focus();
}
function ehaTabsAria(view) {
  const headers = view.header_els;
  if (headers == null || view.headers_wrapper_el == null) { return; }
  const active = view.model.active;
  view.headers_wrapper_el.setAttribute("role", "tablist");
  headers.forEach((el, i) => {
    el.setAttribute("role", "tab");
    el.setAttribute("aria-selected", i === active ? "true" : "false");
    // one stop for Tab in the list (the open tab's header); the arrow keys move between headers
    el.tabIndex = i === active ? 0 : -1;
    if (!el.__eha_keys) {
      el.__eha_keys = true;
      el.addEventListener("keydown", (event) => ehaTabKey(view, i, event));
    }
  });
  (view.child_views || []).forEach((child, i) => {
    if (child != null && child.el != null && view.model.tabs[i] != null) {
      child.el.setAttribute("role", "tabpanel");
      child.el.setAttribute("aria-label", view.model.tabs[i].title);
    }
  });
}
function ehaCheckboxName(view) {
  if (view.checkbox_el == null) { return; }
  const text = view.model.label;
  if (text) { view.checkbox_el.setAttribute("aria-label", text); }
  else { view.checkbox_el.removeAttribute("aria-label"); }
}
function ehaAccessibleWidgets() {
  const tabs = ehaViewClass("Tabs", "TabsView");
  const checkbox = ehaViewClass("Checkbox", "CheckboxView");
  if (tabs == null || checkbox == null) { return false; }
  for (const [proto, names] of [[tabs, ["_update_headers", "update_active", "change_active"]],
                                [checkbox, ["render", "_update_label"]]]) {
    if (names.some((name) => typeof proto[name] !== "function")) { return false; }
  }
  if (tabs._update_headers.__eha_aria) { return true; }
  // Panel's Tabs draws its headers with Bokeh's view and shows a tab with a method of its own
  const panelTabs = ehaViewClass("panel.models.tabs.Tabs", "TabsView");
  // (a method a class inherits is wrapped where it is defined, unless ``here``)
  const after = (proto, name, fn, here = false) => {
    if (!here && !Object.prototype.hasOwnProperty.call(proto, name)) { return; }
    const original = proto[name];
    const wrapped = function (...args) { const out = original.apply(this, args); fn(this); return out; };
    wrapped.__eha_aria = true;
    proto[name] = wrapped;
  };
  for (const proto of [tabs, panelTabs]) {
    if (proto == null) { continue; }
    after(proto, "_update_headers", ehaTabsAria);
    after(proto, "update_active", ehaTabsAria);
  }
  after(checkbox, "render", ehaCheckboxName);
  after(checkbox, "_update_label", ehaCheckboxName, true);
  // views drawn before this ran
  try {
    for (const view of Bokeh.index.query((v) => v instanceof tabs.constructor)) { ehaTabsAria(view); }
    for (const view of Bokeh.index.query((v) => v instanceof checkbox.constructor)) { ehaCheckboxName(view); }
  } catch (e) { console.warn("eha: could not name the widgets drawn before", e); }
  return true;
}
"""

def loop_has_work(loop) -> bool:
    """Does ``loop`` have callbacks ready to run now? (see the module docstring; False for a loop
    that is not one of CPython's, which cannot tell, and on a Python it was not written for)."""
    import asyncio

    return (isinstance(loop, asyncio.BaseEventLoop) and usable("loop_has_work")
            and bool(getattr(loop, "_ready", ())))


def bind_port_shared() -> None:
    """Make this process's Bokeh server bind its port with ``SO_REUSEPORT`` (see the module docstring).

    Then several processes can listen on one port and Linux hands each new
    connection to one of them by a hash of its addresses: an even spread.
    """
    import bokeh.server.server as bokeh_server
    from tornado import netutil

    if getattr(bokeh_server.bind_sockets, "eha_shared", False):
        return

    def bind_sockets(address, port):
        sockets = netutil.bind_sockets(port=port or 0, address=address, reuse_port=True)
        return sockets, sockets[0].getsockname()[1]

    bind_sockets.eha_shared = True
    bokeh_server.bind_sockets = bind_sockets


def guard_paths(route) -> None:
    """Let ``route(request)`` answer any request first: it returns ``(handler class, its kwargs)``,
    or None to leave the request to the server's own routes. Calling it again does nothing."""
    from bokeh.server.tornado import BokehTornado

    find = BokehTornado.find_handler
    if getattr(find, "eha_guarded", False):
        return

    def find_handler(self, request, **kwargs):
        answer = route(request)
        if answer is not None:
            return self.get_handler_delegate(request, answer[0], answer[1])
        return find(self, request, **kwargs)

    find_handler.eha_guarded = True
    BokehTornado.find_handler = find_handler


# -- what the app reads of Bokeh's internals -------------------------------------------------------------

_loop_thread: int | None = None


def note_loop_thread() -> None:
    """Remember the server's event-loop thread (called where a session is made: on that thread)."""
    import threading

    global _loop_thread
    _loop_thread = threading.get_ident()


def holds_lock(doc) -> bool:
    """May ``doc`` be changed here and now? Yes outside a server, and while the page is being built
    (no browser has it yet); else only on the server's event loop while it holds the document's
    lock: Bokeh 3.9's ``ServerSession._pending_writes`` is a list for exactly that time (its
    ``with_document_locked``). A session without that attribute (another Bokeh) is never called
    locked: the caller defers its change to a locked callback, which is always safe."""
    import threading

    context = getattr(doc, "session_context", None)
    if context is None:
        return True                     # not served: a test, a notebook, a report
    session = getattr(context, "_session", _MISSING)
    if session is None:
        return True                     # being built: no browser has the page yet
    if session is _MISSING or not usable("lock_check") or not hasattr(session, "_pending_writes"):
        return False                    # cannot tell: not locked
    return threading.get_ident() == _loop_thread and session._pending_writes is not None


_MISSING = object()


@contextmanager
def lazy_freeze(doc):
    """``doc.models.freeze()`` that recomputes the model graph at the end only if the block changed it.

    Bokeh 3.9 (``bokeh.document.models.DocumentModelManager``) recomputes a document's set of models
    (a walk over every property of every model reachable from its roots: 30-60 ms for a page with
    every tab built) whenever its outermost freeze ends, even when the block only set a text or a
    data source's columns. A change that adds or removes models calls ``models.invalidate()``
    (``Model.trigger``), a new root goes through ``add_root``: the block notes both, and the walk
    is skipped when neither happened. A model manager of another shape (another Bokeh, or the
    patch turned off: ``EHA_PATCHES_OFF=lazy_freeze``) gets Bokeh's own freeze.
    """
    models = getattr(doc, "models", None)
    # (usable: Bokeh's model manager has the freeze internals, checked once per process)
    if models is None or not usable("lazy_freeze") or models._freeze_count > 0:
        with (models.freeze() if models is not None else _nothing()):
            yield
        return
    dirty = []
    roots = list(doc.roots)
    models.invalidate = lambda: dirty.append(True)     # this block only: the document is locked
    models._push_freeze()
    try:
        yield
    finally:
        del models.invalidate                          # back to the class's own
        models._freeze_count -= 1
        if models._freeze_count == 0 and (dirty or list(doc.roots) != roots):
            models.recompute()


@contextmanager
def _nothing():
    yield


class UnlockedChange(RuntimeError):
    """A served page was changed outside its document's lock (strict mode)."""


def strict_mode_on() -> bool:
    """Is the strict mode asked for (``EHA_STRICT=1``)?"""
    import os

    return os.environ.get("EHA_STRICT", "").strip() not in ("", "0")


def _call_site() -> str:
    """The innermost line of the app's own code on the stack (where the change was made)."""
    import traceback

    frames = [f for f in traceback.extract_stack()[:-2]
              if "/eha_app/" in f.filename and not f.filename.endswith(("/patches.py", "/tasks.py"))]
    if not frames:
        return "outside the app's code"
    f = frames[-1]
    return f"{f.filename.rsplit('/eha_app/', 1)[-1]}:{f.lineno} ({f.name}: {f.line})"


def strict_page_changes() -> None:
    """Raise :class:`UnlockedChange` on any change to a served page made without its lock.

    Process-wide (a server's); calling it again does nothing.
    """
    from bokeh.document.callbacks import DocumentCallbackManager
    from bokeh.document.events import DocumentPatchedEvent

    trigger = DocumentCallbackManager.trigger_on_change
    if getattr(trigger, "eha_strict", False):
        return

    def checked(self, event):
        doc = self._document()
        # what goes to the browser (a model's property, a root); not the callbacks' bookkeeping
        if isinstance(event, DocumentPatchedEvent) and doc is not None and not holds_lock(doc):
            what = getattr(event, "attr", None) or type(event).__name__
            model = getattr(event, "model", None)
            raise UnlockedChange(f"{type(model).__name__ if model is not None else 'the document'}.{what} changed "
                                 f"outside the page's lock, at {_call_site()}")
        return trigger(self, event)

    checked.eha_strict = True
    DocumentCallbackManager.trigger_on_change = checked


# -- Bokeh's property defaults ------------------------------------------------------------------------

_DEFAULTS: dict = {}


def cache_stable_defaults() -> None:
    """Remember each model class's stable property defaults instead of building them again.

    Bokeh 3.9 (``PropertyDescriptor._get_default``) computes a property's default on every read of an
    unset property: the class's overrides looked up, the default copied and validated
    (``prepare_value``). Building a page's models and serialising them reads every property of every
    model, most of them unset: a quarter of the server's event-loop time under a class (py-spy, 30
    students). A *stable* default (Bokeh's own word: not a container, not made per instance) is the
    same immutable value for every instance of a class, so it is kept per (class, property) once
    computed; an instance with theme values (a document with a Bokeh theme) and unstable defaults
    take Bokeh's own path.
    """
    from bokeh.core.property.descriptors import PropertyDescriptor

    if getattr(PropertyDescriptor._get_default, "_eha_cached", False):
        return
    original = PropertyDescriptor._get_default
    missing = object()

    def _get_default(self, obj):
        if obj.themed_values() is not None:
            return original(self, obj)
        key = (obj.__class__, self.name)
        value = _DEFAULTS.get(key, missing)
        if value is missing:
            value = original(self, obj)
            if not self.has_unstable_default(obj):
                _DEFAULTS[key] = value
        return value

    _get_default._eha_cached = True
    PropertyDescriptor._get_default = _get_default



def fast_themed_values() -> None:
    """Read a model's theme values from its ``__dict__`` instead of through a failed attribute lookup.

    Bokeh 3.9 (``HasProps.themed_values``) is ``getattr(self, '__themed_values__', None)``, asked at
    every read of an unset property; on the usual model, which has no theme values, the lookup fails
    inside ``HasProps.__getattr__`` and Python builds and swallows an AttributeError each time: 9 % of
    the server's event loop under a class of thirty (py-spy). Bokeh stores the theme values in the
    instance's ``__dict__`` (``apply_theme`` sets them with ``setattr`` on a private name), so reading
    the dict gives the same answer.
    """
    from bokeh.core.has_props import HasProps

    if getattr(HasProps.themed_values, "_eha_fast", False):
        return

    def themed_values(self):
        return self.__dict__.get("__themed_values__")

    themed_values._eha_fast = True
    HasProps.themed_values = themed_values


#: Bokeh's settings that it reads on every model made or serialised (``make_id``,
#: ``HasProps.to_serializable``): each read walks the settings' seven sources (the environment, two
#: configuration files, ...).
SETTLED_SETTINGS = ("simple_ids", "serialize_include_defaults")


def settle_settings() -> None:
    """Fix Bokeh's hot settings (:data:`SETTLED_SETTINGS`) at the values they have when the server
    starts, and turn Bokeh's error diagnostics off.

    Bokeh 3.9 resolves a setting from its sources at every read (``PrioritizedSetting.__call__``):
    ``make_id`` alone, called for every model made, spent 3 % of the event loop there under a class.
    The value is the same for the server's life (from its environment and configuration files); set
    as the user's value, a read returns it at the first of the sources it checks.

    Bokeh's ``perform_error_diagnostics`` (its public setting, ``BOKEH_PERFORM_ERROR_DIAGNOSTICS``)
    checks the signature of every callback a model is given (``inspect.signature``, 250 times for
    the frequency-domain panel: 8 % of building it) and suggests names for a misspelt attribute. The
    app's callbacks are the same on every page and the test suite builds every page with the
    diagnostics on; the server does without them.
    """
    from bokeh.settings import settings

    for name in SETTLED_SETTINGS:
        setting = getattr(settings, name)
        setting.set_value(setting())
    settings.perform_error_diagnostics.set_value(False)


#: (model class, property name) -> (its default is an empty container, Bokeh wraps that default)
_EMPTY_DEFAULTS: dict = {}


def _empty_default(cls, name: str) -> tuple[bool, bool]:
    """Is the class's default of property ``name`` an empty container, and one that Bokeh wraps to
    notice changes (``PropertyValueContainer``: a ``List`` or ``Dict``, not a ``Seq``)? Found once
    per class and property."""
    key = (cls, name)
    known = _EMPTY_DEFAULTS.get(key)
    if known is None:
        from bokeh.core.property.instance import InstanceDefault
        from bokeh.core.property.wrappers import PropertyValueContainer

        overrides = cls._overridden_defaults()
        prop = cls.lookup(name).property
        raw = overrides[name] if name in overrides else prop._default
        if isinstance(raw, InstanceDefault):
            known = (False, False)           # a model made per instance: it must be seen
        else:
            value = raw() if callable(raw) else raw
            empty = isinstance(value, (list, dict, tuple, set)) and not value
            known = (empty, empty and isinstance(prop.themed_default(cls, name, None), PropertyValueContainer))
        _EMPTY_DEFAULTS[key] = known
    return known


def lazy_container_defaults() -> None:
    """Do not make a model's unset, empty container properties only to look into them.

    Bokeh 3.9 makes an unset container property's default (an empty list or dict, wrapped to
    notice changes: ``PropertyValueList``, ``PropertyValueDict``) at its first read, and keeps it in
    the instance. Two walks read every property of every model: the document's graph of models
    (``bokeh.model.util.visit_immediate_value_references``, every property that can refer to a
    model) and serialisation (``HasProps.query_properties_with_values``, every property, though
    it then leaves out the unset ones). A page's 400 models got 14,000 such wrappers, 2.1 MB a
    student (tracemalloc), made and validated for nothing: an empty default refers to no model,
    and an unset property is not serialised. Both walks now skip an unset property whose class
    default is an empty container, serialisation every property it would leave out, and a new
    model does not make the defaults that Bokeh wraps and would not serialise (an unset ``Seq``,
    which it serialises, is still made); a themed model, and every property that is set or was
    read, take Bokeh's own path. The document's models and its JSON are unchanged
    (``tests/app/test_stable_defaults.py``).
    """
    import bokeh.model.util as model_util
    from bokeh.core.has_props import HasProps
    from bokeh.core.property.descriptors import UnsetValueError
    from bokeh.core.property.singletons import Intrinsic, Undefined
    from bokeh.core.property.wrappers import PropertyValueContainer

    if getattr(model_util.visit_immediate_value_references, "_eha_lazy", False):
        return
    _BOKEH.update(HasProps=HasProps, UnsetValueError=UnsetValueError, Intrinsic=Intrinsic, Undefined=Undefined,
                  PropertyValueContainer=PropertyValueContainer,
                  visit_value=model_util.visit_value_and_its_immediate_references)
    model_util.visit_immediate_value_references = _visit_references_lazily
    HasProps.query_properties_with_values = _query_properties_with_values
    HasProps.__init__ = _init_model_lazily


#: What the functions below take from Bokeh (filled in by :func:`lazy_container_defaults`).
_BOKEH: dict = {}


def _visit_references_lazily(value, visitor) -> None:
    """``bokeh.model.util.visit_immediate_value_references`` (3.9), skipping an unset property whose
    default is an empty container."""
    if isinstance(value, _BOKEH["HasProps"]):
        cls, values, unstable = value.__class__, value._property_values, value._unstable_default_values
        plain = value.__dict__.get("__themed_values__") is None
        visit_value = _BOKEH["visit_value"]
        for attr in value.properties_with_refs():
            if plain and attr not in values and attr not in unstable and _empty_default(cls, attr)[0]:
                continue
            visit_value(getattr(value, attr), visitor)
    else:
        _BOKEH["visit_value"](value, visitor)


_visit_references_lazily._eha_lazy = True


def _query_properties_with_values(self, query, *, include_defaults=True, include_undefined=False) -> dict:
    """``HasProps.query_properties_with_values`` (3.9), but the unset properties it leaves out are
    not read."""
    themed_keys: set = set()
    result: dict = {}
    keys = self.properties(_with_props=True)
    if include_defaults:
        selected_keys = set(keys)
    else:
        selected_keys = set(self._property_values.keys()) | set(self._unstable_default_values.keys())
        themed_values = self.themed_values()
        if themed_values is not None:
            themed_keys = set(themed_values.keys())
            selected_keys |= themed_keys
    for key in keys:
        if key not in selected_keys:
            continue
        descriptor = self.lookup(key)
        if not query(descriptor):
            continue
        try:
            value = descriptor.get_value(self)
        except _BOKEH["UnsetValueError"]:
            if not include_undefined:
                raise
            value = _BOKEH["Undefined"]
        else:
            if (not include_defaults and key not in themed_keys and key in self._unstable_default_values
                    and isinstance(value, _BOKEH["PropertyValueContainer"])):
                continue
        result[key] = value
    return result


def _init_model_lazily(self, **properties) -> None:
    """``HasProps.__init__`` (3.9), but the unset properties whose default is an empty container that
    Bokeh wraps are made at their first read."""
    super(_BOKEH["HasProps"], self).__init__()
    self._property_values = {}
    self._unstable_default_values = {}
    self._unstable_themed_values = {}
    undefined, intrinsic = _BOKEH["Undefined"], _BOKEH["Intrinsic"]
    for name, value in properties.items():
        if value is undefined or value is intrinsic:
            continue
        setattr(self, name, value)
    cls = self.__class__
    for name in self.properties(_with_props=True):
        if name in properties or _empty_default(cls, name)[1]:
            continue                # made at its first read; unset, it is not serialised
        desc = self.lookup(name)
        if desc.has_unstable_default(self):
            desc._get(self)         # fills in ``_unstable_*_values`` (a model made per instance)
    self._initialized = True


def incremental_model_graph() -> None:
    """Find a document's models again from what changed, not by walking every model.

    Bokeh 3.9 (``DocumentModelManager.recompute``) finds the set of a document's models after any
    change that adds or removes one (a new figure, a new tooltip, a pane's new child) by a walk over
    every property of every model reachable from the roots: 40-100 ms for a page with every tab
    built, once per page update that touches the graph (the :func:`lazy_freeze` block), and a
    student's path makes some twenty such updates. Here the manager keeps each model's immediate
    references; ``Model.trigger`` (every property change, a container's mutation included) marks
    the model whose property changed, and the walk reads again only the marked models and the ones
    it has not met, then follows the kept references. What it attaches, detaches and names is
    what Bokeh's own walk gives (``tests/app/test_patches.py`` compares both after every step of a
    student's path).
    """
    from bokeh.document.models import DocumentModelManager
    from bokeh.model import Model

    if getattr(DocumentModelManager.recompute, "_eha_incremental", False):
        return
    trigger = Model.trigger

    def marking_trigger(self, attr, old, new, hint=None, setter=None):
        doc = self._document
        if hint is None and doc is not None:
            graph = doc.models.__dict__.get("_eha_graph")
            if graph is not None:
                graph[1].add(self.id)
        trigger(self, attr, old, new, hint=hint, setter=setter)

    marking_trigger._eha_incremental = True
    Model.trigger = marking_trigger
    DocumentModelManager.recompute = _recompute_incrementally


def _recompute_incrementally(self) -> None:
    """``DocumentModelManager.recompute`` (Bokeh 3.9) from the kept references of each model (see
    :func:`incremental_model_graph`)."""
    import bokeh.model.util as model_util
    from bokeh.util.datatypes import MultiValuedDict

    document = self._document()
    if document is None:
        return
    graph = self.__dict__.get("_eha_graph")
    if graph is None:
        graph = self._eha_graph = ({}, set())       # id -> (model, its immediate references), marked ids
    refs, marked = graph
    for mid in marked:
        refs.pop(mid, None)
    marked.clear()
    visit = model_util.visit_immediate_value_references
    reached: dict = {}
    todo = list(document.roots)
    while todo:
        model = todo.pop()
        if model.id in reached:
            continue
        reached[model.id] = model
        known = refs.get(model.id)
        if known is None or known[0] is not model:
            found: list = []
            visit(model, found.append)
            known = refs[model.id] = (model, found)
        todo.extend(known[1])
    for mid in [mid for mid in refs if mid not in reached]:
        del refs[mid]
    new_models = set(reached.values())
    old_models = set(self._models.values())
    by_name: MultiValuedDict = MultiValuedDict()
    for model in new_models:
        if model.name is not None:
            by_name.add_value(model.name, model)
    for model in old_models - new_models:
        self._seen_model_ids.add(model.id)
        model._detach_document()
    for model in new_models - old_models:
        model._attach_document(document)
        self._new_models.add(model)
    self._models = reached
    self._models_by_name = by_name


_recompute_incrementally._eha_incremental = True


def tune_garbage_collector() -> None:
    """Keep the collector's pauses short in the server: what outlives a full collection is frozen.

    Building a page makes hundreds of thousands of small objects (Bokeh models, Panel's parameters,
    their dicts), most of which live as long as the page. CPython's collector looked at every
    object of every open page at each full collection: with thirty pages open one held the event
    loop 0.5-0.7 s (a student typing waited that long, twice a class), and its collections took a
    fifth of the time to build a page (measured in-process; half that with the start-up frozen).
    Here what is loaded at start-up is frozen (``gc.freeze``: moved out of the collector's sight),
    and after each full collection
    what survived it is frozen too: the next one looks only at what was made since (no pause over
    30 ms while a class of thirty works). The young generations' thresholds stay CPython's:
    collected later, the young garbage of 200 pages opened and closed kept 110 MB more
    (``bench_classroom.py --churn 200``); :func:`collect_often` makes full collections sooner.

    A closed page's objects are garbage among the frozen ones: once Panel has discarded a session
    everything is unfrozen, and the next full collection looks at all of it (a long pause, as every
    full collection was before), like Panel's own a few seconds after the last page closed
    (:func:`_collect_everything`).
    """
    import gc

    import panel.io.application as panel_application
    import panel.io.document as panel_document

    gc.collect()
    gc.freeze()
    if _freeze_survivors not in gc.callbacks:
        gc.callbacks.append(_freeze_survivors)
    panel_document._garbage_collect = _collect_everything
    if not getattr(panel_application._destroy_document, "_eha_noted", False):
        panel_application._destroy_document = _noting_discarded(panel_application._destroy_document)


def _freeze_survivors(phase: str, info: dict) -> None:
    """After a full collection, freeze what survived it (see :func:`tune_garbage_collector`)."""
    if phase == "stop" and info.get("generation") == 2:
        import gc

        gc.freeze()


def _noting_discarded(destroy):
    """Panel 1.9's ``_destroy_document`` (its Document.destroy for a served session), after which
    the frozen objects are unfrozen: the closed page's are among them, garbage now, for the next
    full collection to find."""
    def destroy_document(self, session):
        import gc

        try:
            return destroy(self, session)
        finally:
            gc.unfreeze()       # into the oldest generation (cheap: two lists joined)

    destroy_document._eha_noted = True
    return destroy_document


def _collect_everything() -> None:
    """Panel 1.9's ``_garbage_collect`` (a few seconds after the last session was discarded),
    looking at the frozen objects too: a closed page's are garbage now."""
    import gc
    import time

    import panel.io.document as panel_document
    from panel.io.state import state

    waited = time.monotonic() - panel_document._panel_last_cleanup
    if waited < panel_document.GC_DEBOUNCE:
        import datetime as dt

        state.schedule_task("gc.collect", _collect_everything, at=dt.datetime.now() + dt.timedelta(seconds=waited))
        return
    gc.unfreeze()
    gc.collect()            # frozen again after it (_freeze_survivors)


# -- full collections, small and often -------------------------------------------------------------

#: A full collection after this many young ones (CPython's own: ten, and a quarter of the objects
#: that outlived the last full one).
FULL_GC_AFTER = 3
_full_asked = None


def collect_often() -> None:
    """Full collections of the garbage collector three times as often, each a third as long.

    With :func:`tune_garbage_collector` a full collection looks at what was made since the last
    one. CPython starts one after ten young collections: 25-35 ms with a class of thirty at work,
    the event loop stopped meanwhile, and every click that came then waited. Where in a step that
    happens depends on every allocation before it: one more student's page (a study's progress,
    or only a page with tab 3 shown) moved it from after a burst of thirty "Compare both" clicks
    to its middle, and the others' p95 went 0.027 -> 0.047 s (1.7x, eight classes of thirty each
    way, the server's collections logged). After three young collections it takes 2-7 ms,
    wherever it falls, and a study beside leaves every step within 1.05x (``bench_classroom.py
    --sessions 30 --hog study --hog-repeats 8``). Less garbage waits for its collection: in 25
    rounds of Compare both by thirty students the server's full collections took 476 ms in all
    instead of 696, its memory the same (344 MB); six random walks of 300 actions
    (``bench_random_walk.py``) ended at 548 MB instead of 626.

    A collection cannot start another from the collector's callback: the callback asks (a
    reentrant queue) and a thread of its own collects, at once (the thread waits at most the
    interpreter's switch interval, 5 ms, for its turn). CPython's own full collections stay on
    behind it."""
    import gc
    import queue
    import threading

    global _full_asked
    if _full_asked is not None:
        return
    asked: queue.SimpleQueue = queue.SimpleQueue()    # put() is reentrant: safe in the callback

    def after_young(phase: str, info: dict) -> None:
        if (phase == "stop" and info.get("generation") == 1 and gc.get_count()[2] >= FULL_GC_AFTER
                and asked.empty()):
            asked.put(None)

    def collect() -> None:
        while True:
            asked.get()
            if gc.get_count()[2] >= FULL_GC_AFTER:      # not done meanwhile by CPython's own
                gc.collect()                           # then frozen (_freeze_survivors)

    _full_asked = asked
    threading.Thread(target=collect, name="eha-full-gc", daemon=True).start()
    gc.callbacks.append(after_young)


# -- a page's connection closing -----------------------------------------------------------------------

def on_disconnect(doc, fn) -> None:
    """Call ``fn()`` (on the event loop) when the last connection of ``doc``'s session closes (see
    :func:`notice_disconnects`); without a server, never."""
    doc.__dict__.setdefault("_eha_on_disconnect", []).append(fn)


def notice_disconnects() -> None:
    """Tell a page's session at once that its browser went away.

    Bokeh 3.9 (``ServerSession.unsubscribe``) only notes the time of a closed connection; Panel
    destroys the session (and calls ``pn.state.on_session_destroyed``) at the next check of unused
    sessions after their lifetime, about 5 s later with ``eha serve``'s settings. A closed page's
    largest run went on using a core for 4 s meanwhile. This calls the functions
    :func:`on_disconnect` registered for the session's document when its last connection goes,
    within the websocket's close (the session's runs are cancelled there: they stop at their next
    check of the cancel token).
    """
    from bokeh.server.session import ServerSession

    if getattr(ServerSession.unsubscribe, "_eha_notices", False):
        return
    original = ServerSession.unsubscribe

    def unsubscribe(self, connection):
        original(self, connection)
        if self.connection_count:
            return
        for fn in list(self.document.__dict__.get("_eha_on_disconnect", ())):
            try:
                fn()
            except Exception:  # noqa: BLE001 - one page's cleanup must not break the server's
                import logging

                logging.getLogger("eha_app").exception("a closed page's cleanup failed")

    unsubscribe._eha_notices = True
    ServerSession.unsubscribe = unsubscribe


# -- which changes apply, and why ---------------------------------------------------------------------

@dataclass(frozen=True)
class Patch:
    """One change of a library's behaviour beyond its public API (see the module docstring).

    ``versions``: the minor versions of ``library`` it was written for (None: it uses public hooks
    only, and its shape decides); ``replaces``: the dotted names it replaces or reads, each of which
    must exist; ``shape``: a further check of what it replaces ("" when it fits, else why not);
    ``install``: what applies it in this process (None: read where it is used, or pasted into the
    page for the browser); ``gain``: the figure that justifies it (``benchmarks/bench_patches.py``
    measures it with and without the patch in one run) or, for a fix, the test that fails without
    it; ``kind``: "speed" (the app works without it, slower), "fix" (the app misbehaves without it:
    the feature that needs it is refused), "guard" (a security check: the server does not start
    without it) or "test" (the suite's strict mode).
    """

    name: str
    library: str
    versions: tuple[str, ...] | None
    replaces: tuple[str, ...]
    gain: str
    kind: str = "speed"
    install: Callable[[], None] | None = None
    shape: Callable[[], str] | None = None

    @property
    def in_browser(self) -> bool:
        return self.replaces[0].startswith("BokehJS")


def installed_version(library: str) -> str:
    """The installed version of ``library`` ("python" for the interpreter), as its distribution says."""
    if library == "python":
        return f"{sys.version_info[0]}.{sys.version_info[1]}.{sys.version_info[2]}"
    from importlib.metadata import version

    return version(library)


def _resolve(dotted: str):
    """The object a dotted name refers to (a module's attribute, a class's attribute...), or _MISSING."""
    import importlib

    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name, _MISSING)
            if obj is _MISSING:
                return _MISSING
        return obj
    return _MISSING


def _sets_in_init(cls_name: str, *attrs: str) -> Callable[[], str]:
    """A shape check: class ``cls_name``'s ``__init__`` sets each of ``attrs`` (an instance's attribute
    that the class does not hold)."""
    def check() -> str:
        import inspect

        cls = _resolve(cls_name)
        try:
            source = inspect.getsource(cls.__init__)
        except (TypeError, OSError, AttributeError):
            return f"{cls_name}.__init__ cannot be read"
        lacking = [a for a in attrs if f"self.{a}" not in source]
        return f"{cls_name} no longer sets {', '.join(lacking)}" if lacking else ""
    return check


def _find_handler_is_tornados() -> str:
    """``BokehTornado`` is a Tornado ``Application`` that leaves ``find_handler`` (a public Tornado
    method) to Tornado: overriding it then puts a check in front of every route."""
    from tornado.web import Application

    cls = _resolve("bokeh.server.tornado.BokehTornado")
    if not (isinstance(cls, type) and issubclass(cls, Application)):
        return "BokehTornado is not a Tornado Application"
    if "find_handler" in cls.__dict__ and not getattr(cls.find_handler, "eha_guarded", False):
        return "BokehTornado routes requests itself (find_handler)"
    return ""


def _component_handler_is_static() -> str:
    """Panel's component route is a Tornado ``StaticFileHandler`` that resolves its path in
    ``parse_url_path`` (public Tornado methods): a subclass can refuse a path first."""
    from tornado.web import StaticFileHandler

    cls = _resolve("panel.io.server.ComponentResourceHandler")
    if not (isinstance(cls, type) and issubclass(cls, StaticFileHandler)):
        return "ComponentResourceHandler is not a StaticFileHandler"
    return ""


_BOKEH_39 = ("3.9",)
_PANEL_19 = ("1.9",)
_PYTHONS = tuple(f"{major}.{minor}" for major, minor in PYTHONS)

#: Every patch, by name (``EHA_PATCHES_OFF=name,name`` or ``all`` turns patches off, for the benchmarks).
PATCHES: dict[str, Patch] = {p.name: p for p in (
    Patch("component_guard", "panel", None, ("panel.io.server.ComponentResourceHandler",),
          "tests/serve/test_hardening.py: /components/eha_app.cli.__main__/... made the server exit", "guard",
          refuse_foreign_components, _component_handler_is_static),
    Patch("teacher_routes", "bokeh", None, ("bokeh.server.tornado.BokehTornado.get_handler_delegate",),
          "tests/serve/test_dashboard.py: /teacher's page, websocket and autoload answer 403 without the "
          "teacher's cookie; 414/431 for oversized requests", "guard", None, _find_handler_is_tornados),
    Patch("shared_port", "bokeh", _BOKEH_39, ("bokeh.server.server.bind_sockets",),
          "tests/serve/test_hardening.py: --num-procs N binds one port; Bokeh's forks put 28 of 30 students "
          "in one of two processes", "fix", bind_port_shared),
    Patch("strict", "bokeh", _BOKEH_39,
          ("bokeh.document.callbacks.DocumentCallbackManager.trigger_on_change",
           "bokeh.document.events.DocumentPatchedEvent"),
          "tests/app/test_patches.py::test_strict_mode_raises_on_a_change_outside_the_lock", "test",
          strict_page_changes, lambda: why_not("lock_check")),
    Patch("lock_check", "bokeh", _BOKEH_39, ("bokeh.server.session.ServerSession",),
          "tests/serve/test_any_order.py: a change outside the lock broke tab 1 for good", "fix",
          shape=_sets_in_init("bokeh.server.session.ServerSession", "_pending_writes")),
    Patch("stable_defaults", "bokeh", _BOKEH_39,
          ("bokeh.core.property.descriptors.PropertyDescriptor._get_default",
           "bokeh.core.property.descriptors.PropertyDescriptor.has_unstable_default",
           "bokeh.core.has_props.HasProps.themed_values"),
          "bench_patches.py page_build_ms: 689 ms, 814 without it (x1.18)", install=cache_stable_defaults),
    Patch("fast_themed_values", "bokeh", _BOKEH_39, ("bokeh.core.has_props.HasProps.themed_values",),
          "bench_patches.py page_build_ms: 689 ms, 718 without it (x1.04, the smallest)", install=fast_themed_values),
    Patch("settled_settings", "bokeh", _BOKEH_39,
          tuple(f"bokeh.settings.settings.{n}" for n in (*SETTLED_SETTINGS, "perform_error_diagnostics")),
          "bench_patches.py page_build_ms: 689 ms, 754 without it (x1.09)", install=settle_settings),
    Patch("lazy_containers", "bokeh", _BOKEH_39,
          ("bokeh.model.util.visit_immediate_value_references",
           "bokeh.model.util.visit_value_and_its_immediate_references",
           "bokeh.core.has_props.HasProps.query_properties_with_values", "bokeh.core.has_props.HasProps.__init__",
           "bokeh.core.has_props.HasProps._overridden_defaults", "bokeh.core.property.instance.InstanceDefault",
           "bokeh.core.property.wrappers.PropertyValueContainer"),
          "bench_patches.py page_build_ms: 689 ms, 841 without it (x1.22); page_kb 7823, 10845 without",
          install=lazy_container_defaults),
    Patch("lazy_freeze", "bokeh", _BOKEH_39,
          ("bokeh.document.models.DocumentModelManager._push_freeze",
           "bokeh.document.models.DocumentModelManager.recompute",
           "bokeh.document.models.DocumentModelManager.invalidate"),
          "bench_patches.py update_ms: 0.02 ms, 12.4 without it",
          shape=_sets_in_init("bokeh.document.models.DocumentModelManager", "_freeze_count")),
    Patch("incremental_graph", "bokeh", _BOKEH_39,
          ("bokeh.document.models.DocumentModelManager.recompute", "bokeh.model.model.Model.trigger",
           "bokeh.model.util.visit_immediate_value_references", "bokeh.util.datatypes.MultiValuedDict"),
          "bench_patches.py graph_ms: 1.0 ms, 9.6 without it (x9)", install=incremental_model_graph,
          shape=_sets_in_init("bokeh.document.models.DocumentModelManager", "_models", "_models_by_name",
                              "_new_models", "_seen_model_ids")),
    Patch("gc_freeze", "panel", _PANEL_19,
          ("panel.io.document._garbage_collect", "panel.io.document._panel_last_cleanup",
           "panel.io.document.GC_DEBOUNCE", "panel.io.application._destroy_document"),
          "bench_patches.py gc_pause_max_ms: 4.6 ms, 815 without it", install=tune_garbage_collector),
    Patch("gc_often", "python", _PYTHONS, ("gc.callbacks", "gc.freeze"),
          "bench_patches.py gc_pause_max_ms: 4.6 ms, 18.2 without it", install=collect_often),
    Patch("loop_has_work", "python", _PYTHONS, ("asyncio.base_events.BaseEventLoop",),
          "bench_classroom.py --sessions 30 --distinct observer_p95: 0.16 s, 1.27 without it",
          shape=_sets_in_init("asyncio.base_events.BaseEventLoop", "_ready")),
    Patch("disconnects", "bokeh", _BOKEH_39, ("bokeh.server.session.ServerSession.unsubscribe",
                                               "bokeh.server.session.ServerSession.connection_count"),
          "bench_closed_page.py closed_stop_s: 0.02 s, 4.39 without it", install=notice_disconnects),
    Patch("layout_once", "bokeh", _BOKEH_39, ("BokehJS Document._apply_json_patch",
                                               "BokehJS LayoutDOMView.invalidate_layout"),
          "bench_frequency_page.py --visit-all freq_click_to_page_ms_median: 502 ms, 2501 without it"),
    Patch("controls_before_render", "bokeh", _BOKEH_39, ("BokehJS ControlView.connect_signals",),
          "tests/ui/test_patches_in_browser.py: a tab left undrawn in 5 of 12 pages opened from a link", "fix"),
    Patch("accessible_widgets", "bokeh", _BOKEH_39,
          ("BokehJS TabsView._update_headers", "BokehJS TabsView.update_active", "BokehJS CheckboxView.render"),
          "tests/ui/test_accessibility.py: no tab opened from the keyboard; axe-core's label rule on the board's "
          "ticks", "fix"),
)}

#: The patches the server applies when it starts (in this order), and those its pages use.
SERVER_PATCHES = ("component_guard", "teacher_routes", "stable_defaults", "fast_themed_values", "settled_settings",
                  "lazy_containers", "incremental_graph", "disconnects")
#: Applied after the app is loaded (what is loaded then is frozen out of the collector's sight).
AFTER_LOAD_PATCHES = ("gc_freeze", "gc_often")
#: Read where they are used (a page's lock, its freeze, the event loop) or pasted into the page for
#: the browser: checked when the server starts, like the others.
READ_PATCHES = ("lock_check", "lazy_freeze", "loop_has_work", "layout_once", "controls_before_render",
                "accessible_widgets")
#: Without these the server does not start (it would not be safe to open to a class).
GUARDS = ("component_guard", "teacher_routes")

_STATUS: dict[str, str] = {}


def turned_off() -> set[str]:
    """The patches ``EHA_PATCHES_OFF`` turns off (a comma-separated list of names, or ``all``); the
    security guards are never turned off (a server without them would not start)."""
    import os

    names = {n.strip() for n in os.environ.get("EHA_PATCHES_OFF", "").split(",") if n.strip()}
    if "all" in names:
        names = set(PATCHES)
    return {n for n in names if n in PATCHES and PATCHES[n].kind != "guard"}


def unknown_turned_off() -> list[str]:
    """The names in ``EHA_PATCHES_OFF`` that are no patch (a typo turns nothing off)."""
    import os

    names = [n.strip() for n in os.environ.get("EHA_PATCHES_OFF", "").split(",") if n.strip()]
    return [n for n in names if n != "all" and n not in PATCHES]


def why_not(name: str) -> str:
    """Why patch ``name`` cannot be used in this process ("" when it can): turned off, a library
    version it was not written for, or what it replaces not found or of another shape."""
    patch = PATCHES[name]
    if name in turned_off():
        return "turned off by EHA_PATCHES_OFF"
    if patch.versions is not None:
        version = installed_version(patch.library)
        if ".".join(version.split(".")[:2]) not in patch.versions:
            return f"{patch.library} {version} is not the {' or '.join(patch.versions)} it was written for"
    if not patch.in_browser:
        missing = [r for r in patch.replaces if _resolve(r) is _MISSING]
        if missing:
            return f"{missing[0]} not found"
    return patch.shape() if patch.shape is not None else ""


def usable(name: str) -> bool:
    """May patch ``name`` be used here (see :func:`why_not`; decided once per process)?"""
    status = _STATUS.get(name)
    if status is None:
        status = _STATUS[name] = why_not(name) or "usable"
    return status in ("usable", "applied")


def forget_status() -> None:
    """Decide again which patches are usable (a test that changes ``EHA_PATCHES_OFF``)."""
    _STATUS.clear()


def apply_patches(names, log=None) -> dict[str, str]:
    """Apply the patches ``names`` that fit this process and return each one's status: "applied",
    or why it was not (one warning line each in ``log``). Applying one twice does nothing."""
    import logging

    log = log or logging.getLogger("eha_app")
    report = {}
    for name in names:
        known = _STATUS.get(name)
        if known is not None and known != "usable":
            report[name] = known                    # decided already in this process (and said so)
            continue
        patch = PATCHES[name]
        why = why_not(name)
        if not why and patch.install is not None:
            try:
                patch.install()
            except Exception as exc:  # noqa: BLE001 - a library of another shape: the app goes on without it
                why = f"failed: {type(exc).__name__}: {exc}"
        if why and _STATUS.get(name) != why:       # once per process and reason
            consequence = {"speed": "the app works without it, slower", "fix": "what needs it is refused",
                           "guard": "the server cannot start safely", "test": "changes are not checked"}[patch.kind]
            log.warning("library patch %s not applied: %s; %s", name, why, consequence)
        _STATUS[name] = why or "applied"
        report[name] = why or "applied"
    return report
