"""A form of labelled inputs drawn in the browser as one component.

Why not one Panel widget per input: every Panel widget is several Bokeh models
(the widget, its tooltip, the error pane, a layout), and a page of them costs
about 1 ms of the server's single event loop per model to build and serialise.
Tab 1's eighteen fields were 114 models and 0.2 s per student opening the
page; as one :class:`Form` they are one model and 20 ms. A class of thirty
opening the page together waits for the sum of those.

The form only carries text: what the student typed goes to the server
unchanged (``values``); the server parses and validates it and sends back a
message per field (``errors``), shown beside the field, which is marked and,
if it sits in a collapsed group, opened. The server never rewrites a value
while the student types; it sets ``values`` only for an explicit action
(reset, a preset, a restored link).

:class:`Field` describes one input and parses its text with a message in the
field's own unit (``NAME = TEXT is not allowed: WHAT``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

import param
from panel.custom import JSComponent

from eha_core.errors import FieldError

from .state import MAX_TEXT_CHARS, shown_text, too_long

__all__ = ["Form", "Field", "Group", "InputError", "parse_fields"]


class InputError(FieldError):
    """A typed value that is not allowed: the form's field it belongs to (``name``), the label the
    message shows, the text as typed and what is allowed (a :class:`~eha_core.errors.FieldError`)."""

    def __init__(self, name: str, label: str, text: str, what: str):
        self.name = name
        super().__init__(label, text, what, value_text=text)


def _plain(x: float | None) -> str:
    """A bound as a student types it: 1000000, not 1e+06."""
    return "" if x is None else f"{x:.12g}"


@dataclass(frozen=True)
class Field:
    """One input: how it is drawn and how its text is read.

    ``kind`` is ``"number"`` (a text box for a number in ``unit``, within
    ``[lo, hi]``), ``"integer"``, ``"slider"`` (a number with a slider over
    ``[lo, hi]``), ``"select"`` (one of ``options``, pairs of value and label)
    or ``"text"`` (free text, parsed by the owner).
    """

    name: str
    label: str
    kind: str = "number"
    unit: str = ""
    tip: str = ""
    lo: float | None = None
    hi: float | None = None
    step: float | None = None
    options: tuple = ()
    placeholder: str = ""
    lo_open: bool = False
    short: str = ""

    @property
    def display(self) -> str:
        """The name a message uses: the short symbol, else the label."""
        return self.short or self.label

    def to_spec(self) -> dict:
        spec = {"name": self.name, "label": self.label, "kind": self.kind, "unit": self.unit, "tip": self.tip,
                "placeholder": self.placeholder}
        if self.kind == "slider":
            spec.update(lo=self.lo, hi=self.hi, step=self.step or (self.hi - self.lo) / 100)
        if self.kind == "select":
            spec["options"] = [[str(v), str(lab)] for v, lab in self.options]
        return spec

    def _range_text(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        left = "(" if self.lo_open else "["
        lo, hi = (_plain(x) for x in (self.lo, self.hi))
        if self.lo is not None and self.hi is not None:
            return f"must lie in {left}{lo}, {hi}]{unit}"
        if self.lo is not None:
            return f"must be {'>' if self.lo_open else '>='} {lo}{unit}"
        if self.hi is not None:
            return f"must be <= {hi}{unit}"
        return f"must be a number{(' in ' + self.unit) if self.unit else ''}"

    def parse(self, text: str):
        """The value of ``text``; :class:`InputError` naming the field, the text and what is allowed."""
        raw = "" if text is None else str(text)
        if too_long(raw):
            raise InputError(self.name, self.display, shown_text(raw), too_long(raw))
        shown = raw.strip() or "(empty)"
        if self.kind == "select":
            allowed = [str(v) for v, _ in self.options]
            if raw not in allowed:
                raise InputError(self.name, self.display, shown, f"use one of {', '.join(allowed)}")
            return next(v for v, _ in self.options if str(v) == raw)
        if self.kind == "text":
            return raw.strip()
        s = raw.strip().replace(",", ".")
        what = "a whole number" if self.kind == "integer" else "a number"
        if self.lo is None and self.hi is None:
            what += f" in {self.unit}" if self.unit else ""
        else:
            what += f"; {self._range_text()}"
        try:
            value = float(s)
        except ValueError:
            raise InputError(self.name, self.display, shown, f"enter {what}") from None
        if not math.isfinite(value):
            raise InputError(self.name, self.display, shown, f"enter {what}")
        if self.kind == "integer":
            if value != int(value):
                raise InputError(self.name, self.display, shown, f"enter a whole number; {self._range_text()}")
            value = int(value)
        low_bad = self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo)
        high_bad = self.hi is not None and value > self.hi
        if low_bad or high_bad:
            raise InputError(self.name, self.display, shown, self._range_text())
        return value

    def text(self, value) -> str:
        """How a value is written into the field."""
        if self.kind in ("select", "text"):
            return str(value)
        if self.kind == "integer":
            return str(int(value))
        return f"{value:.6g}"


@dataclass(frozen=True)
class Group:
    """Fields shown together; ``collapsible`` groups can be folded (``collapsed`` at first)."""

    title: str
    fields: tuple[Field, ...]
    collapsible: bool = False
    collapsed: bool = False
    css: str = ""

    def to_spec(self) -> dict:
        return {"title": self.title, "collapsible": self.collapsible, "collapsed": self.collapsed,
                "css": self.css, "fields": [f.to_spec() for f in self.fields]}


def parse_fields(fields, values: dict, skip=()) -> tuple[dict, dict]:
    """Parse every field's text: (values by name, messages by name)."""
    parsed, errors = {}, {}
    for f in fields:
        if f.name in skip:
            continue
        try:
            parsed[f.name] = f.parse(values.get(f.name, ""))
        except InputError as exc:
            errors[f.name] = str(exc)
    return parsed, errors


_CSS = """
:host { display: block; }
.eha-form { font-size: 13px; font-family: inherit; }
.eha-group { border: 1px solid #d8dde6; border-radius: 6px; margin: 0 0 8px 0; padding: 4px 8px 6px 8px;
             background: #fff; }
.eha-group > summary, .eha-group-title { font-weight: 600; cursor: pointer; padding: 3px 0; color: #223;
                                         list-style-position: inside; }
.eha-group-title { cursor: default; }
.eha-field { margin: 4px 0 6px 0; }
.eha-field label { display: block; color: #333; margin-bottom: 2px; }
.eha-tip { display: inline-block; width: 14px; height: 14px; line-height: 14px; border-radius: 7px; background: #e4e8ef;
           color: #556; font-size: 10px; text-align: center; margin-left: 4px; cursor: help; }
.eha-field input[type=text], .eha-field select { box-sizing: border-box; width: 100%; padding: 4px 6px;
           border: 1px solid #c3c9d3; border-radius: 4px; font: inherit; background: #fff; }
.eha-field input[type=range] { width: 100%; margin: 2px 0 0 0; }
.eha-slider-row { display: flex; gap: 6px; align-items: center; }
.eha-slider-row input[type=text] { width: 80px; flex: none; }
.eha-field input:focus, .eha-field select:focus { outline: 2px solid #8ab4f8; border-color: #4a7fd6; }
.eha-field.eha-invalid input[type=text], .eha-field.eha-invalid select { border: 2px solid #b00020;
                                                                         background: #fff4f4; }
.eha-field.eha-invalid label { color: #b00020; }
.eha-error { color: #b00020; font-size: 12px; margin-top: 2px; }
.eha-error:empty { display: none; }
.eha-hidden { display: none; }
.eha-form.eha-disabled { opacity: 0.6; pointer-events: none; }
"""


class Form(JSComponent):
    """Labelled inputs, each with its message beneath (see the module docstring).

    ``spec`` is a list of :meth:`Group.to_spec` dicts; ``values`` the text of
    each field; ``errors`` a message per invalid field; ``hidden`` the names of
    fields not shown; ``disabled`` greys the whole form out.
    """

    spec = param.List(default=[], doc="groups of fields to draw")
    values = param.Dict(default={}, doc="the text of each field, as typed")
    errors = param.Dict(default={}, doc="a message per invalid field")
    hidden = param.List(default=[], doc="names of the fields not shown")
    disabled = param.Boolean(default=False)
    url_defaults = param.Dict(default=None, allow_None=True, doc="""
        When set, the fields' texts are written into the page's address as they
        are typed (those that differ from these defaults), so that a reload or a
        shared link restores them.""")

    _stylesheets = [_CSS]
    # Panel batches a browser's changes for 50 ms before handling them; a form
    # already sends one message per keystroke, and the answer (derived values,
    # messages) should come as soon as possible
    _priority_changes = ["values"]

    _esm = """
// a field holds at most this many characters (eha_app.session.state.MAX_TEXT_CHARS): every
// field goes into the page's address, which must stay short enough to load
const MAX_CHARS = __MAX_CHARS__
export function render({ model, el }) {
  const root = document.createElement('div')
  root.className = 'eha-form'
  // a dragged slider sends at most one value per DRAG_MS: 25 a second
  const DRAG_MS = 40
  let dragged = null
  const fields = {}
  const groupOf = {}
  for (const group of model.spec) {
    let box
    if (group.collapsible) {
      box = document.createElement('details')
      box.open = !group.collapsed
      const summary = document.createElement('summary')
      summary.textContent = group.title
      box.append(summary)
    } else {
      box = document.createElement('div')
      if (group.title) {
        const title = document.createElement('div')
        title.className = 'eha-group-title'
        title.textContent = group.title
        box.append(title)
      }
    }
    box.className = 'eha-group' + (group.css ? ' ' + group.css : '')
    for (const f of group.fields) {
      const wrap = document.createElement('div')
      wrap.className = 'eha-field eha-field-' + f.name
      const label = document.createElement('label')
      const id = 'eha-input-' + f.name
      label.htmlFor = id
      label.textContent = f.label + (f.unit ? ' [' + f.unit + ']' : '')
      if (f.tip) {
        const tip = document.createElement('span')
        tip.className = 'eha-tip'
        tip.textContent = '?'
        tip.title = f.tip
        label.title = f.tip
        label.append(tip)
      }
      wrap.append(label)
      let input
      let slider = null
      if (f.kind === 'select') {
        input = document.createElement('select')
        for (const [value, text] of f.options) {
          const opt = document.createElement('option')
          opt.value = value
          opt.textContent = text
          input.append(opt)
        }
        input.addEventListener('change', () => send(f.name, input.value))
      } else {
        input = document.createElement('input')
        input.type = 'text'
        input.maxLength = MAX_CHARS
        input.autocomplete = 'off'
        input.spellcheck = false
        if (f.placeholder) { input.placeholder = f.placeholder }
        input.addEventListener('input', () => {
          send(f.name, input.value)
          if (slider !== null) { follow(slider, f, input.value) }
        })
      }
      input.id = id
      input.setAttribute('aria-describedby', 'eha-error-' + f.name)
      if (f.kind === 'slider') {
        slider = document.createElement('input')
        slider.type = 'range'
        slider.min = String(f.lo)
        slider.max = String(f.hi)
        slider.step = String(f.step)
        slider.setAttribute('aria-label', f.label)
        const s = slider
        // while dragged, the value goes to the server at most every DRAG_MS (the plots
        // follow the slider); the address is written once, when it is let go
        let last = 0
        let pending = null
        s.addEventListener('pointerdown', () => { dragged = s })
        s.addEventListener('pointerup', () => { dragged = null })
        s.addEventListener('pointercancel', () => { dragged = null })
        s.addEventListener('input', () => {
          input.value = s.value
          const now = performance.now()
          if (pending !== null) { clearTimeout(pending); pending = null }
          if (now - last >= DRAG_MS) {
            last = now
            send(f.name, s.value, false)
          } else {
            pending = setTimeout(() => { pending = null; last = performance.now(); send(f.name, s.value, false) },
                                 DRAG_MS - (now - last))
          }
        })
        s.addEventListener('change', () => {
          dragged = null
          if (pending !== null) { clearTimeout(pending); pending = null }
          input.value = s.value
          send(f.name, s.value)
        })
        const row = document.createElement('div')
        row.className = 'eha-slider-row'
        row.append(s, input)
        wrap.append(row)
      } else {
        wrap.append(input)
      }
      const error = document.createElement('div')
      error.className = 'eha-error eha-error-' + f.name
      error.id = 'eha-error-' + f.name
      error.setAttribute('role', 'alert')
      wrap.append(error)
      box.append(wrap)
      fields[f.name] = { wrap, input, slider, error, spec: f }
      groupOf[f.name] = box
    }
    root.append(box)
  }
  el.append(root)

  // A slider shows the typed value only when it can: the browser would clamp
  // 99 to a 0-10 slider's 10 and show a value nobody typed. Out of its range
  // (or not a number) the slider stays put and the server's message says why.
  function follow(slider, f, text) {
    const s = String(text).trim().replace(',', '.')
    const v = Number(s)
    if (s !== '' && Number.isFinite(v) && v >= f.lo && v <= f.hi) { slider.value = String(v) }
  }
  function send(name, text, url = true) {
    if (model.values[name] === text) { if (url) { syncUrl() } return }
    model.values = { ...model.values, [name]: text }
    if (url) { syncUrl() }
  }
  function syncUrl() {
    const defaults = model.url_defaults
    if (defaults === null || defaults === undefined) { return }
    const query = new URLSearchParams(window.location.search)
    for (const name of Object.keys(fields)) {
      const text = model.values[name]
      if (text === undefined || text === null || String(text) === String(defaults[name] ?? '') ||
          String(text).length > MAX_CHARS) {
        query.delete(name)
      } else {
        query.set(name, String(text))
      }
    }
    const search = query.toString()
    const path = window.location.pathname + (search ? '?' + search : '') + window.location.hash
    window.history.replaceState(null, '', path)
  }
  function showValues() {
    syncUrl()
    const active = el.getRootNode().activeElement
    for (const [name, f] of Object.entries(fields)) {
      const text = model.values[name]
      if (text === undefined || text === null) { continue }
      if (f.input !== active && f.input.value !== String(text)) { f.input.value = String(text) }
      // a slider under the student's pointer is theirs: setting its value (even to the
      // same one) would end the drag in Chromium
      if (f.slider !== null && f.slider !== dragged) { follow(f.slider, f.spec, text) }
    }
  }
  function showErrors() {
    for (const [name, f] of Object.entries(fields)) {
      const message = model.errors[name] || ''
      f.error.textContent = message
      f.wrap.classList.toggle('eha-invalid', message !== '')
      f.input.setAttribute('aria-invalid', message !== '' ? 'true' : 'false')
      const box = groupOf[name]
      if (message !== '' && box.tagName === 'DETAILS' && !box.open) { box.open = true }
    }
  }
  function showHidden() {
    const hidden = new Set(model.hidden)
    for (const [name, f] of Object.entries(fields)) { f.wrap.classList.toggle('eha-hidden', hidden.has(name)) }
  }
  function showDisabled() { root.classList.toggle('eha-disabled', model.disabled) }
  showValues(); showErrors(); showHidden(); showDisabled()
  model.on('values', showValues)
  model.on('errors', showErrors)
  model.on('hidden', showHidden)
  model.on('disabled', showDisabled)
}
""".replace("__MAX_CHARS__", str(MAX_TEXT_CHARS))

    def set_values(self, **texts) -> None:
        """Write texts into fields (an explicit action: reset, preset, restored link)."""
        self.values = {**self.values, **{k: str(v) for k, v in texts.items()}}


def with_lower_bounds(fields: Mapping[str, Field], lows: Mapping[str, float], why: str) -> dict[str, Field]:
    """``fields`` with the lower bounds ``lows`` (display units) raised where they are higher; the
    tooltip says ``why`` (an exercise's floor: the student may go above it, not below)."""
    out = dict(fields)
    for name, lo in lows.items():
        f = out[name]
        lo = float(f"{lo:.6g}")
        if lo > (f.lo if f.lo is not None else -math.inf):
            out[name] = dataclasses.replace(f, lo=lo, tip=(f.tip + " " if f.tip else "") +
                                            f"({why}: at least {lo:g}{' ' + f.unit if f.unit else ''})")
    return out


def raised_to_bounds(texts: Mapping[str, str], fields: Mapping[str, Field], names) -> dict[str, str]:
    """``texts`` with each of ``names`` below its field's lower bound raised to it (a default of 0
    under an exercise's floor), the others as typed."""
    out = dict(texts)
    for name in names:
        lo = fields[name].lo
        try:
            below = lo is not None and float(str(out.get(name, "")).replace(",", ".")) < lo
        except ValueError:
            below = False
        if below:
            out[name] = f"{lo:g}"
    return out


def regrouped(groups, fields: Mapping[str, Field]) -> list:
    """The form's groups with their fields replaced by ``fields``' (same names)."""
    return [dataclasses.replace(g, fields=tuple(fields[f.name] for f in g.fields)) for g in groups]
