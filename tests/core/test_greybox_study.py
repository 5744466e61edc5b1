"""The grey-box study over seeds: its summary's keys and ranges, and the Cramér-Rao bound against
cases checkable by hand."""

import json
import math

import numpy as np
import pytest

from eha_app.cli import main
from eha_core.experiments import LSE_INPUT
from eha_core.identify.greybox import greybox_data, simulate_with_sensitivities
from eha_core.identify.greybox_study import (
    LOAD,
    GreyBoxStudyConfig,
    cramer_rao,
    cramer_rao_bound,
    run_greybox_study,
    snr_noise,
)
from eha_core.params import ActuatorParams


def test_one_parameter_bound_is_one_over_the_jacobians_norm():
    J = np.array([[3.0], [4.0]])
    assert cramer_rao(J) == pytest.approx([1 / 5])


def test_the_bound_is_the_inverse_fisher_informations_diagonal():
    # two orthogonal columns: each bound is 1 / its column's norm; correlated ones widen both
    assert cramer_rao(np.array([[2.0, 0.0], [0.0, 0.5]])) == pytest.approx([0.5, 2.0])
    J = np.array([[1.0, 1.0], [1.0, -1.0], [1.0, 0.0]])          # JᵀJ = [[3, 0], [0, 2]]
    assert cramer_rao(J) == pytest.approx([1 / math.sqrt(3), 1 / math.sqrt(2)])
    J = np.array([[1.0, 1.0], [0.0, 1.0]])                       # JᵀJ = [[1, 1], [1, 2]], inverse [[2, -1], [-1, 1]]
    assert cramer_rao(J) == pytest.approx([math.sqrt(2), 1.0])


def test_the_models_bound_of_one_parameter_is_its_value_over_the_weighted_sensitivitys_norm():
    truth = ActuatorParams()
    data = greybox_data(truth, LSE_INPUT, t_end=1.0, d=LOAD, measured=("x", "p1"))
    sigma = {"x": 1e-4, "p1": 5e4}
    _, sens = simulate_with_sensitivities(truth, ("M",), data)
    norm = math.sqrt(np.sum((sens[:, 0, 0] / 1e-4) ** 2) + np.sum((sens[:, 2, 0] / 5e4) ** 2))
    assert cramer_rao_bound(truth, ("M",), data, sigma)["M"] == pytest.approx(truth.M / norm, rel=1e-12)


def test_noise_at_30_db_is_a_thirtieth_of_each_signals_spread():
    truth = ActuatorParams()
    sigma = snr_noise(truth, 30.0, ("x", "p2"), t_end=1.0)
    clean = greybox_data(truth, LSE_INPUT, t_end=1.0, d=LOAD, measured=("x", "p2"))
    for s in ("x", "p2"):
        assert sigma[s] == pytest.approx(np.std(clean.signals[s]) / 10**1.5, rel=1e-12)


def test_a_short_study_gives_every_summary_in_range():
    cfg = GreyBoxStudyConfig(n_seeds=4, t_end=1.5)
    res = run_greybox_study(cfg, workers=1)
    # 1.5 s of record hardly determine B: a seed whose fit drove B to its bound (~0), where the signals no
    # longer move with it, fails and says so (it once counted as a success, B = 2e-15 ± 0); the others summarise
    assert res.n_completed + res.n_failed == 4 and res.n_completed >= 3
    assert all("may be wrong" in f and "B ended at the lower bound" in f for f in res.failures), res.failures
    d = json.loads(json.dumps(res.to_dict()))
    for key in ("coverage", "mean", "std", "crb", "bias_se", "std_over_crb"):
        assert set(d[key]) == set(cfg.params), key
    truth = ActuatorParams()
    for n in cfg.params:
        assert 0.0 <= d["coverage"][n] <= 1.0
        assert d["crb"][n] > 0 and d["std"][n] > 0
        assert abs(d["mean"][n] / getattr(truth, n) - 1) < 0.5, n
        assert abs(d["bias_se"][n]) < 5, n
        assert 0.1 < d["std_over_crb"][n] < 10, n
    # the well-determined ones: near the truth, the spread near the bound
    for n in ("M", "Af"):
        assert abs(d["mean"][n] / getattr(truth, n) - 1) < 0.02, n


def test_the_command_prints_the_studys_json_and_refuses_a_typo(capsys):
    code = main(["study", "greybox", "--seeds", "2", "--t-end", "1", "--measured", "x,p1,p2", "--workers", "1",
                 "--json"])
    out, err = capsys.readouterr()
    assert code == 0 and err == ""
    d = json.loads(out)
    assert {"coverage", "mean", "std", "crb", "bias_se"} <= set(d)
    assert d["settings"]["n_seeds"] == 2 and d["n_completed"] == 2
    code = main(["study", "greybox", "--seeds", "2", "--params", "M,mass"])
    out, err = capsys.readouterr()
    assert code != 0 and "mass is not one of" in err


def test_a_parameter_held_in_the_seeds_is_known_in_the_others_bound():
    # from x alone the record does not determine B: held at the guess in every seed, the bound of the
    # others is the one with B known
    cfg = GreyBoxStudyConfig(n_seeds=2, t_end=1.5, measured=("x",))
    res = run_greybox_study(cfg, workers=1)
    assert res.held["B"] == 2 and math.isnan(res.coverage["B"])
    truth = ActuatorParams()
    clean = greybox_data(truth, LSE_INPUT, t_end=1.5, d=LOAD, measured=("x",))
    known = cramer_rao_bound(truth, ("M", "Af", "beta_e"), clean, res.noise)
    everything = cramer_rao_bound(truth, cfg.params, clean, res.noise)
    assert res.crb["M"] == pytest.approx(known["M"], rel=1e-12) and res.crb["M"] < everything["M"]
    assert res.crb["B"] == pytest.approx(everything["B"], rel=1e-12)
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["coverage"]["B"] is None and d["held"]["B"] == 2


def test_the_study_module_runs_the_same_grey_box_seeds_in_parts():
    import dataclasses

    from eha_core.study import StudyConfig, combine_studies, run_study

    g = GreyBoxStudyConfig(n_seeds=6, t_end=2.0)
    alone = run_greybox_study(g, workers=1)
    cfg = StudyConfig("greybox", n_seeds=6, greybox=g)
    parts = [run_study(dataclasses.replace(cfg, n_seeds=4), workers=2),
             run_study(dataclasses.replace(cfg, first_seed=4, n_seeds=2), workers=1)]
    both = combine_studies(cfg, parts)
    assert both.n_completed == 6 and both.nominal_is_truth and both.message == "ok"
    for n in g.params:
        assert both.mean[n] == pytest.approx(alone.mean[n], rel=1e-12)
        assert both.std[n] == pytest.approx(alone.std[n], rel=1e-9)
        assert both.coverage[n] == alone.coverage[n]             # the same (log-scale) intervals counted
        assert both.bound[n] == pytest.approx(alone.crb[n], rel=1e-12)
    json.dumps(both.to_dict())
    with pytest.raises(ValueError, match="disturbance = white:10 is not allowed: the grey-box study's load"):
        StudyConfig("greybox", disturbance="white:10")
    with pytest.raises(ValueError, match="greybox = 3 is not allowed"):
        StudyConfig("greybox", greybox=3)


def test_a_study_whose_estimator_holds_a_parameter_also_shows_the_coverage_without_the_hold():
    # from x alone over 2 s B is not determined at the paper's values: held there in every seed
    held = run_greybox_study(GreyBoxStudyConfig(n_seeds=3, t_end=2.0, measured=("x",)), workers=1)
    assert held.held["B"] == 3 and held.without_hold is not None
    assert set(held.without_hold["coverage"]) == set(held.config.params)
    assert held.without_hold["n_completed"] + held.without_hold["n_failed"] == 3
    free = run_greybox_study(GreyBoxStudyConfig(n_seeds=3, t_end=2.0, measured=("x",), hold=False), workers=1)
    assert free.without_hold is None and free.held["B"] == 0
    assert free.coverage == held.without_hold["coverage"]
    d = json.loads(json.dumps(held.to_dict()))
    assert d["without_hold"]["coverage"]["M"] == held.without_hold["coverage"]["M"]
