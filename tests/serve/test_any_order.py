"""Tab 1 after tabs 2 and 3: what every earlier test missed by always typing on tab 1 first.

On 58ceb4b, once a student had shown tab 2, typing on tab 1 changed none of
its derived values for good: Panel handles a form's keystrokes without the
page's lock, and tab 2's watcher then changed a Bokeh model there
(``RuntimeError: _pending_writes should be non-None``). Every watcher of a
widget now runs under the lock (``eha_app.runtime.tasks.locked``), and the servers of
the suite run in strict mode, where any change made outside it raises.
"""

from __future__ import annotations

import asyncio

from benchmarks.classroom_client import Student


def test_typing_on_tab_1_after_every_tab_was_shown_updates_its_derived_values(serve):
    server = serve("--workers", "1")

    async def scenario():
        s = Student(server.url, name="any-order", timeout=60)
        await s.open()
        await s.show_simulation()
        await s.show_identification()
        await s.show_frequency()
        await s.show_subtab(s.IDENT_TABS, s.GB_SUBTAB, "eha-gb-form")
        await s.show_subtab(s.IDENT_TABS, s.BB_SUBTAB, "eha-bb-form")
        await s.show_subtab(s.IDENT_TABS, s.BOARD_SUBTAB, "eha-board-form")
        await s.show_subtab(s.IDENT_TABS, s.STUDY_SUBTAB, "eha-study-form")
        await s.show_tab(0, s.FORM)
        seconds = []
        for name, text in (("M", "7000"), ("Dc", "125"), ("kp", "12"), ("M", "4000")):
            seconds.append(await s.change_parameter(name, text, timeout=20))
        derived = s.pane("eha-derived").text()
        # an invalid value gets its message beside the field and disables the runs
        form = s.form(s.FORM)
        await s.set_property(form, "values", {**form.get("values"), "M": "-5"})
        await s.wait_for(lambda: "M = -5 kg is not allowed" in str(s.form(s.FORM).get("errors")), 20,
                         "M's message")
        await s.wait_for(lambda: s.button("Compare both").get("disabled") is True, 20, "Compare both disabled")
        await s.close()
        return seconds, derived

    seconds, derived = asyncio.run(scenario())
    assert all(t < 20 for t in seconds)
    # exactly what tab 1 shows for these fields (the app's own rendering of its own state)
    from eha_app.render.tables import derived_html
    from eha_app.session.state import AppState

    state = AppState()
    for name, text in (("M", "7000"), ("Dc", "125"), ("kp", "12"), ("M", "4000")):
        state.set_text(name, text)
    assert derived == derived_html(state.params, state.kp, stale=False)
    log = server.log_text()
    assert "RuntimeError" not in log and "UnlockedChange" not in log and " ERROR" not in log, log[-3000:]
