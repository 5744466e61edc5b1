import random
import re

import pytest

from eha_app.session import Session
from eha_app.session.state import FIELD_LABELS, AppState, cross_field_errors, display_text, parse_display
from eha_core.linear import operating_point
from eha_core.params import FIELD_INFO, PARAM_NAMES, ActuatorParams, ParameterError


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


@pytest.mark.parametrize("name, text, message", [
    ("M", "-5", "M = -5 kg is not allowed: must be > 0 kg (load mass)"),
    ("M", "abc", "M = abc is not allowed: must be a number in kg"),
    ("M", "", "M = (empty) is not allowed: enter a number in kg"),
    ("B", "-1", "B = -1 N s/m is not allowed: must be >= 0 N s/m (viscous friction coefficient)"),
    ("beta_e", "0", "βe = 0 GPa is not allowed: must be > 0 GPa (effective bulk modulus of the oil)"),
    ("Dc", "-120", "Dc = -120 mm is not allowed: must be > 0 mm (cylinder bore diameter)"),
    ("Kq1", "-3", "Kq1 = -3 × 1e-8 m³/(s V √Pa) is not allowed: must be > 0 (valve flow gain, piston side)"),
    ("ps", "0", "ps = 0 MPa is not allowed: must be > 0 MPa (supply pressure)"),
    ("pr", "-0.1", "pr = -0.1 MPa is not allowed: must be >= 0 MPa (return (tank) pressure)"),
    ("x0", "x", "x(0) = x is not allowed: must be a number in mm"),
    ("v0", "1e999", "v(0) = 1e999 is not allowed: must be a finite number in mm/s"),
    ("p1_0", "", "p1(0) = (empty) is not allowed: enter a number in MPa"),
    ("kp", "0", "Kp = 0 V/m is not allowed: must be > 0 V/m (proportional gain)"),
    ("kp", "abc", "Kp = abc is not allowed: must be a number in V/m"),         # the words of every field
    ("kp", " ", "Kp = (empty) is not allowed: enter a number in V/m"),
])
def test_a_field_on_its_own_is_refused_in_its_display_unit(name, text, message):
    s = AppState()
    before = s.params
    s.set_text(name, text)
    assert not s.valid
    assert s.errors == {name: message}
    assert s.params == before                       # the last valid set is kept
    s.reset_defaults()
    assert s.valid and s.errors == {}


# Every rule that ties fields together (ActuatorParams.__post_init__ and the
# linearisation's operating point), typed from each of its fields: the message
# goes on the typed field and names the others with their values as typed.
# (first typed, then the field, its text, words the message holds)
CROSS_FIELD = [
    # dc < Dc
    ((), "dc", "130", ["the rod diameter must be smaller than the bore Dc = 120 mm"]),
    ((), "dc", "120", ["Dc = 120 mm"]),
    ((), "Dc", "60", ["the bore must be larger than the rod diameter dc = 70 mm"]),
    # pr < ps
    ((), "pr", "40", ["the return pressure must be below the supply pressure ps = 32 MPa"]),
    ((("pr", "5"),), "ps", "4", ["the supply pressure must be above the return pressure pr = 5 MPa"]),
    # |x0| <= 0.8 L0
    ((), "x0", "300", ["end stops ±0.8 L0 = ±240 mm (L0 = 300 mm)"]),
    ((), "x0", "-250", ["end stops ±0.8 L0 = ±240 mm (L0 = 300 mm)"]),
    ((("x0", "20"),), "L0", "10", ["the end stops ±0.8 L0 = ±8 mm must hold the initial position x(0) = 20 mm"]),
    # pr <= p1_0 <= ps
    ((), "p1_0", "40", ["the initial piston-chamber pressure must lie within [pr, ps] = [0, 32] MPa"]),
    ((("pr", "5"),), "p1_0", "3", ["[pr, ps] = [5, 32] MPa"]),
    ((), "ps", "10", ["the supply pressure must be at least the initial piston-chamber pressure p1(0) = 12 MPa"]),
    ((), "pr", "15", ["the return pressure must be at most the initial piston-chamber pressure p1(0) = 12 MPa"]),
    # pr <= p2_0 <= ps, p2_0 typed
    ((), "p2_0", "40", ["the initial rod-chamber pressure must lie within [pr, ps] = [0, 32] MPa"]),
    ((), "p2_0", "-1", ["[pr, ps] = [0, 32] MPa"]),
    ((("p2_0", "25"),), "ps", "20", ["the supply pressure must be at least the initial rod-chamber pressure "
                                     "p2(0) = 25 MPa"]),
    ((("p1_0", "20"), ("p2_0", "15")), "pr", "17", ["the return pressure must be at most the initial rod-chamber "
                                                    "pressure p2(0) = 15 MPa"]),
    # pr <= (A1 p1_0 - d0)/A2 <= ps, p2_0 blank (force balance)
    ((), "p1_0", "25", ["force balance", "p2(0) = (A1 p1(0) − d0)/A2 = 37.89 MPa", "above the supply pressure "
                                                                               "ps = 32 MPa"]),
    ((), "d0", "200000", ["p2(0) = (A1 p1(0) − d0)/A2 = -8.616 MPa", "below the return pressure pr = 0 MPa"]),
    ((), "dc", "100", ["p2(0) = (A1 p1(0) − d0)/A2 = 39.27 MPa", "ps = 32 MPa"]),
    ((), "Dc", "75", ["(A1 p1(0) − d0)/A2 = 93.1 MPa", "ps = 32 MPa"]),
    ((), "ps", "15", ["at least the initial rod-chamber pressure p2(0) = (A1 p1(0) − d0)/A2 = 18.19 MPa"]),
    ((("d0", "100000"),), "pr", "6", ["at most the initial rod-chamber pressure p2(0) = (A1 p1(0) − d0)/A2 "
                                      "= 4.787 MPa"]),
    # the same force balance as the linearised model's operating point, p2_0 typed
    ((("p2_0", "15"),), "p1_0", "30", ["operating point", "(A1 p1(0) − d0)/A2 = 45.47 MPa", "ps = 32 MPa"]),
    ((("p2_0", "15"),), "d0", "-300000", ["operating point", "58.4 MPa", "ps = 32 MPa"]),
    ((("p2_0", "15"),), "ps", "17", ["operating point", "(A1 p1(0) − d0)/A2 = 18.19 MPa"]),
]

# SI renderings of a display-unit field: an exponent, or a number in m or Pa
_SI = re.compile(r"\d(\.\d+)?e[+-]?\d|\d (m|Pa)\b")
_PYTHON_NAMES = re.compile(r"\b(p1_0|p2_0|x0|v0|k_f|beta_e|x_e|p1_e|p2_e)\b")


def _case_id(case):
    first, name, text, _ = case
    return " ".join(f"{n}={t}" for n, t in first) + f" {name}={text}"


@pytest.mark.parametrize("first, name, text, words", CROSS_FIELD, ids=[_case_id(c) for c in CROSS_FIELD])
def test_a_cross_field_rule_speaks_on_the_typed_field_in_display_units(first, name, text, words):
    s = AppState()
    for n, t in first:
        s.set_text(n, t)
        assert s.valid, s.errors                    # the setting up is allowed
    before = s.params
    s.set_text(name, text)
    assert not s.valid and s.params == before
    assert list(s.errors) == [name], s.errors       # on the field typed, and only there
    message = s.errors[name]
    assert message.startswith(f"{FIELD_LABELS[name]} = {text} {FIELD_INFO[name].display_unit} is not allowed: ")
    for w in words:
        assert w in message, message
    assert not _SI.search(message), message
    assert not _PYTHON_NAMES.search(message), message
    # the core refuses the same set (the app's rules are the core's, in display units)
    values = {n: parse_display(n, t) for n, t in s.texts.items() if n in PARAM_NAMES}     # Kp is not the actuator's
    with pytest.raises(ParameterError):
        operating_point(ActuatorParams(**values))


def test_the_issues_example_word_for_word():
    s = AppState()
    s.set_text("ps", "10")
    assert s.errors == {"ps": "ps = 10 MPa is not allowed: the supply pressure must be at least the initial "
                              "piston-chamber pressure p1(0) = 12 MPa"}
    s.set_text("dc", "130")
    assert s.errors["dc"] == "dc = 130 mm is not allowed: the rod diameter must be smaller than the bore Dc = 120 mm"


def test_a_message_stays_on_its_field_while_others_are_typed():
    s = AppState()
    s.set_text("ps", "10")
    s.set_text("M", "5000")                          # not part of the broken rule
    assert list(s.errors) == ["ps"]
    s.set_text("p1_0", "8")                          # part of it, and still broken: the message follows
    assert list(s.errors) == ["p1_0"] and "ps = 10 MPa" in s.errors["p1_0"]
    s.set_text("p1_0", "6")                          # the force balance 9.1 MPa fits below 10 MPa
    assert s.valid and s.params.ps == 10e6


def test_without_a_typed_field_a_rule_speaks_on_its_own_field():
    values = {n: getattr(ActuatorParams(), n) for n in PARAM_NAMES}
    texts = {n: display_text(n, values[n]) for n in PARAM_NAMES}
    values["ps"], texts["ps"] = 10e6, "10"
    errors = cross_field_errors(values, texts)
    assert list(errors) == ["p1_0"]
    assert errors["p1_0"].startswith("p1(0) = 12 MPa is not allowed: the initial piston-chamber pressure must "
                                     "lie within [pr, ps] = [0, 10] MPa")
    assert list(cross_field_errors(values, texts, typed=["M", "ps"])) == ["ps"]


def test_several_fields_in_error_each_keep_their_message():
    s = AppState()
    s.set_text("M", "-1")
    s.set_text("Dc", "abc")
    s.set_text("kp", "0")
    assert set(s.errors) == {"M", "Dc", "kp"}
    s.set_text("M", "4000")
    s.set_text("Dc", "120")
    s.set_text("kp", "10")
    assert s.valid


def test_the_app_and_the_core_agree_on_what_is_allowed():
    """Random sets near the rules' edges: the app refuses exactly what the core (and the linearisation) refuse,
    always with its own message, in display units."""
    rng = random.Random(7)
    choices = {"Dc": ["120", "70", "75", "60", "100"], "dc": ["70", "100", "119", "120", "130"],
               "L0": ["300", "10", "25"], "x0": ["0", "20", "-20", "240", "241"], "ps": ["32", "10", "15", "5"],
               "pr": ["0", "5", "12", "15", "32"], "p1_0": ["12", "0", "25", "30", "3"],
               "p2_0": ["", "15", "25", "40", "-1", "0"], "d0": ["0", "200000", "-300000", "100000"]}
    for _ in range(600):
        s = AppState()
        for name in rng.sample(sorted(choices), 4):
            s.set_text(name, rng.choice(choices[name]))
        values = {n: parse_display(n, t) for n, t in s.texts.items() if n in PARAM_NAMES}
        try:
            operating_point(ActuatorParams(**values))
            core_ok = True
        except ParameterError:
            core_ok = False
        assert s.valid == core_ok, (s.texts, s.errors)
        for message in s.errors.values():
            assert not _SI.search(message) and not _PYTHON_NAMES.search(message), message


def test_the_first_tab_never_draws_a_set_the_linearisation_refuses():
    # p2(0) typed keeps the initial state valid, but the operating point's force balance is out of [pr, ps]

    s = AppState()
    tab = Session(s).build("parameters")
    s.set_text("p2_0", "15")
    s.set_text("p1_0", "30")                         # raised in the tab's watcher before
    assert not s.valid and list(s.errors) == ["p1_0"]
    assert "Fix the highlighted input" in tab.status.object


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


def test_the_form_and_its_messages_use_the_same_names():
    from eha_app.sections.parameters import PARAMETER_FORM

    labels = {f.name: f.label for g in PARAMETER_FORM for f in g.fields}
    assert labels == FIELD_LABELS


def test_sessions_do_not_share_state():
    a, b = AppState(), AppState()
    a.set_text("M", "5000")
    a.set_text("B", "-1")
    assert b.params.M == 4000.0 and b.valid and b.errors == {}


def test_a_bore_whose_area_overflows_is_refused_beside_it():
    """Found by the long random walk: Dc = 1e200 raised OverflowError in the page's callback (Dc ** 2), so
    tab 1 stopped following what was typed. Now the field says why, and the core refuses it too."""
    s = AppState()
    s.set_text("Dc", "1e200")
    assert not s.valid and list(s.errors) == ["Dc"]
    assert s.errors["Dc"] == ("Dc = 1e200 mm is not allowed: the bore is too large: its area π Dc²/4 is not a "
                              "finite number")
    s.set_text("Dc", "100")
    assert s.valid
    with pytest.raises(ParameterError, match="its area pi Dc"):
        ActuatorParams(Dc=1e200)


def test_derived_values_are_the_same_for_zero_and_minus_zero():
    """Found by the long random walk: tab 1's derived values are cached per parameter set, and -0.0 == 0.0,
    so a student who typed 0 could see another's '-0' (a2, p1 of the operating point). Now both are
    written 0, and the cache's sharing is invisible."""
    from eha_app.render.tables import derived_html

    zeroable = [n for n, f in FIELD_INFO.items() if f.bound != ">"]
    assert {"B", "Af", "d0", "x0", "v0", "p1_0"} <= set(zeroable)
    for name in zeroable:
        plus, minus = derived_html(ActuatorParams(**{name: 0.0})), derived_html(ActuatorParams(**{name: -0.0}))
        assert plus == minus, name
        assert ">-0<" not in minus and " -0 " not in minus and "= -0 " not in minus, name
