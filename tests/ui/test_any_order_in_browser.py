"""Tab 1 after tabs 2 and 3, in Chromium: its derived values follow what is typed.

On 58ceb4b a student who had shown tab 2 could type on tab 1 for good without
any derived value changing (a change made outside the page's lock broke it).
"""

from __future__ import annotations

from tests.ui.browser_helpers import text_of, wait_until


def test_tab_1_follows_what_is_typed_after_tabs_2_and_3_were_shown(session):
    page = session.page
    session.tab("2. Simulation")
    page.wait_for_selector(".eha-sim-info", timeout=60_000)
    session.tab("3. Identification")
    page.wait_for_selector(".eha-lse-table", timeout=60_000)
    session.tab("1. Parameters")
    # a1 = B/M (Table 1): 1500/4000 = 0.375 before, 1500/7000 = 0.2143 after
    assert "0.375" in text_of(page, ".eha-derived")
    field = page.locator(".eha-field-M input").first
    field.fill("7000")
    wait_until(lambda: "0.2143" in text_of(page, ".eha-derived"), 15, message="a1 = B/M with M = 7000 kg")
    field.fill("-5")
    wait_until(lambda: "M = -5 kg is not allowed" in page.locator(".eha-error-M").first.inner_text(), 15,
               message="M's message beside the field")
    session.tab("2. Simulation")
    wait_until(lambda: page.get_by_role("button", name="Compare both").is_disabled(), 15,
               message="Compare both disabled while M is invalid")
