"""``eha identify arx|armax|oe|bj|ss|process|select``, run as a user runs them: in a subprocess.

Each subcommand prints its model, the parameters with standard errors, the fits on estimation and
validation data in the same words, and the residual tests; ``--json`` parses; ``--out`` writes a
model whose polynomials reproduce the printed validation fit; bad input ends with one line on stderr
naming the option and the value as typed, and exit code 2, before anything heavy is imported.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest
import scipy.signal

#: The system of the records: a first-order lag K / (1 + T s), K = 2, T = 0.5 s, held input at ts = 0.05 s,
#: one sample of delay: y = 0.19 q^-1 / (1 - 0.905 q^-1) u + white noise (an output-error system).
TS = 0.05
POLE = float(np.exp(-TS / 0.5))
B_TRUE, A_TRUE = [0.0, 2.0 * (1 - POLE)], [1.0, -POLE]


def write_record(path, seed: int, n: int = 300, ts: float = TS) -> str:
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], n // 5 + 1), 5)[:n]           # a random binary input held 5 samples
    y = scipy.signal.lfilter(B_TRUE, A_TRUE, u) + 0.05 * rng.standard_normal(n)
    np.savetxt(path, np.column_stack([np.arange(n) * ts, u, y]), delimiter=",", header="t,u,y", comments="")
    return str(path)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("blackbox")
    return {"est": write_record(folder / "est.csv", 1), "est2": write_record(folder / "est2.csv", 2),
            "val": write_record(folder / "val.csv", 3), "slow": write_record(folder / "slow.csv", 4, ts=0.1),
            "short": write_record(folder / "short.csv", 5, n=60),
            "folder": folder}


def eha(*argv, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eha_app.cli", *argv], capture_output=True, text=True, timeout=120,
                          cwd=cwd)


FIT_LINE = re.compile(r"^validation data \((?P<data>.+)\): fit (?P<fit>-?[\d.]+) % \(simulation, zero initial "
                      r"conditions\)$", re.M)


@pytest.mark.parametrize("argv", [
    ["arx", "--na", "1", "--nb", "1"],
    ["armax", "--na", "1", "--nb", "1", "--nc", "1"],
    ["oe", "--nb", "1", "--nf", "1"],
    ["bj", "--nb", "1", "--nc", "1", "--nd", "0", "--nf", "1"],
    ["ss", "--n", "1"],
    ["process", "--kind", "P1D"],
])
def test_each_subcommand_prints_its_model_fits_and_residual_tests(files, argv):
    proc = eha("identify", *argv, "--data", files["est"], "--val-data", files["val"])
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    out = proc.stdout
    assert re.search(r"^\s+parameter\s+estimate\s+std error\s+95 % interval$", out, re.M)
    assert re.search(r"^estimation data \(.+est\.csv\): fit [\d.]+ % \(simulation, zero initial conditions\)$", out,
                     re.M)
    match = FIT_LINE.search(out)
    assert match and match["data"].endswith("val.csv")
    # the system is first order with white output noise: every structure simulates it closely
    assert float(match["fit"]) > 80
    assert "residual tests on the validation data (1-step prediction errors):" in out
    assert re.search(r"^  [✓✗] whiteness: ", out, re.M) and re.search(r"^  [✓✗] independence: ", out, re.M)
    if argv[0] in ("arx", "armax", "oe", "bj"):
        assert re.search(r"^  B\(q\) = ", out, re.M)
    if argv[0] == "ss":
        assert re.search(r"^  A = \[\[", out, re.M) and "singular values:" in out
    if argv[0] == "process":
        assert re.search(r"^  G\(s\) = ", out, re.M) and re.search(r"^  Tp1\s", out, re.M)


def test_select_prints_the_table_and_the_picked_model_of_a_simulated_record():
    proc = eha("identify", "select", "--samples", "300", "--na", "1:2", "--nb", "1:2", "--nk", "1")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("4 ARX candidates estimated on estimation experiment (seed 0)")
    assert lines[0].endswith("validation fit on validation experiment (seed 1) (simulation, zero initial conditions)")
    rows = [line for line in lines if re.match(r"^[* ]\s+ARX\(", line)]
    marked = [line for line in rows if line.startswith("*")]
    assert len(rows) == 4 and len(marked) == 1
    picked = re.search(r"^picked by the best validation fit \(the fewest parameters within the data's "
                       r"uncertainty\): (ARX\(.+\))$", proc.stdout, re.M)[1]
    assert picked in marked[0]
    assert re.search(rf"^{re.escape(picked)} from simulated closed loop", proc.stdout, re.M)


def test_json_parses_and_the_export_rebuilds_the_model_of_merged_experiments(files):
    from eha_core.identify.blackbox import IdData, LinearModel, compare

    out_file = files["folder"] / "model.json"
    proc = eha("identify", "oe", "--nb", "1", "--nf", "1", "--data", files["est"], "--data", files["est2"],
               "--val-data", files["val"], "--json", "--out", str(out_file))
    assert proc.returncode == 0, proc.stderr
    printed = json.loads(proc.stdout)
    assert printed["name"] == "OE(nb=1, nf=1, nk=1)" and printed["validation"]["label"].endswith(
        "(simulation, zero initial conditions)")
    # two experiments of 300 samples, estimated together
    assert printed["n_samples"] == 600 and printed["source"] == f"data: {files['est']} + {files['est2']}, means removed"
    assert set(printed["residual_tests"]) >= {"whiteness", "independence", "passed"}
    exported = json.loads(out_file.read_text())
    assert exported["params"] == printed["params"]
    cov = np.array(exported["covariance"])
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), exported["param_std"], rtol=1e-12)
    np.testing.assert_allclose(exported["params"], [2.0 * (1 - POLE), -POLE], atol=0.02)

    class Exported(LinearModel):
        ts = exported["ts"]

        def g_poly(self):
            return np.array(exported["G"]["num"]), np.array(exported["G"]["den"])

        def h_poly(self):
            return np.array(exported["H"]["num"]), np.array(exported["H"]["den"])

    t, u, y = np.loadtxt(files["val"], delimiter=",", skiprows=1).T
    fit = compare(Exported(), IdData(y, u, TS).detrended()).fit_percent      # the means removed by default
    np.testing.assert_allclose(fit, printed["validation"]["fit_percent"], atol=1e-9)


#: (argv, the refusal's start: the option and the value as typed). {est}, {val}, {slow}, {short} are the files.
BAD = [
    (["arx", "--na", "30", "--samples", "50"], "--na = 30 is not allowed: 32 parameters"),
    (["arx", "--nk", "60", "--samples", "50"], "--nk = 60 is not allowed: the input delay must be shorter"),
    (["arx", "--na", "-1"], "--na = -1 is not allowed"),
    (["arx", "--na", "two"], "--na = two is not allowed"),
    (["arx", "--nk", "400", "--data", "{est}"], "--nk = 400 is not allowed: the input delay must be shorter"),
    # 60 samples split in half: 30 parameters and a lag of 15 need 45
    (["oe", "--nb", "15", "--nf", "15", "--data", "{short}"], "--nb = 15 is not allowed: 30 parameters and a "
                                                              "longest lag of 15 samples need at least 45 samples"),
    (["process", "--delay", "100", "--samples", "100"], "--delay = 100 is not allowed: a delay must be shorter"),
    (["process", "--delay", "20", "--data", "{est}"], "--delay = 20 is not allowed: a delay must be shorter"),
    (["process", "--kind", "P3"], "--kind = P3 is not allowed"),
    (["ss", "--n", "20", "--samples", "100"], "--n = 20 is not allowed: order 20 needs"),
    (["arx", "--data", "{est}", "--data", "{slow}", "--val-data", "{val}"],
     "--data = '{slow}' is not allowed: its sample time is 0.1 s"),
    (["arx", "--data", "{est}", "--val-data", "{slow}"], "--val-data = '{slow}' is not allowed: its sample time"),
    (["select", "--structure", "fir"], "--structure = fir is not allowed"),
    (["select", "--structure", "ss", "--na", "1:2"], "--na = 1:2 is not allowed: ss has no na"),
    (["select", "--na", "1:40"], "--na = 1:40 is not allowed"),
    (["select", "--criterion", "r2"], "--criterion = r2 is not allowed"),
    (["select", "--na", "1", "--nb", "1", "--nk", "1:60", "--samples", "50"],
     "--nk = 1:60 is not allowed: 2 parameters and a longest lag of 49 samples"),
    (["arx", "--loop", "half"], "--loop = half is not allowed"),
    (["arx", "--horizon", "0"], "--horizon = 0 is not allowed"),
    (["arx", "--val-data", "{val}"], "--val-data = '{val}' is not allowed"),
]


def test_bad_input_is_one_line_naming_the_option_and_exit_code_2(files):
    cases = [([a.format(**files) for a in argv], start.format(**files)) for argv, start in BAD]
    # one interpreter for all the cases (each is refused before anything is simulated), and whether scipy was
    # imported by a refusal made before the records are read
    script = ("import contextlib, io, json, sys\nfrom eha_app.cli import main\nresults = []\n"
              f"for argv in {[['identify', *argv] for argv, _ in cases]!r}:\n"
              "    out, err = io.StringIO(), io.StringIO()\n"
              "    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):\n"
              "        code = main(argv)\n"
              "    results.append([code, out.getvalue(), err.getvalue()])\n"
              "print(json.dumps(results))\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for (argv, start), (code, out, err) in zip(cases, json.loads(proc.stdout), strict=True):
        assert code == 2, (argv, out, err)
        assert out == "" and err.count("\n") == 1, (argv, err)
        assert err.startswith(f"eha: error: {start}"), (argv, err)


def test_a_bad_order_is_refused_before_scipy_is_imported():
    code = ("import sys; from eha_app.cli import main; code = main(['identify', 'armax', '--nc', '-2']); "
            "print(code, 'scipy' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.stdout.split() == ["2", "False"], proc.stdout + proc.stderr
    assert proc.stderr.startswith("eha: error: --nc = -2 is not allowed")


def test_the_process_kinds_are_the_cores():
    from eha_app.cli.blackbox import KINDS
    from eha_core.identify import process

    assert KINDS == process.KINDS


def test_the_simulated_records_defaults_are_the_experiments():
    from eha_app.cli.blackbox import DEFAULT_SAMPLES, DEFAULT_TS
    from eha_core.identify.blackbox_experiment import BlackBoxExperiment

    assert (DEFAULT_SAMPLES, DEFAULT_TS) == (BlackBoxExperiment().n_samples, BlackBoxExperiment().ts)
