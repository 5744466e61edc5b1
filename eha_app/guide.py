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

from .render.layout import BUTTON_CONTRAST
from .runtime.tasks import on_click
from .session import SECTIONS, SectionRegistry

__all__ = ["Guide", "Step", "guide_steps"]


@dataclass(frozen=True)
class Step:
    """One stop on the way: a section's key, its short name, what is done there, the label of the
    button that leads to it, what to do there (naming the button) and the main tab it is on."""

    key: str
    short: str
    what: str
    go: str
    press: str = ""
    tab: str = ""
    runs: bool = True


def guide_steps(registry: SectionRegistry = SECTIONS) -> tuple[Step, ...]:
    """The stops, in page order (the paper's): every section of the page's tabs with a guide step
    (:attr:`~eha_app.session.section.Section.guide_step`); tab 3's sub-tabs are stops of their own."""
    return tuple(Step(p.key, p.cls.guide_step.short, p.cls.guide_step.what, p.cls.guide_step.go,
                      p.cls.guide_step.press, p.tab or "", p.cls.guide_step.runs)
                 for p in registry if p.within is None and p.cls.guide_step is not None)


#: What the last stop says, after the steps (``{hand_in}``: the lab's hand-in, or nothing).
FINISH = ("<b>Last stop.</b> When you are done: {hand_in}download the report of your session "
          "(<b>Report of this session</b>, above, or the button here): every result, with its settings.")
HAND_IN = "hand in your estimates (the <b>Hand in</b> box under each route's result), then "


class Guide:
    """The start card and the guide line; ``go(key)`` shows a section (the page's ``show``), one of
    ``steps`` (:func:`guide_steps`).

    ``done(key)``: is that step's result on the page (None: its section is not made yet)? "Next" is
    offered once it is; until then the line names the button to press. ``finish``: what the last stop's
    button does (the session's report); ``lab``: the page is an exercise's (the last stop says hand in).
    """

    def __init__(self, go: Callable[[str], object], *, steps: tuple[Step, ...], start: bool = True,
                 done: Callable[[str], bool | None] | None = None, finish: Callable[[], object] | None = None,
                 lab: bool = False):
        self._go = go
        self._done = done
        self.lab = lab
        self.steps = tuple(steps)
        self.current = self.steps[0].key if self.steps else ""
        self.start = pn.Column(
            pn.Row(pn.pane.HTML("<b>Three steps</b>, as in the paper's app (its Fig. 14): parameters, simulation, "
                                "identification, the last in five ways. Start with step 1; the line above the "
                                "tabs always says where you are, which button to press and what comes next.",
                                sizing_mode="stretch_width"), self._hide_button(), sizing_mode="stretch_width"),
            pn.FlexBox(*self._cards(), sizing_mode="stretch_width"),
            visible=start, sizing_mode="stretch_width", css_classes=["eha-start"],
            styles={"background": "#f3f6fb", "border": "1px solid #d5deeb", "border-radius": "6px",
                    "padding": "4px 8px"})
        self.where = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-guide-where"],
                                  styles={"font-size": "13px", "color": "#333"})
        self.next = pn.widgets.Button(label="", width=300, color="primary",
                                      css_classes=["eha-guide-next"])
        on_click(self.next, lambda _e: self.go_next())
        self.finish = pn.widgets.Button(label="Report of this session", width=200, color="success", visible=False,
                                        css_classes=["eha-guide-finish"], stylesheets=[BUTTON_CONTRAST])
        if finish is not None:
            on_click(self.finish, lambda _e: finish())
        self._can_finish = finish is not None
        # wraps at 800 px (the button goes under the text) rather than widening the page
        self.where.styles = {**self.where.styles, "flex": "1 1 380px"}
        self.line = pn.FlexBox(self.where, self.next, self.finish, flex_wrap="wrap", align_items="center",
                               sizing_mode="stretch_width", css_classes=["eha-guide"], margin=(0, 0, 4, 0))
        self.show_step(self.current)

    def _hide_button(self):
        hide = pn.widgets.Button(label="Hide", width=70, css_classes=["eha-start-hide"])
        on_click(hide, lambda _e: self.hide_start())
        return hide

    def _cards(self) -> list:
        """One card per main tab, in order: its steps' buttons (tab 3's five ways each a button of its own),
        so that every stop shows on the card."""
        tabs: list[tuple[str, list[Step]]] = []
        for s in self.steps:
            if tabs and tabs[-1][0] == s.tab:
                tabs[-1][1].append(s)
            else:
                tabs.append((s.tab, [s]))
        cards = []
        for i, (tab, steps) in enumerate(tabs):
            if len(steps) == 1:
                s = steps[0]
                text = f"<b>{html.escape(s.short)}</b><br>{s.what}"
                buttons = [self._go_button("Start here" if i == 0 else f"Go to {s.short}", s.key, primary=i == 0)]
            else:
                ways = ", ".join(html.escape(s.short.split(". ", 1)[-1]) for s in steps)
                text = f"<b>{html.escape(tab or steps[0].short)}</b><br>Its sub-tabs, in order: {ways}."
                buttons = [self._go_button(s.short.split(". ", 1)[-1], s.key, width=135) for s in steps]
            cards.append(pn.Column(pn.pane.HTML(f"<div class='eha-start-step'>{text}</div>",
                                                sizing_mode="stretch_width"),
                                   *(buttons if len(buttons) == 1 else [pn.FlexBox(*buttons)]),
                                   width=300 if len(steps) == 1 else 460, css_classes=["eha-start-card"]))
        return cards

    def _go_button(self, label: str, key: str, *, primary: bool = False, width: int = 170):
        button = pn.widgets.Button(label=label, width=width, color="primary" if primary else "default",
                                   css_classes=[f"eha-start-{key}"])
        on_click(button, lambda _e: self.go(key))
        return button

    def go(self, key: str) -> None:
        """Show section ``key`` (its tab and sub-tab) and say so; the start card has done its job."""
        self.hide_start()
        self._go(key)
        self.show_step(key)

    def go_next(self) -> None:
        following = self.following(self.current)
        # a click sent before "Next" was taken back (the student changed tab meanwhile) goes nowhere
        if following is not None and not self.next.disabled:
            self.go(following.key)

    def following(self, key: str) -> Step | None:
        keys = [s.key for s in self.steps]
        if key not in keys or keys.index(key) + 1 >= len(keys):
            return None
        return self.steps[keys.index(key) + 1]

    def hide_start(self) -> None:
        if self.start.visible:
            self.start.visible = False

    def is_done(self, key: str) -> bool:
        """Is step ``key``'s result on the page? (Without a ``done`` function: always.)"""
        return True if self._done is None else bool(self._done(key))

    def refresh(self) -> None:
        """Say the current step again (its result may have arrived: "Next" is offered then)."""
        self.show_step(self.current)

    def show_step(self, key: str) -> None:
        """The guide line for the section shown now (``key``), from whichever way the student came."""
        step = next((s for s in self.steps if s.key == key), None)
        if step is None:
            return
        self.current = key
        trail = " › ".join(f"<b>{html.escape(s.short)}</b>" if s.key == key else html.escape(s.short)
                           for s in self.steps)
        following = self.following(key)
        done = self.is_done(key)
        if following is None:
            finish = FINISH.format(hand_in=HAND_IN if self.lab else "")
            do = finish if done or not step.press else f"{step.press} {finish}"
        elif not step.runs:
            do = step.press
        elif done:
            do = f"Done: its result is on the page. Next: {html.escape(following.go)}, or try other settings here."
        else:
            do = f"{step.press} “Next” follows once the result is on the page."
        text = (f"<div class='eha-guide-trail' style='color:#555'>{trail}</div>"
                f"<div class='eha-guide-what'>{step.what} <span class='eha-guide-do'>{do}</span></div>")
        if self.where.object != text:
            self.where.object = text
        if following is None:
            self.next.visible = False
        else:
            label = f"Next: {following.go} →"
            if self.next.label != label:
                self.next.label = label
            self.next.disabled = not done
            self.next.visible = True
        self.finish.visible = following is None and self._can_finish
