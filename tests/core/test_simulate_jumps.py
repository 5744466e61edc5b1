"""The simulator at the inputs' jumps: it stops at every discontinuity the signals report, so a jump
between output samples costs nothing in accuracy; against an independent implicit reference."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from eha_core._kernels import derivatives as compiled_derivatives
from eha_core.model import pack_params, rhs
from eha_core.params import ActuatorParams
from eha_core.signals import Sampled, Sine, Square, Step, WhiteNoise, parse_signal
from eha_core.simulate import _as_signal, simulate, simulate_closed_loop

P = ActuatorParams(M=9000.0, B=300.0)


def radau(params, u, d, t_end, t, cuts=()):
    """Radau rtol 1e-10, restarted at ``cuts`` (none: one run over the jumps, its error control finds them)."""
    prm = pack_params(params)
    edges = np.unique(np.concatenate([[0.0, t_end], np.asarray(cuts, dtype=float)]))
    y0, out = params.initial_state, np.full((t.size, 4), np.nan)
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        inner = 1e-9 * (b - a) if len(cuts) else 0.0

        def f(tt, y, a=a, b=b, inner=inner):
            tc = min(max(tt, a + inner), b - inner)
            return compiled_derivatives(y[0], y[1], y[2], y[3], float(u(tc)), float(d(tc)), prm)

        sol = solve_ivp(f, (a, b), y0, method="Radau", rtol=1e-10, atol=[1e-13, 1e-12, 1e-4, 1e-4],
                        dense_output=True)
        assert sol.success
        sel = (t >= a) & (t <= b)
        out[sel] = sol.sol(t[sel]).T
        y0 = sol.y[:, -1]
    return out


def test_square_and_step_off_the_grid_match_the_reference_to_1e6_of_the_range():
    u, d = parse_signal("square:3:1.5"), parse_signal("step:4000:1.25")
    res = simulate(P, u, d, t_end=2.0)
    # the reference is restarted at the edges; one Radau run over them agrees with it to ~1e-9
    ref = radau(P, u, d, 2.0, res.t, cuts=np.concatenate([u.discontinuities(2.0), d.discontinuities(2.0)]))
    span = np.ptp(ref, axis=0)
    err = np.abs(res.states - ref).max(axis=0) / span
    assert np.all(err < 1e-6), err
    # the previous fixed-step RK4 straddled the edges: first order in h, ~1e-3 of the range
    assert res.success and np.abs(res.v - ref[:, 1]).max() > 0


def test_an_edge_is_a_breakpoint_the_states_continuous_their_derivative_jumps():
    t0 = 0.25037                                  # between output samples
    u = Step(-3.0, t0=t0, initial=3.0)
    dt = 1e-5
    res = simulate(P, u, 0.0, t_end=0.2504 + 30 * dt, dt=dt)
    k = int(np.floor(t0 / dt))                    # the last sample before the edge
    y = res.states
    # the state at the edge, from the samples either side (continuous: the same from both)
    left = y[k] + (t0 - res.t[k]) * rhs(y[k], 3.0, 0.0, P)
    right = y[k + 1] - (res.t[k + 1] - t0) * rhs(y[k + 1], -3.0, 0.0, P)
    span = np.ptp(y, axis=0)
    assert np.all(np.abs(left - right) < 1e-6 * span)
    # one-sided slopes of the output: the model's derivative with the command before and after the edge
    for sample, command in ((k - 1, 3.0), (k + 2, -3.0)):
        slope = (y[sample + 1] - y[sample]) / dt
        f = rhs(0.5 * (y[sample] + y[sample + 1]), command, 0.0, P)
        assert np.abs(slope[2] - f[2]) < 1e-4 * abs(f[2])      # dp1/dt jumps with the flow (eq. 3)


def test_held_samples_off_the_output_grid_equal_their_step_sum():
    t = np.array([0.0, 0.1234, 0.40005, 0.7777])
    vals = np.array([1.0, -2.0, 3.0, 0.5])
    a = simulate(P, u=Sampled(t, vals, hold="zoh"), t_end=1.0)
    b = simulate(P, u=Step(1.0) + Step(-3.0, 0.1234) + Step(5.0, 0.40005) + Step(-2.5, 0.7777), t_end=1.0)
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-9 * np.ptp(b.states, axis=0).max())


def test_the_sampled_controller_is_held_exactly_between_its_instants():
    res = simulate_closed_loop(P, Step(0.02, t0=0.0153), kp=10.0, ts=0.01, dt=0.001, t_end=0.5)
    held = res.u.reshape(-1)[:500].reshape(50, 10)
    assert np.all(held == held[:, :1])                       # constant over each ts
    np.testing.assert_allclose(res.u[::10], 10.0 * (res.r[::10] - res.x[::10]), atol=1e-12)


@pytest.mark.parametrize("sig, t_end, expected", [
    (Square(1.0, 1.5), 1.0, [0.0, 1 / 3, 2 / 3, 1.0]),
    (Step(2.0, 0.3), 1.0, [0.3]),
    (Step(2.0, 3.0), 1.0, []),
    (WhiteNoise(1.0, hold_s=0.25), 0.6, [0.0, 0.25, 0.5]),
    (Sine(1.0, 2.0), 1.0, []),
    (Sine(1.0, 2.0) + Step(1.0, 0.5) + Square(1.0, 1.0), 1.0, [0.0, 0.5, 1.0]),
    (Sampled([0.0, 0.2, 0.7], [1.0, 2.0, 0.0], hold="zoh"), 0.5, [0.0, 0.2]),
])
def test_signals_report_their_discontinuities(sig, t_end, expected):
    np.testing.assert_allclose(sig.discontinuities(t_end), expected, atol=1e-15)


def test_a_function_of_t_has_unknown_discontinuities_and_takes_the_fixed_step_integrator():
    sig = _as_signal(lambda t: np.sign(np.sin(3 * t)), "u", np.arange(3.0))
    assert sig.discontinuities(1.0) is None
    res = simulate(P, u=lambda t: 0.0 * t + 1.0, t_end=0.1)
    assert res.h == pytest.approx(5e-4)


def test_greybox_states_agree_with_the_simulator_far_below_the_noise():
    """The grey-box fit's states (fixed-step RK4 on the record's grid, where its held inputs change)
    against the simulator's (adaptive): the record's noise is 1e-3 of the range or more."""
    from eha_core.identify.greybox import greybox_data, simulate_with_sensitivities

    truth = ActuatorParams(M=5200.0, B=1900.0)
    data = greybox_data(truth, Sine(6.0, 2.0), t_end=3.0, d=WhiteNoise(500.0, seed=2, hold_s=1e-3))
    out, _ = simulate_with_sensitivities(truth, ("M",), data)
    # the same inputs as the fit sees them: the record's samples, interpolated as it says
    hold = "linear" if data.intersample == "foh" else "zoh"
    t0 = data.t - data.t[0]
    ref = simulate(truth, Sampled(t0, data.u, hold=hold), Sampled(t0, data.d, hold=hold), t_end=3.0).states
    err = np.abs(out - ref).max(axis=0) / np.ptp(ref, axis=0)
    assert np.all(err < 1e-5), err
