import pytest

from eha_app.state import AppState, display_text, parse_display
from eha_core.params import ActuatorParams, ParameterError


def test_defaults_are_the_papers():
    s = AppState()
    assert s.valid and s.errors == {}
    assert s.params == ActuatorParams()
    assert s.texts["beta_e"] == "1.1" and s.texts["Dc"] == "120" and s.texts["p1_0"] == "12"
    assert s.texts["Kq1"] == "3.043" and s.texts["p2_0"] == ""     # blank: force balance


def test_typing_updates_params_in_si_units():
    s = AppState()
    rev = s.revision
    s.set_text("Dc", "100")
    s.set_text("beta_e", "0.8")
    assert s.params.Dc == pytest.approx(0.1) and s.params.beta_e == pytest.approx(8e8)
    assert s.revision == rev + 2


@pytest.mark.parametrize("name, text, words", [
    ("M", "-5", "M = -5 is not allowed: must be > 0 kg"),
    ("M", "abc", "M = abc is not allowed: must be a number in kg"),
    ("M", "", "enter a number"),
    ("dc", "130", "smaller than the bore"),
    ("ps", "1", "pr"),
    ("p1_0", "40", "p1_0"),
    ("x0", "300", "end stops"),
    ("kp", "0", "Kp = 0 is not allowed"),
])
def test_invalid_input_names_field_and_blocks_runs(name, text, words):
    s = AppState()
    before = s.params
    s.set_text(name, text)
    assert not s.valid
    assert any(words in m for m in s.errors.values()), s.errors
    assert s.params == before                       # the last valid set is kept
    s.reset_defaults()
    assert s.valid and s.errors == {}


def test_blank_p2_0_means_force_balance():
    s = AppState()
    s.set_text("p2_0", "")
    assert s.valid and s.params.p2_0 is None
    s.set_text("p1_0", "10")
    assert s.params.p2_init == pytest.approx(s.params.A1 / s.params.A2 * 10e6)


def test_display_round_trip():
    p = ActuatorParams()
    for name in ("M", "beta_e", "Dc", "Kq1", "ps", "p1_0", "x0"):
        assert parse_display(name, display_text(name, getattr(p, name))) == pytest.approx(getattr(p, name))
    with pytest.raises(ParameterError):
        parse_display("M", "1e999")


def test_sessions_do_not_share_state():
    a, b = AppState(), AppState()
    a.set_text("M", "5000")
    a.set_text("B", "-1")
    assert b.params.M == 4000.0 and b.valid and b.errors == {}
