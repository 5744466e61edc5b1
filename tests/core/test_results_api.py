"""The results at a Python prompt: short reprs that never hide a failure, tables, figures, defaults.

Every result type the simulation and the identification routes return is made once by a realistic run
(module fixtures); then:

* its repr is a few lines (< 1000 characters), names the route and the verdict, and shows the estimates
  in display units with the standard errors the result holds (parsed back and compared);
* a result whose checks failed says ``FAILED`` on its first line, whatever it is;
* ``to_pandas()`` gives back exactly the result's numbers (round trips), SI with the display units;
* ``plot()`` draws with matplotlib what the result holds, in display units, and without matplotlib
  raises an ImportError that says ``pip install matplotlib``; drawing never loads the web stack;
* ``greybox_data(params)`` works from its defaults, and the grey-box estimate from them recovers the truth.
"""

from __future__ import annotations

import dataclasses
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from eha_core._display import in_units, polynomial, with_error
from eha_core.experiments import LSE_INPUT, lse_data, run_frequency_identification
from eha_core.identify._stats import Z95
from eha_core.identify.greybox import greybox_data, identify_greybox
from eha_core.identify.greybox_study import GreyBoxStudyConfig, run_greybox_study
from eha_core.identify.lse import identify_lse
from eha_core.identify.record import identify_record
from eha_core.identify.spectral import spa
from eha_core.identify.tfest import tfest
from eha_core.param_table import FIELD_INFO
from eha_core.params import ActuatorParams
from eha_core.signals import Constant, Sine
from eha_core.simulate import simulate, simulate_closed_loop
from eha_core.study import StudyConfig, run_study

P = ActuatorParams()
TRUTH = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8)
#: The app's grey-box panel defaults: sensor noise (0.01 mm, 0.05 MPa) and the signals measured.
APP_NOISE = {"x": 1e-5, "p1": 5e4, "p2": 5e4}
APP_MEASURED = ("x", "p1", "p2")
#: An estimate line of a repr: ``NAME = VALUE ± ERROR UNIT``.
ESTIMATE = re.compile(r"(?P<name>\w+) = (?P<value>-?[\d.]+(?:e[+-]\d+)?) ± (?P<se>[\d.]+(?:e[+-]\d+)?) "
                      r"(?P<unit>[^;(\n]*?)(?=;|\(|$)", re.MULTILINE)


@pytest.fixture(scope="module")
def sim():
    return simulate(P, u=Sine(6.0, 2.0), d=Sine(5e3, 1.0), t_end=5.0)


@pytest.fixture(scope="module")
def closed():
    return simulate_closed_loop(P, r=Sine(0.01, 0.5), kp=10.0, t_end=4.0)


@pytest.fixture(scope="module")
def lse():
    return identify_lse(lse_data(P, "white:1000", seed=0), P)


@pytest.fixture(scope="module")
def fi():
    return run_frequency_identification(P)


@pytest.fixture(scope="module")
def gb():
    return identify_greybox(greybox_data(TRUTH, noise=APP_NOISE, measured=APP_MEASURED))


@pytest.fixture(scope="module")
def study():
    return run_study(StudyConfig("lse", n_seeds=3, disturbance="white:1000"))


@pytest.fixture(scope="module")
def gb_study():
    return run_greybox_study(GreyBoxStudyConfig(n_seeds=2))


@pytest.fixture(scope="module")
def results(sim, closed, lse, fi, gb, study, gb_study):
    """Every result type of a realistic run, by name, with the words its repr must hold."""
    record = identify_record(fi.data.t, fi.data.r, fi.data.x, n_poles=3)
    return {
        "simulation": (sim, ("SimulationResult", "open loop", "success")),
        "closed loop": (closed, ("SimulationResult", "closed loop", "kp 10 V/m", "success")),
        "least squares": (lse, ("LSEResult", "least squares", "success", "kg", "GPa")),
        "frequency identification": (fi, ("FrequencyIdentification", "tfest", "success", "back-out", "GPa")),
        "tfest": (fi.estimate, ("TFEstimate", "3 poles", "success", "a1 = ")),
        "back-out": (fi.backout, ("BackoutResult", "eq. 27", "damping = ", "GPa")),
        "data response": (fi.data_response, ("DataFrequencyResponse", "etfe")),
        "spectral": (spa(fi.data.r, fi.data.x, fi.config.ts), ("SpectralEstimate", "spa")),
        "bode": (fi.bode, ("BodeData",)),
        "validation": (fi.validation, ("CompareResult", "fit")),
        "residuals": (fi.residuals, ("ResidualAnalysis", "white")),
        "record": (record, ("RecordIdentification", "validation", "success")),
        "grey box": (gb, ("GreyBoxResult", "output error", "checks passed", "GPa")),
        "study": (study, ("StudyResult", "least squares", "3 of 3 seeds successful", "covers")),
        "seed": (study.seeds[0], ("SeedEstimate",)),
        "grey-box study": (gb_study, ("GreyBoxStudyResult", "2 of 2 seeds passed", "std/CRB")),
    }


# -- reprs ---------------------------------------------------------------------------------------------------

def test_every_result_has_a_short_repr_naming_its_route_and_verdict(results):
    for name, (result, words) in results.items():
        text = repr(result)
        assert len(text) < 1000, f"{name}: {len(text)} characters\n{text}"
        assert text.count("\n") < 8, f"{name}: {text.count(chr(10)) + 1} lines\n{text}"
        missing = [w for w in words if w not in text]
        assert not missing, f"{name}: no {missing} in\n{text}"
        assert str(result) == text
        assert "array(" not in text, f"{name} prints an array:\n{text}"


@pytest.mark.parametrize("which", ["lse", "gb"])
def test_the_repr_shows_each_estimate_and_its_standard_error_in_display_units(which, request):
    res = request.getfixturevalue(which)
    found = {m["name"]: m for m in ESTIMATE.finditer(repr(res))}
    assert set(found) == set(res.estimates)
    for name, m in found.items():
        scale = FIELD_INFO[name].display_scale
        assert m["unit"].strip() == FIELD_INFO[name].display_unit
        se = res.std_errors[name]
        # rounded at the standard error's second significant digit
        assert float(m["se"]) * scale == pytest.approx(se, rel=0.05)
        assert abs(float(m["value"]) * scale - res.estimates[name]) <= 0.05 * se


def test_values_are_rounded_at_the_standard_errors_second_digit():
    assert with_error("M", 4999.923, 0.0812) == "M = 4999.923 ± 0.081 kg"
    assert with_error("B", 1824.92, 636.4) == "B = 1820 ± 640 N s/m"
    assert with_error("beta_e", 1.1e9, 1.2e6) == "beta_e = 1.1000 ± 0.0012 GPa"
    assert with_error("d0", -5.69, 14.4) == "d0 = -6 ± 14 N"
    assert with_error("M", 4000.0, math.nan) == "M = 4000 kg (no s.e.)"
    assert in_units("Kq1", 2.5e-8) == "2.5 × 1e-8 m³/(s V √Pa)"
    assert in_units("x", 0.0353) == "35.3 mm"
    assert polynomial([1.0, 9.459, 17090.0, -51.9]) == "s^3 + 9.459 s^2 + 1.709e+04 s - 51.9"


def test_a_failed_least_squares_says_so_first():
    # no motion: the regressors are dependent, the estimator reports a failure
    res = identify_lse(lse_data(P, "none", u=Constant(0.0)), P)
    assert not res.success
    first, second = repr(res).splitlines()[:2]
    assert first.endswith(": FAILED")
    assert "linearly dependent" in second


def test_a_failed_transfer_function_estimate_says_so_first(fi):
    est = tfest(fi.data.r, fi.data.x, fi.config.ts, 3, 0, max_nfev=1)
    assert not est.success
    assert repr(est).splitlines()[0].endswith(": FAILED")
    assert "success" not in repr(est)


def test_a_failed_grey_box_estimate_says_so_and_gives_no_interval():
    # a load force the model is not told of: the residuals are no noise and the checks fail
    data = greybox_data(P, d=Sine(3000.0, 1.0), noise=APP_NOISE, measured=APP_MEASURED)
    res = identify_greybox(dataclasses.replace(data, d=None), shooting="single")
    assert not res.success
    text = repr(res)
    assert text.splitlines()[0].endswith(": FAILED") and "checks passed" not in text
    assert "no interval is given" in text and " ± " not in text
    assert all(c.name in text for c in res.failed_checks)
    assert res.to_pandas()["ci95_low"].isna().all()


def test_a_frequency_identification_whose_estimate_failed_says_so(fi):
    failed = dataclasses.replace(fi, success=False, message="the output-error fit did not converge")
    lines = repr(failed).splitlines()
    assert lines[0].endswith(": FAILED") and "did not converge" in lines[1]


# -- tables ----------------------------------------------------------------------------------------------------

def test_a_run_is_a_table_indexed_by_time(sim, closed):
    df = sim.to_pandas()
    assert df.index.name == "t" and list(df.columns) == ["x", "v", "p1", "p2", "u", "d"]
    np.testing.assert_array_equal(df.index.to_numpy(), sim.t)
    for name in df.columns:
        np.testing.assert_array_equal(df[name].to_numpy(), getattr(sim, name))
    np.testing.assert_array_equal(closed.to_pandas()["r"].to_numpy(), closed.r)
    # the CSV keeps t as its first column
    assert sim.to_csv().splitlines()[0] == "t,x,v,p1,p2,u,d"


def _check_estimates(df, estimates, std_errors, ci95):
    assert list(df.index) == list(estimates)
    for name in estimates:
        row = df.loc[name]
        assert row["value"] == estimates[name]
        assert row["std_error"] == std_errors[name] or (math.isnan(row["std_error"]) and math.isnan(std_errors[name]))
        assert (row["ci95_low"], row["ci95_high"]) == pytest.approx(ci95[name], nan_ok=True)
        if name in FIELD_INFO:
            info = FIELD_INFO[name]
            assert (row["unit"], row["display_unit"], row["display_scale"]) == (info.unit, info.display_unit,
                                                                                info.display_scale)


def test_least_squares_table_round_trips(lse):
    df = lse.to_pandas()
    _check_estimates(df, lse.estimates, lse.std_errors, lse.ci95)
    assert dict(df["std_error_textbook"]) == lse.std_errors_textbook


def test_grey_box_table_round_trips(gb):
    df = gb.to_pandas()
    _check_estimates(df, gb.estimates, gb.std_errors, gb.ci95)
    assert not df["held"].any()
    assert df.loc["beta_e", "display_unit"] == "GPa"


def test_transfer_function_table_round_trips(fi):
    est = fi.estimate
    df = est.to_pandas()
    coefficients = df.loc[list(est.coefficient_names())]
    np.testing.assert_array_equal(coefficients["value"], [*est.den[1:], *est.num])
    np.testing.assert_array_equal(coefficients["std_error"], est.param_std)
    np.testing.assert_allclose(coefficients["ci95_high"] - coefficients["value"], Z95 * est.param_std)
    assert list(coefficients["unit"]) == ["1/s", "1/s^2", "1/s^3", "(y/u)/s^3"]
    assert df.loc["input_offset", "value"] == est.input_offset
    assert df.loc["input_offset", "std_error"] == est.input_offset_std
    assert est.formula() == "b0 / (s^3 + a1 s^2 + a2 s + a3)"


def test_back_out_and_frequency_identification_tables_round_trip(fi):
    b = fi.backout
    df = b.to_pandas()
    _check_estimates(df, {n: getattr(b, n) for n in df.index}, {n: getattr(b, n + "_std") for n in df.index},
                     b.ci95())
    assert df.loc["beta_e_from_gain", "display_unit"] == "GPa"
    whole = fi.to_pandas()
    assert list(whole.index) == [*fi.estimate.to_pandas().index, *df.index]
    assert whole.loc["beta_e_from_stiffness", "value"] == b.beta_e_from_stiffness


def test_frequency_responses_are_tables_indexed_by_frequency(fi, results):
    dr = fi.data_response.to_pandas()
    np.testing.assert_array_equal(dr.index.to_numpy(), fi.data_response.w)
    np.testing.assert_array_equal(dr["magnitude_db"].to_numpy(), fi.data_response.magnitude_db)
    assert "lower_db" not in dr          # an ETFE has no band
    sp = results["spectral"][0]
    df = sp.to_pandas()
    np.testing.assert_array_equal(df["upper_db"].to_numpy(), sp.upper_db)
    np.testing.assert_array_equal(df["coherence"].to_numpy(), sp.coherence)


def test_study_tables_round_trip(study, gb_study):
    df = study.to_pandas()
    assert list(df.index) == list(study.parameters)
    for column in ("nominal", "mean", "std", "mean_std_error", "coverage", "bias"):
        assert dict(df[column]) == pytest.approx(getattr(study, column), nan_ok=True)
    seeds = study.seeds_to_pandas()
    assert list(seeds.index) == [s.seed for s in study.seeds]
    assert seeds.loc[study.seeds[1].seed, "M"] == study.seeds[1].estimates["M"]
    assert seeds.loc[study.seeds[1].seed, "M_std_error"] == study.seeds[1].std_errors["M"]
    g = gb_study.to_pandas()
    assert dict(g["crb"]) == gb_study.crb and dict(g["coverage"]) == gb_study.coverage
    assert g.loc["beta_e", "truth"] == gb_study.truth["beta_e"]


# -- figures ---------------------------------------------------------------------------------------------------

@pytest.fixture
def pyplot():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    yield plt
    plt.close("all")


def test_a_run_draws_its_signals_in_display_units(sim, closed, pyplot):
    fig = sim.plot()
    assert [ax.get_ylabel() for ax in fig.axes] == ["x [mm]", "v [mm/s]", "p [MPa]", "u [V]", "d [kN]"]
    np.testing.assert_allclose(fig.axes[0].lines[0].get_ydata(), sim.x * 1e3)
    np.testing.assert_allclose(fig.axes[2].lines[1].get_ydata(), sim.p2 / 1e6)
    np.testing.assert_allclose(fig.axes[4].lines[0].get_ydata(), sim.d / 1e3)
    fig = closed.plot()
    assert len(fig.axes) == 4            # no load
    np.testing.assert_allclose(fig.axes[0].lines[1].get_ydata(), closed.r * 1e3)


def test_the_least_squares_draws_its_equations_and_fit(lse, pyplot):
    fig = lse.plot()
    measured, fit = fig.axes[0].lines
    np.testing.assert_allclose(measured.get_ydata(), lse.y1f / 1e3)
    np.testing.assert_allclose(fit.get_ydata(), lse.y1_fit / 1e3)
    np.testing.assert_allclose(fig.axes[1].lines[1].get_ydata(), lse.y2_fit / 1e6)


def test_a_transfer_function_draws_its_bode_diagram(fi, pyplot):
    w = np.logspace(-1, 2, 50)
    fig = fi.estimate.plot(w)
    response = fi.estimate.frequency_response(w)
    np.testing.assert_allclose(fig.axes[0].lines[0].get_ydata(), response.magnitude_db)
    np.testing.assert_allclose(fig.axes[1].lines[0].get_ydata(), response.phase_deg)
    assert fig.axes[0].get_xscale() == "log"
    fig = fi.plot()
    labels = [line.get_label() for line in fig.axes[0].lines]
    assert labels == ["estimate", "linearised (eq. 24)", "data (etfe)"]
    np.testing.assert_allclose(fig.axes[0].lines[2].get_ydata(), fi.bode.data_magnitude_db)


def test_the_grey_box_draws_each_measured_signal_against_its_model(gb, pyplot):
    fig = gb.plot()
    assert [ax.get_ylabel() for ax in fig.axes] == ["x [mm]", "p1 [MPa]", "p2 [MPa]"]
    measured, model = fig.axes[0].lines
    np.testing.assert_allclose(measured.get_ydata(), gb.data.signals["x"] * 1e3)
    np.testing.assert_allclose(model.get_ydata(), gb.simulated[:, 0] * 1e3)
    assert f"fit {gb.fit['x']:.1f} %" in model.get_label()


def test_without_matplotlib_a_plot_says_how_to_install_it(monkeypatch, sim, lse, fi, gb):
    # None in sys.modules makes an import of that name fail, as when the package is absent
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    for draw in (sim.plot, lse.plot, fi.estimate.plot, fi.plot, gb.plot):
        with pytest.raises(ImportError, match="pip install matplotlib"):
            draw()


def test_drawing_loads_neither_the_web_stack_nor_matplotlib_before_it_draws():
    code = ("import sys\n"
            "import eha_core.plotting, eha_core._display\n"
            "from eha_core.simulate import simulate\n"
            "res = simulate(t_end=0.05)\n"
            "before = 'matplotlib' in sys.modules\n"
            "try:\n"
            "    import matplotlib\n"
            "    matplotlib.use('Agg')\n"
            "    res.plot()\n"
            "except ImportError:\n"
            "    pass\n"
            "print(before, sorted(m for m in ('bokeh', 'panel', 'holoviews', 'param') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == ["False", "[]"]


# -- grey-box defaults -----------------------------------------------------------------------------------------

def test_greybox_data_defaults_to_the_apps_excitation():
    data = greybox_data(P)
    assert data.t[-1] == pytest.approx(5.0) and data.ts == pytest.approx(1e-3)
    np.testing.assert_allclose(data.u, LSE_INPUT(data.t), atol=1e-12)
    np.testing.assert_allclose(data.u, 6.0 * np.sin(4.0 * np.pi * data.t), atol=1e-12)
    assert set(data.signals) == {"x", "v", "p1", "p2"} and data.r is None


def test_the_grey_box_from_defaults_recovers_the_truth():
    # everything at its default: the paper's input, every signal, no noise, estimated from the paper's values
    res = identify_greybox(greybox_data(TRUTH))
    assert res.success, res.message
    for name in res.names:
        assert res.estimates[name] == pytest.approx(getattr(TRUTH, name), rel=1e-5)


def test_the_grey_box_with_the_apps_noise_covers_the_truth(gb):
    assert gb.success, gb.message
    for name, (lo, hi) in gb.ci95.items():
        assert lo <= getattr(TRUTH, name) <= hi, (name, lo, getattr(TRUTH, name), hi)
