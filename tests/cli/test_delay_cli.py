"""``eha identify tf --delay``: a fixed or estimated input delay from the command line."""

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from eha_app.cli import main

TS = 0.01


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def delayed_csv(tmp_path):
    from eha_core.identify.validate import simulate_tf

    u = np.repeat(np.random.default_rng(0).standard_normal(200), 5)
    y = simulate_tf([400.0], [1.0, 16.0, 400.0], u, TS, input_delay=3.4 * TS)
    path = tmp_path / "io.csv"
    pd.DataFrame({"t": TS * np.arange(u.size), "u": u, "y": y}).to_csv(path, index=False, float_format="%.17g")
    return str(path)


def test_an_estimated_delay_in_json(capsys, delayed_csv):
    code, out, _ = run(capsys, "identify", "tf", "--data", delayed_csv, "--np", "2", "--delay", "estimate", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["input_delay"] / TS == pytest.approx(3.4, abs=1e-4)
    assert data["input_delay_std"] is not None
    np.testing.assert_allclose(data["den"], [1.0, 16.0, 400.0], rtol=1e-6)


def test_the_summary_shows_a_fixed_delay(capsys, delayed_csv):
    code, out, err = run(capsys, "identify", "tf", "--data", delayed_csv, "--np", "2", "--delay", "0.034")
    assert code == 0 and err == ""
    assert "input delay 0.034 s = 3.4 samples (fixed); G(s) above excludes it" in out
    assert "fit 100.00 %" in out


@pytest.mark.parametrize("argv, line", [
    (["--delay", "-1"], "--delay = -1 is not allowed: use a delay >= 0 s or estimate"),
    (["--delay", "soon"], "--delay = soon is not allowed: use a delay >= 0 s or estimate"),
    (["--delay", "nan"], "--delay = nan is not allowed: use a delay >= 0 s or estimate"),
    (["--delay", "0.02", "--max-delay", "0.1"],
     "--max-delay = 0.1 is not allowed: it bounds an estimated delay; give it with --delay estimate"),
    (["--delay", "estimate", "--max-delay", "0"], "--max-delay = 0 is not allowed: use a number > 0 s"),
])
def test_bad_delays_are_one_line(capsys, delayed_csv, argv, line):
    code, out, err = run(capsys, "identify", "tf", "--data", delayed_csv, "--np", "2", *argv)
    assert code == 2 and out == ""
    assert err == f"eha: error: {line}\n"


def test_a_delay_the_record_cannot_hold_names_the_option(capsys, delayed_csv):
    code, _, err = run(capsys, "identify", "tf", "--data", delayed_csv, "--np", "2", "--delay", "9")
    assert code == 2
    assert err == "eha: error: --delay = 9 is not allowed: must be at most half the record, N ts / 2 = 5 s\n"


def test_a_delay_without_data_is_refused(capsys):
    code, _, err = run(capsys, "identify", "tf", "--delay", "estimate")
    assert code == 2
    assert err == ("eha: error: --delay = estimate is not allowed without --data: the paper experiment's loop "
                   "has no delay\n")


def test_a_bad_delay_is_refused_before_the_estimators_load():
    argv = ["identify", "tf", "--delay", "-0.5"]
    code = (f"import sys; from eha_app.cli import main; code = main({argv!r}); "
            "print(code, 'scipy' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["2", "False", "False"], out.stderr
