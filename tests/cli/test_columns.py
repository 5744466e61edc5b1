"""``--data`` with other column names: guessed as the web app guesses them (one note line says which it
took), or mapped with ``--columns``; a mapping or a file that cannot be used is one line, exit code 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eha_app.cli import main
from eha_core.data import write_data

RENAMED = "time,position[mm],velocity[mm/s],pA[bar],pB[bar],valve[V]"


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """A simulated least-squares record three ways, the same numbers read back from each: SI with the needed
    names, with the app's names and units (position[mm], pA[bar]...), and with the chambers named so that the
    guess takes them the wrong way round (by unit: the first column in bar is p1)."""
    from eha_core.experiments import lse_simulation

    root = tmp_path_factory.mktemp("columns")
    res = lse_simulation(disturbance="none", t_end=2.0)
    # in the file's units, as %.17g writes them; SI as the reader converts them (value * 1e-3, * 1e5): the
    # three files then hold the same floats, and the estimates are the same to the last bit
    scaled = [res.t, res.x * 1e3, res.v * 1e3, res.p1 / 1e5, res.p2 / 1e5, res.u]
    scaled = [np.array([float(f"{v:.17g}") for v in col]) for col in scaled]
    si = np.column_stack([c * k for c, k in zip(scaled, (1.0, 1e-3, 1e-3, 1e5, 1e5, 1.0), strict=True)])
    files = {"si": root / "si.csv", "renamed": root / "run.csv", "swapped": root / "rig.csv"}
    np.savetxt(files["si"], si, delimiter=",", header="t,x,v,p1,p2,u", comments="", fmt="%.17g")
    np.savetxt(files["renamed"], np.column_stack(scaled), delimiter=",", header=RENAMED, comments="", fmt="%.17g")
    swapped = np.column_stack([*scaled[:3], scaled[4], scaled[3], scaled[5]])     # the rod side first
    np.savetxt(files["swapped"], swapped, delimiter=",", header="time,position[mm],velocity[mm/s],rod[bar],"
                                                                "cap[bar],valve[V]", comments="", fmt="%.17g")
    files["app"] = root / "lse-data.csv"
    files["app"].write_bytes(write_data({"t": res.t, "x": res.x, "v": res.v, "p1": res.p1, "p2": res.p2,
                                         "u": res.u}, "csv", units="si"))
    return files


def lse_estimates(capsys, path, *more):
    code, out, err = run(capsys, "identify", "lse", "--data", path, "--json", *more)
    assert code == 0, err
    return json.loads(out)["estimates"], err


def test_guessed_columns_give_the_same_estimates_as_the_needed_names(capsys, records):
    reference, err = lse_estimates(capsys, records["si"])
    assert err == ""
    guessed, err = lse_estimates(capsys, records["renamed"])
    assert err == (f"eha: note: columns taken from {records['renamed']}: t=time, x=position[mm], v=velocity[mm/s], "
                   "p1=pA[bar], p2=pB[bar], u=valve[V] (override with --columns)\n")
    assert set(guessed) == set(reference)
    for name, value in reference.items():
        assert guessed[name] == pytest.approx(value, rel=1e-9), name


def test_columns_overrides_a_wrong_guess(capsys, records):
    reference, _ = lse_estimates(capsys, records["si"])
    wrong, err = lse_estimates(capsys, records["swapped"])
    assert "p1=rod[bar], p2=cap[bar]" in one_line(err)
    assert wrong["M"] != pytest.approx(reference["M"], rel=1e-3)
    # the unit of a column may be left out; the columns not given are still guessed (and the note says so)
    right, err = lse_estimates(capsys, records["swapped"], "--columns", "p1=cap[bar],p2=rod")
    assert one_line(err) == (f"eha: note: columns taken from {records['swapped']}: t=time, x=position[mm], "
                             "v=velocity[mm/s], p1=cap[bar], p2=rod[bar], u=valve[V] (override with --columns)")
    for name, value in reference.items():
        assert right[name] == pytest.approx(value, rel=1e-9), name
    # every column given: the same
    every = "t=time,x=position[mm],v=velocity[mm/s],p1=cap[bar],p2=rod[bar],u=valve[V]"
    assert lse_estimates(capsys, records["swapped"], "--columns", every)[0] == right


def test_a_file_the_app_writes_reads_back_without_a_note(capsys, records):
    reference, _ = lse_estimates(capsys, records["si"])
    estimates, err = lse_estimates(capsys, records["app"])
    assert err == ""
    for name in ("M", "B", "Af", "beta_e"):         # d0 is 0 here: the file's 10 digits move it by 1e-6 N
        assert estimates[name] == pytest.approx(reference[name], rel=1e-6), name


@pytest.mark.parametrize("columns, says", [
    ("q=time", "--columns = q=time is not allowed: q is not a column this command needs; use t, x, v, p1, p2, u"),
    ("x=pos", "--columns = x=pos is not allowed: pos is not a column of {path}; it has time, position[mm], "
              "velocity[mm/s], pA[bar], pB[bar], valve[V]"),
    ("t=time,position[mm]", "--columns = position[mm] is not allowed: give NEEDED=COLUMN joined by commas"),
    ("x", "--columns = x is not allowed: give NEEDED=COLUMN"),
    ("x=", "--columns = x= is not allowed: give NEEDED=COLUMN"),
    ("=time", "--columns = =time is not allowed: give NEEDED=COLUMN"),
    ("", "--columns = (empty) is not allowed: give NEEDED=COLUMN"),
    ("x=position[mm],x=position", "--columns = x=position is not allowed: x is given twice"),
])
def test_a_bad_mapping_is_one_line_naming_the_part_as_typed(capsys, records, columns, says):
    code, out, err = run(capsys, "identify", "lse", "--data", records["renamed"], "--columns", columns)
    assert code == 2 and out == ""
    assert one_line(err).startswith("eha: error: " + says.format(path=records["renamed"])), err


def test_a_mapping_without_a_file_or_of_a_column_not_needed_is_refused(capsys, records):
    code, _, err = run(capsys, "identify", "tf", "--columns", "u=r")
    assert code == 2 and one_line(err) == ("eha: error: --columns = u=r is not allowed without --data: it says which "
                                           "of a file's columns is which; give the file with --data")
    # the needed names are the route's: greybox's are t, u and those of --measured
    code, _, err = run(capsys, "identify", "greybox", "--data", records["renamed"], "--measured", "x",
                       "--columns", "p1=pA")
    assert code == 2 and "--columns = p1=pA is not allowed: p1 is not a column this command needs; use t, u, x" \
        in one_line(err)


@pytest.mark.parametrize("argv, need", [
    (["identify", "lse"], "need t, x, v, p1, p2, u"),
    (["identify", "tf"], "need t, u, y (or t, r, x)"),
    (["identify", "greybox", "--measured", "x"], "need t, u, x"),
])
def test_columns_that_cannot_be_guessed_are_one_line_saying_how_to_give_them(capsys, tmp_path, argv, need):
    path = tmp_path / "odd.csv"
    path.write_text("a,b,c\n" + "".join(f"{k},0,0\n" for k in range(60)))
    code, out, err = run(capsys, *argv, "--data", path)
    assert code == 2 and out == ""
    line = one_line(err)
    assert line.startswith(f"eha: error: --data = {str(path)!r} is not allowed: no column t, ")
    assert f"the file has a, b, c; {need}: say which column is which with --columns, e.g. --columns t=COLUMN" in line


def test_a_column_guessed_for_some_needs_and_not_others_names_those_missing(capsys, records, tmp_path):
    path = tmp_path / "no-velocity.csv"
    path.write_text("time,position[mm],pA[bar],pB[bar],valve[V]\n" + "".join(f"{k * 1e-3},0,120,180,0\n"
                                                                            for k in range(60)))
    code, _, err = run(capsys, "identify", "lse", "--data", path)
    assert code == 2 and "is not allowed: no column v: the file has time, position[mm], pA[bar], pB[bar], " \
        "valve[V]; need t, x, v, p1, p2, u: say which column is which with --columns, e.g. --columns v=COLUMN" \
        in one_line(err)


@pytest.fixture(scope="module")
def io_record():
    from eha_core.identify.validate import simulate_tf

    ts = 0.01
    u = np.sign(np.sin(2 * np.pi * 0.4 * ts * np.arange(1500)))
    y = simulate_tf([2437.0], [1.0, 430.1, 1.721e4, 2437.0], u, ts)
    return ts * np.arange(u.size), u, y


def tf_estimate(capsys, path, *more):
    code, out, err = run(capsys, "identify", "tf", "--data", path, "--json", *more)
    assert code == 0, err
    return json.loads(out), err


def test_tf_reads_the_apps_closed_loop_record_and_guesses_other_names(capsys, tmp_path, io_record):
    t, u, y = io_record
    plain, loop, other, mat = (tmp_path / n for n in ("io.csv", "loop.csv", "scope.csv", "scope.mat"))
    plain.write_bytes(write_data({"t": t, "u": u, "y": y}))
    # the frequency tab's download: the reference r is the input, the position x the output (u is the valve's)
    loop.write_bytes(write_data({"t": t, "r": u, "x": y, "u": 3 * u}, units="si"))
    other.write_bytes(write_data({"time": t, "command": u, "position": y},
                                 units={"time": "ms", "command": "V", "position": "mm"}))
    mat.write_bytes(write_data({"time": t, "command": u, "position": y}, "mat"))
    reference, err = tf_estimate(capsys, plain)
    assert err == ""
    est, err = tf_estimate(capsys, loop)
    assert err == "" and est["den"] == pytest.approx(reference["den"], rel=1e-9)
    est, err = tf_estimate(capsys, other)
    assert one_line(err) == (f"eha: note: columns taken from {other}: t=time[ms], u=command[V], "
                             "y=position[mm] (override with --columns)")
    assert est["den"] == pytest.approx(reference["den"], rel=1e-6)
    est, err = tf_estimate(capsys, mat)
    assert "u=command, y=position" in one_line(err) and est["den"] == pytest.approx(reference["den"], rel=1e-6)
    # the valve command (3 r) instead of the reference, by --columns: a third of the gain (a note for the rest)
    est, err = tf_estimate(capsys, loop, "--columns", "u=u")
    assert "t=t[s], u=u[V], y=x[m]" in one_line(err)
    assert est["den"] == pytest.approx(reference["den"], rel=1e-6)
    assert est["num"] == pytest.approx(np.divide(reference["num"], 3), rel=1e-6)


def test_greybox_guesses_the_columns_of_a_record(capsys, records):
    code, out, err = run(capsys, "identify", "greybox", "--data", records["renamed"], "--measured", "x,p1,p2",
                         "--params", "M", "--json")
    assert code in (0, 1), err
    assert one_line(err) == (f"eha: note: columns taken from {records['renamed']}: t=time, u=valve[V], "
                             "x=position[mm], p1=pA[bar], p2=pB[bar] (override with --columns)")
    assert json.loads(out)["estimates"]["M"] == pytest.approx(4000, rel=1e-3)


@pytest.mark.parametrize("method", ["lse", "tf", "greybox"])
def test_every_command_with_data_documents_columns(capsys, method):
    with pytest.raises(SystemExit):
        main(["identify", method, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--columns NEEDED=COLUMN,..." in text and "--data FILE" in text
    assert "as NEEDED=COLUMN joined by commas" in text and "guessed from the names and units" in text
