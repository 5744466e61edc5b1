"""Every input's message in a real browser: beside its field, in its unit, the field marked, its group open.

One page for the whole module (a page costs seconds, a case a round trip);
each case restores the valid value before the next. Fields in a collapsible
group are typed with that group folded: the message must open it.
"""

from __future__ import annotations

import pytest

from eha_app.session.state import FIELD_LABELS, FORM_FIELDS
from eha_core.params import PARAM_NAMES
from tests.ui.browser_helpers import Session, text_of, wait_until

RED = "rgb(176, 0, 32)"                  # #b00020, the Form's invalid border

JS_FIELD = """w => {
  const input = w.querySelector('input[type=text], select')
  const slider = w.querySelector('input[type=range]')
  const error = w.querySelector('.eha-error')
  const details = w.closest('details')
  const others = Array.from(w.closest('.eha-form').querySelectorAll('.eha-error'))
    .filter(e => e !== error && e.textContent !== '').map(e => e.id)
  return {message: error.textContent, displayed: error.getClientRects().length > 0,
          beside: error.parentElement === w, invalid: w.classList.contains('eha-invalid'),
          aria: input.getAttribute('aria-invalid'), border: getComputedStyle(input).borderTopColor,
          open: details === null ? null : details.open, value: input.value,
          slider: slider === null ? null : slider.value, others}
}"""
# what a paste, an autofill or a restored link does: a new text and an input event (works in a folded group)
JS_TYPE = """(w, text) => {
  const input = w.querySelector('input[type=text]')
  input.value = text
  input.dispatchEvent(new Event('input', {bubbles: true}))
}"""
JS_FOLD = "w => { for (const d of w.closest('.eha-form').querySelectorAll('details')) { d.open = false } }"
# the texts of a form's boxes, and the ids of its messages that are not empty
JS_FORM = """w => {
  const form = w.closest('.eha-form')
  const values = {}
  for (const input of form.querySelectorAll('input[type=text]')) { values[input.id.slice(10)] = input.value }
  const errors = Array.from(form.querySelectorAll('.eha-error')).filter(e => e.textContent !== '').map(e => e.id)
  return {values, errors}
}"""


def _unit(name: str) -> str:
    return FORM_FIELDS[name].display_unit


def _bad_values(name: str) -> list[tuple[tuple, str, list[str]]]:
    """(fields typed first, the text, words of the message) for one field of tab 1."""
    cases = [((), "abc", [f"{FIELD_LABELS[name]} = abc is not allowed: must be a number in {_unit(name)}"])]
    if name != "p2_0":                                    # blank p2(0) is the force balance
        cases.append(((), "", [f"{FIELD_LABELS[name]} = (empty) is not allowed: enter a number in {_unit(name)}"]))
    return cases + OUT_OF_RANGE.get(name, [])


OUT_OF_RANGE = {
    "M": [((), "-5", ["must be > 0 kg"])],
    "B": [((), "-1", ["must be >= 0 N s/m"])],
    "Af": [((), "-1", ["must be >= 0 N"])],
    "beta_e": [((), "0", ["must be > 0 GPa"])],
    "Dc": [((), "-1", ["must be > 0 mm"]), ((), "60", ["the rod diameter dc = 70 mm"]),
           ((), "75", ["(A1 p1(0) − d0)/A2 = 93.1 MPa", "ps = 32 MPa"])],
    "dc": [((), "0", ["must be > 0 mm"]), ((), "130", ["smaller than the bore Dc = 120 mm"]),
           ((), "100", ["(A1 p1(0) − d0)/A2 = 39.27 MPa", "ps = 32 MPa"])],
    "d0": [((), "200000", ["(A1 p1(0) − d0)/A2 = -8.616 MPa", "pr = 0 MPa"]),
           ((("p2_0", "15"),), "-300000", ["operating point", "58.4 MPa", "ps = 32 MPa"])],
    "L0": [((), "0", ["must be > 0 mm"]), ((("x0", "20"),), "10", ["±0.8 L0 = ±8 mm", "x(0) = 20 mm"])],
    "Kq1": [((), "-3", ["must be > 0"])],
    "Kq2": [((), "0", ["must be > 0"])],
    "ps": [((), "0", ["must be > 0 MPa"]), ((), "10", ["p1(0) = 12 MPa"]),
           ((), "15", ["p2(0) = (A1 p1(0) − d0)/A2 = 18.19 MPa"]), ((("pr", "5"),), "4", ["pr = 5 MPa"])],
    "pr": [((), "-1", ["must be >= 0 MPa"]), ((), "40", ["supply pressure ps = 32 MPa"]),
           ((), "15", ["p1(0) = 12 MPa"])],
    "k_f": [((), "-1", ["must be >= 0 s/m"])],
    "x0": [((), "300", ["±0.8 L0 = ±240 mm (L0 = 300 mm)"])],
    "v0": [((), "inf", ["must be a finite number in mm/s"])],
    "p1_0": [((), "40", ["[pr, ps] = [0, 32] MPa"]), ((), "25", ["37.89 MPa", "ps = 32 MPa"]),
             ((("p2_0", "15"),), "30", ["operating point", "45.47 MPa", "ps = 32 MPa"])],
    "p2_0": [((), "40", ["[pr, ps] = [0, 32] MPa"]), ((), "-1", ["[pr, ps] = [0, 32] MPa"])],
    "kp": [((), "0", ["must be > 0 V/m"]), ((), "-1", ["must be > 0 V/m"])],
}
TAB1 = (*PARAM_NAMES, "kp")


@pytest.fixture(scope="module")
def student(browser, server):
    s = Session(browser, server)
    yield s
    problems = list(s.console)
    s.close()
    assert not problems, f"browser console: {problems}"


def _wrap(student, name: str):
    return student.page.locator(f".eha-field-{name}").first


def _field(student, name: str) -> dict:
    return _wrap(student, name).evaluate(JS_FIELD)


def _type(student, name: str, text: str) -> None:
    """Type into a visible field as a student does; into a folded one as a paste or a link would."""
    wrap = _wrap(student, name)
    box = wrap.locator("input[type=text]")
    if box.is_visible():
        box.fill(text)
    else:
        wrap.evaluate(JS_TYPE, text)


def _message(student, name: str, words) -> dict:
    """The field's state once its message holds every one of ``words``."""
    return wait_until(lambda: (lambda f: f if all(w in f["message"] for w in words) else None)(
        _field(student, name)), timeout=15, message=f"the message of {name} to hold {words}")


def _assert_marked(f: dict, name: str, text: str) -> None:
    assert f["displayed"] and f["beside"], f                  # shown, in the field's own wrapper
    assert f["invalid"] and f["aria"] == "true" and f["border"] == RED, f
    assert f["open"] in (None, True), f"the folded group of {name} stayed shut"
    assert f["value"] == text, f"the box of {name} shows {f['value']!r}, not what was typed"
    assert f["others"] == [], f"messages on other fields: {f['others']}"


def _valid_again(student, names) -> None:
    def ok():
        return _wrap(student, "M").evaluate(JS_FORM)["errors"] == [] and \
            "All inputs valid" in text_of(student.page, ".eha-param-status")
    wait_until(ok, timeout=15, message=f"{names} valid again")


@pytest.mark.parametrize("name", TAB1)
def test_each_bad_value_of_tab_1_gets_its_message_beside_its_field(student, name):
    page = student.page
    if not _wrap(student, "M").is_visible():
        student.tab("1. Parameters")
    defaults = _wrap(student, "M").evaluate(JS_FORM)["values"]
    assert set(defaults) == set(TAB1)
    label = FIELD_LABELS[name]
    for first, text, words in _bad_values(name):
        _wrap(student, name).evaluate(JS_FOLD)            # every collapsible group folded
        for n, t in first:
            _type(student, n, t)
        _type(student, name, text)
        f = _message(student, name, words)
        message = f["message"]
        assert message.startswith(f"{label} = {text.strip() or '(empty)'}"), message
        assert " is not allowed: " in message, message
        assert _unit(name) in message, f"no {_unit(name)} in {message!r}"
        if text not in ("", "abc"):
            assert "e+0" not in message and " Pa" not in message, message      # no SI rendering
        _assert_marked(f, name, text)
        assert "Fix the highlighted input" in text_of(page, ".eha-param-status")
        # back to the paper's values
        _type(student, name, defaults[name])
        for n, _ in reversed(first):
            _type(student, n, defaults[n])
        _valid_again(student, [name, *(n for n, _ in first)])
        assert _field(student, name)["border"] != RED


def test_tab_2_slider_boxes_and_horizon_refuse_without_substituting(student):
    page = student.page
    student.tab("2. Simulation")
    _wrap(student, "u_amplitude").wait_for(state="visible", timeout=60_000)
    amplitude = _field(student, "u_amplitude")
    assert amplitude["slider"] == amplitude["value"] == "6"
    cases = [("u_amplitude", "99", ["u amplitude = 99 is not allowed: must lie in [0, 10] V"]),
             ("u_amplitude", "-1", ["must lie in [0, 10] V"]),
             ("u_amplitude", "abc", ["u amplitude = abc is not allowed: enter a number; must lie in [0, 10] V"]),
             ("u_freq", "25", ["u frequency = 25 is not allowed: must lie in [0.05, 20] Hz"]),
             ("t_end", "0", ["horizon = 0 is not allowed: must lie in (0, 60] s"]),
             ("t_end", "abc", ["horizon = abc is not allowed", " s"])]
    for name, text, words in cases:
        before = _field(student, name)
        _type(student, name, text)
        f = _message(student, name, words)
        _assert_marked(f, name, text)
        assert f["slider"] == before["slider"], f"the slider of {name} moved to {f['slider']} for {text!r}"
        assert page.get_by_role("button", name="Run nonlinear").is_disabled()
        _type(student, name, before["value"])
        wait_until(lambda n=name: _field(student, n)["message"] == "", timeout=15, message=f"{name} valid again")
    # a value the slider can show still moves it
    _type(student, "u_amplitude", "7.5")
    wait_until(lambda: _field(student, "u_amplitude")["slider"] == "7.5", message="the slider at 7.5")
    _type(student, "u_amplitude", "6")
    wait_until(lambda: page.get_by_role("button", name="Run nonlinear").is_enabled(), message="runs enabled")


def test_tab_3_frequency_form_refuses_without_substituting(student):
    page = student.page
    student.tab("3. Identification")
    page.locator(".bk-tab", has_text="Frequency domain").first.click()
    _wrap(student, "n_samples").wait_for(state="visible", timeout=60_000)
    cases = [("n_samples", "99999", ["N = 99999 is not allowed: must lie in [20, 20000]"]),
             ("n_samples", "12.5", ["N = 12.5 is not allowed: enter a whole number"]),
             ("ts", "0", ["Ts = 0 is not allowed: must lie in [0.0001, 1] s"]),
             ("ts", "abc", ["Ts = abc is not allowed: enter a number; must lie in [0.0001, 1] s"]),
             ("band_hi", "2", ["band high = 2 is not allowed: must lie in [0, 1] × Nyquist"]),
             ("freq_seed", "-1", ["seed = -1 is not allowed: must lie in [0, 1000000]"])]
    button = page.locator(".eha-run-freq button").first
    for name, text, words in cases:
        before = _field(student, name)
        _type(student, name, text)
        f = _message(student, name, words)
        _assert_marked(f, name, text)
        assert button.is_disabled()
        _type(student, name, before["value"])
        wait_until(lambda n=name: _field(student, n)["message"] == "", timeout=15, message=f"{name} valid again")
    wait_until(button.is_enabled, timeout=30, message="the experiment's button enabled again")
