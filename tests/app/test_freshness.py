"""After any input change, every result view shows results of the current inputs or is marked out of date."""

from eha_app.state import AppState
from eha_app.tabs.simulation import AUTO_RUN_MAX_SECONDS, SimulationTab


def type_into(form, **texts):
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


def assert_true_to_inputs(view, key):
    """The view's promise: current and computed from ``key``, or marked (and then not current)."""
    if view.status == "current":
        assert view.computed_from == key, (view.name, view.computed_from, key)
        assert "eha-current" in view.container.css_classes
    else:
        assert view.status in ("updating", "stale"), view.status
        assert view.computed_from != key
        mark = "eha-updating" if view.status == "updating" else "eha-out-of-date"
        assert mark in view.container.css_classes


def test_simulation_reruns_as_the_student_types():
    s = AppState()
    tab = SimulationTab(s)
    assert tab.view.status == "current" and tab.view.computed_from == tab.key("nonlinear", "all")
    runs = tab.run_count
    type_into(tab.form, u_amplitude="3")         # leaves the preset: a custom sine, re-run at once
    assert tab.run_count == runs + 1 and tab.view.status == "current"
    assert_true_to_inputs(tab.view, tab.key(tab.last_model))
    assert "3 sin(4πt)" in tab.info.text
    s.set_text("M", "6000")                      # tab 1: the plots follow
    assert tab.run_count == runs + 2 and tab.results[0].params.M == 6000.0
    assert_true_to_inputs(tab.view, tab.key(tab.last_model))


def test_a_long_run_is_marked_out_of_date_not_rerun():
    s = AppState()
    tab = SimulationTab(s)
    tab.run("both")
    runs = tab.run_count
    t_long = AUTO_RUN_MAX_SECONDS / 2 + 1        # two runs (both models) beyond the automatic limit
    type_into(tab.form, t_end=f"{t_long:g}")
    assert tab.run_count == runs and tab.view.status == "stale"
    assert tab.view.banner.visible and "Out of date" in tab.view.banner.object
    assert_true_to_inputs(tab.view, tab.key("both"))
    tab.run("both")                              # the Run button
    assert tab.view.status == "current" and not tab.view.banner.visible
    assert tab.results[0].t[-1] == t_long


def test_invalid_parameters_mark_the_plots():
    s = AppState()
    tab = SimulationTab(s)
    s.set_text("M", "-1")
    assert tab.view.status == "stale" and "not valid" in tab.view.banner.object
    s.set_text("M", "4000")                      # back to what is drawn
    assert tab.view.status == "current"


def test_linearised_model_beyond_its_range_is_flagged_in_the_status_line():
    s = AppState()
    tab = SimulationTab(s)
    type_into(tab.form, u_kind="step", u_amplitude="6", u_t0="0")
    tab.run("linear")
    assert "Beyond the physical range" in tab.info.text and "below the tank pressure" in tab.info.text
    tab.run("nonlinear")
    assert "Beyond the physical range" not in tab.info.text
