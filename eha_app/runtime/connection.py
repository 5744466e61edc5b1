"""The page's link to the server: says when it is lost, comes back when the server does.

Bokeh's client only logs a lost websocket to the console: the page looks alive
while every click goes nowhere. :class:`ConnectionWatch` is an invisible
component that listens for the document's ``connection_lost`` event, then
covers the page with a notice (so nobody clicks into the void), asks the server
every two seconds whether it answers again, and reloads the page when it does.
A restarted server has no memory of the old session, but nothing typed is
lost: every form writes its fields into the page's address as they are typed,
and the app reads them back when it starts (:func:`eha_app.app.create_app`).

It also keeps the address in step with the open tab (``tab=2``), and installs
the page's one layout per message
(:data:`~eha_app.runtime.patches.LAYOUT_ONCE_JS`), the guard of widgets
changed before they are drawn
(:data:`~eha_app.runtime.patches.CONTROLS_BEFORE_RENDER_JS`) and the tabs and
checkboxes for the keyboard and screen readers
(:data:`~eha_app.runtime.patches.ACCESSIBLE_WIDGETS_JS`), reporting in
``patches`` whether each took effect.
"""

from __future__ import annotations

import param
from panel.custom import JSComponent

from .patches import ACCESSIBLE_WIDGETS_JS, CONTROLS_BEFORE_RENDER_JS, LAYOUT_ONCE_JS, VIEW_CLASS_JS

__all__ = ["ConnectionWatch"]


class ConnectionWatch(JSComponent):
    """Invisible; see the module docstring. ``retry_ms``: how often to ask the server."""

    retry_ms = param.Integer(default=2000, bounds=(100, None))
    tabs_class = param.String(default="eha-main-tabs", doc="css class of the Tabs whose index goes into the URL")
    patches = param.Dict(default={}, doc="what the page reports of the library patches it installed, e.g. "
                                         "{'layout_once': True, 'controls_before_render': True, "
                                         "'accessible_widgets': True}")
    install = param.List(default=[], doc="the BokehJS patches the server found fit for its Bokeh (patches.usable)")

    def __init__(self, **params):
        from .patches import usable

        params.setdefault("install", [n for n in ("layout_once", "controls_before_render", "accessible_widgets")
                                      if usable(n)])
        super().__init__(**params)

    _esm = VIEW_CLASS_JS + LAYOUT_ONCE_JS + CONTROLS_BEFORE_RENDER_JS + ACCESSIBLE_WIDGETS_JS + """
export function render({ view, model, el }) {
  el.style.display = 'none'
  const doc = view.model.document
  // one layout per message from the server: the page says whether BokehJS had what it needs
  // and a widget enabled or disabled before it is drawn does not break the message
  // (only those the server found written for its Bokeh: patches.py)
  const wanted = model.install
  const applied = {}
  if (wanted.includes('layout_once')) { applied.layout_once = ehaLayoutOncePerMessage(doc) }
  if (wanted.includes('controls_before_render')) { applied.controls_before_render = ehaControlsBeforeRender() }
  // tab headers a keyboard opens and a screen reader names, named checkboxes
  if (wanted.includes('accessible_widgets')) { applied.accessible_widgets = ehaAccessibleWidgets() }
  window.__eha_patches = applied
  model.patches = applied
  let overlay = null
  let lost = false
  function show(text) {
    if (overlay === null) {
      overlay = document.createElement('div')
      overlay.className = 'eha-offline'
      overlay.setAttribute('role', 'alertdialog')
      overlay.setAttribute('aria-live', 'assertive')
      Object.assign(overlay.style, {
        position: 'fixed', inset: '0', zIndex: '100000', background: 'rgba(255,255,255,0.72)',
        display: 'flex', alignItems: 'flex-start', justifyContent: 'center', paddingTop: '80px',
      })
      const box = document.createElement('div')
      box.className = 'eha-offline-box'
      Object.assign(box.style, {
        background: '#fff4e5', border: '2px solid #b26a00', borderRadius: '8px', padding: '16px 22px',
        maxWidth: '560px', font: '15px sans-serif', color: '#3d2500', boxShadow: '0 4px 18px rgba(0,0,0,0.18)',
      })
      overlay.append(box)
      document.body.append(overlay)
    }
    overlay.firstChild.textContent = text
    if (document.activeElement && document.activeElement.blur) { document.activeElement.blur() }
  }
  function poll() {
    // a GET: the page handler answers nothing else (HEAD is 405)
    fetch(window.location.href, { cache: 'no-store' })
      .then((response) => {
        if (response.ok) {
          show('The server is back: reloading the page with your values…')
          window.location.reload()
        } else {
          setTimeout(poll, model.retry_ms)
        }
      })
      .catch(() => setTimeout(poll, model.retry_ms))
  }
  doc.on_event('connection_lost', () => {
    if (lost) { return }
    lost = true
    show('The connection to the server was lost. Your values are kept in this page\\'s address; ' +
         'it reconnects by itself as soon as the server answers again.')
    setTimeout(poll, model.retry_ms)
  })
  // the open tab goes into the address, next to the fields the forms write there
  for (const m of doc.all_models) {
    if (m.css_classes !== undefined && m.css_classes.includes(model.tabs_class)) {
      m.property('active').change.connect(() => {
        const query = new URLSearchParams(window.location.search)
        if (m.active === 0) { query.delete('tab') } else { query.set('tab', String(m.active + 1)) }
        const search = query.toString()
        const path = window.location.pathname + (search ? '?' + search : '') + window.location.hash
        window.history.replaceState(null, '', path)
      })
    }
  }
}
"""
