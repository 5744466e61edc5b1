"""What an estimate and its interval say: exact, covers, undetermined, misses, impossible."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from eha_core.experiments import LSE_SCENARIOS, lse_data
from eha_core.identify.lse import identify_lse
from eha_core.identify.lse_reading import EXACT_TOLERANCE, disturbance_leak, read_all, read_estimate


@pytest.fixture(scope="module")
def runs():
    out = {}
    for scen in ("none", "200 sin", "5000 sin", "white noise"):
        data = lse_data(disturbance=LSE_SCENARIOS[scen])
        out[scen] = (data, identify_lse(data), identify_lse(data, disturbance_model="harmonic"))
    return out


def test_noise_free_estimates_are_exact_not_failing(runs):
    _, const, harm = runs["none"]
    for res in (const, harm):
        r = read_all(res)
        for k in ("M", "B", "Af", "d0", "beta_e"):
            assert r[k].kind == "exact" and r[k].ok is True, (k, r[k])
    # the constant model's collapsed interval misses the nominal B by the regressors' error: still exact
    lo, hi = const.ci95["B"]
    assert not lo <= 1500.0 <= hi
    assert read_all(harm)["d_sin"].kind == "estimated" and read_all(harm)["d_sin"].ok is None
    sentence = read_estimate(const, "B").sentence
    off_percent = float(re.search(r"off by ([0-9.]+) %", sentence).group(1))
    # B's error without noise is the regressors' discretisation error, 0.0038 % on this simulated record. The
    # record's own error moves it: the fixed-step RK4's record (2.7e-7 of v's range from the adaptive
    # integrator's, RK4's stated error) gave 0.0033 %, so it is known to 0.0005 %
    assert "exact" in sentence and off_percent == pytest.approx(0.0038, abs=5e-4), sentence


def test_negative_friction_is_impossible_whatever_its_interval(runs):
    _, const, _ = runs["5000 sin"]
    lo, hi = const.ci95["B"]
    assert const.estimates["B"] < 0 and lo <= 1500.0 <= hi       # the interval covers: no ✓ for it
    r = read_estimate(const, "B")
    assert r.kind == "impossible" and r.ok is False and "must be ≥ 0" in r.sentence
    for name, value in (("M", -1.0), ("M", 0.0), ("beta_e", 0.0), ("Af", -3.0)):
        res = dataclasses.replace(const, estimates={**const.estimates, name: value})
        assert read_estimate(res, name).kind == "impossible", name
    res = dataclasses.replace(const, estimates={**const.estimates, "B": 0.0})
    assert read_estimate(res, "B").kind != "impossible"             # B = 0 (no viscous friction) is possible
    res = dataclasses.replace(const, estimates={**const.estimates, "M": float("nan")})
    assert read_estimate(res, "M").kind == "impossible"


def test_an_interval_wider_than_its_estimate_does_not_determine_it(runs):
    for scen in ("200 sin", "white noise"):
        _, const, _ = runs[scen]
        lo, hi = const.ci95["B"]
        assert hi - lo > abs(const.estimates["B"]) and lo <= 1500.0 <= hi
        r = read_estimate(const, "B")
        assert r.kind == "undetermined" and r.ok is None and "do not determine B" in r.sentence
        assert read_estimate(const, "M").kind == "covers"
    # d0's nominal value is 0: a wide interval around it is not "undetermined" but a plain cover
    assert read_estimate(runs["white noise"][1], "d0").kind == "covers"


def test_misses_and_narrow_misses(runs):
    _, const, _ = runs["white noise"]
    lo, hi = const.ci95["M"]
    res = dataclasses.replace(const, estimates={**const.estimates, "M": 4100.0}, ci95={**const.ci95, "M": (4090, 4110)})
    r = read_estimate(res, "M")
    assert r.kind == "misses" and r.ok is False and not r.narrow
    res = dataclasses.replace(const, estimates={**const.estimates, "M": 4010.0},
                              ci95={**const.ci95, "M": (4009.99, 4010.01)})
    r = read_estimate(res, "M")
    assert r.kind == "misses" and r.narrow and "the model's, not the noise's" in r.sentence
    # exact needs both: a collapsed interval and the nominal value within the tolerance
    tol = EXACT_TOLERANCE * 4000
    res = dataclasses.replace(const, estimates={**const.estimates, "M": 4000 + 0.9 * tol},
                              ci95={**const.ci95, "M": (4000 + 0.5 * tol, 4000 + 1.3 * tol)})
    assert read_estimate(res, "M").kind == "exact"
    res = dataclasses.replace(const, estimates={**const.estimates, "M": 4000 + 1.1 * tol},
                              ci95={**const.ci95, "M": (4000 + 0.7 * tol, 4000 + 1.5 * tol)})
    assert read_estimate(res, "M").kind == "misses"


def test_unknown_truth_never_shapes_the_reading(runs):
    _, const, _ = runs["none"]
    for k in const.estimates:
        r = read_estimate(const, k, known=False)
        assert r.nominal is None and r.kind in ("estimated", "undetermined", "impossible")
        assert str(const.nominal[k]) not in r.sentence or const.nominal[k] == 0
    r = read_all(runs["5000 sin"][1], hidden=("B", "M"))
    assert r["B"].kind == "impossible" and r["M"].nominal is None and r["Af"].nominal == 3000.0


def test_the_sinusoid_the_constant_model_leaves_out(runs):
    data, const, harm = runs["5000 sin"]
    leak = disturbance_leak(const, harm, data)
    assert leak is not None and leak.worst == "B"
    assert leak.freq_hz == pytest.approx(1.0, abs=1e-3) and leak.amplitude == pytest.approx(5000, rel=1e-3)
    assert leak.shifted["B"] == pytest.approx(const.estimates["B"] - harm.estimates["B"])
    assert leak.residual_ratio < 1e-3
    # B v is small against the sinusoid: that is why a small correlation moves B so far
    assert leak.reach["B"] < 0.05 * leak.amplitude and 0 < abs(leak.partial_correlations["B"]) < 0.1
    assert "5000 N" in leak.sentence and "B by -3073" in leak.sentence
    data2, const2, harm2 = runs["200 sin"]
    assert disturbance_leak(const2, harm2, data2).amplitude == pytest.approx(200, rel=1e-3)
    for scen in ("none", "white noise"):                # nothing sinusoidal to leave out
        data, const, harm = runs[scen]
        assert disturbance_leak(const, harm, data) is None
    assert disturbance_leak(harm, harm, data) is None     # only the constant model leaks
    assert np.isfinite(list(leak.partial_correlations.values())).all()
