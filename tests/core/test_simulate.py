import numpy as np
import pytest
from scipy.integrate import solve_ivp

from eha_core._kernels import derivatives as compiled_derivatives
from eha_core.experiments import PAPER_CASES, run_paper_cases
from eha_core.linear import linearize
from eha_core.model import pack_params
from eha_core.params import ActuatorParams
from eha_core.signals import Sampled, Sine, Square, Step, WhiteNoise
from eha_core.simulate import simulate, simulate_closed_loop, simulate_many

P = ActuatorParams()


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_equilibrium_stays_put(model):
    res = simulate(P, u=0.0, d=0.0, t_end=5.0, model=model)
    assert res.success
    assert np.abs(res.x).max() < 1e-12
    assert np.abs(res.v).max() < 1e-12
    assert np.abs(res.p1 - P.p1_0).max() < 1e-3
    assert np.abs(res.p2 - P.p2_init).max() < 1e-3


@pytest.mark.parametrize("u", [10.0, -10.0, Square(10.0, 0.3), Sine(10.0, 0.5), Sine(10.0, 40.0)])
def test_bounds_hold_under_extreme_inputs(u):
    res = simulate(P, u=u, t_end=5.0)
    assert res.success
    assert np.all(res.p1 >= P.pr) and np.all(res.p1 <= P.ps)
    assert np.all(res.p2 >= P.pr) and np.all(res.p2 <= P.ps)
    assert np.all(np.abs(res.x) <= 0.8 * P.L0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_end_stop_holds_then_releases(sign):
    # full command until the stop, then the opposite command
    res = simulate(P, u=Step(-sign * 10.0, t0=3.0, initial=sign * 10.0), t_end=5.0)
    at_stop = res.t < 3.0
    reached = np.isclose(sign * res.x, 0.8 * P.L0) & at_stop
    assert reached.any(), "the piston should reach the stop within 3 s at 10 V"
    first = np.argmax(reached)
    assert np.all(res.v[first:3000] == 0.0)                  # it stays put at the stop
    assert np.all(sign * res.x[first:3000] == 0.8 * P.L0)
    assert sign * res.x[-1] < 0.8 * P.L0 - 0.1               # and is pulled back


def test_paper_cases_land_in_the_ranges_of_spec_section_3():
    res = {int(r.label[-1]): r for r in run_paper_cases(P)}
    for k, r in res.items():
        assert r.success
        x_hi = 0.045 if k in (3, 4) else 0.016
        assert -1e-6 <= r.x.min() and r.x.max() <= x_hi
        assert r.x.max() >= 0.7 * x_hi                       # a drift, not a standstill
        assert np.abs(r.v).max() < 0.1
        assert 6e6 <= r.p1.min() and r.p1.max() <= 16.5e6
        assert 10e6 <= r.p2.min() and r.p2.max() <= 24.5e6
    # the disturbance barely changes the response (d/M is small)
    for a, b in ((1, 2), (3, 4)):
        assert np.abs(res[a].x - res[b].x).max() < 0.02 * res[a].x.max()


def test_linear_and_nonlinear_agree_for_small_inputs():
    def worst(amplitude):
        rn = simulate(P, u=Sine(amplitude, 2.0))
        rl = simulate(P, u=Sine(amplitude, 2.0), model="linear")
        return max(np.abs(getattr(rn, s) - getattr(rl, s)).max() / np.ptp(getattr(rn, s))
                   for s in ("x", "v", "p1", "p2"))

    small, larger = worst(0.01), worst(0.1)
    assert small < 1e-2
    assert small < larger / 10                              # the gap closes as the input shrinks


def test_linear_run_is_the_linear_ode_with_absolute_states():
    """The switching linear model, integrated by scipy, with eq. 14 applied."""
    lin = linearize(P)
    u = Sine(3.0, 2.0)
    res = simulate(P, u=u, d=Sine(2e3, 1.0), t_end=1.0, model="linear")

    def f(t, z):
        ut = float(u(t))
        return lin.A @ z + lin.B("positive" if ut >= 0 else "negative") * ut + lin.E * 2e3 * np.sin(2 * np.pi * t)

    sol = solve_ivp(f, (0, 1.0), np.zeros(4), t_eval=res.t, rtol=1e-10, atol=[1e-14, 1e-13, 1e-4, 1e-4], method="Radau")
    np.testing.assert_allclose(res.states, sol.y.T + lin.op.state, rtol=0, atol=1e-6 * np.ptp(res.states, axis=0).max())
    for s in range(4):
        assert np.abs(res.states[:, s] - sol.y[s] - lin.op.state[s]).max() < 1e-5 * np.ptp(sol.y[s])


def test_nonlinear_run_matches_a_tight_reference():
    case = PAPER_CASES[3]
    res = simulate(P, u=case.u, d=case.d, t_end=1.0)
    prm = pack_params(P)
    sol = solve_ivp(lambda t, y: compiled_derivatives(*y, float(case.u(t)), float(case.d(t)), prm),
                    (0, 1.0), P.initial_state, method="Radau", rtol=1e-10,
                    atol=[1e-13, 1e-12, 1e-4, 1e-4], t_eval=res.t)
    for s in range(4):
        assert np.abs(res.states[:, s] - sol.y[s]).max() < 1e-5 * np.ptp(sol.y[s])


def test_integrator_error_follows_its_tolerance(monkeypatch):
    import eha_core.simulate as sim

    case = PAPER_CASES[4]
    monkeypatch.setattr(sim, "TOL", 1e-12)
    fine = simulate(P, u=case.u, t_end=1.0).states
    errs = []
    for tol in (1e-6, 1e-8):
        monkeypatch.setattr(sim, "TOL", tol)
        errs.append(np.abs(simulate(P, u=case.u, t_end=1.0).states - fine).max(axis=0) / np.ptp(fine, axis=0))
    assert np.all(errs[1] < errs[0] / 10) and np.all(errs[1] < 1e-6)


def test_closed_loop_zoh_equals_the_exact_discrete_loop():
    import control

    lin = linearize(P)
    ts, kp = 0.01, 10.0
    r = 0.01 * np.sign(np.sin(np.arange(300) * 0.05))
    res = simulate_closed_loop(P, r, kp=kp, ts=ts, model="linear", branch="positive")
    Pd = control.c2d(control.ss(lin.tf()), ts, "zoh")
    z, xs = np.zeros((3, 1)), []
    for k in range(r.size):
        xk = (Pd.C @ z).item()
        xs.append(xk)
        z = Pd.A @ z + Pd.B * (kp * (r[k] - xk))
    np.testing.assert_allclose(res.x, xs, atol=1e-9 * np.abs(xs).max())
    np.testing.assert_allclose(res.u, kp * (res.r - res.x), atol=1e-12)
    assert res.t.size == r.size and res.controller == "zoh"


def test_closed_loop_continuous_equals_H_of_s():
    import control

    lin = linearize(P)
    res = simulate_closed_loop(P, Step(0.01), kp=10.0, ts=0.01, controller="continuous",
                               t_end=3.0, dt=0.001, model="linear", branch="positive")
    _, y = control.step_response(lin.closed_loop_tf(10.0), res.t)
    np.testing.assert_allclose(res.x, 0.01 * y, atol=1e-6 * 0.01)


def test_closed_loop_nonlinear_tracks_and_keeps_bounds():
    # with Kp = 10 the slow closed-loop pole is near -Kp N / (l2 + l3) l4 = -0.14 rad/s (eq. 24)
    lin = linearize(P)
    slow = np.min(np.abs(lin.closed_loop_poles(10.0).real))
    assert slow == pytest.approx(2437.0 / 17207.0, rel=0.05)
    res = simulate_closed_loop(P, Step(0.05), kp=10.0, ts=0.01, t_end=40.0)
    assert res.success
    assert abs(res.x[-1] - 0.05) < 0.05 * np.exp(-slow * 40.0) * 3   # settled as the slow pole says
    assert np.all(np.diff(res.x) > -1e-9)                              # no overshoot back
    assert np.all((res.p1 >= P.pr) & (res.p1 <= P.ps))


def test_inputs_as_function_array_and_signal_agree():
    t = np.arange(2001) * 1e-3
    by_signal = simulate(P, u=Sine(6.0, 2.0), t_end=2.0)
    by_function = simulate(P, u=lambda tt: 6.0 * np.sin(4 * np.pi * tt), t_end=2.0)
    def scalar_only(tt):
        return 6.0 * float(np.sin(4 * np.pi * tt)) if np.ndim(tt) == 0 else 1 / 0

    by_scalar_fn = simulate(P, u=scalar_only, t_end=2.0)
    by_samples = simulate(P, u=6.0 * np.sin(4 * np.pi * t), t_end=2.0)
    # a function's jumps are unknown, so it takes the fixed-step RK4 (its last stage read a hair before
    # the step's end), the signal the adaptive integrator: equal to their accuracies, ~3e-7 of the range
    span = np.ptp(by_signal.states, axis=0)
    assert np.all(np.abs(by_function.states - by_signal.states).max(axis=0) < 1e-6 * span)
    np.testing.assert_array_equal(by_scalar_fn.states, by_function.states)
    # linear interpolation between 1 ms samples of a 2 Hz sine: close, not identical
    assert np.abs(by_samples.x - by_signal.x).max() < 1e-4 * np.ptp(by_signal.x)


def test_zoh_samples_are_seen_held_until_the_next_sample():
    """A held input equals the equivalent step sum: no early look at the next sample."""
    t = np.arange(11) * 0.1
    vals = np.array([0, 3, 3, -2, -2, 5, 0, 0, 1, 1, 1], float)
    a = simulate(P, u=Sampled(t, vals, hold="zoh"), t_end=1.0)
    steps = Step(3, 0.1) + Step(-5, 0.3) + Step(7, 0.5) + Step(-5, 0.6) + Step(1, 0.8)
    b = simulate(P, u=steps, t_end=1.0)
    # the same segments; the held values are summed in another order, so the error control may take
    # other steps: equal to the integrator's accuracy (~1e-8 of each state's range here)
    span = np.ptp(b.states, axis=0)
    assert np.all(np.abs(a.states - b.states).max(axis=0) < 1e-6 * span)


def test_white_noise_disturbance_is_reproducible():
    r1 = simulate(P, u=Sine(6.0, 2.0), d=WhiteNoise(1000.0, seed=3), t_end=1.0)
    r2 = simulate(P, u=Sine(6.0, 2.0), d=WhiteNoise(1000.0, seed=3), t_end=1.0)
    r3 = simulate(P, u=Sine(6.0, 2.0), d=WhiteNoise(1000.0, seed=4), t_end=1.0)
    np.testing.assert_array_equal(r1.states, r2.states)
    assert np.abs(r1.v - r3.v).max() > 0
    assert r1.d.std() == pytest.approx(1000.0, rel=0.1)


def test_batch_equals_single_runs():
    cases = [PAPER_CASES[k] for k in (1, 2, 3, 4)]
    batch = simulate_many(P, [c.u for c in cases], [c.d for c in cases])
    for c, b in zip(cases, batch, strict=True):
        np.testing.assert_array_equal(simulate(P, c.u, c.d).states, b.states)


def test_result_object():
    res = simulate(P, u=Sine(6.0, 2.0), t_end=0.01)
    df = res.to_pandas()
    assert df.index.name == "t" and list(df.columns) == ["x", "v", "p1", "p2", "u", "d"]
    np.testing.assert_array_equal(df.index.to_numpy(), res.t)
    assert res.to_csv().splitlines()[0] == "t,x,v,p1,p2,u,d"
    assert res.states.shape == (11, 4)
    np.testing.assert_allclose(res.u, 6.0 * np.sin(4 * np.pi * res.t), atol=1e-12)


@pytest.mark.parametrize("kwargs, words", [
    ({"t_end": -1.0}, "t_end"),
    ({"t_end": 1.0, "dt": 0.3}, "whole number"),
    ({"dt": 0.0}, "dt"),
    ({"t_end": 1.0, "dt": 2.0}, "must not exceed"),
    ({"model": "quadratic"}, "model"),
    ({"branch": "up"}, "branch"),
    ({"u": np.ones(7)}, "samples"),
    ({"u": lambda t: np.where(t > 0.5, np.nan, 0.0), "t_end": 1.0}, "not finite at t = 0.5"),
    ({"initial_state": [0, 0, 1]}, "initial_state = \\[0, 0, 1\\]"),
    ({"t_end": 1e6}, "limit"),
])
def test_bad_arguments_name_the_problem(kwargs, words):
    with pytest.raises(ValueError, match=words):
        simulate(P, **kwargs)


def test_closed_loop_bad_arguments():
    with pytest.raises(ValueError, match="kp"):
        simulate_closed_loop(P, np.zeros(10), kp=-1)
    with pytest.raises(ValueError, match="controller"):
        simulate_closed_loop(P, np.zeros(10), controller="pid")
    with pytest.raises(ValueError, match="t_end"):
        simulate_closed_loop(P, Sine(0.01, 1.0))
    with pytest.raises(ValueError, match="ts"):
        simulate_closed_loop(P, Sine(0.01, 1.0), ts=0.003, dt=0.002, t_end=1.0)


def test_the_linearised_model_driven_beyond_its_range_says_where():
    """A 6 V step: the linearised model passes the end stop and reaches negative pressures, the nonlinear one not."""
    from eha_core.signals import Step

    P = ActuatorParams()
    lin = simulate(P, u=Step(6.0), t_end=5.0, model="linear")
    found = {(e.state, e.side): e for e in lin.beyond_physical_range()}
    assert set(found) >= {("x", "above"), ("p1", "below")}
    assert found[("x", "above")].bound == P.x_max and found[("x", "above")].extreme > P.x_max
    assert found[("p1", "below")].extreme == lin.p1.min() < P.pr
    assert simulate(P, u=Step(6.0), t_end=5.0, model="nonlinear").beyond_physical_range() == ()
    assert simulate(P, u=Step(0.5), t_end=0.2, model="linear").beyond_physical_range() == ()
