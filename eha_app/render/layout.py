"""The tabs' one layout rule: controls beside results on a wide screen, above them on a narrow one."""

from __future__ import annotations

import panel as pn

__all__ = ["WRAP_TAB_HEADERS", "side_by_side"]


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
WRAP_TAB_HEADERS = ":host .bk-header { flex-wrap: wrap; } :host .bk-header .bk-tab { white-space: nowrap; }"
