"""A session's settings saved as JSON and loaded into another session: the same inputs everywhere."""

import json

import pytest

from eha_app import settings
from eha_app.app import create_app
from eha_app.state import AppState


def typed(form, **texts):
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


def test_saved_settings_load_into_another_session():
    a = create_app(AppState())
    a.eha_state.set_text("M", "6000")
    a.eha_state.set_text("kp", "20")
    sim = a.eha_lazy.build(1)
    typed(sim.form, u_amplitude="3", d_kind="white noise", d_seed="7")
    ident = a.eha_lazy.build(2)
    typed(ident.lse.form, lse_scenario="5000 sin", lse_model="harmonic")
    typed(ident.frequency_panel().form, signal_type="prbs", n_samples="500")
    typed(ident.board_panel().form, board_seed="7", board_step="20")
    typed(ident.study_panel().form, study_kind="tf", study_seeds="50")
    blob = settings.to_bytes(a)
    data = json.loads(blob)
    assert data["parameters"]["M"] == "6000" and data["parameters"]["kp"] == "20"
    assert data["simulation"]["u_amplitude"] == "3" and data["frequency"]["n_samples"] == "500"

    b = create_app(AppState())
    b_sim = b.eha_lazy.build(1)                      # one tab built, the others later
    assert settings.apply(b, blob) == []
    assert b.eha_state.params.M == 6000.0 and b.eha_state.kp == 20.0
    assert b_sim.form.values["u_amplitude"] == "3" and b_sim.results[0].label.startswith("u = 3 sin")
    b_ident = b.eha_lazy.build(2)                    # built from the loaded values
    assert b_ident.lse.form.values["lse_model"] == "harmonic"
    assert b_ident.frequency_panel().form.values["signal_type"] == "prbs"
    assert b_ident.board_panel().form.values["board_step"] == "20"
    assert b_ident.study_panel().form.values["study_seeds"] == "50"
    assert json.loads(settings.to_bytes(b)) == {**data, "tab": json.loads(settings.to_bytes(b))["tab"]}


def test_a_bad_value_in_a_settings_file_gets_the_typed_message():
    page = create_app(AppState())
    notes = settings.apply(page, json.dumps({"format": settings.FORMAT, "parameters": {"M": "-5", "mass": "1"},
                                             "simulation": {"u_amplitude": "99", "colour": "red"}}))
    assert page.eha_state.errors["M"].startswith("M = -5 kg is not allowed")
    assert "parameters.mass" in notes[0] and "simulation.colour" in notes[0]
    sim = page.eha_lazy.build(1)
    assert "u amplitude = 99 is not allowed" in sim.form.errors["u_amplitude"]


@pytest.mark.parametrize("content, message", [(b"{", "it is not JSON"), (b"{}", "not a settings file")])
def test_a_file_that_is_not_settings_is_refused(content, message):
    with pytest.raises(settings.SettingsError, match=message):
        settings.apply(create_app(AppState()), content, "x.json")


def test_the_session_report_holds_what_the_student_ran(tmp_path):
    from eha_app.report import session_report

    page = create_app(AppState())
    page.eha_state.set_text("M", "6000")
    page.eha_lazy.build(1).run("both")
    ident = page.eha_lazy.build(2)
    ident.lse.run()
    ident.frequency_panel().run()
    text = session_report(page).decode()
    for part in ("report of a session", "Simulation", "Least squares", "Transfer function", "95 % interval",
                 "Backed-out parameters", "&quot;M&quot;: &quot;6000&quot;", "Bokeh"):
        assert part in text, part
    assert text.count('class="fig"') == 5                     # the grid, the fit of eqs. 15-18, Figs. 11-13
    assert "<script src=" not in text and "<link" not in text            # all inline: it opens offline
    # with the board opened: its ticked models, their fits, steps and pole-zero map
    board = ident.board_panel()
    text = session_report(page).decode()
    assert "Model board" in text and "LS1" in text and "H1" in text and "nonlinear plant" in text
    assert text.count('class="fig"') == 9
    board.tick(board.entries[0], False)
    assert "H(s) eq. 24" not in session_report(page).decode().split("Model board", 1)[1].split("Settings of")[0]


def test_the_report_button_prepares_the_download():
    page = create_app(AppState())
    page.eha_lazy.build(1)
    assert not page.eha_report_download.visible
    page.eha_report_button.clicks += 1                 # without a server the worker's job runs here
    assert page.eha_report_download.visible and "MB" in page.eha_report_download.label
    assert b"report of a session" in page.eha_report_download.file.getvalue()
