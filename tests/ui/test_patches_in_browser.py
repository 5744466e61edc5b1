"""The page's one layout per message takes effect in the browser (BokehJS internals, eha_app/runtime/patches.py).

A Bokeh upgrade that moves ``Document._apply_json_patch`` or
``LayoutDOMView.invalidate_layout`` would silently make every result lay the
page out a dozen times (about a second on tab 3): this fails instead.
"""

from __future__ import annotations

from tests.ui.browser_helpers import wait_until

JS_INSTALLED = """() => {
  let proto = Bokeh.Models.get("Column").prototype.default_view.prototype;
  while (proto != null && proto.constructor.__name__ !== "LayoutDOMView") { proto = Object.getPrototypeOf(proto); }
  const doc = Bokeh.documents[0];
  return {reported: window.__eha_patches, deferring: proto != null && proto.invalidate_layout.__eha_deferring === true,
          document: doc != null && doc.__eha_layout_once === true};
}"""


def test_the_page_lays_itself_out_once_per_message_and_says_so(session):
    page = session.page
    state = wait_until(lambda: page.evaluate(JS_INSTALLED), 15, message="the page's patches")
    assert state == {"reported": {"layout_once": True}, "deferring": True, "document": True}
    # a message that changes many classes at once still draws the page (a result, then tab 1 again)
    session.tab("2. Simulation")
    page.get_by_role("button", name="Compare both").click()
    page.wait_for_selector(".eha-sim-info >> text=run 2", timeout=60_000)
