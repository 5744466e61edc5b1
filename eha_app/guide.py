"""The way through the three steps: a start card like the paper's opening window (Fig. 14) and a
one-line guide above the tabs that says where the student is and what comes next.

The paper's app opens on three steps: fill in the physical parameters, simulate the nonlinear and
linear models, identify (section IV). A first-time student here should reach the frequency
identification without reading the README: the start card names the steps and where to start, and
the guide's "Next" button goes to the following step (or sub-step of tab 3) from wherever the
student is, whichever order they took.
"""

from __future__ import annotations

import html
from collections.abc import Callable
from dataclasses import dataclass

import panel as pn

from .runtime.tasks import on_click
from .session import SECTIONS, SectionRegistry

__all__ = ["Guide", "Step", "guide_steps"]


@dataclass(frozen=True)
class Step:
    """One stop on the way: a section's key, its short name, what is done there, and the label of the
    button that leads to it."""

    key: str
    short: str
    what: str
    go: str


def guide_steps(registry: SectionRegistry = SECTIONS) -> tuple[Step, ...]:
    """The stops, in page order (the paper's): every section of the page's tabs with a guide step
    (:attr:`~eha_app.session.section.Section.guide_step`); tab 3's sub-tabs are stops of their own."""
    return tuple(Step(p.key, p.cls.guide_step.short, p.cls.guide_step.what, p.cls.guide_step.go)
                 for p in registry if p.within is None and p.cls.guide_step is not None)


class Guide:
    """The start card and the guide line; ``go(key)`` shows a section (the page's ``show``), one of
    ``steps`` (:func:`guide_steps`)."""

    def __init__(self, go: Callable[[str], object], *, steps: tuple[Step, ...], start: bool = True):
        self._go = go
        self.steps = tuple(steps)
        self.current = self.steps[0].key if self.steps else ""
        # the start card: what the steps are and where to start
        cards = []
        for i, s in enumerate(self.steps[:4]):
            button = pn.widgets.Button(label="Start here" if i == 0 else f"Go to {s.short}", width=170,
                                       color="primary" if i == 0 else "default",
                                       css_classes=[f"eha-start-{s.key}"])
            on_click(button, lambda _e, key=s.key: self.go(key))
            cards.append(pn.Column(pn.pane.HTML(f"<div class='eha-start-step'><b>{html.escape(s.short)}</b><br>"
                                                f"{s.what}</div>", sizing_mode="stretch_width"),
                                   button, width=300, css_classes=["eha-start-card"]))
        hide = pn.widgets.Button(label="Hide", width=70, css_classes=["eha-start-hide"])
        on_click(hide, lambda _e: self.hide_start())
        self.start = pn.Column(
            pn.Row(pn.pane.HTML("<b>Three steps</b>, as in the paper's app (its Fig. 14): parameters, simulation, "
                                "identification. Start with step 1; the line above the tabs always says "
                                "where you are and what comes next.", sizing_mode="stretch_width"), hide,
                   sizing_mode="stretch_width"),
            pn.FlexBox(*cards, sizing_mode="stretch_width"),
            visible=start, sizing_mode="stretch_width", css_classes=["eha-start"],
            styles={"background": "#f3f6fb", "border": "1px solid #d5deeb", "border-radius": "6px",
                    "padding": "4px 8px"})
        self.where = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-guide-where"],
                                  styles={"font-size": "13px", "color": "#333"})
        self.next = pn.widgets.Button(label="", width=300, color="primary",
                                      css_classes=["eha-guide-next"])
        on_click(self.next, lambda _e: self.go_next())
        # wraps at 800 px (the button goes under the text) rather than widening the page
        self.where.styles = {**self.where.styles, "flex": "1 1 380px"}
        self.line = pn.FlexBox(self.where, self.next, flex_wrap="wrap", align_items="center",
                               sizing_mode="stretch_width", css_classes=["eha-guide"], margin=(0, 0, 4, 0))
        self.show_step(self.current)

    def go(self, key: str) -> None:
        """Show section ``key`` (its tab and sub-tab) and say so; the start card has done its job."""
        self.hide_start()
        self._go(key)
        self.show_step(key)

    def go_next(self) -> None:
        following = self.following(self.current)
        if following is not None:
            self.go(following.key)

    def following(self, key: str) -> Step | None:
        keys = [s.key for s in self.steps]
        if key not in keys or keys.index(key) + 1 >= len(keys):
            return None
        return self.steps[keys.index(key) + 1]

    def hide_start(self) -> None:
        if self.start.visible:
            self.start.visible = False

    def show_step(self, key: str) -> None:
        """The guide line for the section shown now (``key``), from whichever way the student came."""
        step = next((s for s in self.steps if s.key == key), None)
        if step is None:
            return
        self.current = key
        trail = " › ".join(f"<b>{html.escape(s.short)}</b>" if s.key == key else html.escape(s.short)
                           for s in self.steps)
        self.where.object = (f"<div class='eha-guide-trail' style='color:#666'>{trail}</div>"
                             f"<div class='eha-guide-what'>{step.what}</div>")
        following = self.following(key)
        if following is None:
            self.next.visible = False
        else:
            self.next.label = f"Next: {following.go} →"
            self.next.visible = True
