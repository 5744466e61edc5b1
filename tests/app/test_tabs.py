import io

import numpy as np
import pandas as pd
import pytest

from eha_app.app import create_app
from eha_app.sections.simulation import parse_t_end
from eha_app.session import Session
from eha_app.session.form import InputError
from eha_app.session.state import AppState


def type_into(form, **texts):
    """What the browser sends while a student types: the form's whole text dict."""
    form.values = {**form.values, **{k: str(v) for k, v in texts.items()}}


def test_parameters_tab_shows_eq23_and_follows_typing():
    s = AppState()
    tab = Session(s).build("parameters")
    html = tab.derived.object
    assert "243.7" in html and "430.1" in html and "1.721·10<sup>4</sup>" in html and "2437" in html
    type_into(tab.form, M="8000")
    assert s.params.M == 8000.0
    assert "215" in tab.derived.object and "430.1" not in tab.derived.object   # l1 halves
    type_into(tab.form, M="-8000")
    assert "M = -8000" in tab.form.errors["M"]
    assert "Fix the highlighted input" in tab.status.object
    tab._reset()
    assert tab.form.values["M"] == "4000" and tab.form.errors == {}


def test_simulation_runs_four_case_comparison():
    s = AppState()
    tab = Session(s).build("simulation")
    assert len(tab.results) == 4                      # opens on Fig. 2
    tab._apply_preset("all")
    job = tab.run("both")
    assert job.state == "done"
    assert len(tab.results) == 8
    assert {r.model for r in tab.results} == {"nonlinear", "linear"}
    assert all(r.success and r.t[-1] == 5.0 for r in tab.results)
    # the plot source holds the data (x in mm, p in MPa), one line per run, every ~2 ms
    tab.case_select.value = "all"                     # (it opens on case 1: two lines)
    src = tab.grid.source.data
    assert tab.grid.line_count == 8
    np.testing.assert_allclose(src["x"][2][-1], tab.results[2].x[-1] * 1e3, rtol=1e-6)
    np.testing.assert_allclose(src["p2"][7][-1], tab.results[7].p2[-1] * 1e-6, rtol=1e-6)
    assert src["dash"][0] == "solid" and src["dash"][7] == "dashed"
    assert "computed in" in tab.info.text
    df = pd.read_csv(io.StringIO(tab._csv().read().decode()))
    assert list(df.columns) == ["run", "model", "t[s]", "x[m]", "v[m/s]", "p1[Pa]", "p2[Pa]", "u[V]", "d[N]"]
    assert len(df) == 8 * 5001


def test_simulation_custom_input_and_preset():
    s = AppState()
    tab = Session(s).build("simulation")
    tab._apply_preset(3)
    tab.run("nonlinear")
    assert [r.label for r in tab.results] == ["Case 3"]
    type_into(tab.form, u_kind="step", u_amplitude="2", d_kind="none", t_end="1.5")
    assert tab.preset == "custom"
    tab.run("linear")
    assert tab.results[0].t[-1] == 1.5 and tab.results[0].model == "linear"
    assert "d_amplitude" in tab.form.hidden and "u_t0" not in tab.form.hidden


def test_invalid_inputs_disable_runs():
    s = AppState()
    tab = Session(s).build("simulation")
    ident = Session(s)
    freq = ident.build("frequency")
    s.set_text("dc", "200")
    assert all(b.disabled for b in tab.run_buttons.values())
    assert ident.build("least_squares").button.disabled and freq.button.disabled
    s.set_text("dc", "70")
    assert not any(b.disabled for b in tab.run_buttons.values())
    type_into(tab.form, t_end="-2")
    assert "horizon = -2 is not allowed" in tab.form.errors["t_end"]
    assert all(b.disabled for b in tab.run_buttons.values())
    with pytest.raises(InputError, match="milliseconds"):
        parse_t_end("1.0005")
    type_into(tab.form, t_end="2", u_amplitude="12")    # beyond the slider: a message, not a silent clip
    assert tab.form.errors["u_amplitude"] == "u amplitude = 12 is not allowed: must lie in [0, 10] V"
    assert tab.run("nonlinear") is None


def test_a_failing_computation_is_shown_and_the_session_keeps_working(monkeypatch):
    from eha_app.runtime.shared import shared_results

    shared_results.clear()          # computed here, not taken from an earlier test's identical run
    s = AppState()
    tab = Session(s).build("simulation")
    import eha_app.sections.simulation as sim

    def boom(*a, **k):
        raise RuntimeError("integrator exploded")
    monkeypatch.setattr(sim, "simulate_many", boom)
    tab.run("nonlinear")
    assert tab.alert.visible and "integrator exploded" in tab.alert.object
    assert not tab.plot_area.loading
    monkeypatch.undo()
    tab.run("nonlinear")
    assert len(tab.results) == 4


def test_identification_least_squares_and_table4():
    lse = Session(AppState()).build("least_squares")
    type_into(lse.form, lse_scenario="5000 sin", lse_model="harmonic")
    lse.run()
    res = lse.result
    assert abs(res.rel_error["B"]) < 0.02
    assert "Table 4, d = 5000 sin(2πt)" in lse.table.object and "1326.3" in lse.table.object
    assert len(lse.plot.objects) == 1 and len(lse.figure.resim.data["t"]) > 1000
    lse.run_all()
    assert set(lse.all_results) == {"constant", "harmonic"}
    assert "white noise" in lse.table4.object and "4003.4" in lse.table4.object


def test_identification_custom_disturbance_validation():
    lse = Session(AppState()).build("least_squares")
    type_into(lse.form, lse_scenario="custom", lse_custom="sine:x")
    assert "lse_custom" in lse.form.errors and lse.button.disabled
    type_into(lse.form, lse_custom="sine:800:3+noise:50:2")
    assert "lse_custom" not in lse.form.errors and not lse.button.disabled
    type_into(lse.form, lse_model="harmonic", lse_freq="abc")
    assert "lse_freq" in lse.form.errors and lse.button.disabled


def test_identification_frequency_domain():
    s = AppState()
    tab = Session(s)
    assert tab.section("frequency") is None                       # built when first shown
    freq = tab.build("frequency")
    assert len(freq.figures["excitation"].source.data["t"]) == 1000
    freq.run()
    fi = freq.result
    assert fi.success and fi.estimate.den[1] < 50
    assert "Ĥ(s)" in freq.summary.object and "84.81" in freq.summary.object
    assert "friction" in freq.backout.object and "u &lt; 0 branch" in freq.backout.object
    # figures shown later draw the last result
    for i, key in enumerate(("data", "fit", "bode", "validation", "residuals"), start=1):
        freq.figure_tabs.active = i
        assert key in freq.figures
    assert len(freq.figures["bode"].points.data["w"]) == fi.etfe.w.size
    type_into(freq.form, band_lo="0.9", band_hi="0.2")
    assert freq.error.visible and freq.button.disabled


def test_each_app_has_its_own_state_and_builds_tabs_when_shown():
    a, b = create_app(), create_app()
    assert a.session.state is not b.session.state
    a.session.state.set_text("M", "5000")
    assert b.session.state.params.M == 4000.0
    assert a.tabs.names == ["1. Parameters", "2. Simulation", "3. Identification"]
    assert set(a.tabs.built) == {"1. Parameters"}
    a.tabs.tabs.active = 2
    # tab 3's first sub-tab is made with it; the others, and tab 2, when shown
    assert set(a.tabs.built) == {"1. Parameters", "3. Identification"}
    assert a.session.section("least_squares") is not None and a.session.section("frequency") is None


def test_the_address_restores_what_was_typed():
    page = create_app(query={"M": "6000", "dc": "130", "tab": "2", "u_kind": "step", "t_end": "-1"})
    state = page.session.state
    assert state.params.M == 6000.0
    assert "dc" in state.errors                   # a bad value gets its message, the page still opens
    sim = page.session.section("simulation")               # the tab of the address, opened
    assert page.tabs.active_name == "2. Simulation"
    assert sim.form.values["u_kind"] == "step" and "t_end" in sim.form.errors


def test_the_server_warm_up_runs():
    import eha_app.app as app_module

    app_module._warm = False
    app_module.warm_up()
    assert app_module._warm


def test_simulation_downloads_as_mat():
    import scipy.io

    tab = Session(AppState()).build("simulation")
    tab.run("both")
    mat = scipy.io.loadmat(io.BytesIO(tab.download_mat.callback().read()))
    assert mat["t"].shape == (5001, 1) and mat["x"].shape == (5001, 8)
    np.testing.assert_allclose(mat["p2"][:, 7], tab.results[7].p2)
    assert [str(m[0]) for m in mat["models"].ravel()][:1] == ["nonlinear"]


def test_sensor_noise_on_the_simulation_is_seeded_and_said():
    s = AppState()
    tab = Session(s).build("simulation")
    clean = tab.results[0]
    tab.form.values = {**tab.form.values, "sensor_p": "0.2", "sensor_seed": "3"}
    noisy = tab.results[0]                                      # re-run at once: the four cases, with noise
    assert noisy.label == "Case 1 + sensor noise" and "sensor noise" in tab.info.text
    dp = noisy.p1 - clean.p1
    assert 0.15e6 < dp.std() < 0.25e6 and np.array_equal(noisy.x, clean.x)
    tab.run("nonlinear")
    np.testing.assert_array_equal(tab.results[0].p1, noisy.p1)  # the same seed, the same draw
    tab.form.values = {**tab.form.values, "sensor_p": "-1"}
    assert "sensor σ p = -1 is not allowed" in tab.form.errors["sensor_p"]


def test_the_frequency_experiment_with_an_input_delay_and_residual_verdicts():
    from eha_app.sections.frequency import FREQ_DEFAULTS, parse_freq

    cfg, errors = parse_freq({**FREQ_DEFAULTS,
                              "input_delay": "estimate", "model": "linear"})
    assert not errors and cfg.input_delay == "estimate"
    _, errors = parse_freq({**FREQ_DEFAULTS,
                            "input_delay": "-2"})
    assert errors["input_delay"] == "input delay = -2 is not allowed: enter a time >= 0 s, or estimate"
    _, errors = parse_freq({**FREQ_DEFAULTS,
                            "input_delay": "99"})
    assert errors["input_delay"] == ("input delay = 99 is not allowed: must be a time in [0, 5] s (half the "
                                     "record), or estimate")
    panel = Session(AppState()).build("frequency")
    panel.form.values = {**panel.form.values, "input_delay": "estimate", "model": "linear"}
    panel.run()
    e = panel.result.estimate
    assert 0 <= e.input_delay < 0.01                      # the linear loop has no dead time: under a sample
    assert "input delay" in panel.summary.object and "(estimated" in panel.summary.object
    panel._shown.add("residuals")
    panel._draw("residuals")
    verdicts = panel.figures["residuals"].verdicts.text
    assert verdicts.count("<p>") == 2 and "lags outside the 99 % band" in verdicts


def test_a_failed_estimate_shows_its_data_in_every_figure():
    """Found by the long random walk: when tfest failed (no validation, no Bode), Figs. 8-13 raised
    instead of showing the experiment's data and no estimate."""
    from types import SimpleNamespace

    from eha_app.render import plots

    t = np.arange(50) * 0.01
    fi = SimpleNamespace(excitation=SimpleNamespace(u=np.sign(np.sin(t * 9)), type="rbs", seed=3),
                         config=SimpleNamespace(ts=0.01), validation=None, bode=None, estimate_output=None,
                         data=SimpleNamespace(t=t, r=np.sin(t), x=0.01 * np.sin(t), u=np.cos(t)))
    view = plots.frequency_view(fi, hidden=("M",))
    assert not view.fit_ok and view.y_hat_mm is None and np.allclose(view.x_mm, 10 * np.sin(t))
    plots.ExcitationFigure().update(view.excitation_t, view.excitation_r, view.excitation_title)
    for figure in (plots.ClosedLoopFigure, plots.FitFigure, plots.BodeFigure, plots.ValidationFigure,
                   plots.ResidualFigure):
        fig = figure()
        fig.update(view, "nonlinear") if figure is plots.FitFigure else fig.update(view)


def test_table_4_takes_the_seed_as_the_form_reads_it(monkeypatch):
    """Found by the long random walk: the noise seed typed as '1e3' was valid in the form (1000) but
    "All four cases" read the raw text with int() and failed in the page's callback."""
    from eha_app.sections import least_squares

    seeds = []
    monkeypatch.setattr(least_squares, "run_lse_table",
                        lambda params, disturbance_model, seed, cancel: seeds.append(seed) or {})
    lse = Session(AppState()).build("least_squares")
    type_into(lse.form, lse_seed="1e3")
    assert "lse_seed" not in lse.form.errors and not lse.all_button.disabled
    key = lse.table4_key()
    type_into(lse.form, lse_seed="1000")
    assert lse.table4_key() == key
    lse.run_all()
    assert seeds == [1000, 1000]


@pytest.mark.parametrize("changes", [{"B": 0.0, "k_f": 0.0}, {"k_f": 0.0}, {"B": 0.0, "Af": 0.0}])
def test_backout_without_damping_or_friction_slope_renders(changes):
    """B = 0 with k_f A_f = 0 leaves the linearised model no damping (its relative error is undefined),
    k_f = 0 no friction slope (1/k_f): the back-out is shown, not a ZeroDivisionError (long random walk)."""
    from eha_app.render.tables import backout_html
    from eha_core.experiments import FrequencyExperiment, run_frequency_identification
    from eha_core.params import ActuatorParams

    fi = run_frequency_identification(ActuatorParams().replace(**changes), FrequencyExperiment())
    html = backout_html(fi)
    assert "eq. 27a" in html and "nan" not in html.lower()
    if changes.get("B") == 0.0 and fi.params.k_f * fi.params.Af == 0:
        assert np.isnan(fi.backout.rel_errors()["damping"])


def test_an_unstable_open_loop_estimate_says_so_where_it_is_shown():
    """eq. 26 on an Ĥ(s) whose static gain exceeds 1 gives P̂(s) a right-half-plane pole: the page says so
    and why (Ĥ(0) > 1), with the numbers of this run."""
    from eha_app.render.tables import freq_summary_html, open_loop_note
    from eha_core.experiments import run_frequency_identification
    from eha_core.identify.backout import open_loop_instability

    fi = run_frequency_identification()
    e = fi.estimate
    found = open_loop_instability(e.num, e.den, fi.config.kp)
    html = freq_summary_html(fi)
    if fi.open_loop[1][-1] < 0:                 # the default run: Ĥ(0) = 1.025, P̂'s constant term -52
        assert found is not None and found[1] > 1
        assert "P̂(s) is unstable</b>: a pole at +" in html and f"Ĥ(0) = {found[1]:.4g} &gt; 1" in html
    # an integrating plant's loop: H(0) = 1 exactly, P̂ keeps its pole at 0: nothing to say
    assert open_loop_instability([2437.0], [1.0, 430.1, 1.721e4, 2437.0], 10.0) is None
    pole, gain = open_loop_instability([2500.0], [1.0, 430.1, 1.721e4, 2437.0], 10.0)
    assert gain == pytest.approx(2500 / 2437) and 0 < pole < 0.01
    assert open_loop_note([1.0, 2.0, 3.0], None) == ""


def test_compare_both_over_four_cases_shows_one_case_at_a_time():
    """Eight traces per plot hid case 1 under case 2: with several cases and both models a selector shows
    one case (both models) at a time; the form says which case it holds."""
    tab = Session(AppState()).build("simulation")
    assert "four cases" in tab.form_note.object or "Case" in tab.form_note.object
    tab._apply_preset("all")
    assert "the form&#x27;s u and d are not used" in tab.form_note.object
    tab.run("both")
    assert len(tab.results) == 8 and tab.case_select.visible
    assert tab.case_select.options == ["all", "Case 1", "Case 2", "Case 3", "Case 4"]
    assert tab.case_select.value == "Case 1"
    assert [sig[:2] for sig in tab.grid._signature] == [("Case 1", "nonlinear"), ("Case 1", "linear")]
    assert "Case 1 of Case 1, Case 2, Case 3, Case 4" in tab.info.text
    tab.case_select.value = "Case 3"
    assert "Case 3 of" in tab.info.text and {sig[0] for sig in tab.grid._signature} == {"Case 3"}
    tab.case_select.value = "all"
    assert tab.info.text.startswith("<b>Case 1, Case 2, Case 3, Case 4</b>") and len(tab.grid._signature) == 8
    tab.run("both")                                   # the student's choice stays for the next run
    assert tab.case_select.value == "all" and len(tab.grid._signature) == 8
    tab.run("nonlinear")                              # Fig. 2: four traces, all shown
    assert not tab.case_select.visible and tab.case_select.value == "all"
    tab._apply_preset(3)
    assert "The form holds the paper&#x27;s Case 3: u = " in tab.form_note.object
    tab.set_inputs(u_amplitude="5")
    assert "Your own inputs" in tab.form_note.object
