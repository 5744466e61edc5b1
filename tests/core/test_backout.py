import math

import numpy as np
import pytest

from eha_core.identify.backout import backout, open_loop_from_closed
from eha_core.linear import linearize
from eha_core.params import ActuatorParams


@pytest.mark.parametrize("params", [ActuatorParams(), ActuatorParams(M=2500, B=900, Af=1200, beta_e=7e8, Kq2=2.5e-8)])
def test_backout_of_the_linearised_model_returns_the_nominal_values(params):
    lin = linearize(params)
    num_p, den_p = open_loop_from_closed(*lin.closed_loop_coeffs(10.0), kp=10.0)
    np.testing.assert_allclose(den_p, lin.tf_coeffs()[1], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(num_p, lin.tf_coeffs()[0], rtol=1e-12)
    b = backout(num_p, den_p, params, lin.op)
    assert b.damping == pytest.approx(params.B + 2 * params.k_f * params.Af / math.pi, rel=1e-12)
    assert b.beta_e_from_gain == pytest.approx(params.beta_e, rel=1e-12)
    assert b.beta_e_from_stiffness == pytest.approx(params.beta_e, rel=1e-12)
    assert abs(b.integrator_coefficient) < 1e-9


def test_open_loop_from_closed_inverts_eq22():
    num_h, den_h = [2108.5], [1.0, 9.46, 17091.5, 2056.3]
    num_p, den_p = open_loop_from_closed(num_h, den_h, kp=10.0)
    s = 1j * np.array([0.3, 3.0, 30.0, 300.0])
    P = np.polyval(num_p, s) / np.polyval(den_p, s)
    H = np.polyval(num_h, s) / np.polyval(den_h, s)
    np.testing.assert_allclose(10 * P / (1 + 10 * P), H, rtol=1e-12)


def test_standard_errors_carry_over_linearly():
    p = ActuatorParams()
    std_h = np.array([0.5, 30.0, 10.0, 8.0])          # [a1, a2, a3, n]
    b = backout([210.8], [1.0, 9.46, 17091.5, -52.2], p, std_h=std_h, kp=10.0)
    assert b.damping_std == pytest.approx(0.5 * p.M)
    assert b.beta_e_from_stiffness_std == pytest.approx(30.0 * p.M * p.L0 / (p.A1 + p.A2))
    ratio = b.beta_e_from_gain / 210.8
    assert b.beta_e_from_gain_std == pytest.approx(8.0 / 10.0 * ratio)
    lo, hi = b.ci95()["damping"]
    assert lo < b.damping < hi


def test_bad_shapes_name_the_argument_and_its_value():
    with pytest.raises(ValueError, match=r"^num_p = \[1, 2\] is not allowed: P_hat must be .*\(3 poles, no zeros\)"
                                         r".*it has 1 zeros and 3 poles"):
        backout([1.0, 2.0], [1.0, 2.0, 3.0, 4.0])
    with pytest.raises(ValueError, match=r"^den_p = \[1, 2, 3\] is not allowed: .*it has 0 zeros and 2 poles"):
        backout([1.0], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"^kp = 0 is not allowed: must be a finite gain > 0"):
        open_loop_from_closed([1.0], [1.0, 1.0], kp=0.0)
    with pytest.raises(ValueError, match=r"^num_h = \[1, 2, 3\] is not allowed: .*must be proper"):
        open_loop_from_closed([1.0, 2.0, 3.0], [1.0, 1.0], kp=1.0)
    with pytest.raises(ValueError, match=r"^num_h = \[1, 2\] is not allowed: .*feedthrough of 1"):
        open_loop_from_closed([1.0, 2.0], [1.0, 1.0], kp=1.0)
