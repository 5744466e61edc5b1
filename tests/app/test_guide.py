"""The way through the three steps: a first-time student reaches the frequency identification by the
start card and the guide's "Next" alone, and the guide follows whichever way the student came."""

from __future__ import annotations

from eha_app.app import create_app
from eha_app.session.state import AppState


def _press(button):
    button.clicks += 1


def test_start_card_then_next_reaches_the_frequency_identification():
    page = create_app(AppState())
    guide = page.guide
    assert guide.start.visible and "Three steps" in guide.start.objects[0].objects[0].object
    start = next(b for b in guide.start.select(lambda m: hasattr(m, "clicks")) if b.label == "Start here")
    _press(start)
    assert not guide.start.visible and page.tabs.active_name == "1. Parameters"
    assert guide.next.label == "Next: 2. Simulation →" and "Step 1" in guide.where.object
    seen = []
    while guide.current != "frequency":
        _press(guide.next)
        seen.append((page.tabs.active_name, guide.current))
        assert len(seen) < 5
    assert seen == [("2. Simulation", "simulation"), ("3. Identification", "least_squares"),
                    ("3. Identification", "frequency")]
    sub = page.tabs.built["3. Identification"]
    assert sub.lazy.active_name == "Frequency domain: transfer function"
    assert "Step 3, frequency domain" in guide.where.object
    assert guide.next.label == "Next: 3. Identification: grey-box →"


def test_the_guide_follows_any_order():
    page = create_app(AppState())
    guide = page.guide
    page.show("study")
    assert guide.current == "study" and not guide.next.visible and not guide.start.visible
    page.tabs.tabs.active = 0
    assert guide.current == "parameters" and guide.next.visible
    page.tabs.tabs.active = 2                     # tab 3 opens on the sub-tab it was left at
    assert guide.current == "study"
    sub = page.tabs.built["3. Identification"]
    sub.lazy.tabs.active = 2
    assert guide.current == "greybox" and guide.next.label == "Next: the model board →"
    sub.lazy.tabs.active = 3
    assert guide.current == "board" and guide.next.label == "Next: the study over seeds →"
    assert [s.key for s in guide.steps] == ["parameters", "simulation", "least_squares", "frequency", "greybox",
                                            "board", "study"]          # the own record is within a step


def test_an_address_with_a_tab_opens_without_the_start_card():
    page = create_app(AppState(), query={"tab": "2"})
    assert not page.guide.start.visible and page.guide.current == "simulation"
