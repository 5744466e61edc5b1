"""The tabs' one layout rule: controls beside results on a wide screen, above them on a narrow one."""

from __future__ import annotations

import panel as pn

__all__ = ["WRAP_TAB_HEADERS", "LABEL_FOR_SCREEN_READERS", "BUTTON_CONTRAST", "side_by_side"]


def side_by_side(*objects, css_classes=()) -> pn.FlexBox:
    """``objects`` in a row that wraps: at 800 px the results go below the controls
    instead of past the window's edge. A stretching object (``sizing_mode=
    "stretch_width"``) shares the row's free width from its ``min_width`` on, and
    moves to the next line only when even that does not fit."""
    for obj in objects:
        if getattr(obj, "sizing_mode", None) == "stretch_width":
            basis = obj.min_width or 300
            obj.styles = {**obj.styles, "flex": f"1 1 {basis}px", "width": "auto"}
    return pn.FlexBox(*objects, flex_wrap="wrap", align_items="flex-start", sizing_mode="stretch_width",
                      css_classes=["eha-side-by-side", *css_classes])


#: Tab headers that wrap onto a second line instead of running past a narrow window's edge (at 800 px
#: the frequency panel's sixth figure tab, "Residuals", sat at x = 794, out of sight).
WRAP_TAB_HEADERS = (":host .bk-header { flex-wrap: wrap; } :host .bk-header .bk-tab { white-space: nowrap; }"
                    # Bokeh 3 puts the tabs in a wrapper row of their own: it must wrap too, or the last
                    # tab runs off a narrow window (six sub-tabs of tab 3 need 811 px)
                    " :host .bk-header .bk-headers-wrapper { flex-wrap: wrap; }"
                    # where the keyboard is: Bokeh's own ring is a thin line the active tab's border hides
                    " :host .bk-header .bk-tab:focus-visible { outline: 2px solid #1a56c4; outline-offset: -3px; }")

#: A widget's label read by screen readers but not shown, where the row around it says what it is
#: (a tick and a name field beside a model's colour on the model board).
LABEL_FOR_SCREEN_READERS = (":host label, :host .bk-label { position: absolute; width: 1px; height: 1px; "
                            "overflow: hidden; clip-path: inset(50%); white-space: nowrap; }")

#: Bokeh's green, orange and red buttons with white text of at least 4.5:1 (WCAG 2.1 AA; Bokeh's
#: own are 2.5:1, 2.0:1 and 3.9:1), in the same hues. Bokeh declares the colours on each button's
#: :host, so a button takes these in its ``stylesheets``.
BUTTON_CONTRAST = """
:host {
  --success: #2e7d32; --success-border: #276b2b; --success-hover: #276b2b; --success-hover-border: #1b5e20;
  --success-active: #1b5e20; --success-active-border: #14471a;
  --warning: #a35200; --warning-border: #8f4700; --warning-hover: #8f4700; --warning-hover-border: #7a3d00;
  --warning-active: #7a3d00; --warning-active-border: #663300;
  --danger: #c62828; --danger-border: #b71c1c; --danger-hover: #b71c1c; --danger-hover-border: #a61b1b;
  --danger-active: #a61b1b; --danger-active-border: #8e1616;
}
"""
