"""The page's changes to BokehJS take effect in the browser (its internals, eha_app/runtime/patches.py).

A Bokeh upgrade that moves ``Document._apply_json_patch`` or
``LayoutDOMView.invalidate_layout`` would silently make every result lay the
page out a dozen times (about a second on tab 3), one that moves
``ControlView.connect_signals`` would leave a tab undrawn when a widget is
enabled before it is drawn: these fail instead.
"""

from __future__ import annotations

from tests.ui.browser_helpers import wait_until

JS_INSTALLED = """() => {
  let proto = Bokeh.Models.get("Column").prototype.default_view.prototype;
  while (proto != null && proto.constructor.__name__ !== "LayoutDOMView") { proto = Object.getPrototypeOf(proto); }
  const doc = Bokeh.documents[0];
  let control = Bokeh.Models.get("Button").prototype.default_view.prototype;
  while (control != null && control.constructor.__name__ !== "ControlView") {
    control = Object.getPrototypeOf(control);
  }
  return {reported: window.__eha_patches, deferring: proto != null && proto.invalidate_layout.__eha_deferring === true,
          document: doc != null && doc.__eha_layout_once === true,
          controls: control != null && control.connect_signals.__eha_before_render === true};
}"""

#: A button's view built and connected as BokehJS does for a new part of the page, then disabled and
#: enabled before it is drawn (a message from the server meanwhile), then drawn.
JS_ENABLED_BEFORE_DRAWN = """async () => {
  const Button = Bokeh.Models.get("Button");
  const model = new Button({label: "early"});
  const view = new model.default_view({model, parent: null});
  view.initialize();
  await view.lazy_initialize();
  view.connect_signals();
  let error = null;
  try { model.disabled = true; model.disabled = false; model.disabled = true; } catch (e) { error = String(e); }
  view.render();
  const drawn = view.button_el != null && view.button_el.hasAttribute("disabled");
  view.remove();
  return {error, drawn};
}"""


def test_the_page_lays_itself_out_once_per_message_guards_early_widgets_and_says_so(session):
    page = session.page
    state = wait_until(lambda: page.evaluate(JS_INSTALLED), 15, message="the page's patches")
    assert state == {"reported": {"layout_once": True, "controls_before_render": True, "accessible_widgets": True},
                     "deferring": True,
                     "document": True, "controls": True}
    # a widget enabled and disabled before it is drawn: no exception, and drawn in its last state
    assert page.evaluate(JS_ENABLED_BEFORE_DRAWN) == {"error": None, "drawn": True}
    # a message that changes many classes at once still draws the page (a result, then tab 1 again)
    session.tab("2. Simulation")
    page.get_by_role("button", name="Compare both").click()
    page.wait_for_selector(".eha-sim-info >> text=run 2", timeout=60_000)
