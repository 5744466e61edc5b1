"""One reader for measured data: CSV with units in the header, MATLAB .mat, messages naming file, column, row."""

import io

import numpy as np
import pytest
import scipy.io

from eha_core.data import DataError, file_columns, read_data, sample_time, write_data

T = np.arange(0, 0.05, 0.001)
COLS = {"t": T, "x": 0.01 * np.sin(40 * T), "p1": 12e6 + 1e5 * np.cos(40 * T), "u": np.ones_like(T)}


@pytest.mark.parametrize("kind", ["csv", "mat"])
def test_written_data_reads_back_in_si(kind):
    units = {"x": "mm", "p1": "MPa", "t": "ms"} if kind == "csv" else None
    blob = write_data(COLS, kind, units=units)
    back = read_data(blob, ("t", "x", "p1", "u"), filename=f"run.{kind}")
    for k, v in COLS.items():
        np.testing.assert_allclose(back[k], v, rtol=1e-9, atol=1e-12)
    assert sample_time(back["t"]) == pytest.approx(0.001)
    if kind == "csv":
        assert blob.decode().splitlines()[0] == "t[ms],x[mm],p1[MPa],u"


def test_a_mapping_names_the_files_own_columns():
    blob = b"time[s],pos[mm],cmd\n0,1,0.5\n0.001,2,0.5\n0.002,3,0.5\n"
    assert file_columns(blob, "lab.csv") == ["time[s]", "pos[mm]", "cmd"]
    with pytest.raises(DataError, match=r"no column t, y, u: the file has time\[s\], pos\[mm\], cmd"):
        read_data(blob, ("t", "y", "u"), filename="lab.csv")
    d = read_data(blob, ("t", "y", "u"), filename="lab.csv", mapping={"t": "time[s]", "y": "pos[mm]", "u": "cmd"})
    assert d["y"].tolist() == [0.001, 0.002, 0.003] and d["u"].tolist() == [0.5] * 3


@pytest.mark.parametrize("content, message", [
    (b"t,x\n0,1\n0.001,abc\n", r"'lab.csv' is not allowed: column x, row 2 \(line 3\): 'abc' is not a number"),
    (b"t,x\n0,1\n0.001,nan\n", r"column x, row 2 \(line 3\): nan is not finite"),
    (b"t,x\n0,1\n0.001,\n", r"column x, row 2 \(line 3\) is empty"),
    (b"t,x\n0,1\n", r"1 row of data; need at least 2"),
    (b"t,x[furlong]\n0,1\n1,2\n", r"column x\[furlong\]: the unit 'furlong' is not known"),
    (b"", r"it is empty"),
    (b"\xff\xfe\x00garbage", r"neither a text \(CSV\) file nor a MATLAB .mat file"),
])
def test_malformed_csv_files_are_named_with_column_and_row(content, message):
    with pytest.raises(DataError, match=message):
        read_data(content, ("t", "x"), filename="lab.csv")


def test_malformed_mat_files():
    buf = io.BytesIO()
    scipy.io.savemat(buf, {"t": T, "x": np.r_[COLS["x"][:-1], np.nan]})
    with pytest.raises(DataError, match=rf"'run.mat' is not allowed: column x, row {T.size}: nan is not finite"):
        read_data(buf.getvalue(), ("t", "x"), filename="run.mat")
    buf = io.BytesIO()
    scipy.io.savemat(buf, {"t": T, "x": COLS["x"][:10]})
    with pytest.raises(DataError, match=r"the columns differ in length: t 50, x 10"):
        read_data(buf.getvalue(), ("t", "x"), filename="run.mat")
    with pytest.raises(DataError, match=r"not a MATLAB .mat file scipy can read"):
        read_data(b"MATLAB 5.0 MAT-file, but truncated", ("t", "x"), filename="run.mat")


def test_non_uniform_sampling_is_named_by_row():
    t = np.r_[T[:10], T[10:] + 0.0004]
    with pytest.raises(DataError, match=r"column t, row 11 \(line 12\): the sampling is not uniform"):
        sample_time(t, path="lab.csv")
