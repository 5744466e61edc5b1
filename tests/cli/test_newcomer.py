"""What a newcomer to ``eha`` meets: one ``--noise`` grammar, Ctrl-C that ends with one line,
``--version``, and tables that do not mislead."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

import pytest

from eha_app.cli import main
from eha_app.cli.common import NOISE_GRAMMAR, UsageError, parse_noise


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# -- one --noise grammar ---------------------------------------------------------------------

#: Every subcommand with --noise, and the arguments that let it run quickly.
NOISE_COMMANDS = {
    "identify greybox": ["identify", "greybox", "--t-end", "0.5", "--params", "M"],
    "study lse": ["study", "lse", "--seeds", "1", "--t-end", "0.5", "--workers", "1"],
    "study tf": ["study", "tf", "--seeds", "1", "--model", "linear", "--workers", "1"],
    "exercise new": ["exercise", "new"],
}


def test_the_grammar_reads_units_and_both_pressures():
    assert parse_noise("x=0.01mm,v=1mm/s,p=0.05MPa") == {"x": 1e-5, "v": 1e-3, "p1": 5e4, "p2": 5e4}
    assert parse_noise("p1=1e4, p2 = 2kPa") == {"p1": 1e4, "p2": 2e3}        # no unit: SI
    assert parse_noise("x=0.1mm") == {"x": 1e-4}                              # as typed, not 1.0000000000000002e-04
    assert parse_noise("none") == {} and parse_noise("x=1um,x=2um") == {"x": 2e-6}
    assert parse_noise("2e-4", signals=("x",), bare="x") == {"x": 2e-4}


@pytest.mark.parametrize("text, says", [
    ("x=-1mm", "--noise = x=-1mm is not allowed: σ of x must be a finite number >= 0"),
    ("p=-0.05MPa", "--noise = p=-0.05MPa is not allowed: σ of p must be a finite number >= 0"),
    ("x=1e400", "σ of x must be a finite number >= 0"),
    ("x=nan", "σ of x as a number with a unit of m, mm, um"),
    ("x=1furlong", "σ of x as a number with a unit of m, mm, um"),
    ("q=1", "q is not a signal; use x, v, p1, p2 (p: both pressures)"),
    ("1e4", "give SIGNAL=SIGMA[UNIT]"),
])
def test_the_grammar_refuses_with_the_text_as_typed(text, says):
    with pytest.raises(UsageError, match=re.escape(says)):
        parse_noise(text)


@pytest.mark.parametrize("command", NOISE_COMMANDS)
def test_every_noise_option_documents_the_one_grammar(capsys, command):
    with pytest.raises(SystemExit):
        main([*command.split(), "--help"])
    assert NOISE_GRAMMAR in " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize("command", NOISE_COMMANDS)
@pytest.mark.parametrize("sigma", ["x=-1mm", "x=-0.001", "x=nan"])
def test_every_noise_option_refuses_a_negative_or_nan_sigma(capsys, tmp_path, command, sigma):
    argv = [*NOISE_COMMANDS[command], "--noise", sigma]
    if command == "exercise new":
        argv += ["--out", str(tmp_path / "class.json")]
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == ""
    assert err.startswith(f"eha: error: --noise = {sigma} is not allowed: σ of x ") and err.count("\n") == 1, err


def test_study_tf_takes_only_the_position_and_says_so(capsys):
    code, _, err = run(capsys, "study", "tf", "--seeds", "1", "--noise", "p=0.05MPa")
    assert code == 2 and "--noise = p=0.05MPa is not allowed: p is not a signal; use x" in err


def test_every_noise_option_takes_the_grammar(capsys, tmp_path):
    code, out, _ = run(capsys, *NOISE_COMMANDS["study tf"], "--noise", "x=0.2mm", "--json")
    assert code == 0 and json.loads(out)["settings"]["noise_m"] == 2e-4
    code, out, _ = run(capsys, *NOISE_COMMANDS["study tf"], "--noise", "2e-4", "--json")     # the old spelling
    assert code == 0 and json.loads(out)["settings"]["noise_m"] == 2e-4
    code, out, _ = run(capsys, *NOISE_COMMANDS["study lse"], "--noise", "x=0.01mm,p=50kPa", "--noise", "v=1mm/s",
                       "--json")
    assert code == 0
    assert dict(json.loads(out)["settings"]["sensor_noise"]) == {"x": 1e-5, "p1": 5e4, "p2": 5e4, "v": 1e-3}
    code, out, _ = run(capsys, *NOISE_COMMANDS["study lse"], "--noise", "p1=1e4", "--json")    # the old spelling
    assert code == 0 and dict(json.loads(out)["settings"]["sensor_noise"]) == {"p1": 1e4}
    code, out, err = run(capsys, *NOISE_COMMANDS["identify greybox"], "--noise", "x=0.02mm,p=0.1MPa", "--json")
    assert code in (0, 1) and json.loads(out)["estimates"], err
    path = tmp_path / "class.json"
    code, out, _ = run(capsys, "exercise", "new", "--noise", "x=0.02mm,p=0.1MPa", "--out", str(path))
    from eha_core.exercise import Exercise

    assert code == 0 and Exercise.load(path).conditions.noise == {"x": 2e-5, "p1": 1e5, "p2": 1e5}


# -- Ctrl-C ----------------------------------------------------------------------------------

def _interrupted(argv, tmp_path, after_s: float = 1.0):
    """Run ``eha ARGV`` in a process of its own, send it SIGINT once it runs, and return its exit code
    and stderr."""
    # as in a terminal: SIGINT interrupts (a job a shell starts in the background would ignore it)
    code = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            f"from eha_app.cli import main; print('started', flush=True); sys.exit(main({argv!r}))")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "started"
        time.sleep(after_s)                     # into the computation (anywhere in main is the same)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    return proc.returncode, err


def test_ctrl_c_ends_a_study_with_one_line_and_130(tmp_path):
    code, err = _interrupted(["study", "lse", "--seeds", "1000", "--workers", "1"], tmp_path)
    assert code == 130
    assert err.splitlines() == ["eha study lse: interrupted"], err


def test_ctrl_c_ends_the_report_with_one_line_of_its_own(tmp_path):
    code, err = _interrupted(["reproduce", "--out", str(tmp_path / "report")], tmp_path, after_s=2.0)
    assert code == 130 and "Traceback" not in err
    assert err.splitlines()[-1] == "eha reproduce: interrupted", err
    assert all(line.startswith("[") for line in err.splitlines()[:-1]), err     # its progress lines before


# -- --version --------------------------------------------------------------------------------

def test_version_is_the_installed_distributions(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out == f"eha {version('eha')}\n"


def test_version_falls_back_to_the_packages(capsys, monkeypatch):
    import importlib.metadata

    import eha_app

    def not_installed(name):
        raise importlib.metadata.PackageNotFoundError(name)
    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out == f"eha {eha_app.__version__}\n"


# -- tables that do not mislead ----------------------------------------------------------------

def test_lse_on_a_users_file_prints_no_nominal_or_relative_error(capsys, tmp_path):
    from eha_core.experiments import lse_simulation

    path = tmp_path / "rig.csv"
    lse_simulation(disturbance="none").to_csv(path)
    code, out, _ = run(capsys, "identify", "lse", "--data", str(path))
    assert code == 0
    header = next(line for line in out.splitlines() if "estimate" in line)
    assert header.split() == ["estimate", "95", "%", "interval"]
    assert "nominal" not in out and "rel. error" not in out and "%" not in out.split("interval", 1)[1]
    code, out, _ = run(capsys, "identify", "lse", "--t-end", "1")      # simulated: its truth is known
    header = next(line for line in out.splitlines() if "estimate" in line)
    assert code == 0 and header.split() == ["nominal", "estimate", "rel.", "error", "95", "%", "interval"]


def test_study_tf_columns_never_run_together(capsys):
    code, out, _ = run(capsys, "study", "tf", "--seeds", "2", "--workers", "1")
    assert code == 0
    lines = out.splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("parameter"))
    rows = lines[start + 1:start + 5]
    assert [row.split()[0] for row in rows] == ["a1", "a2", "a3", "b0"]
    for row in rows:
        # parameter, nominal, mean, std, mean std err, bias "+- " its error, coverage
        assert len(row.split()) == 9, row
        assert not re.search(r"\d-\d", row), row                   # 0.1109-3791.854: two numbers as one


def test_a_table_keeps_two_spaces_between_columns_whatever_their_width():
    from eha_app.cli.common import table_text

    lines = table_text(["p", "se", "bias"], [["a1", "0.1129", "-3728.006"], ["a2", "14.69", "-7.9"]])
    assert lines == ["p       se       bias", "a1  0.1129  -3728.006", "a2   14.69       -7.9"]
