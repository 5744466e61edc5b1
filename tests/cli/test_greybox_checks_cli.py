"""``eha identify greybox`` tells the truth about its estimate: one that failed its checks prints no
interval or standard error as if they held, says what each check found and what to try, and exits 1;
its JSON writes a value not given as null; ``--shooting`` is checked before anything is computed."""

import json
import re

import numpy as np
import pytest

from eha_app.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def micrometres(tmp_path_factory):
    """A rig's record whose x column is in µm, not m: the estimate fails its checks."""
    from eha_core.experiments import LSE_INPUT
    from eha_core.identify.greybox import greybox_data
    from eha_core.params import ActuatorParams

    rec = greybox_data(ActuatorParams(), LSE_INPUT, t_end=3.0, noise={"x": 1e-5}, seed=1, measured=("x",))
    path = tmp_path_factory.mktemp("rig") / "um.csv"
    np.savetxt(path, np.column_stack([rec.t, rec.u, rec.signals["x"] * 1e6]), delimiter=",", header="t,u,x",
               comments="")
    return str(path)


def test_a_failed_estimate_prints_no_interval_its_checks_and_what_to_try(capsys, micrometres):
    code, out, err = run(capsys, "identify", "greybox", "--data", micrometres, "--measured", "x")
    assert code == 1
    table = out.split("fit:")[0]
    assert "[" not in table                                   # no interval
    for n in ("M", "B", "Af", "beta_e"):
        (row,) = [line for line in table.splitlines() if line.startswith(f"{n} ")]
        # the estimate, then no standard error and no interval: dashes (or where it ended)
        assert re.fullmatch(rf"{n}\s+\S+\s+—\s+(—|at the bound of its range|held at the initial value)", row), row
    assert "no standard error or interval is given: the estimate failed its checks" in out
    assert re.search(r"^strategy: single shooting", out, re.M)
    checks = out.split("checks:\n")[1].split("try:\n")[0].splitlines()
    assert len(checks) == 5 and all(re.match(r"  [✓✗] \w+: ", line) for line in checks), checks
    assert any(line.startswith("  ✗ noise: the residuals of x are") for line in checks)
    assert any(line.startswith("  ✓ optimiser:") for line in checks)
    tries = out.split("try:\n")[1].splitlines()
    assert tries and any("SI units" in line for line in tries) and all(line.startswith("  - ") for line in tries)
    assert err.startswith("eha identify greybox: warning: the estimate may be wrong") and len(err.splitlines()) == 1


def test_the_json_of_a_failed_estimate_has_null_not_nan(capsys, micrometres):
    code, out, _ = run(capsys, "identify", "greybox", "--data", micrometres, "--measured", "x", "--json")
    assert code == 1 and "NaN" not in out and "Infinity" not in out
    data = json.loads(out, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert not data["success"] and data["ci95"]["M"] == [None, None] and data["std_errors"]["M"] is None
    assert all(v is None for row in data["correlation"].values() for v in row.values())
    assert data["strategy"] and data["advice"] and {"name", "passed", "says", "about"} <= set(data["checks"][0])
    assert any(not c["passed"] for c in data["checks"]) and isinstance(data["held_bias"], dict)


def test_a_passed_estimate_prints_its_intervals_and_checks(capsys):
    code, out, err = run(capsys, "identify", "greybox", "--t-end", "3", "--measured", "x", "--param", "M=5200")
    assert code == 0 and err == ""
    (row,) = [line for line in out.splitlines() if line.startswith("M ")]
    lo, hi = (float(v) for v in re.search(r"\[(\S+), (\S+)\]", row).groups())
    assert lo < 5200 < hi
    assert "strategy: single shooting over the first 1 s" in out and "try:" not in out
    checks = out.split("checks:\n")[1].splitlines()
    assert len(checks) == 5 and all(line.startswith("  ✓ ") for line in checks)


def test_a_held_parameter_prints_the_bias_it_can_cause(capsys):
    code, out, _ = run(capsys, "identify", "greybox", "--u", "sine:0.01:2", "--t-end", "5")
    held = [line for line in out.splitlines() if line.startswith("held: ")]
    assert any(re.match(r"held: B held at 1500 N s/m; if it is 10 % off, \w+ moves by [+-][\d.]+ %", line)
               for line in held), held
    assert re.search(r"^B\s+1500\s+—\s+held at the initial value", out, re.M)


@pytest.mark.parametrize("value", ["bogus", "Single", ""])
def test_shooting_is_refused_unless_auto_single_or_multiple(capsys, value):
    code, out, err = run(capsys, "identify", "greybox", "--shooting", value)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1
    assert f"--shooting = {value}" in err and "is not allowed: use auto, single, multiple" in err


def test_shooting_is_passed_to_the_core(capsys):
    code, out, _ = run(capsys, "identify", "greybox", "--t-end", "2", "--measured", "x", "--shooting", "single",
                       "--json")
    assert code == 0 and json.loads(out)["strategy"] == "single shooting"
