import io
import json
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from eha_app.cli import main
from eha_core.experiments import PAPER_CASES
from eha_core.simulate import simulate


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_simulate_case_csv_matches_the_core(capsys):
    code, out, err = run(capsys, "simulate", "--case", "3", "--t-end", "1")
    assert code == 0 and err == ""
    df = pd.read_csv(io.StringIO(out))
    assert list(df.columns) == ["t", "x", "v", "p1", "p2", "u", "d"]
    assert len(df) == 1001
    ref = simulate(u=PAPER_CASES[3].u, d=PAPER_CASES[3].d, t_end=1.0)
    np.testing.assert_allclose(df["x"], ref.x, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(df["p2"], ref.p2, rtol=1e-9)


def test_simulate_linear_is_absolute_and_custom_inputs(capsys, tmp_path):
    out_file = tmp_path / "run.csv"
    code, out, _ = run(capsys, "simulate", "--model", "linear", "--u", "sine:6:2", "--d", "sine:5e3:1",
                       "--t-end", "0.5", "--dt", "0.01", "--param", "M=5000", "--out", str(out_file))
    assert code == 0 and out == ""
    df = pd.read_csv(out_file)
    assert len(df) == 51
    assert df["p1"].iloc[0] == pytest.approx(12e6)           # absolute, operating point added back
    np.testing.assert_allclose(df["d"], 5e3 * np.sin(2 * np.pi * df["t"]), atol=1e-6)


def test_linearize_json(capsys):
    code, out, _ = run(capsys, "linearize", "--json")
    assert code == 0
    data = json.loads(out)
    assert set(data) >= {"operating_point", "lambdas", "A", "B", "tf", "closed_loop_tf"}
    assert data["operating_point"] == pytest.approx({"x": 0, "v": 0, "p1": 12e6, "p2": 18.18947e6, "u": 0}, rel=1e-6)
    assert len(data["lambdas"]) == 6
    np.testing.assert_allclose(data["tf"]["num"], [243.7], rtol=2e-4)
    np.testing.assert_allclose(data["tf"]["den"], [1, 430.1, 1.721e4, 0], rtol=3e-4)
    np.testing.assert_allclose(data["closed_loop_tf"]["den"], [1, 430.1, 1.721e4, 2437], rtol=3e-4)
    assert np.array(data["A"]).shape == (4, 4)
    code, out, _ = run(capsys, "linearize", "--json", "--kp", "20", "--param", "beta_e=5e8")
    np.testing.assert_allclose(json.loads(out)["closed_loop_tf"]["num"][0], 20 * json.loads(out)["tf"]["num"][0])


@pytest.mark.parametrize("argv, words", [
    (["simulate", "--case", "7"], "--case = 7"),
    (["simulate", "--case", "x"], "--case"),
    (["simulate", "--case", "1", "--param", "M=-1"], "M = -1"),
    (["simulate", "--case", "1", "--param", "mass=1"], "mass"),
    (["simulate", "--case", "1", "--param", "M=abc"], "M = abc"),
    (["simulate", "--case", "1", "--param", "dc=0.2"], "dc = 0.2"),
    (["simulate", "--case", "1", "--model", "cubic"], "--model = cubic"),
    (["simulate", "--case", "1", "--dt", "0.003"], "dt = 0.003"),
    (["simulate", "--u", "sine:a:2"], "--u = sine:a:2"),
    (["simulate", "--d", "wobble:3"], "wobble"),
    (["simulate"], "--case or --u"),
    (["simulate", "--case", "1", "--t-end", "-3"], "--t-end = -3"),
    (["linearize", "--kp", "0"], "kp = 0"),
    (["linearize", "--kp", "ten"], "--kp"),
    (["frobnicate"], "frobnicate"),
])
def test_bad_input_one_line_exit_2(capsys, argv, words):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("eha: error: ")
    assert words in err
    assert "Traceback" not in err


def test_installed_command_exit_code_and_stderr():
    proc = subprocess.run([sys.executable, "-m", "eha_app.cli", "simulate", "--case", "5"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "eha: error: --case = 5 is not allowed: use one of 1, 2, 3, 4"


def test_idinput_csv_and_json_match_the_core(capsys):
    from eha_core.excitation import idinput

    code, out, _ = run(capsys, "idinput", "--type", "sine", "--n", "1000", "--band", "0", "1",
                       "--range", "-1", "1", "--sinedata", "100", "50", "1", "--seed", "3")
    assert code == 0
    df = pd.read_csv(io.StringIO(out))
    ex = idinput(1000, "sine", (0, 1), (-1, 1), (100, 50, 1), seed=3)
    assert list(df.columns) == ["k", "u"]
    np.testing.assert_allclose(df["u"], ex.u, rtol=1e-9, atol=1e-12)
    code, out, _ = run(capsys, "idinput", "--type", "sine", "--n", "1000", "--sinedata", "100", "50", "1",
                       "--seed", "3", "--json")
    data = json.loads(out)
    assert len(data["u"]) == 1000 and len(data["freqs"]) == 100
    np.testing.assert_allclose(data["freqs"], ex.freqs)


def test_identify_lse_json(capsys):
    code, out, _ = run(capsys, "identify", "lse", "--disturbance", "sine:5000", "--disturbance-model", "harmonic",
                       "--json")
    assert code == 0
    data = json.loads(out)
    assert set(data) >= {"estimates", "std_errors", "ci95"}
    assert set(data["estimates"]) >= {"M", "B", "Af", "d0", "beta_e"}
    assert data["estimates"]["B"] == pytest.approx(1500, rel=0.02)
    lo, hi = data["ci95"]["M"]
    assert lo <= data["estimates"]["M"] <= hi


def test_identify_lse_with_the_iv_estimator(capsys):
    code, out, _ = run(capsys, "identify", "lse", "--disturbance", "white:2000", "--seed", "1", "--estimator", "iv",
                       "--json")
    assert code == 0
    data = json.loads(out)
    assert (data["estimator"], data["intervals"], data["cosine_terms"]) == ("iv", "ewc", 15)
    assert data["iterations"] >= 1 and data["estimates"]["M"] == pytest.approx(4000, rel=0.03)
    lo, hi = data["ci95"]["M"]
    assert (hi - lo) / 2 == pytest.approx(data["critical_value"] * data["std_errors"]["M"], rel=1e-9)
    code, out, _ = run(capsys, "identify", "lse", "--disturbance", "white:2000", "--estimator", "iv")
    lines = out.splitlines()
    assert code == 0 and lines[0].startswith("instrumental variables (simulation: ")
    assert lines[-1] == "95 % interval: estimate +- 2.131 standard errors (Student's t, 15 equal-weighted cosines)"


def test_identify_lse_from_a_csv(capsys, tmp_path):
    from eha_core.experiments import lse_simulation

    path = tmp_path / "meas.csv"
    lse_simulation(disturbance="none").to_csv(path)
    code, out, _ = run(capsys, "identify", "lse", "--data", str(path), "--json")
    assert code == 0
    assert json.loads(out)["estimates"]["M"] == pytest.approx(4000, rel=1e-3)


def test_identify_tf_on_data_recovers_a_known_system(capsys, tmp_path):
    from eha_core.identify.validate import simulate_tf

    ts = 0.01
    u = np.sign(np.sin(2 * np.pi * 0.4 * ts * np.arange(1500)))
    y = simulate_tf([2437.0], [1.0, 430.1, 1.721e4, 2437.0], u, ts)
    path = tmp_path / "io.csv"
    pd.DataFrame({"t": ts * np.arange(u.size), "u": u, "y": y}).to_csv(path, index=False, float_format="%.17g")
    code, out, _ = run(capsys, "identify", "tf", "--data", str(path), "--json")
    assert code == 0
    data = json.loads(out)
    np.testing.assert_allclose(data["den"], [1.0, 430.1, 1.721e4, 2437.0], rtol=1e-6)
    assert data["fit_percent"] == pytest.approx(100.0, abs=1e-4)
    assert data["initial_condition"] == "zero"


def test_identify_tf_paper_experiment_json(capsys):
    code, out, _ = run(capsys, "identify", "tf", "--json")
    assert code == 0
    data = json.loads(out)
    assert set(data) >= {"num", "den", "fit_percent", "initial_condition", "open_loop", "backout"}
    assert data["den"][0] == 1.0 and len(data["den"]) == 4
    assert data["den"][1] < 50


@pytest.mark.parametrize("argv, words", [
    (["idinput", "--type", "pink", "--n", "10"], "pink"),
    (["idinput", "--n", "0"], "n"),
    (["idinput", "--n", "100", "--band", "0.6", "0.2"], "band"),
    (["identify"], "METHOD"),
    (["identify", "lse", "--disturbance", "gust"], "--disturbance = gust"),
    (["identify", "lse", "--disturbance-model", "cubic"], "--disturbance-model"),
    (["identify", "lse", "--disturbance-model", "harmonic:x"], "--disturbance-model"),
    (["identify", "lse", "--data", "/nonexistent.csv"], "nonexistent"),
    (["identify", "lse", "--estimator", "ols"], "--estimator = ols is not allowed: use ls (the paper's least"),
    (["identify", "lse", "--estimator", "iv", "--intervals", "hac"], "--intervals = hac is not allowed: use "),
    (["identify", "tf", "--np", "0"], "--np = 0"),
    (["identify", "tf", "--model", "soft"], "--model = soft"),
    (["identify", "tf", "--data", "/nonexistent.csv"], "nonexistent"),
])
def test_identification_bad_input(capsys, argv, words):
    code, out, err = run(capsys, *argv)
    assert code == 2 and err.count("\n") == 1 and words in err


# -- what a newcomer hit -------------------------------------------------------------------

def test_every_size_argument_has_a_limit(capsys):
    code, _, err = run(capsys, "idinput", "--n", "1000000000000")
    assert code == 2 and err == "eha: error: --n = 1000000000000 is not allowed: use 1 to 10000000 samples\n"
    code, _, err = run(capsys, "idinput", "--type", "sine", "--n", "1000000", "--sinedata", "10", "500", "1")
    assert code == 2 and "--sinedata NT = 500 is not allowed with --n 1000000" in err
    code, _, err = run(capsys, "identify", "lse", "--t-end", "1e9")
    assert code == 2 and "--t-end = 1e+09 is not allowed" in err
    code, _, err = run(capsys, "identify", "tf", "--np", "40")
    assert code == 2 and "--np = 40 is not allowed: use 1 to 8 poles" in err


def test_an_output_that_cannot_be_written_is_refused_before_computing(capsys, monkeypatch):
    import eha_core.simulate as sim

    def never(*a, **k):
        raise AssertionError("simulated although the output cannot be written")
    monkeypatch.setattr(sim, "simulate", never)
    code, out, err = run(capsys, "simulate", "--case", "1", "--out", "/nonexistent/dir/x.csv")
    assert code == 2 and out == ""
    assert err == "eha: error: --out = '/nonexistent/dir/x.csv' is not allowed: the folder '/nonexistent/dir' " \
                  "does not exist\n"


def test_a_notice_of_the_core_is_one_plain_line(capsys):
    code, out, err = run(capsys, "idinput", "--type", "prbs", "--n", "127", "--band", "0", "0.5", "--json")
    assert code == 0 and json.loads(out)["u"]
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("eha: note: idinput:")
    assert "UserWarning" not in err and "warnings.warn" not in err


def test_a_branch_with_the_nonlinear_model_is_refused(capsys):
    code, _, err = run(capsys, "simulate", "--case", "1", "--branch", "positive")
    assert code == 2 and "--branch = positive is not allowed with --model nonlinear" in err
    code, out, _ = run(capsys, "simulate", "--case", "1", "--model", "linear", "--branch", "positive",
                       "--t-end", "0.1")
    assert code == 0 and len(out.splitlines()) == 102


def test_a_bad_cell_is_named_by_file_column_and_row_in_both_identifications(capsys, tmp_path):
    tf_file, lse_file = tmp_path / "tf.csv", tmp_path / "lse.csv"
    tf_file.write_text("t,u,y\n0,1,0\n0.01,1,abc\n0.02,1,0.5\n")
    code, _, err = run(capsys, "identify", "tf", "--data", str(tf_file))
    assert code == 2
    assert err == f"eha: error: --data = {str(tf_file)!r} is not allowed: column y, row 2 (line 3): 'abc' is not a " \
                  f"number\n"
    rows = "\n".join(f"{k * 1e-3},0,0,12e6,18e6,{'x' if k == 7 else 0}" for k in range(60))
    lse_file.write_text("t,x,v,p1,p2,u\n" + rows + "\n")
    code, _, err = run(capsys, "identify", "lse", "--data", str(lse_file))
    assert code == 2
    assert err == f"eha: error: --data = {str(lse_file)!r} is not allowed: column u, row 8 (line 9): 'x' is not a " \
                  f"number\n"


def test_a_port_in_use_is_refused_before_anything_starts(capsys):
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, out, err = run(capsys, "serve", "--port", str(port))
    assert code == 2 and out == ""
    assert err.startswith(f"eha: error: --port = {port} is not allowed: 127.0.0.1:{port} is in use")


@pytest.mark.parametrize("argv", [["identify", "tf", "--np", "0"], ["identify", "lse", "--disturbance", "gust"],
                                  ["identify", "tf", "--data", "/nonexistent.csv"],
                                  ["identify", "lse", "--estimator", "ols"]])
def test_bad_identification_arguments_are_refused_before_the_estimators_load(argv):
    code = (f"import sys; from eha_app.cli import main; code = main({argv!r}); "
            "print(code, 'scipy' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["2", "False", "False"], out.stderr


def test_exercise_commands(capsys, tmp_path):
    path = str(tmp_path / "class.json")
    assert main(["exercise", "new", "--hide", "M,B", "--vary", "20%", "--tolerance", "5%", "--out", path]) == 0
    assert "hides M, B" in capsys.readouterr().out
    assert main(["exercise", "new", "--hide", "M", "--out", path]) == 2          # would change every actuator
    assert "it exists" in capsys.readouterr().err
    assert main(["exercise", "new", "--hide", "M,p2_0", "--out", str(tmp_path / "b.json")]) == 2
    assert "--hide = M,p2_0 is not allowed: p2_0 cannot be hidden" in capsys.readouterr().err
    assert main(["exercise", "new", "--hide", "M", "--vary", "lots", "--out", str(tmp_path / "c.json")]) == 2
    assert "--vary = lots is not allowed" in capsys.readouterr().err
    from eha_app.runtime.handins import HandIns

    HandIns(path).check().seen("ada")
    assert main(["exercise", "reveal", path, "--student", " Ada "]) == 0
    out = capsys.readouterr().out
    from eha_core.exercise import Exercise

    truth = Exercise.load(path).student_params("ada")
    # by default every route that exists may be handed in from, grey-box identification included
    assert Exercise.load(path).conditions.methods == ("lse", "frequency", "greybox")
    assert f"M = {truth.M:.6g} kg" in out and f"B = {truth.B:.6g} N s/m" in out
    assert main(["exercise", "results", path]) == 0
    assert "0 students handed in" in capsys.readouterr().out
    # an open exercise: only an id that joined has an actuator to reveal
    from eha_app.runtime.handins import HandIns

    HandIns(path).check().seen("ada")
    assert main(["exercise", "reveal", path, "--student", "nobody"]) == 2
    assert "--student = nobody is not allowed: no student with this id has joined" in capsys.readouterr().err
    assert main(["exercise", "results", str(tmp_path / "nothere.json")]) == 2
    (tmp_path / "bad.json").write_text("{}")
    assert main(["exercise", "results", str(tmp_path / "bad.json")]) == 2
    assert "not an exercise file" in capsys.readouterr().err
    assert main(["serve", "--exercise", str(tmp_path / "bad.json")]) == 2


def test_identify_tf_says_when_p_hat_is_unstable(capsys):
    code, out, _ = run(capsys, "identify", "tf")
    assert code == 0
    lines = out.splitlines()
    p_hat = next(line for line in lines if line.startswith("P_hat(s) ="))
    # the paper's experiment: H_hat(0) = 1.025 puts a small positive pole in P_hat. Its constant term
    # and pole follow the simulated record: simulated to ~1e-7 of the range now (the fixed-step RK4
    # straddled the square's edges at ~1e-3 of it and gave 52.15 and +0.00305); 1 % leaves room for
    # rounding in the fit, and no room for an integrator error at the edges
    const = float(re.search(r"s - ([0-9.]+)\)$", p_hat).group(1))
    assert const == pytest.approx(51.9, rel=0.01)
    unstable = [line for line in lines if line.startswith("P_hat(s) is unstable: a pole at +")]
    assert len(unstable) == 1 and "H_hat(0) = 1.025 > 1" in unstable[0]
    pole = float(re.search(r"a pole at \+([0-9.e-]+) rad/s", unstable[0]).group(1))
    assert pole == pytest.approx(0.00304, rel=0.01)


def test_a_roster_gives_every_student_a_code_and_reveal_knows_only_the_roster(capsys, tmp_path):
    roster = tmp_path / "class.csv"
    roster.write_text("id,name,email\ns1,Ada Lovelace,a@x\ns2,=HYPERLINK(\"http://x\"),b@x\n", encoding="utf-8")
    path = str(tmp_path / "lab.json")
    assert main(["exercise", "new", "--roster", str(roster), "--tolerance", "M=3%,beta_e=10%", "--attempts", "2",
                 "--deadline", "2030-01-01T17:00", "--feedback", "after-deadline", "--hide", "M,B,Af,beta_e,Kq1,d0",
                 "--out", path]) == 0
    out = capsys.readouterr().out
    assert "M ±3 %" in out and "beta_e ±10 %" in out and "B ±5 %" in out and "roster: 2 students" in out
    assert "sensor noise σ x ≥ 0.01 mm" in out
    text = open(path, encoding="utf-8").read()
    assert main(["exercise", "codes", path, "--csv", str(tmp_path / "codes.csv")]) == 0
    lines = capsys.readouterr().out.splitlines()
    codes = [line.split()[0] for line in lines]
    assert len(codes) == 2 and all(len(c.replace("-", "")) == 10 for c in codes) and codes[0] != codes[1]
    assert not any(c in text or c.replace("-", "") in text for c in codes)       # the file keeps only hashes
    assert "'=HYPERLINK" in (tmp_path / "codes.csv").read_text()                  # neutralised in the CSV
    from eha_core.exercise import Exercise

    ex = Exercise.load(path)
    assert ex.entry_for_code(codes[1]).id == "s2" and ex.tolerance_of("M") == 0.03 and ex.attempts == 2
    assert main(["exercise", "reveal", path, "--student", "s3"]) == 2
    assert "--student = s3 is not allowed: no student with this id in the exercise's roster" in capsys.readouterr().err
    assert main(["exercise", "reveal", path, "--student", "S1 "]) == 0
    assert f"Kq1 = {ex.student_params('s1').Kq1:.6g}" in capsys.readouterr().out
    assert main(["exercise", "results", path]) == 0
    out = capsys.readouterr().out
    assert "0 students handed in of 2 in the roster" in out and "Ada Lovelace" in out
    for bad, message in ((["--deadline", "friday"], "--deadline = friday is not allowed"),
                         (["--tolerance", "Q=3%"], "--tolerance = Q=3% is not allowed: Q is not hidden"),
                         (["--noise", "y=1mm"], "--noise = y=1mm is not allowed: y is not a signal"),
                         (["--measured", "v,p1"], "--measured = v,p1 is not allowed: the position x must be measured"),
                         (["--roster", str(tmp_path / "none.csv")], "--roster")):
        assert main(["exercise", "new", *bad, "--out", str(tmp_path / "x.json")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_serve_passes_panels_oauth_settings_on():
    from eha_app.cli import build_parser
    from eha_app.cli.serve import _oauth_argv

    args = build_parser().parse_args(["serve", "--oauth-provider", "generic", "--oauth-key", "eha-lab",
                                      "--cookie-secret", "x" * 40])
    assert _oauth_argv(args) == ["--oauth-provider", "generic", "--oauth-key", "eha-lab", "--cookie-secret", "x" * 40]
    assert _oauth_argv(build_parser().parse_args(["serve"])) == []


def test_serve_refuses_an_exercise_in_a_folder_it_cannot_write_to(tmp_path, capsys, monkeypatch):
    import os

    from eha_core.exercise import Exercise

    path = tmp_path / "lab.json"
    Exercise.new(hide=("M",)).save(path)
    real = os.access
    # (as root a read-only folder stays writable: the check is what is tested)
    monkeypatch.setattr(os, "access", lambda p, mode: False if str(p) == str(tmp_path) and mode == os.W_OK
                        else real(p, mode))
    assert main(["serve", "--exercise", str(path)]) == 2
    err = capsys.readouterr().err
    assert "is read-only; the server could not store a single hand-in" in err and len(err.strip().splitlines()) == 1


def test_identify_greybox_gives_the_issues_json_and_refuses_bad_names(capsys):
    import json

    code = main(["identify", "greybox", "--param", "M=5200", "--t-end", "3", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and {"estimates", "std_errors", "ci95", "correlation", "fit", "success", "message", "nfev",
                          "time_s"} <= set(out)
    assert abs(out["estimates"]["M"] - 5200) < 4 * out["std_errors"]["M"] and out["true"]["M"] == 5200
    assert out["ci95"]["M"][0] < out["estimates"]["M"] < out["ci95"]["M"][1] and set(out["fit"]) == {"x", "p1", "p2"}
    for argv, message in ((["--params", "M,Q"], "--params = M,Q is not allowed: Q is not one of"),
                          (["--measured", "x,y"], "--measured = x,y is not allowed: y is not one of"),
                          (["--t-end", "0"], "--t-end = 0"), (["--noise", "q=1"], "--noise = q=1 is not allowed")):
        assert main(["identify", "greybox", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_identify_greybox_reads_a_record_from_a_file(capsys, tmp_path):
    import json

    import numpy as np

    from eha_core.experiments import LSE_INPUT
    from eha_core.identify.greybox import greybox_data
    from eha_core.params import ActuatorParams

    truth = ActuatorParams(M=4800.0, beta_e=1.0e9)
    data = greybox_data(truth, LSE_INPUT, t_end=3.0, noise={"x": 1e-5, "p1": 5e4, "p2": 5e4}, seed=4,
                        measured=("x", "p1", "p2"))
    rows = np.column_stack([data.t, data.u, data.signals["x"], data.signals["p1"] / 1e6, data.signals["p2"] / 1e6])
    path = tmp_path / "rig.csv"
    np.savetxt(path, rows, delimiter=",", header="t[s],u[V],x[m],p1[MPa],p2[MPa]", comments="")
    assert main(["identify", "greybox", "--data", str(path), "--params", "M,beta_e", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for n, v in (("M", 4800.0), ("beta_e", 1.0e9)):
        assert abs(out["estimates"][n] - v) < 4 * out["std_errors"][n], n
    assert out["source"] == str(path) and "true" not in out
    assert main(["identify", "greybox", "--data", str(path), "--measured", "x,v"]) == 2
    assert "is not allowed: no column v: the file has t[s], u[V], x[m], p1[MPa], p2[MPa]" in capsys.readouterr().err
