"""The structural variants of the actuator (eha_core.variants, docs/model.md §6): off, the paper's model to the
bit; on, each effect's equations, steady states, linearisation and balance of the fluid as derived by hand."""

from __future__ import annotations

import inspect
import json
import math
import re

import numpy as np
import pytest

from eha_core import model
from eha_core._checks import FieldError
from eha_core._kernels import derivatives as compiled_derivatives
from eha_core.experiments import PAPER_CASES
from eha_core.linear import linearize, operating_point
from eha_core.model import PARAM_INDEX, pack_params, rhs
from eha_core.params import ActuatorParams, ParameterError
from eha_core.signals import Constant, Sine, parse_signal
from eha_core.simulate import simulate, simulate_closed_loop, simulate_many
from eha_core.variants import (
    EFFECT_FIELDS,
    EFFECTS_OFF,
    VARIANTS,
    Effects,
    describe_effects,
    variant_effects,
    variant_name,
)

PAPER = ActuatorParams()
#: Every effect off, but not the default Effects: the inactive values differ (they must not matter).
OFF_OTHERWISE = ActuatorParams(effects=Effects(zeta_v=0.3, v_s=0.02, v_eps=5e-3))
CASES = [PAPER_CASES[k] for k in (1, 2, 3, 4)]


def with_effects(name: str, **changes) -> ActuatorParams:
    return ActuatorParams(**changes, effects=variant_effects(name))


def response(lin, s, branch="positive"):
    """P(s) = X(s)/U(s) of a linear model's coefficients at the complex frequency ``s``."""
    num, den = lin.tf_coeffs(branch)
    return np.polyval(num, s) / np.polyval(den, s)


# -- (a) every effect off: the paper's model, unchanged ------------------------------------------------------

def test_effects_off_are_the_default_and_change_nothing_of_the_parameter_set():
    assert ActuatorParams().effects == EFFECTS_OFF == Effects() and EFFECTS_OFF.off and EFFECTS_OFF.active == ()
    assert OFF_OTHERWISE.effects.off and OFF_OTHERWISE.effects.n_states == 4
    # the repr and to_dict of the default are those of a parameter set without effects
    assert "effects" not in repr(PAPER) and repr(PAPER).startswith("ActuatorParams(M=4000.0, B=1500.0, ")
    assert repr(PAPER).endswith(", p1_0=12000000.0, p2_0=None)")
    assert "effects" not in PAPER.to_dict() and len(PAPER.to_dict()) == 17
    assert PAPER == ActuatorParams() and hash(PAPER) == hash(ActuatorParams())
    assert PAPER.replace(M=4000.0) == PAPER and ActuatorParams(**json.loads(json.dumps(PAPER.to_dict()))) == PAPER
    assert list(pack_params(PAPER)[14:]) == list(EFFECTS_OFF.packed())


def test_derivatives_with_every_effect_off_are_the_papers_to_the_bit():
    prm, prm_off = pack_params(PAPER), pack_params(OFF_OTHERWISE)
    assert not np.array_equal(prm, prm_off)          # the inactive values do differ
    rng = np.random.default_rng(1)
    for _ in range(300):
        state = (rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), rng.uniform(-1e6, 33e6), rng.uniform(-1e6, 33e6))
        u, d = rng.uniform(-10, 10), rng.uniform(-1e4, 1e4)
        for f in (model.derivatives, compiled_derivatives):
            assert f(*state, u, d, prm) == f(*state, u, d, prm_off)
    # and the paper's equations (eqs. 1-4) at one state, written out here
    x, v, p1, p2, u = 0.01, 0.02, 12e6, 18e6, 1.5
    p = PAPER
    q1, q2 = p.Kq1 * u * math.sqrt(p.ps - p1), p.Kq2 * u * math.sqrt(p2 - p.pr)
    expected = (v, (p.A1 * p1 - p.A2 * p2 - p.B * v - p.Af * 2 / math.pi * math.atan(p.k_f * v)) / p.M,
                p.beta_e / (p.A1 * (p.L0 + x)) * (q1 - p.A1 * v), p.beta_e / (p.A2 * (p.L0 - x)) * (p.A2 * v - q2))
    np.testing.assert_allclose(model.derivatives(x, v, p1, p2, u, 0.0, prm), expected, rtol=1e-14)


def test_simulations_with_every_effect_off_are_the_papers_to_the_bit():
    us, ds = [c.u for c in CASES], [c.d for c in CASES]
    for model_ in ("nonlinear", "linear"):
        a = simulate_many(PAPER, us, ds, model=model_)
        b = simulate_many(OFF_OTHERWISE, us, ds, model=model_)
        assert all(np.array_equal(x.states, y.states) and np.array_equal(x.u, y.u) for x, y in zip(a, b, strict=True))
    r = parse_signal("sine:0.02:0.5")
    for controller in ("zoh", "continuous"):
        a = simulate_closed_loop(PAPER, r=r, t_end=3.0, controller=controller)
        b = simulate_closed_loop(OFF_OTHERWISE, r=r, t_end=3.0, controller=controller)
        assert np.array_equal(a.states, b.states) and np.array_equal(a.u, b.u)
    # the fixed-step RK4 (an input given as a function of t)
    a = simulate(PAPER, u=lambda t: 2 * np.sin(4 * np.pi * t), t_end=1.0)
    b = simulate(OFF_OTHERWISE, u=lambda t: 2 * np.sin(4 * np.pi * t), t_end=1.0)
    assert np.array_equal(a.states, b.states)


#: Outputs of the paper's model before the variants existed (the same code paths, this machine's build):
#: (run, t [s], [x, v, p1, p2]).
BEFORE = [
    ("case 1", 1.0, [0.0015568976366330165, -0.001174702999684848, 13249698.765360277, 20124494.06667928]),
    ("case 1", 5.0, [0.008100154850004423, -0.0012253447433568081, 13426755.4980967, 20393681.06955452]),
    ("case 3", 1.234, [0.01780809706144824, 0.020636245330322954, 9067339.03993953, 13340549.523891706]),
    ("closed loop", 5.0, [0.0018335769515165174, 1.0025745198649215e-05, 11673151.610201154, 17695300.686035566]),
    ("rk4", 2.0, [0.0031832794065155792, -0.0009129682251063728, 13420472.576506373, 20375098.590562064]),
    ("linear case 2", 5.0, [0.008186400014445332, -0.0067683243163389, 13638502.1356012, 22089860.16703877]),
]


def test_the_papers_model_gives_what_it_gave_before_the_variants():
    runs = {"case 1": simulate(PAPER, CASES[0].u, CASES[0].d), "case 3": simulate(PAPER, CASES[2].u, CASES[2].d),
            "closed loop": simulate_closed_loop(PAPER, r=parse_signal("sine:0.02:0.5"), t_end=5.0),
            "rk4": simulate(PAPER, u=lambda t: 2 * np.sin(4 * np.pi * t), t_end=2.0),
            "linear case 2": simulate(PAPER, CASES[1].u, CASES[1].d, model="linear")}
    for name, t, state in BEFORE:
        run = runs[name]
        k = int(round(t / (run.t[1] - run.t[0])))
        # bit for bit on the machine they were recorded on; another CPU's build may round differently
        np.testing.assert_allclose(run.states[k], state, rtol=1e-11, atol=1e-16, err_msg=name)


def test_the_linearisation_with_every_effect_off_is_the_papers():
    a, b = linearize(PAPER), linearize(OFF_OTHERWISE)
    for name in ("A", "B_positive", "B_negative", "E"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert a.lambdas == b.lambdas and a.states == b.states and a.A_negative is None
    for x, y in zip(a.tf_coeffs() + a.closed_loop_coeffs(10.0), b.tf_coeffs() + b.closed_loop_coeffs(10.0),
                    strict=True):
        assert np.array_equal(x, y)
    np.testing.assert_array_equal(a.packed()[32:], 0.0)          # no offset: the point holds with u = 0


# -- the registry ------------------------------------------------------------------------------------------

def test_the_registry_names_one_effect_per_variant_and_says_what_each_is():
    assert list(VARIANTS) == ["paper", "spool", "leakage", "stribeck"]
    for name, variant in VARIANTS.items():
        assert variant.name == name and variant.description and "\n" not in variant.description
        assert variant_effects(name) == variant.effects
        assert variant.effects.active == (() if name == "paper" else (name,))
        assert variant_name(variant.effects) == name
    assert variant_effects("spool+leakage+stribeck").active == ("spool", "leakage", "stribeck")
    assert variant_name(variant_effects("spool+leakage")) is None
    assert describe_effects(EFFECTS_OFF).startswith("the paper's model")
    text = describe_effects(variant_effects("spool+stribeck"))
    assert "spool (ω_v = 150 rad/s, ζ_v = 0.7)" in text and "F_s = 1500 N" in text and "leakage" not in text


@pytest.mark.parametrize("name", ["stiction", "", "Spool", "spool+", "paper+stiction"])
def test_an_unknown_variant_is_refused_naming_it_and_the_names_allowed(name):
    with pytest.raises(FieldError) as info:
        variant_effects(name)
    assert info.value.field == "variant" and info.value.value == name
    assert all(known in info.value.what for known in VARIANTS)
    assert str(info.value).startswith(f"variant = {name.strip() or '(empty)'} is not allowed: use one of paper, ")


@pytest.mark.parametrize("changes, field", [
    ({"omega_v": -1.0}, "omega_v"), ({"zeta_v": 0.0}, "zeta_v"), ({"C_L": -1e-13}, "C_L"), ({"F_c": -1.0}, "F_c"),
    ({"F_c": 100.0, "F_s": 50.0}, "F_s"), ({"v_s": 0.0}, "v_s"), ({"v_eps": -1e-3}, "v_eps"),
    ({"C_L": math.nan}, "C_L"), ({"omega_v": "fast"}, "omega_v"), ({"F_s": True}, "F_s"),
])
def test_effects_outside_their_range_are_refused_naming_the_field(changes, field):
    with pytest.raises(FieldError) as info:
        Effects(**changes)
    assert info.value.field == field
    # through the parameter set: its own kind of refusal, the same field
    with pytest.raises(ParameterError) as info:
        ActuatorParams(effects=changes)
    assert info.value.field == field


def test_parameter_sets_with_effects_round_trip_and_differ_from_the_papers():
    p = with_effects("spool+leakage", M=4500.0)
    assert p != PAPER.replace(M=4500.0) and hash(p) == hash(with_effects("spool+leakage", M=4500.0))
    assert ActuatorParams(**json.loads(json.dumps(p.to_dict()))) == p
    assert p.replace(B=100.0).effects == p.effects and p.replace(effects=None).effects == EFFECTS_OFF
    assert "effects=Effects(omega_v=150.0" in repr(p)
    assert ActuatorParams(effects="stribeck").effects == VARIANTS["stribeck"].effects


def test_the_model_reads_the_effects_where_the_packed_vector_puts_them():
    assert list(PARAM_INDEX)[14:] == list(EFFECT_FIELDS)
    for function in (model.derivatives, model.spool_derivatives):
        reads = re.findall(r"^\s*(\w+) = prm\[(\d+)\]", inspect.getsource(function), flags=re.M)
        assert reads and {n: int(i) for n, i in reads} == {n: PARAM_INDEX[n] for n, _ in reads}


# -- (b) each effect's equations and steady states, by hand --------------------------------------------------

def test_leakage_holds_still_only_with_the_valve_feeding_the_leak():
    p = with_effects("leakage")
    C_L = p.effects.C_L
    op = operating_point(p)
    # by hand (docs/model.md §6.2): Kq1 = Kq2, pr = 0, d0 = 0, so p2 = (A1/A2) p1 > p1: the leak runs from
    # chamber 2 to 1, u < 0, and Kq1 sqrt(p1) = Kq2 sqrt(ps - p2) gives p1 = ps A2 / (A1 + A2)
    p1 = p.ps * p.A2 / (p.A1 + p.A2)
    p2 = p.A1 / p.A2 * p1
    u_e = C_L * (p1 - p2) / (p.Kq1 * math.sqrt(p1))
    assert (op.x, op.v) == (0.0, 0.0)
    np.testing.assert_allclose([op.p1, op.p2, op.u], [p1, p2, u_e], rtol=1e-12)
    assert op.p1 == pytest.approx(12.7197e6, rel=1e-5) and op.u == pytest.approx(-0.030226, rel=1e-4)
    # an equilibrium with the valve so open, and not with it shut: the leak then fills chamber 1
    np.testing.assert_allclose(rhs(op.state, op.u, 0.0, p), 0.0, atol=1e-9)
    dp1 = rhs(op.state, 0.0, 0.0, p)[2]
    assert dp1 == pytest.approx(p.beta_e / (p.A1 * p.L0) * C_L * (p2 - p1), rel=1e-12) and dp1 > 0
    # the paper's model holds still at any pressures with the valve shut
    np.testing.assert_allclose(rhs(op.state, 0.0, 0.0, PAPER), 0.0, atol=1e-9)
    with pytest.raises(ParameterError, match="p1_e"):
        operating_point(p, p1_e=12e6)


def test_under_proportional_control_the_leak_leaves_a_steady_error_of_u_e_over_kp():
    p = with_effects("leakage")
    op = operating_point(p)
    kp = 10.0
    run = simulate_closed_loop(p, r=0.0, kp=kp, controller="continuous", t_end=400.0, dt=0.5)
    # the controller's steady command is the one that holds still: u_e = kp (0 - x)
    assert run.success
    assert run.x[-1] == pytest.approx(-op.u / kp, rel=1e-3)          # 3.0 mm
    np.testing.assert_allclose([run.p1[-1], run.p2[-1]], [op.p1, op.p2], rtol=1e-3)
    paper = simulate_closed_loop(PAPER, r=0.0, kp=kp, controller="continuous", t_end=400.0, dt=0.5)
    assert abs(paper.x[-1]) < 1e-9                                   # no leak, no error


@pytest.mark.parametrize("name", ["leakage", "spool+leakage"])
def test_simulations_started_at_the_leakage_operating_point_stay_there(name):
    p = with_effects(name)
    lin = linearize(p)
    for model_ in ("nonlinear", "linear"):
        # the spool (when on) at rest at u_v = u_e
        run = simulate(p, u=Constant(lin.op.u), t_end=1.0, initial_state=lin.op_state, model=model_)
        np.testing.assert_allclose(run.states[-1], lin.op.state, rtol=1e-9, atol=1e-12)


def stribeck_term(e: Effects, v: float) -> float:
    """eq. V3 written out: (F_c + (F_s - F_c) exp(-(v/v_s)^2)) tanh(v/v_eps)."""
    return (e.F_c + (e.F_s - e.F_c) * math.exp(-(v / e.v_s) ** 2)) * math.tanh(v / e.v_eps)


def test_stribeck_friction_is_the_papers_plus_the_stribeck_term():
    p = ActuatorParams(effects=Effects(F_c=500.0, F_s=1500.0, v_s=0.01, v_eps=1e-4))
    e = p.effects
    prm, prm0 = pack_params(p), pack_params(PAPER)
    op = operating_point(p)
    for v in (-0.05, -3e-3, -1e-4, 1e-5, 1e-3, 0.01, 0.05):
        extra = (model.derivatives(0.0, v, op.p1, op.p2, 0.0, 0.0, prm0)[1]
                 - model.derivatives(0.0, v, op.p1, op.p2, 0.0, 0.0, prm)[1]) * p.M
        assert extra == pytest.approx(stribeck_term(e, v), rel=1e-9, abs=1e-9)
    # at rest no friction (the law is smooth): the operating point is an equilibrium as in the paper's model
    np.testing.assert_allclose(rhs(op.state, 0.0, 0.0, p), 0.0, atol=1e-9)
    # breakaway: just off rest (v_eps << v << v_s) the term is the static level F_s, odd in v ...
    assert stribeck_term(e, 1e-3) == pytest.approx(e.F_s, rel=0.01)
    assert stribeck_term(e, -1e-3) == -stribeck_term(e, 1e-3)
    # ... and well above v_s the Coulomb level F_c
    assert stribeck_term(e, 0.05) == pytest.approx(e.F_c, rel=1e-9)
    # the acceleration just off rest: the net force less B v + Af S(v) + F_s (to within the 1 % above)
    v = 1e-3
    acc = model.derivatives(0.0, v, op.p1, op.p2, 0.0, 0.0, prm)[1]
    hand = -(p.B * v + p.Af * 2 / math.pi * math.atan(p.k_f * v) + e.F_s) / p.M
    assert acc == pytest.approx(hand, rel=0.01)
    # its slope at rest adds F_s / v_eps to the paper's friction slope (l1 M, Table 2)
    dv = 1e-9
    slope = -(model.derivatives(0.0, dv, op.p1, op.p2, 0.0, 0.0, prm)[1]
              - model.derivatives(0.0, -dv, op.p1, op.p2, 0.0, 0.0, prm)[1]) / (2 * dv) * p.M
    assert slope == pytest.approx(p.B + 2 * p.k_f * p.Af / math.pi + e.F_s / e.v_eps, rel=1e-6)
    assert linearize(p).friction_damping == pytest.approx(slope - p.B, rel=1e-6)


def test_at_a_steady_slow_speed_the_pressures_carry_the_stribeck_friction():
    # u = 0.05 V moves the piston at about 0.5 mm/s, inside the Stribeck hump (v_s = 5 mm/s)
    for params in (PAPER, with_effects("stribeck")):
        run = simulate(params, u=Constant(0.05), t_end=2.0)
        v, p1, p2 = run.v[-1], run.p1[-1], run.p2[-1]
        # steady: the speed moves by less than 1e-3 of itself over the last 0.1 s (the pressures' common
        # level still creeps, the valve's flows hardly depending on it), so M dv/dt < 1e-5 of the friction
        assert 2e-4 < v < 1e-3 and abs(run.v[-1] - run.v[-101]) < 1e-3 * v
        paper_friction = params.B * v + params.Af * 2 / math.pi * math.atan(params.k_f * v)
        expected = paper_friction + (stribeck_term(params.effects, v) if params.effects.stribeck else 0.0)
        assert params.A1 * p1 - params.A2 * p2 - params.d0 == pytest.approx(expected, rel=1e-5)
    # the variant's term there is some hundreds of newtons, well above the check's tolerance
    assert stribeck_term(VARIANTS["stribeck"].effects, v) > 300.0


def test_the_spool_follows_the_command_through_its_second_order():
    p = with_effects("spool")
    w, z = p.effects.omega_v, p.effects.zeta_v
    prm = pack_params(p)
    # eq. V1 written out
    assert model.spool_derivatives(0.2, 3.0, 1.0, prm) == (3.0, w * w * (1.0 - 0.2) - 2 * z * w * 3.0)
    # the orifices see the spool's position, not the command
    state = np.array([0.0, 0.0, 12e6, p.p2_init, 0.5, 0.0])
    f = rhs(state, 2.0, 0.0, p)
    np.testing.assert_array_equal(f[:4], rhs(state[:4], 0.5, 0.0, PAPER))
    assert f[5] == pytest.approx(w * w * 1.5)
    with pytest.raises(FieldError, match="state"):
        rhs(p.initial_state, 0.0, 0.0, p)
    # P(s) with the spool is the paper's times w^2 / (s^2 + 2 z w s + w^2): at s = j w, 1 / (2 j z)
    lin, lin0 = linearize(p), linearize(PAPER)
    assert response(lin, 1j * w) / response(lin0, 1j * w) == pytest.approx(1 / (2j * z), rel=1e-9)


def test_the_six_state_kernels_agree_with_an_independent_integration():
    from scipy.integrate import solve_ivp

    p = with_effects("spool+leakage+stribeck")
    case = CASES[2]
    run = simulate(p, case.u, case.d, t_end=1.0)
    rk4 = simulate(p, u=lambda t: case.u(t), d=lambda t: case.d(t), t_end=1.0, h_max=2.5e-4)
    prm = pack_params(p)
    y0 = np.concatenate([p.initial_state, [0.0, 0.0]])
    sol = solve_ivp(lambda t, y: rhs(y, float(case.u(t)), float(case.d(t)), prm), (0.0, 1.0), y0,
                    method="DOP853", rtol=1e-11, atol=[1e-14, 1e-13, 1e-4, 1e-4, 1e-12, 1e-10], t_eval=run.t)
    span = np.ptp(sol.y[:4], axis=1)
    # the paper's accuracy (docs/model.md §1: 2e-7 of each state's range); the RK4 at its step 1e-6
    assert np.max(np.abs(run.states - sol.y[:4].T).max(axis=0) / span) < 1e-6
    assert np.max(np.abs(rk4.states - sol.y[:4].T).max(axis=0) / span) < 1e-5


# -- (c) the linearisation is the Jacobian of the model with its effects ----------------------------------

#: Each state's scale (x, v, p1, p2, u_v, du_v/dt) and the step of its central difference. The steps' truncation
#: errors (h^2 times f's third derivative: (k_f h)^2 in the friction, (h / p)^2 in the square roots) are below
#: 1e-12 of each entry; their rounding errors, eps times the terms that cancel in f (34 m/s^2 in dv, 1e6 Pa/s
#: in dp) over h, below 1e-7 of the entries they fall on: hence rtol 1e-6, each entry in the states' scales.
SCALES = np.array([1e-3, 1e-3, 1e6, 1e6, 1.0, 100.0])
STEPS = np.array([1e-10, 1e-10, 10.0, 10.0, 1e-7, 1e-5])


def assert_same_jacobian(J, A):
    """J and A entry by entry, in the states' scales (so that a small entry counts as much as a large one)."""
    n = A.shape[0]
    scaling = SCALES[None, :n] / SCALES[:n, None]
    np.testing.assert_allclose(J * scaling, A * scaling, rtol=1e-6, atol=1e-9 * np.abs(A * scaling).max())


def jacobian(params, state, u, side=0):
    """Central differences of the model's right-hand side; ``side`` +1 or -1: the spool's column one-sided
    (at u_v = 0, the valve's kink, each branch's slope; the flows are linear in u_v on each side, eq. 3)."""
    n = state.size
    J = np.zeros((n, n))
    for j in range(n):
        h = STEPS[j]
        hi, lo = state.copy(), state.copy()
        if j == 4 and side:
            hi[j] += side * h
            J[:, j] = (rhs(hi, u, 0.0, params) - rhs(lo, u, 0.0, params)) / (side * h)
            continue
        hi[j] += h
        lo[j] -= h
        J[:, j] = (rhs(hi, u, 0.0, params) - rhs(lo, u, 0.0, params)) / (2 * h)
    return J


@pytest.mark.parametrize("name", ["spool", "leakage", "stribeck", "spool+leakage+stribeck"])
def test_the_linearisation_of_each_variant_is_the_jacobian_of_its_model(name):
    for x_e in (0.0, 0.05):
        p = with_effects(name)
        lin = linearize(p, operating_point(p, x_e=x_e))
        state = lin.op_state
        assert lin.n_states == state.size == p.effects.n_states
        np.testing.assert_allclose(rhs(state, lin.op.u, 0.0, p), 0.0, atol=1e-9)      # an equilibrium
        if p.effects.spool:
            # the branch follows the sign of u_v: A on u_v >= 0, A_negative on u_v < 0; the spool rests at u_e
            if lin.op.u == 0.0:
                assert_same_jacobian(jacobian(p, state, 0.0, side=1), lin.A)
                assert_same_jacobian(jacobian(p, state, 0.0, side=-1), lin.A_negative)
            else:
                assert_same_jacobian(jacobian(p, state, lin.op.u), lin.A_negative if lin.op.u < 0 else lin.A)
            du = 1e-3
            B = (rhs(state, lin.op.u + du, 0.0, p) - rhs(state, lin.op.u - du, 0.0, p)) / (2 * du)
            np.testing.assert_allclose(B, lin.B("positive"), rtol=1e-9, atol=1e-12)
            np.testing.assert_array_equal(lin.B("negative"), lin.B("positive"))
        else:
            assert_same_jacobian(jacobian(p, state, lin.op.u), lin.A)
            # B: the one-sided slopes of each branch of the valve (eq. 13) at the point's pressures
            du = 1e-6
            for branch, u0 in (("positive", 0.0), ("negative", -du)):
                B = (rhs(state, u0 + du, 0.0, p) - rhs(state, u0, 0.0, p)) / du
                np.testing.assert_allclose(B, lin.B(branch), rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose((rhs(state, lin.op.u, 1.0, p) - rhs(state, lin.op.u, 0.0, p)), lin.E, rtol=1e-9)


@pytest.mark.parametrize("name", ["paper", "spool", "leakage", "stribeck", "spool+leakage+stribeck"])
def test_the_transfer_function_is_that_of_the_state_space_model(name):
    p = with_effects(name)
    lin = linearize(p)
    for branch in ("positive", "negative"):
        num, den = lin.tf_coeffs(branch)
        assert den[0] == 1.0 and den[-1] == 0.0                   # monic, the integrator X = V / s kept exact
        A, B = lin.state_matrix(branch), lin.B(branch)
        C = np.eye(lin.n_states)[0]
        for w in (0.3, 10.0, 45.0, 150.0, 1000.0):
            s = 1j * w
            direct = C @ np.linalg.solve(s * np.eye(lin.n_states) - A, B)
            assert np.polyval(num, s) / np.polyval(den, s) == pytest.approx(direct, rel=1e-9)
    cnum, cden = lin.closed_loop_coeffs(10.0)
    num, den = lin.tf_coeffs()
    s = 2j
    h = 10 * np.polyval(num, s) / np.polyval(den, s)
    assert np.polyval(cnum, s) / np.polyval(cden, s) == pytest.approx(h / (1 + h), rel=1e-12)
    assert len(lin.poles()) == len(den) - 1 and lin.ss().nstates == lin.n_states
    json.dumps(lin.to_dict())


def test_the_spool_variant_shows_near_the_actuators_dominant_dynamics_and_not_at_low_frequency():
    lin, lin0 = linearize(with_effects("spool")), linearize(PAPER)

    def phase_lag(w):
        return np.degrees(np.angle(response(lin0, 1j * w) / response(lin, 1j * w)))

    slow = -max(pole.real for pole in lin0.poles() if pole.real < 0)         # 45 rad/s (eq. 23)
    assert 15.0 < phase_lag(slow) < 40.0 and phase_lag(1.0) < 1.0
    assert abs(abs(response(lin, 1j * slow) / response(lin0, 1j * slow)) - 1) < 0.05


def test_a_linear_spool_run_follows_the_nonlinear_one_as_closely_as_the_papers_does():
    u = Sine(0.2, 3.0)

    def mismatch(params):
        lin_run, run = simulate(params, u, t_end=1.0, model="linear"), simulate(params, u, t_end=1.0)
        return np.abs(lin_run.x - run.x).max() / np.ptp(run.x)

    # 8 % for the paper's model (the pressures' drift under the valve's two branches, eq. 13)
    spool, paper = mismatch(with_effects("spool")), mismatch(PAPER)
    assert spool < 1.1 * paper < 0.1


# -- (d) the fluid's balance with the valve shut ------------------------------------------------------------

@pytest.mark.parametrize("name", ["leakage", "spool+leakage+stribeck"])
def test_with_the_valve_shut_the_leak_out_of_chamber_1_is_the_leak_into_chamber_2(name):
    p = with_effects(name, d0=5000.0)
    C_L = p.effects.C_L
    rng = np.random.default_rng(3)
    for _ in range(50):
        x, v = rng.uniform(-0.2, 0.2), rng.uniform(-0.05, 0.05)
        p1, p2 = rng.uniform(1e6, 31e6, size=2)
        state = np.array([x, v, p1, p2] + ([0.0, 0.0] if p.effects.spool else []))
        f = rhs(state, 0.0, 0.0, p)
        V1, V2 = p.A1 * (p.L0 + x), p.A2 * (p.L0 - x)
        # each chamber: its compression plus the piston's displacement is the flow in (eqs. 1b-1c, V2)
        out_of_1 = -(V1 * f[2] / p.beta_e + p.A1 * v)
        into_2 = V2 * f[3] / p.beta_e - p.A2 * v
        leak = C_L * (p1 - p2)
        scale = p.A1 * abs(v) + abs(leak)
        assert out_of_1 == pytest.approx(leak, rel=1e-9, abs=1e-12 * scale)
        assert into_2 == pytest.approx(leak, rel=1e-9, abs=1e-12 * scale)
        # the whole: no fluid made or lost, the leak only moves it
        total = V1 * f[2] / p.beta_e + V2 * f[3] / p.beta_e + (p.A1 - p.A2) * v
        assert abs(total) <= 1e-9 * scale


def test_with_the_valve_shut_and_the_piston_at_its_stop_the_leak_equalises_the_pressures():
    # the piston pressed against its end stop x_max = 0.8 L0 keeps the volumes V1, V2: the leak alone moves
    # fluid, V1 dp1 = -beta_e Q_L dt = -V2 dp2, so V1 p1 + V2 p2 stays and p1 - p2 decays as
    # exp(-t / tau), 1 / tau = beta_e C_L (1/V1 + 1/V2) (eq. V2), to their mean weighted by the volumes
    p = with_effects("leakage", x0=0.24, p1_0=20e6, p2_0=10e6)
    V1, V2 = p.A1 * (p.L0 + p.x_max), p.A2 * (p.L0 - p.x_max)
    rate = p.beta_e * p.effects.C_L * (1 / V1 + 1 / V2)                # 1.32 1/s
    run = simulate(p, u=0.0, t_end=5.0, dt=0.01)
    assert run.success and np.all(run.x == p.x_max) and np.all(run.v == 0.0)
    # to the integrator's accuracy: TOL 1e-9 of (1 MPa + the pressure) per step, some 0.02 Pa
    np.testing.assert_allclose(run.p1 - run.p2, 10e6 * np.exp(-rate * run.t), rtol=1e-7, atol=0.1)
    np.testing.assert_allclose(V1 * run.p1 + V2 * run.p2, V1 * 20e6 + V2 * 10e6, rtol=1e-12)
    # without the leak nothing moves
    held = simulate(ActuatorParams(x0=0.24, p1_0=20e6, p2_0=10e6), u=0.0, t_end=5.0, dt=0.01)
    assert np.all(held.p1 == 20e6) and np.all(held.p2 == 10e6)
