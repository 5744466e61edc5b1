"""Refusals are values: FieldError and its subclasses carry field, value and what; the text is rendered."""

import pickle

import pytest

from eha_core.data import DataError, columns_text, read_data
from eha_core.errors import FieldError, not_allowed
from eha_core.params import ActuatorParams, ParameterError
from eha_core.signals import SignalSpecError, parse_signal


def test_the_sentence_and_its_parts():
    error = not_allowed("n_poles", 0, "must be a whole number >= 1")
    assert isinstance(error, FieldError) and isinstance(error, ValueError)
    assert str(error) == "n_poles = 0 is not allowed: must be a whole number >= 1"
    assert (error.field, error.value, error.what) == ("n_poles", 0, "must be a whole number >= 1")


def test_render_writes_the_sentence_for_a_form():
    error = FieldError("beta_e", 1.1e9, "must be at most 2 GPa")
    assert error.render() == str(error) == "beta_e = 1.1e+09 is not allowed: must be at most 2 GPa"
    assert error.render("βe", "GPa", value_text="1.1") == "βe = 1.1 GPa is not allowed: must be at most 2 GPa"
    assert error.render(unit="Pa") == "beta_e = 1.1e+09 Pa is not allowed: must be at most 2 GPa"


def test_value_text_and_context():
    error = FieldError("--out", "a b.csv", "no such folder", value_text=repr("a b.csv"))
    assert str(error) == "--out = 'a b.csv' is not allowed: no such folder"
    error = FieldError("--branch", "upper", "the branch ...", context="with --model nonlinear")
    assert str(error) == "--branch = upper is not allowed with --model nonlinear: the branch ..."
    assert str(error.renamed("branch")) == "branch = upper is not allowed with --model nonlinear: the branch ..."


def test_parameter_error_is_a_field_error_with_its_own_attributes():
    with pytest.raises(ParameterError) as info:
        ActuatorParams(M=-1.0)
    error = info.value
    assert isinstance(error, FieldError)
    assert (error.field, error.value, error.allowed, error.what) == ("M", -1.0, "must be > 0 kg (load mass)",
                                                                    "must be > 0 kg (load mass)")
    assert str(error) == "M = -1 is not allowed: must be > 0 kg (load mass)"


def test_data_error_names_the_file_quoted_and_says_which_columns_are_missing():
    with pytest.raises(DataError) as info:
        read_data(b"time,pos\n0,1\n1,2\n", ("t", "x"), name="--data", filename="run.csv")
    error = info.value
    assert isinstance(error, FieldError)
    assert (error.field, error.name, error.value, error.path) == ("--data", "--data", "run.csv", "run.csv")
    assert str(error).startswith("--data = 'run.csv' is not allowed: no column t, x: the file has time, pos; ")
    assert error.missing_columns == ("t", "x") and error.file_columns == ("time", "pos")
    with pytest.raises(DataError) as info:
        read_data(b"t,x\n0,1\n1,abc\n", ("t", "x"), filename="run.csv")
    assert info.value.missing_columns == () and info.value.file_columns == ()


def test_columns_text_lists_what_the_message_lists():
    names = [f"c{k}" for k in range(25)]
    assert columns_text(names) == ", ".join(names[:20]) + ", and 5 more"
    assert columns_text(["x" * 50, "t"]) == "x" * 40 + "…, t"
    assert columns_text([]) == "nothing"


def test_signal_spec_error_is_a_field_error():
    with pytest.raises(SignalSpecError) as info:
        parse_signal("sine:two", name="--u")
    assert isinstance(info.value, FieldError)
    assert (info.value.field, info.value.value) == ("--u", "sine:two")


@pytest.mark.parametrize("error", [
    FieldError("x", 1.5, "no", context="with y"),
    ParameterError("M", -1.0, "must be > 0 kg"),
    DataError("--data", "run.csv", "no column t", missing_columns=("t",), file_columns=("a", "b")),
    SignalSpecError("--u", "sine:x", "amplitude x is not a number"),
])
def test_an_error_survives_pickling_as_the_same_value(error):
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is type(error) and str(copy) == str(error) and copy.args == error.args
    assert copy.__dict__ == error.__dict__
