"""`eha reproduce`: every section, numbers equal to the core's, sentences from the numbers."""

import io
import json

import numpy as np
import pandas as pd
import pytest

from eha_app.cli import main
from eha_app.render.formatting import estimate_texts, num_html
from eha_app.render.report import SECTIONS, build_report
from eha_core.experiments import FrequencyExperiment, run_frequency_identification, run_lse_table, run_paper_cases
from eha_core.params import ActuatorParams
from eha_core.reproduction import ReproductionSettings

SETTINGS = ReproductionSettings(seed=3)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    stream = io.StringIO()
    result = build_report(out, seed=SETTINGS.seed, stream=stream)
    return out, result, stream.getvalue()


def test_every_section_is_present(report):
    out, result, progress = report
    page = (out / "report.html").read_text(encoding="utf-8")
    for sid in SECTIONS:
        assert f'<section id="{sid}">' in page
    assert page.count('class="fig"') >= 12                      # Figs. 2, 3, 4-7, 8, 9, 11, 12, 13, residuals
    # self-contained: no script or stylesheet loaded from anywhere else
    assert "<script src=" not in page and "<link " not in page
    assert "[8/8] writing report.html" in progress and "report written in" in progress
    for name in ("numpy", "scipy", "control", "numba", "bokeh", "panel"):
        assert f"<td>{name}</td>" in page
    assert "Seed 3" in page
    # the three routes side by side: the least squares' and grey-box's M on Table 3's record, eq. 27's damping
    routes = page.split('<section id="routes">')[1].split("</section>")[0]
    gb = result.reproduction.greybox
    assert estimate_texts(gb.estimates["M"], *gb.ci95["M"])[0] in routes and "not run" not in routes
    assert abs(result.reproduction.greybox.estimates["M"] / 4000.0 - 1) < 1e-3


def test_table_numbers_equal_the_core_functions(report):
    out, result, _ = report
    numbers = json.loads((out / "data" / "results.json").read_text())
    page = (out / "report.html").read_text(encoding="utf-8")
    p = ActuatorParams()
    for model in ("constant", "harmonic"):
        table = run_lse_table(p, disturbance_model=model, seed=SETTINGS.seed, t_end=SETTINGS.lse_t_end)
        rows = [r for r in numbers["least_squares"] if r["model"] == model]
        assert len(rows) == sum(len(res.estimates) for res in table.values())
        for r in rows:
            res = table[r["scenario"]]
            assert r["estimate"] == res.estimates[r["parameter"]]
            assert [r["ci95_lo"], r["ci95_hi"]] == list(res.ci95[r["parameter"]])
        for res in table.values():
            assert estimate_texts(res.estimates["M"], *res.ci95["M"])[0] in page
    fi = run_frequency_identification(p, FrequencyExperiment(seed=SETTINGS.seed, n_samples=SETTINGS.freq_samples))
    assert numbers["hhat_den"] == list(fi.estimate.den)
    assert numbers["hhat_num"] == list(fi.estimate.num)
    assert numbers["fit_percent"] == fi.estimate.fit_percent
    assert f"{fi.estimate.fit_percent:.2f} %" in page
    assert numbers["beta_e_stiffness"] == fi.backout.beta_e_from_stiffness


def test_data_files_match_the_simulations(report):
    out, _, _ = report
    df = pd.read_csv(out / "data" / "fig2_nonlinear.csv")
    runs = run_paper_cases(ActuatorParams(), "nonlinear", t_end=SETTINGS.case_t_end)
    case3 = df[df["run"] == "Case 3"]
    np.testing.assert_allclose(case3["x"], runs[2].x, rtol=1e-9, atol=1e-15)
    diffs = pd.read_csv(out / "data" / "figs4-7_differences.csv")
    linear = run_paper_cases(ActuatorParams(), "linear", t_end=SETTINGS.case_t_end)
    d = (runs[0].p1 - linear[0].p1) * 1e-6
    row = diffs[(diffs["case"] == "Case 1") & (diffs["state"] == "p1")].iloc[0]
    assert row["max"] == pytest.approx(np.abs(d).max(), rel=1e-9)
    for name in ("parameters.csv", "fig8_excitation.csv", "fig9_closed_loop.csv", "fig12_bode.csv",
                 "fig13_validation.csv", "tables3-4_least_squares.csv"):
        assert (out / "data" / name).stat().st_size > 0


def test_the_differences_are_filled_from_numbers(report):
    out, _, _ = report
    numbers = json.loads((out / "data" / "results.json").read_text())
    items = numbers["differences_from_paper"]
    assert len(items) >= 6
    joined = " ".join(items)
    assert f"{numbers['fit_percent']:.2f} %" in joined
    assert f"{numbers['hhat_den'][1]:.4g}" in joined


def test_reproduce_command_line_errors(capsys, tmp_path):
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    assert main(["reproduce", "--out", str(afile)]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main(["reproduce", "--seed", "-1", "--out", str(tmp_path / "r")]) == 2


def test_sentences_follow_the_parameters_not_the_papers(tmp_path):
    """Other parameters: the report's statements speak of them (no 1.1e9 or 1500 written in)."""
    p = ActuatorParams(beta_e=0.9e9, B=1200.0)
    result = build_report(tmp_path / "other", params=p, stream=io.StringIO())
    numbers = result.numbers
    assert numbers["params"]["beta_e"] == 0.9e9 and numbers["params"]["B"] == 1200.0
    joined = " ".join(numbers["differences_from_paper"])
    stiffness = numbers["beta_e_stiffness"]
    assert f"({100 * (stiffness / 0.9e9 - 1):+.2f} %)" in joined
    assert f"{100 * numbers['b_se_default'] / 1200.0:.0f} %" in joined
    page = result.path.read_text(encoding="utf-8")
    assert "1.2·10<sup>3</sup>" in page or "1200" in page


def test_numbers_of_any_size_are_written():
    """Found by the long random walk: a subnormal value typed on tab 1 (5e-324) broke Table 4, the least
    squares' table and the report (10**-324 is 0.0 in floating point)."""
    assert num_html(5e-324) == "4.941·10<sup>-324</sup>"
    assert num_html(-2.5e-310, 5) == "-2.5·10<sup>-310</sup>"
    assert num_html(1.7e308) == "1.7·10<sup>308</sup>"
    assert num_html(9999.7) == "1·10<sup>4</sup>" and num_html(17210.0) == "1.721·10<sup>4</sup>"
    assert num_html(0.0012345) == "0.001234" and num_html(0.00012345) == "1.234·10<sup>-4</sup>"


def test_a_least_squares_table_with_no_textbook_interval_is_written():
    """Found by the long random walk: when every textbook standard error was zero (an exact fit), the
    table's note failed ('max() arg is an empty sequence') and the least squares showed nothing."""
    import dataclasses

    from eha_app.render.tables import lse_table_html
    from eha_core.experiments import run_lse

    res = run_lse(disturbance="none")
    html = lse_table_html(res, "none")
    assert "textbook intervals are up to" in html
    exact = dataclasses.replace(res, std_errors_textbook={k: 0.0 for k in res.std_errors_textbook})
    html = lse_table_html(exact, "none")
    assert "narrower" not in html and "lags (the prefilter colours the residual)." in html
