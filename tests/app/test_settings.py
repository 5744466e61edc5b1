"""A session's settings saved as JSON and loaded into another session: the same inputs everywhere.

Settings, the page's address and the session report iterate the registry of
sections: a section registered with one line is in all three (the last test).
"""

import json

import pytest

from eha_app.app import create_app
from eha_app.session import SECTIONS, SETTINGS_FORMAT, ReportPart, Section, SectionSnapshot, SettingsError
from eha_app.session.form import Field, Form, Group
from eha_app.session.state import AppState


def typed(form, **texts):
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


def test_saved_settings_load_into_another_session():
    a = create_app(AppState())
    a.session.state.set_text("M", "6000")
    a.session.state.set_text("kp", "20")
    sim = a.session.build("simulation")
    typed(sim.form, u_amplitude="3", d_kind="white noise", d_seed="7")
    ident = a.session
    typed(ident.build("least_squares").form, lse_scenario="5000 sin", lse_model="harmonic")
    typed(ident.build("frequency").form, signal_type="prbs", n_samples="500")
    ident.section("record").load({"rec_detrend": "mean", "rec_to": "7"})
    typed(ident.build("board").form, board_seed="7", board_step="20")
    typed(ident.build("study").form, study_kind="tf", study_seeds="50")
    blob = a.session.settings_bytes()
    data = json.loads(blob)
    assert data["parameters"]["M"] == "6000" and data["parameters"]["kp"] == "20"
    assert data["simulation"]["u_amplitude"] == "3" and data["frequency"]["n_samples"] == "500"

    b = create_app(AppState())
    b_sim = b.session.build("simulation")                      # one tab built, the others later
    assert b.session.load_settings(blob) == []
    assert b.session.state.params.M == 6000.0 and b.session.state.kp == 20.0
    assert b_sim.form.values["u_amplitude"] == "3"
    assert b_sim.view.status == "stale"                        # run again once tab 2 is on show
    b.show("simulation")
    assert b_sim.results[0].label.startswith("u = 3 sin") and b_sim.view.status == "current"
    b.tabs.tabs.active = 0                                     # back where a was
    b_ident = b.session                    # built from the loaded values
    assert b_ident.build("least_squares").form.values["lse_model"] == "harmonic"
    assert b_ident.build("frequency").form.values["signal_type"] == "prbs"
    assert b_ident.section("record").detrend.value == "mean"
    assert b_ident.build("board").form.values["board_step"] == "20"
    assert b_ident.build("study").form.values["study_seeds"] == "50"
    assert json.loads(b.session.settings_bytes()) == data


def test_a_bad_value_in_a_settings_file_gets_the_typed_message():
    page = create_app(AppState())
    notes = page.session.load_settings(json.dumps({"format": SETTINGS_FORMAT, "parameters": {"M": "-5", "mass": "1"},
                                             "simulation": {"u_amplitude": "99", "colour": "red"}}))
    assert page.session.state.errors["M"].startswith("M = -5 kg is not allowed")
    assert "parameters.mass" in notes[0] and "simulation.colour" in notes[0]
    sim = page.session.build("simulation")
    assert "u amplitude = 99 is not allowed" in sim.form.errors["u_amplitude"]


def test_a_text_too_long_for_its_field_is_left_out_of_the_settings_so_the_rest_still_loads():
    # typed into a field it is refused there; saved, it made the whole file (and a student's kept work,
    # saved the same way) unloadable
    a = create_app(AppState())
    sim = a.session.build("simulation")
    typed(sim.form, u_amplitude="9" * 201, d_seed="7")
    assert sim.form.errors["u_amplitude"]
    blob = a.session.settings_bytes()
    assert "u_amplitude" not in json.loads(blob)["simulation"]
    b = create_app(AppState())
    b.session.load_settings(blob)
    assert b.session.build("simulation").form.values["d_seed"] == "7"


@pytest.mark.parametrize("content, message", [(b"{", "it is not JSON"), (b"{}", "not a settings file")])
def test_a_file_that_is_not_settings_is_refused(content, message):
    with pytest.raises(SettingsError, match=message):
        create_app(AppState()).session.load_settings(content, "x.json")


def test_the_session_report_holds_what_the_student_ran(tmp_path):
    from eha_app.render.report import session_report

    page = create_app(AppState())
    page.session.state.set_text("M", "6000")
    page.session.build("simulation").run("both")
    ident = page.session
    ident.build("least_squares").run()
    ident.build("frequency").run()
    text = session_report(page.session, page.session.snapshot()).decode()
    for part in ("report of a session", "Simulation", "Least squares", "Transfer function", "95 % interval",
                 "Backed-out parameters", "&quot;M&quot;: &quot;6000&quot;", "Bokeh"):
        assert part in text, part
    assert text.count('class="fig"') == 5                     # the grid, the fit of eqs. 15-18, Figs. 11-13
    assert "<script src=" not in text and "<link" not in text            # all inline: it opens offline
    # with the board opened: its ticked models, their fits, steps and pole-zero map
    board = ident.build("board")
    text = session_report(page.session, page.session.snapshot()).decode()
    assert "Model board" in text and "LS1" in text and "H1" in text and "nonlinear plant" in text
    assert text.count('class="fig"') == 9
    board.tick(board.entries[0], False)
    text = session_report(page.session, page.session.snapshot()).decode()
    assert "H(s) eq. 24" not in text.split("Model board", 1)[1].split("Settings of")[0]


def test_the_report_button_prepares_the_download():
    page = create_app(AppState())
    page.session.build("simulation")
    assert not page.report_download.visible
    page.report_button.clicks += 1                 # without a server the worker's job runs here
    assert page.report_download.visible and "MB" in page.report_download.label
    assert b"report of a session" in page.report_download.file.getvalue()


def test_the_report_holds_the_study_and_the_own_record_from_a_snapshot():
    from eha_app.render.report import session_report

    page = create_app(AppState())
    session = page.session
    freq = session.build("frequency")
    freq.run()
    record = session.section("record")
    record.upload.filename, record.upload.value = "loop.csv", freq.data_bytes("csv")
    record.run()
    study = session.build("study")
    typed(study.form, study_seeds="4")
    study.run()
    snapshot = session.snapshot()
    # the snapshot is what the worker reads: a later run on the page does not change it
    study.form.values = {**study.form.values, "study_seeds": "6"}
    study.run()
    text = session_report(session, snapshot).decode()
    assert "Study over seeds" in text and "4 of 4 seeds" in text and "6 of 6 seeds" not in text
    assert "Transfer function from your own record" in text and "loop.csv" in text
    assert snapshot.section("study").settings["study_seeds"] == "4"


class DummySection(Section):
    """A panel of the fewest lines: one field, its value in the report."""

    key = "dummy"
    title = "A dummy panel"
    defaults = {"dummy_x": "1"}

    def __init__(self, session, **params):
        super().__init__(session, **params)
        self.form = Form(spec=[Group("Dummy", (Field("dummy_x", "x", "integer"),)).to_spec()],
                         values=self.initial_texts(), url_defaults=self.defaults)

    def snapshot(self) -> SectionSnapshot:
        return SectionSnapshot(self.key, self.title, self.settings(), content=self.form.values["dummy_x"])

    @classmethod
    def report(cls, snapshot, hidden=()):
        return ReportPart("A dummy panel", f"<p>x is {snapshot.content}</p>")

    def __panel__(self):
        return self.form


def test_a_section_registered_with_one_line_is_in_the_page_settings_address_and_report():
    from eha_app.render.report import session_report

    with SECTIONS.added(DummySection, tab="3. Identification", subtab="Dummy"):
        page = create_app(query={"dummy_x": "5"})                    # the page's address
        assert page.session.section("dummy") is None
        data = json.loads(page.session.settings_bytes())               # saved before it was ever shown
        assert data["dummy"] == {"dummy_x": "5"}
        other = create_app()
        other.session.load_settings(json.dumps({**data, "dummy": {"dummy_x": "7"}}))
        dummy = other.show("dummy")                                  # a sub-tab of tab 3 of its own
        assert other.tabs.active_name == "3. Identification" and dummy.form.values["dummy_x"] == "7"
        assert "Dummy" in other.tabs.built["3. Identification"].lazy.names
        text = session_report(other.session, other.session.snapshot()).decode()
        assert "A dummy panel" in text and "x is 7" in text
        assert json.loads(other.session.settings_bytes())["dummy"] == {"dummy_x": "7"}
    assert "dummy" not in SECTIONS and "dummy" not in create_app().session.settings()


def test_the_report_names_the_student_and_every_parameter_with_its_symbol_unit_and_source():
    """A name field; β_e with its unit, not "beta_e 1.1"; p2(0) filled (it was blank); the paper's value
    and where it comes from; the study and the student's own record in it too."""
    page = create_app(AppState())
    session = page.session
    page.report_name.value = "  Ada   Lovelace "
    study = session.build("study")
    study.form.values = {**study.form.values, "study_seeds": "4"}
    study.run()
    freq = session.build("frequency")
    source = create_app(AppState()).session.build("frequency")
    source.run()
    freq.record.upload.filename = "loop.csv"
    freq.record.upload.value = source.data_bytes("csv")
    freq.record.run()
    page.report_button.clicks += 1
    assert page.report_button.label == "Report of this session" and not page.report_button.disabled
    assert "The report is ready" in page.settings_note.object
    text = page.report_download.file.getvalue().decode()
    assert "Student: <b>Ada Lovelace</b>" in text
    params = text.split("Parameters (tab 1)", 1)[1].split("</table>", 1)[0]
    assert "β<sub>e</sub>" in params and "1.1 GPa" in params and "1.1·10<sup>9</sup> Pa" in params
    assert "beta_e" not in params
    p2 = params.split("p<sub>2</sub>(0)", 1)[1].split("</tr>", 1)[0]
    assert "(blank)" in p2 and "1.8189·10<sup>7</sup> Pa (force balance)" in p2 and "section II-A" in p2
    assert "inferred from eq. 23" in params and "Table 3" in params
    assert "Study over seeds" in text and "Transfer function from your own record" in text
