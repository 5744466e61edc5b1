import numpy as np
import pytest

from eha_core.linear import linearize, operating_point
from eha_core.model import rhs
from eha_core.params import ActuatorParams, ParameterError


def numerical_jacobian(params, op_state, u=0.0, eps_rel=1e-7):
    J = np.zeros((4, 4))
    scale = np.array([1e-3, 1e-3, 1e6, 1e6])
    for j in range(4):
        h = eps_rel * scale[j]
        xp, xm = op_state.copy(), op_state.copy()
        xp[j] += h
        xm[j] -= h
        J[:, j] = (rhs(xp, u, 0.0, params) - rhs(xm, u, 0.0, params)) / (2 * h)
    return J


def test_eq23_and_eq24_from_defaults():
    lin = linearize(ActuatorParams())
    num, den = lin.tf_coeffs()
    # eq. 23: 243.7 / (s^3 + 430.1 s^2 + 1.721e4 s)
    np.testing.assert_allclose(num, [243.7], rtol=2e-4)
    np.testing.assert_allclose(den[:3], [1.0, 430.1, 1.721e4], rtol=3e-4)
    assert den[3] == 0.0
    # eq. 24 with Kp = 10: 2437 / (s^3 + 430.1 s^2 + 1.721e4 s + 2437)
    cnum, cden = lin.closed_loop_coeffs(10.0)
    np.testing.assert_allclose(cnum, [2437], rtol=2e-4)
    np.testing.assert_allclose(cden, [1.0, 430.1, 1.721e4, 2437], rtol=3e-4)


def test_lambda_formulas_of_table2():
    p = ActuatorParams()
    l1, l2, l3, l4, l5, l6 = linearize(p).lambdas
    assert l1 == pytest.approx((p.B + 1800 * p.Af / np.pi) / p.M)
    assert (l2, l3, l4) == pytest.approx((p.A1 / p.M, p.A2 / p.M, p.beta_e / p.L0))
    assert l5 == pytest.approx(p.beta_e * p.Kq1 * np.sqrt(p.ps - 12e6) / (p.A1 * p.L0))
    assert l6 == pytest.approx(p.beta_e * p.Kq2 * np.sqrt(p.p2_init - p.pr) / (p.A2 * p.L0))


@pytest.mark.parametrize("params, x_e, p1_e", [
    (ActuatorParams(), 0.0, None),
    (ActuatorParams(M=2500, B=800, Af=1000, beta_e=8e8, Kq2=2e-8, d0=3000), 0.0, None),
    (ActuatorParams(), 0.05, 9e6),          # away from x = 0 the chambers differ
])
def test_A_equals_numerical_jacobian(params, x_e, p1_e):
    op = operating_point(params, x_e=x_e, p1_e=p1_e)
    lin = linearize(params, op)
    J = numerical_jacobian(params, op.state)
    np.testing.assert_allclose(J, lin.A, rtol=1e-6, atol=1e-9 * np.abs(lin.A).max())


def test_B_and_E_are_one_sided_derivatives_of_the_model():
    p = ActuatorParams()
    lin = linearize(p)
    x = lin.op.state
    du = 1e-6
    np.testing.assert_allclose((rhs(x, du, 0.0, p) - rhs(x, 0.0, 0.0, p)) / du, lin.B("positive"), rtol=1e-6)
    np.testing.assert_allclose((rhs(x, -du, 0.0, p) - rhs(x, 0.0, 0.0, p)) / -du, lin.B("negative"), rtol=1e-6)
    np.testing.assert_allclose((rhs(x, 0.0, 1.0, p) - rhs(x, 0.0, 0.0, p)), lin.E, rtol=1e-9)
    assert lin.B_negative[2] < lin.B_positive[2]  # eq. 13: smaller drop p1 - pr < ps - p1


def test_operating_point_is_an_equilibrium():
    p = ActuatorParams(d0=1500.0)
    op = operating_point(p)
    np.testing.assert_allclose(rhs(op.state, 0.0, 0.0, p), 0.0, atol=1e-9)


def test_python_control_types_agree_with_coefficients():
    import control

    lin = linearize(ActuatorParams())
    P = lin.tf()
    assert isinstance(P, control.TransferFunction)
    num, den = lin.tf_coeffs()
    np.testing.assert_allclose(P.num[0][0], num)
    np.testing.assert_allclose(P.den[0][0], den)
    # C (sI - A)^-1 B of the state-space model (x output, u input) is P(s) (eq. 20)
    sys = lin.ss()
    assert isinstance(sys, control.StateSpace)
    Pss = control.ss2tf(sys[0, 0])
    w = np.array([0.5, 5.0, 50.0, 500.0])
    np.testing.assert_allclose(Pss(1j * w), P(1j * w), rtol=1e-8)
    H = lin.closed_loop_tf(10.0)
    np.testing.assert_allclose(H(1j * w), 10 * P(1j * w) / (1 + 10 * P(1j * w)), rtol=1e-9)
    assert np.all(lin.closed_loop_poles(10.0).real < 0)
    np.testing.assert_allclose(np.sort(lin.poles().real), [-385.4, -44.66, 0.0], atol=0.1)


def test_bad_arguments():
    lin = linearize(ActuatorParams())
    with pytest.raises(ValueError, match="branch"):
        lin.tf_coeffs("sideways")
    with pytest.raises(ValueError, match="kp"):
        lin.closed_loop_coeffs(0.0)
    with pytest.raises(ParameterError, match="x_e"):
        operating_point(ActuatorParams(), x_e=1.0)
