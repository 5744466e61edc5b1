"""Grey-box identification: its Jacobian, recovery of parameters other than the paper's, what the data
cannot determine said in words, and bad requests refused before any computation."""

import numpy as np
import pytest

from eha_core.experiments import LSE_INPUT
from eha_core.identify.greybox import (
    GreyBoxData,
    greybox_data,
    identifiability,
    identify_greybox,
    simulate_with_sensitivities,
)
from eha_core.params import ActuatorParams
from eha_core.signals import parse_signal

TRUTH = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8, Kq1=3.3e-8, d0=400.0)


def _whole_run_difference(p, names, data, n, log):
    """d(states)/dz of whole simulations (what the kernel's sensitivities must equal)."""
    eps = 1e-5
    if log:
        v = getattr(p, n)
        up, dn = p.replace(**{n: v * np.exp(eps)}), p.replace(**{n: v * np.exp(-eps)})
    else:
        scale = {"d0": 1000.0, "x0": 0.01, "v0": 0.01}[n]
        up, dn = p.replace(**{n: getattr(p, n) + eps * scale}), p.replace(**{n: getattr(p, n) - eps * scale})
    a, _ = simulate_with_sensitivities(up, (), data)
    b, _ = simulate_with_sensitivities(dn, (), data)
    return (a - b) / (2 * eps)


@pytest.mark.parametrize("loop", ["open", "closed"])
def test_the_sensitivities_equal_differences_of_whole_runs(loop):
    if loop == "open":
        data = greybox_data(TRUTH, LSE_INPUT, t_end=3.0, d=parse_signal("sine:2000:1"))
    else:
        data = greybox_data(TRUTH, r=parse_signal("sine:0.02:0.5"), kp=10.0, t_end=3.0, dt=0.01)
    names = ("M", "B", "Af", "beta_e", "Kq1", "Kq2", "d0", "p1_0")
    logs = (True,) * 6 + (False, True)
    out, sens = simulate_with_sensitivities(TRUTH, names, data)
    for j, (n, lg) in enumerate(zip(names, logs, strict=True)):
        fd = _whole_run_difference(TRUTH, names, data, n, lg)
        for k in range(4):
            scale = max(np.linalg.norm(fd[:, k]), 1e-300)
            assert np.linalg.norm(sens[:, k, j] - fd[:, k]) / scale < 5e-4, (loop, n, k)


def test_parameters_other_than_the_papers_are_recovered_from_noise_free_records():
    data = greybox_data(TRUTH, LSE_INPUT, t_end=5.0, measured=("x", "p1", "p2"))
    res = identify_greybox(data, ("M", "B", "Af", "beta_e", "Kq1", "d0"))
    assert res.success and not res.held
    for n in ("M", "Af", "beta_e", "Kq1"):
        assert res.estimates[n] == pytest.approx(getattr(TRUTH, n), rel=2e-4), n
    assert res.estimates["B"] == pytest.approx(TRUTH.B, rel=5e-3)            # B adds little to the friction
    assert res.estimates["d0"] == pytest.approx(TRUTH.d0, abs=2.0)
    assert min(res.fit.values()) > 99.9


def test_a_noisy_record_gives_estimates_within_their_intervals_and_position_alone_works():
    noise = {"x": 1e-5, "p1": 5e4, "p2": 5e4}
    data = greybox_data(TRUTH, LSE_INPUT, t_end=5.0, noise=noise, seed=11, measured=("x", "p1", "p2"))
    guess = TRUTH.replace(M=4000.0, B=1500.0, Af=3000.0, beta_e=1.1e9)     # the rest known (Kq1, d0)
    res = identify_greybox(data, ("M", "B", "Af", "beta_e"), guess=guess)
    for n in res.names:
        assert abs(res.estimates[n] - getattr(TRUTH, n)) < 4 * res.std_errors[n], n
    assert res.noise_std["x"] == pytest.approx(1e-5, rel=0.1) and res.noise_std["p1"] == pytest.approx(5e4, rel=0.1)
    assert np.allclose(np.diag(res.correlation), 1.0) and abs(res.correlation[1, 2]) > 0.5     # B with Af
    alone = identify_greybox(data, ("M", "beta_e"), measured=("x",), guess=TRUTH.replace(M=4800.0, beta_e=1.0e9))
    for n in alone.names:
        assert abs(alone.estimates[n] - getattr(TRUTH, n)) < 4 * alone.std_errors[n], n
    assert alone.std_errors["beta_e"] > res.std_errors["beta_e"]          # less measured, less known


def test_what_the_data_cannot_determine_is_said_and_held():
    p = ActuatorParams()
    # a command so small that the piston never leaves the friction law's linear part
    small = greybox_data(p, parse_signal("sine:0.05:2"), t_end=5.0, noise={"x": 1e-6}, seed=1, measured=("x",))
    res = identify_greybox(small, ("M", "B", "Af"))
    assert "B" in res.held
    sentence = " ".join(s for _, s in res.identifiability)
    assert "the data do not determine B: the record never leaves |v| <" in sentence
    assert "where the friction law is linear" in sentence and np.isnan(res.std_errors["B"])
    # a parameter that does nothing: the friction slope without Coulomb friction
    dead = identify_greybox(greybox_data(p.replace(Af=0.0), LSE_INPUT, t_end=2.0, measured=("x",)),
                            ("M", "k_f"), guess=p.replace(Af=0.0))
    assert dead.held == ("k_f",) and "k_f does not affect the measured signals at all" in dead.identifiability[0][1]
    # two columns that move together: only their product is determined
    J = np.outer(np.linspace(1, 2, 50), [1.0, 1.0]) * 1e3
    assert identifiability(J, ("beta_e", "Kq1"), pressures=False)[0] == (
        ("beta_e", "Kq1"), "beta_e and Kq1 enter only as their product without pressure measurements: the data "
                           "determine that, not each")


def test_bad_requests_are_refused_before_any_computation():
    data = greybox_data(ActuatorParams(), LSE_INPUT, t_end=1.0, measured=("x", "p1"))
    cases = [(dict(params=("M", "Qx")), "params = M,Qx is not allowed: Qx cannot be estimated"),
             (dict(params=("M",), measured=("x", "v")), "measured = x,v is not allowed: the record has no v"),
             (dict(params=("M", "M")), "params = M,M is not allowed: name each parameter once")]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message.replace("(", r"\(")):
            identify_greybox(data, **kwargs)
    short = GreyBoxData(t=np.arange(5) * 1e-3, u=np.zeros(5), signals={"x": np.zeros(5)})
    with pytest.raises(ValueError, match="record = 5 samples is not allowed: too short for 4 parameters"):
        identify_greybox(short, ("M", "B", "Af", "beta_e"))
    with pytest.raises(ValueError, match="give the command u .open loop. or the reference r"):
        GreyBoxData(t=np.arange(5.0), u=None, signals={"x": np.zeros(5)})


def test_multiple_shooting_has_the_right_jacobian_and_ends_where_output_error_does():
    from eha_core.identify import greybox as G

    data = greybox_data(TRUTH, LSE_INPUT, t_end=2.0, noise={"x": 1e-5, "p1": 5e4, "p2": 5e4}, seed=11,
                        measured=("x", "p1", "p2"))
    setup = G._Setup(("M", "beta_e"), (True, True), TRUTH.replace(M=4500.0), data)
    y = np.stack([data.signals["x"], data.signals["p1"]], axis=1)
    fun, jac, w0 = G._multiple_shooting(setup, data, ("x", "p1"), [0, 2], y, np.array([1e-5, 5e4]), 3, 0, None)
    J = jac(w0)
    for j in range(w0.size):       # the parameters', the segments' initial states' and the continuity's columns
        e = 1e-6
        fd = (fun(w0 + e * np.eye(w0.size)[j]) - fun(w0 - e * np.eye(w0.size)[j])) / (2 * e)
        assert np.linalg.norm(J[:, j] - fd) / np.linalg.norm(fd) < 1e-4, j
    guess = TRUTH.replace(M=4000.0, B=1500.0, Af=3000.0, beta_e=1.1e9)
    single = identify_greybox(data, ("M", "B", "Af", "beta_e"), guess=guess)
    multiple = identify_greybox(data, ("M", "B", "Af", "beta_e"), guess=guess, shooting="multiple", segments=2)
    for n in single.names:
        assert multiple.estimates[n] == pytest.approx(single.estimates[n], rel=1e-3 * (1 + 50 * (n == "B"))), n
    with pytest.raises(ValueError, match="segments = 1 is not allowed"):
        identify_greybox(data, ("M",), shooting="multiple", segments=1)
