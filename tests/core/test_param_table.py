"""The table of parameter facts is the one source: ActuatorParams, the packed vector and the rules read it."""

import dataclasses
import inspect
import re
import string

import numpy as np
import pytest

from eha_core import model
from eha_core.model import PARAM_INDEX, pack_params
from eha_core.param_table import (
    DERIVED,
    FIELD_INFO,
    NON_NEGATIVE_FIELDS,
    PACKED,
    POSITIVE_FIELDS,
    RULES,
    broken_rules,
)
from eha_core.params import ActuatorParams, ParameterError
from eha_core.variants import EFFECT_FIELDS

DEFAULTS = dataclasses.asdict(ActuatorParams())


def test_the_table_lists_every_field_of_the_parameter_set_in_its_order():
    # every field but the structural effects (eha_core.variants), which are not the form's parameters
    names = tuple(f.name for f in dataclasses.fields(ActuatorParams))
    assert names[-1] == "effects" and "effects" not in FIELD_INFO
    assert tuple(FIELD_INFO) == names[:-1]
    assert all(info.label and info.bound in (None, ">", ">=") for info in FIELD_INFO.values())
    assert set(POSITIVE_FIELDS) == {n for n, f in FIELD_INFO.items() if f.bound == ">"}
    assert set(NON_NEGATIVE_FIELDS) == {n for n, f in FIELD_INFO.items() if f.bound == ">="}


def test_the_packed_vector_follows_the_table():
    p = ActuatorParams(M=4100.0, d0=12.0, p2_0=17e6)
    # the table's values, then the structural effects' (eha_core.variants.EFFECT_FIELDS) at the end
    assert list(PARAM_INDEX) == list(PACKED) + list(EFFECT_FIELDS)
    assert set(PACKED) <= set(FIELD_INFO) | set(DERIVED)
    np.testing.assert_array_equal(pack_params(p), [getattr(p, name) for name in PACKED] + list(p.effects.packed()))
    assert [PARAM_INDEX[n] for n in ("A1", "A2", "x_max")] == [4, 5, 12]
    assert (p.A1, p.A2, p.x_max) == tuple(DERIVED[n].compute(vars(p)) for n in ("A1", "A2", "x_max"))


@pytest.mark.parametrize("function", [model.derivatives, model.project_state])
def test_the_compiled_model_reads_the_packed_vector_where_the_table_puts_each_value(function):
    # the kernel reads literal indices (numba): each `name = prm[i]` must agree with the table
    reads = re.findall(r"^\s*(\w+) = prm\[(\d+)\]", inspect.getsource(function), flags=re.M)
    assert reads
    assert {name: int(i) for name, i in reads} == {name: PARAM_INDEX[name] for name, _ in reads}


def _placeholders(template: str) -> set[str]:
    return {field for _, field, _, _ in string.Formatter().parse(template) if field}


def test_every_rule_is_worded_from_known_facts():
    for rule in RULES:
        assert set(rule.fields) <= set(FIELD_INFO), rule.name
        assert {s.field for s in rule.says} <= set(rule.fields), rule.name
        for saying in rule.says:
            for name in _placeholders(saying.template):
                kind, _, key = name.partition("[")
                key = key.rstrip("]")
                assert (kind, bool(key)) in (("ref", True), ("value", True), ("pressures", False)), name
                assert key in (FIELD_INFO if kind == "ref" else DERIVED if kind == "value" else ("",)), name
        if rule.core is not None:
            assert {n.split(":")[0] for n in _placeholders(rule.core)} <= set(FIELD_INFO) | set(DERIVED)


PRESSURES = "[pr, ps] = [0, 3.2e+07] Pa"
# one set breaking each rule the parameter set checks (first), and what the core says
BREAKING = [
    ({"dc": 0.13}, "rod inside the bore", "dc", "the rod diameter must be smaller than the bore Dc = 0.12 m"),
    ({"pr": 33e6}, "return below supply", "pr",
     "the return pressure must be below the supply pressure ps = 3.2e+07 Pa"),
    ({"x0": 0.25}, "within the end stops", "x0", "must lie within the end stops [-0.24, 0.24] m (|x0| <= 0.8 L0)"),
    ({"p1_0": 33e6}, "initial piston-chamber pressure within [pr, ps]", "p1_0", f"must lie within {PRESSURES}"),
    ({"p2_0": 33e6}, "initial rod-chamber pressure within [pr, ps]", "p2_0", f"must lie within {PRESSURES}"),
    ({"p1_0": 25e6}, "force balance within [pr, ps]", "p2_0",
     f"the force balance (A1 p1_0 - d0)/A2 must lie within {PRESSURES}; change p1_0 or d0, or set p2_0"),
]


@pytest.mark.parametrize("changes, name, field, what", BREAKING, ids=[b[1] for b in BREAKING])
def test_the_parameter_set_raises_the_rule_of_the_table(changes, name, field, what):
    values = {**DEFAULTS, **changes}
    assert next(broken_rules(values)).name == name
    with pytest.raises(ParameterError) as info:
        ActuatorParams(**changes)
    assert (info.value.field, info.value.what) == (field, what)


def test_the_operating_point_rule_is_the_linearisations():
    from eha_core.linear import operating_point

    values = {**DEFAULTS, "p2_0": 15e6, "p1_0": 30e6}
    assert [rule.name for rule in broken_rules(values)] == ["operating point's force balance within [pr, ps]"]
    with pytest.raises(ParameterError) as info:
        operating_point(ActuatorParams(p2_0=15e6, p1_0=30e6))   # the parameter set itself is valid
    assert info.value.field == "p2_e"
