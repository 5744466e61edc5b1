import math

import numpy as np
import pytest

from eha_core.model import pack_params, rhs
from eha_core.params import (
    NON_NEGATIVE_FIELDS,
    PARAM_NAMES,
    POSITIVE_FIELDS,
    ActuatorParams,
    ParameterError,
    parse_param_assignments,
)
from eha_core.variants import EFFECT_FIELDS


def test_defaults_and_derived_areas():
    p = ActuatorParams()
    assert p.A1 == pytest.approx(math.pi * 0.12**2 / 4)
    assert p.A2 == pytest.approx(math.pi * (0.12**2 - 0.07**2) / 4)
    # section II-A: p2(0) = (A1/A2) p1(0) = 18.189 MPa
    assert p.p2_init == pytest.approx(18.189e6, rel=1e-4)
    assert p.x_max == pytest.approx(0.24)
    np.testing.assert_allclose(p.initial_state, [0, 0, 12e6, p.A1 / p.A2 * 12e6])


def test_force_balance_follows_p1_and_d0_unless_p2_given():
    p = ActuatorParams(p1_0=10e6, d0=2000.0)
    assert p.p2_init == pytest.approx((p.A1 * 10e6 - 2000.0) / p.A2)
    assert ActuatorParams(p2_0=15e6).p2_init == 15e6


def test_compact_form_a1_a10_is_the_same_model():
    """eqs. 6-8 with Table 1's a1..a10 give the same derivatives as eq. 4."""
    p = ActuatorParams()
    a = p.a
    x, v, p1, p2, u = 0.01, 0.02, 11e6, 19e6, 1.5
    f2 = -a["a1"] * v - a["a2"] * math.atan(900 * v) + a["a3"] * p1 - a["a4"] * p2
    f3 = -v / (a["a5"] + a["a6"] * x) + math.sqrt(p.ps - p1) / (a["a7"] + a["a8"] * x) * u
    f4 = v / (a["a5"] - a["a6"] * x) - math.sqrt(p2 - p.pr) / (a["a9"] - a["a10"] * x) * u
    np.testing.assert_allclose(rhs([x, v, p1, p2], u, 0.0, p), [v, f2, f3, f4], rtol=1e-12)


@pytest.mark.parametrize("changes, field, words", [
    ({"M": 0.0}, "M", "> 0"),
    ({"M": -4000.0}, "M", "> 0"),
    ({"beta_e": 0.0}, "beta_e", "> 0"),
    ({"Dc": -0.1}, "Dc", "> 0"),
    ({"dc": 0.0}, "dc", "> 0"),
    ({"L0": 0.0}, "L0", "> 0"),
    ({"Kq1": 0.0}, "Kq1", "> 0"),
    ({"B": -1.0}, "B", ">= 0"),
    ({"Af": -1.0}, "Af", ">= 0"),
    ({"dc": 0.12}, "dc", "smaller than the bore"),
    ({"dc": 0.2}, "dc", "smaller than the bore"),
    ({"pr": 32e6}, "pr", "below the supply"),
    ({"p1_0": 33e6}, "p1_0", "[pr, ps]"),
    ({"p1_0": -1.0}, "p1_0", "[pr, ps]"),
    ({"p2_0": 40e6}, "p2_0", "[pr, ps]"),
    ({"p1_0": 25e6}, "p2_0", "force balance"),
    ({"x0": 0.25}, "x0", "0.8 L0"),
    ({"x0": -0.25}, "x0", "0.8 L0"),
    ({"M": float("nan")}, "M", "finite"),
    ({"ps": float("inf")}, "ps", "finite"),
    ({"M": "heavy"}, "M", "real number"),
])
def test_validation_names_field_value_and_range(changes, field, words):
    with pytest.raises(ParameterError) as info:
        ActuatorParams(**changes)
    err = info.value
    assert err.field == field
    assert str(err).startswith(f"{field} = ")
    assert words in str(err)


def test_the_one_field_bounds_are_the_ones_the_constants_list():
    """POSITIVE_FIELDS and NON_NEGATIVE_FIELDS (the app checks them in display units) are what the core checks."""
    assert set(POSITIVE_FIELDS) | set(NON_NEGATIVE_FIELDS) <= set(PARAM_NAMES)
    for name in POSITIVE_FIELDS:
        with pytest.raises(ParameterError, match=r"must be > 0") as info:
            ActuatorParams(**{name: 0.0})
        assert info.value.field == name
    for name in NON_NEGATIVE_FIELDS:
        with pytest.raises(ParameterError, match=r"must be >= 0") as info:
            ActuatorParams(**{name: -1e-9})
        assert info.value.field == name
        assert getattr(ActuatorParams(**{name: 0.0}), name) == 0.0


def test_replace_rejects_unknown_names():
    with pytest.raises(ParameterError, match="unknown parameter"):
        ActuatorParams().replace(mass=1.0)


def test_parse_assignments():
    p = parse_param_assignments(["M=5000", "p2_0=17e6", "x0=0.01"])
    assert (p.M, p.p2_0, p.x0) == (5000.0, 17e6, 0.01)
    assert parse_param_assignments(["p2_0=balance"], p).p2_0 is None
    with pytest.raises(ParameterError, match="must be a number"):
        parse_param_assignments(["M=lots"])
    with pytest.raises(ParameterError, match="NAME=VALUE"):
        parse_param_assignments(["M"])


def test_equal_parameters_hash_equal():
    assert hash(ActuatorParams(M=4000)) == hash(ActuatorParams(M=4000.0))
    # the paper's 14 values, then the structural effects' (eha_core.variants, all off by default)
    assert pack_params(ActuatorParams()).shape == (14 + len(EFFECT_FIELDS),)
