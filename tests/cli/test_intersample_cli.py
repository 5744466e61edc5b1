"""``eha identify tf --intersample``: the input held (zoh) or linear (foh) between samples."""

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import scipy.signal

from eha_app.cli import main

TS = 0.04


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def linear_csv(tmp_path):
    """10 / (s + 10) driven by white samples linear between them (lsim's interpolation), noise-free."""
    u = np.random.default_rng(0).standard_normal(400)
    t = TS * np.arange(u.size)
    _, y, _ = scipy.signal.lsim(([10.0], [1.0, 10.0]), u, t, interp=True)
    path = tmp_path / "io.csv"
    pd.DataFrame({"t": t, "u": u, "y": y}).to_csv(path, index=False, float_format="%.17g")
    return str(path)


def test_foh_recovers_the_model_that_zoh_biases(capsys, linear_csv):
    code, out, _ = run(capsys, "identify", "tf", "--data", linear_csv, "--np", "1", "--intersample", "foh", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["intersample"] == "foh"
    np.testing.assert_allclose(data["num"], [10.0], rtol=1e-6)
    np.testing.assert_allclose(data["den"], [1.0, 10.0], rtol=1e-6)
    code, out, _ = run(capsys, "identify", "tf", "--data", linear_csv, "--np", "1", "--json")
    data = json.loads(out)
    assert code == 0 and data["intersample"] == "zoh"
    assert data["num"][0] < 9.0  # taken as held: about 17 % low


def test_the_summary_names_it(capsys, linear_csv):
    code, out, err = run(capsys, "identify", "tf", "--data", linear_csv, "--np", "1", "--intersample", "foh")
    assert code == 0 and err == ""
    assert "input linear between samples (foh)" in out
    assert "fit 100.00 %" in out
    _, out, _ = run(capsys, "identify", "tf", "--data", linear_csv, "--np", "1")
    assert "between samples" not in out


@pytest.mark.parametrize("value", ["linear", "FOH", "hold"])
def test_a_bad_intersample_is_one_line(capsys, linear_csv, value):
    code, out, err = run(capsys, "identify", "tf", "--data", linear_csv, "--np", "1", "--intersample", value)
    assert code == 2 and out == ""
    assert err == f"eha: error: --intersample = {value} is not allowed: use zoh or foh\n"


def test_foh_without_data_is_refused(capsys):
    code, _, err = run(capsys, "identify", "tf", "--intersample", "foh")
    assert code == 2
    assert err == ("eha: error: --intersample = foh is not allowed without --data: the paper experiment's "
                   "reference is held between samples\n")


def test_a_bad_intersample_is_refused_before_the_estimators_load():
    argv = ["identify", "tf", "--intersample", "linear"]
    code = (f"import sys; from eha_app.cli import main; code = main({argv!r}); "
            "print(code, 'scipy' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["2", "False", "False"], out.stderr
