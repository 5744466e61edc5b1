import numpy as np
import pandas as pd
import pytest
import io

from eha_app.app import create_app
from eha_app.state import AppState
from eha_app.tabs.identification import IdentificationTab
from eha_app.tabs.parameters import ParametersTab
from eha_app.tabs.simulation import SimulationTab, parse_t_end


def test_parameters_tab_shows_eq23_and_follows_typing():
    s = AppState()
    tab = ParametersTab(s)
    html = tab.derived.object
    assert "243.7" in html and "430.1" in html and "1.721·10<sup>4</sup>" in html and "2437" in html
    tab.fields["M"].input.value_input = "8000"       # what the browser sends while typing
    assert s.params.M == 8000.0
    assert "215" in tab.derived.object and "430.1" not in tab.derived.object   # l1 halves
    tab.fields["M"].input.value_input = "-8000"
    assert tab.fields["M"].error.visible and "M = -8000" in tab.fields["M"].error.object
    assert "Fix the highlighted input" in tab.status.object
    tab._reset()
    assert tab.fields["M"].input.value == "4000" and not tab.fields["M"].error.visible


def test_simulation_runs_four_case_comparison(run_async):
    s = AppState()
    tab = SimulationTab(s)
    assert len(tab.results) == 4                      # opens on Fig. 2
    tab._apply_preset("all")
    run_async(tab.run("both"))
    assert len(tab.results) == 8
    assert {r.model for r in tab.results} == {"nonlinear", "linear"}
    assert all(r.success and r.t[-1] == 5.0 for r in tab.results)
    # the plot sources hold the data (x in mm)
    src = tab.grid.source.data
    np.testing.assert_allclose(src["x_2"][-1], tab.results[2].x[-1] * 1e3)
    np.testing.assert_allclose(src["p2_7"][-1], tab.results[7].p2[-1] * 1e-6)
    assert sum(r.visible for r in tab.grid.renderers[0]) == 8
    assert "computed in" in tab.info.text
    df = pd.read_csv(io.StringIO(tab._csv().read().decode()))
    assert list(df.columns) == ["run", "model", "t", "x", "v", "p1", "p2", "u", "d"]
    assert len(df) == 8 * 5001


def test_simulation_custom_input_and_preset(run_async):
    s = AppState()
    tab = SimulationTab(s)
    tab._apply_preset(3)
    run_async(tab.run("nonlinear"))
    assert [r.label for r in tab.results] == ["Case 3"]
    tab.request.param.update(u_kind="step", u_amplitude=2.0, d_kind="none", t_end_text="1.5")
    assert tab.request.preset == "custom"
    run_async(tab.run("linear"))
    assert tab.results[0].t[-1] == 1.5 and tab.results[0].model == "linear"


def test_invalid_inputs_disable_runs():
    s = AppState()
    tab = SimulationTab(s)
    ident = IdentificationTab(s)
    s.set_text("dc", "200")
    assert all(b.disabled for b in tab.run_buttons.values())
    assert ident.lse_button.disabled and ident.freq_button.disabled
    s.set_text("dc", "70")
    assert not any(b.disabled for b in tab.run_buttons.values())
    tab.request.t_end_text = "-2"
    assert tab.t_end_error.visible and "horizon = -2" in tab.t_end_error.object
    assert all(b.disabled for b in tab.run_buttons.values())
    with pytest.raises(ValueError, match="milliseconds"):
        parse_t_end("1.0005")


def test_a_failing_computation_is_shown_and_the_session_keeps_working(run_async, monkeypatch):
    s = AppState()
    tab = SimulationTab(s)
    import eha_app.tabs.simulation as sim

    def boom(*a, **k):
        raise RuntimeError("integrator exploded")
    monkeypatch.setattr(sim, "simulate_many", boom)
    run_async(tab.run("nonlinear"))
    assert tab.alert.visible and "integrator exploded" in tab.alert.object
    assert not tab.plot_area.loading
    monkeypatch.undo()
    run_async(tab.run("nonlinear"))
    assert len(tab.results) == 4


def test_identification_least_squares_and_table4(run_async):
    s = AppState()
    tab = IdentificationTab(s)
    tab.lse_req.scenario = "5000 sin"
    tab.lse_req.model = "harmonic"
    run_async(tab._run_lse())
    res = tab.lse_result
    assert abs(res.rel_error["B"]) < 0.02
    assert "paper (Table 3/4)" in tab.lse_table.object and "1326.3" in tab.lse_table.object
    assert len(tab.lse_plot.objects) == 1
    run_async(tab._run_lse_all())
    assert set(tab.lse_all) == {"constant", "harmonic"}
    assert "white noise" in tab.table4.object and "4003.4" in tab.table4.object


def test_identification_custom_disturbance_validation():
    s = AppState()
    tab = IdentificationTab(s)
    tab.lse_req.scenario = "custom"
    tab.lse_req.custom = "sine:x"
    assert tab.lse_errors["custom"].visible and tab.lse_button.disabled
    tab.lse_req.custom = "sine:800:3+noise:50:2"
    assert not tab.lse_errors["custom"].visible and not tab.lse_button.disabled
    tab.lse_req.model = "harmonic"
    tab.lse_req.freq_text = "abc"
    assert tab.lse_errors["freq_text"].visible and tab.lse_button.disabled


def test_identification_frequency_domain(run_async):
    s = AppState()
    tab = IdentificationTab(s)
    run_async(tab._run_freq())
    fi = tab.freq_result
    assert fi.success and fi.estimate.den[1] < 50
    assert "Ĥ(s)" in tab.freq_summary.object and "84.81" in tab.freq_summary.object
    assert "friction" in tab.backout.object and "u &lt; 0 branch" in tab.backout.object
    assert all(len(area.objects) >= 1 for area in tab.freq_plots.values())
    tab.freq_req.band_lo = 0.9
    tab.freq_req.band_hi = 0.2
    assert tab.freq_error.visible and tab.freq_button.disabled


def test_each_app_has_its_own_state():
    a, b = create_app(), create_app()
    assert a.eha_state is not b.eha_state
    a.eha_state.set_text("M", "5000")
    assert b.eha_state.params.M == 4000.0
    assert [t for t in a.eha_tabs._names] == ["1. Parameters", "2. Simulation", "3. Identification"]
