"""``eha study lse|tf``: the command over eha_core.study."""

import json
import subprocess
import sys

import pytest

from eha_app.cli import main
from eha_core.study import StudyConfig, run_study


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_lse_json_holds_every_seed_and_the_summary(capsys):
    code, out, err = run(capsys, "study", "lse", "--seeds", "3", "--first-seed", "5", "--workers", "1", "--json")
    assert code == 0 and err == ""               # no progress line: stderr is not a terminal
    data = json.loads(out)
    assert {"coverage", "mean", "std", "nominal", "n_seeds", "settings", "seeds"} <= set(data)
    assert data["n_seeds"] == 3 and data["n_completed"] == 3 and data["kind"] == "lse"
    assert data["settings"]["disturbance"] == "white:1000" and data["settings"]["first_seed"] == 5
    names = ["M", "B", "Af", "d0", "beta_e"]
    assert data["parameters"] == names
    for key in ("coverage", "mean", "std", "mean_std_error", "nominal"):
        assert set(data[key]) == set(names), key
    assert all(0.0 <= data["coverage"][k] <= 1.0 for k in names)
    assert [s["seed"] for s in data["seeds"]] == [5, 6, 7]
    core = run_study(StudyConfig("lse", n_seeds=3, first_seed=5), workers=1)
    for mine, theirs in zip(data["seeds"], core.seeds, strict=True):
        assert mine["estimates"] == pytest.approx(theirs.estimates, rel=1e-15)
        assert mine["std_errors"] == pytest.approx(theirs.std_errors, rel=1e-15)
    assert data["coverage"] == core.coverage and data["mean"] == pytest.approx(core.mean, rel=1e-15)


def test_lse_table_and_sensor_noise(capsys):
    code, out, err = run(capsys, "study", "lse", "--seeds", "2", "--disturbance", "sine:5000:1",
                         "--disturbance-model", "harmonic:1", "--noise", "p1=1e4", "--noise", "p2=1e4")
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0] == ("study: least squares, disturbance sine:5000:1, disturbance model harmonic, "
                        "sensor noise p1=10000, p2=10000")
    header = next(line for line in lines if line.startswith("parameter"))
    assert header.split() == ["parameter", "nominal", "mean", "std", "mean", "std", "err", "bias/se", "coverage"]
    rows = {line.split()[0]: line.split() for line in lines[lines.index(header) + 1:] if line.split()}
    assert {"M", "B", "Af", "d0", "d_sin", "d_cos", "beta_e"} <= set(rows)
    assert float(rows["d_sin"][1]) == 5000 and float(rows["M"][1]) == 4000
    assert any(line.startswith("coverage: ") for line in lines)


def test_tf_json_on_the_linear_plant(capsys):
    code, out, err = run(capsys, "study", "tf", "--seeds", "2", "--model", "linear", "--noise", "2e-4", "--json")
    assert code == 0 and err == ""
    data = json.loads(out)
    assert data["parameters"] == ["a1", "a2", "a3", "b0"] and data["nominal_is_truth"] is True
    assert data["settings"]["model"] == "linear" and data["settings"]["noise_m"] == 2e-4
    assert data["nominal"]["a1"] == pytest.approx(430.1, rel=1e-3)
    assert set(data["coverage"]) == {"a1", "a2", "a3", "b0"} and len(data["seeds"]) == 2
    assert data["std"]["a1"] is not None


@pytest.mark.parametrize("argv, message", [
    (["lse", "--seeds", "0"], "--seeds = 0 is not allowed: use 1 to 1000 seeds"),
    (["tf", "--seeds", "1001"], "--seeds = 1001 is not allowed: use 1 to 1000 seeds"),
    (["lse", "--seeds", "3", "--workers", "0"], "--workers = 0 is not allowed: use 1 to 16 threads"),
    (["lse", "--seeds", "3", "--first-seed", "-2"], "--first-seed = -2 is not allowed"),
    (["lse", "--seeds", "3", "--disturbance", "white:1000:4"],
     "--disturbance = white:1000:4 is not allowed: its noise"),
    (["lse", "--seeds", "3", "--disturbance", "sine:x"], "--disturbance = sine:x is not allowed"),
    (["lse", "--seeds", "3", "--disturbance-model", "cubic"], "--disturbance-model = cubic is not allowed"),
    (["lse", "--seeds", "3", "--noise", "1e4"], "--noise = 1e4 is not allowed: give SIGNAL=SIGMA[UNIT]"),
    (["lse", "--seeds", "3", "--noise", "p1=-5"], "--noise = p1=-5 is not allowed"),
    (["lse", "--seeds", "3", "--model", "linear"], "--model = linear is not allowed: the least squares"),
    (["lse", "--seeds", "3", "--t-end", "0"], "--t-end = 0 is not allowed"),
    (["tf", "--seeds", "3", "--model", "arx"], "--model = arx is not allowed: use nonlinear or linear"),
    (["lse", "--seeds", "3", "--estimator", "ols"], "--estimator = ols is not allowed: use ls (the paper's"),
    (["lse", "--seeds", "3", "--intervals", "boot"], "--intervals = boot is not allowed: use newey-west or ewc"),
    (["tf", "--seeds", "3", "--estimator", "iv"], "unrecognized arguments: --estimator iv"),
    (["tf", "--seeds", "3", "--noise", "-1"], "--noise = -1 is not allowed"),
    (["lse"], "the following arguments are required: --seeds"),
    ([], "study needs a METHOD: lse, tf, greybox or grading"),
])
def test_bad_arguments_get_one_line_and_exit_code_2(capsys, argv, message):
    code, out, err = run(capsys, "study", *argv)
    assert code == 2 and out == ""
    assert err.startswith(f"eha: error: {message}") and err.count("\n") == 1, err


def test_arguments_are_refused_before_the_estimators_are_imported():
    code = ("import sys; from eha_app.cli import main; "
            "rc = main(['study', 'lse', '--seeds', '0']); "
            "print(rc, ' '.join(m for m in ('scipy', 'numba') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "2"
    assert out.stderr.strip() == "eha: error: --seeds = 0 is not allowed: use 1 to 1000 seeds"


def test_lse_with_the_iv_estimator_reports_its_bias_against_the_standard_errors(capsys):
    code, out, err = run(capsys, "study", "lse", "--seeds", "4", "--estimator", "iv", "--json")
    assert code == 0 and err == ""
    data = json.loads(out)
    assert data["settings"]["estimator"] == "iv" and data["settings"]["intervals"] == "ewc"
    core = run_study(StudyConfig("lse", n_seeds=4, estimator="iv"), workers=1)
    assert data["bias_per_std_error"] == pytest.approx(core.bias_per_std_error, rel=1e-12)
    assert data["seeds"][0]["critical_value"] == pytest.approx(2.1314, abs=1e-4)
    code, out, err = run(capsys, "study", "lse", "--seeds", "2", "--estimator", "iv", "--intervals", "newey-west")
    assert code == 0 and out.splitlines()[0].startswith("study: instrumental variables with newey-west intervals, ")
    assert any(line.startswith("bias/se: ") for line in out.splitlines())
