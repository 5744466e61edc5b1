"""Reading and writing measured data: CSV and MATLAB ``.mat``, one reader, one form of message.

Identification (the least squares and the transfer-function estimate) reads
the same kind of file: a header of column names, then one row per sample, the
time ``t`` uniformly sampled. A column name may carry its unit in brackets
(``p1[MPa]``, ``x[mm]``, ``t[ms]``): the values are converted to SI. A ``.mat``
file (MATLAB, read with :mod:`scipy.io`) holds one vector per column, named
like the columns. :func:`read_data` reads either, from a path or from the
bytes of an upload, with an optional mapping of the names it needs to the
file's own; :func:`write_data` writes either. A problem is reported as
``NAME = 'FILE' is not allowed: WHAT``, WHAT naming the column and the row
(data rows are counted from 1, the header being line 1 of the file).

>>> import tempfile, os
>>> path = os.path.join(tempfile.mkdtemp(), "run.csv")
>>> _ = open(path, "w").write("t,u,y\\n0,1,2\\n0.1,1,abc\\n")
>>> read_columns(path, ("t", "u", "y"))  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
eha_core.data.DataError: --data = '...run.csv' is not allowed: column y, row 2 (line 3): 'abc' is not a number
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["DataError", "read_columns", "read_data", "write_data", "sample_time", "UNITS", "file_columns"]

#: Units a column name may carry, as ``name[unit]``, and their factor to SI.
UNITS = {"s": 1.0, "ms": 1e-3, "m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "m/s": 1.0, "mm/s": 1e-3,
         "pa": 1.0, "kpa": 1e3, "mpa": 1e6, "bar": 1e5, "v": 1.0, "n": 1.0, "kn": 1e3}


class DataError(ValueError):
    """A data file that cannot be used, with what is wrong and where."""

    def __init__(self, name: str, path, what: str):
        self.name = name
        self.path = str(path)
        self.what = what
        super().__init__(f"{name} = {str(path)!r} is not allowed: {what}")


def read_columns(path, columns: Sequence[str], *, name: str = "--data", min_rows: int = 2) -> dict[str, np.ndarray]:
    """The named columns of a CSV (or ``.mat``) file as float arrays in SI: :func:`read_data`
    for a file name or an open file."""
    if hasattr(path, "read"):             # an open file or a buffer
        data = path.read()
        data = data.encode() if isinstance(data, str) else data
        return read_data(data, columns, name=name, filename=getattr(path, "name", "data"), min_rows=min_rows)
    return read_data(path, columns, name=name, min_rows=min_rows)


def sample_time(t: np.ndarray, *, name: str = "--data", path="data", rtol: float = 1e-6) -> float:
    """The sample interval of uniformly sampled times, or a :class:`DataError` at the first bad row."""
    t = np.asarray(t, dtype=float)
    if t.size < 2:
        raise DataError(name, path, "column t needs at least 2 rows")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = int(bad[0]) + 2
        raise DataError(name, path, f"column t, row {k} (line {k + 1}): the time does not increase "
                                    f"({t[k - 1]:g} after {t[k - 2]:g})")
    ts = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - ts) > rtol * max(ts, abs(float(t[-1]))))
    if off.size:
        k = int(off[0]) + 2
        raise DataError(name, path, f"column t, row {k} (line {k + 1}): the sampling is not uniform "
                                    f"(a step of {dt[k - 2]:.6g} s where the others are {ts:.6g} s)")
    return float((t[-1] - t[0]) / (t.size - 1))


def _split_unit(header: str, name: str, path) -> tuple[str, float]:
    """``"p1[MPa]"`` -> ``("p1", 1e6)``; a name without unit is in SI."""
    h = header.strip()
    for open_, close in (("[", "]"), ("(", ")")):
        if h.endswith(close) and open_ in h:
            base, unit = h[: h.rindex(open_)].strip(), h[h.rindex(open_) + 1:-1].strip()
            scale = UNITS.get(unit.lower())
            if scale is None:
                raise DataError(name, path, f"column {h}: the unit {unit!r} is not known; use one of "
                                            "s, ms, m, mm, m/s, mm/s, Pa, kPa, MPa, bar, V, N (or none: SI)")
            return base, scale
    return h, 1.0


def _is_mat(data: bytes, filename: str) -> bool:
    return filename.lower().endswith(".mat") or data[:6] == b"MATLAB"


def _mat_columns(data: bytes, name: str, path) -> dict[str, np.ndarray]:
    import scipy.io

    try:
        mat = scipy.io.loadmat(io.BytesIO(data), squeeze_me=True)
    except Exception as exc:  # noqa: BLE001 - scipy raises several kinds for a bad file
        raise DataError(name, path, f"it is not a MATLAB .mat file scipy can read ({type(exc).__name__}: "
                                    f"{' '.join(str(exc).split())[:120]})") from None
    out = {}
    for key, value in mat.items():
        if key.startswith("__"):
            continue
        arr = np.asarray(value)
        if arr.dtype.kind in "fiu" and arr.ndim == 1 and arr.size >= 1:
            out[key] = arr.astype(float)
    if not out:
        raise DataError(name, path, "it holds no numeric vector; save one vector per column, "
                                    "e.g. save('run.mat', 't', 'x', 'v', 'p1', 'p2', 'u')")
    return out


def _csv_columns(text: str, name: str, path) -> tuple[list[str], list[list[str]]]:
    rows = list(csv.reader(io.StringIO(text)))
    while rows and not any(cell.strip() for cell in rows[-1]):
        rows.pop()
    if not rows:
        raise DataError(name, path, "it is empty; need a header line and one row per sample")
    return [h.strip() for h in rows[0]], rows[1:]


def file_columns(data: bytes, filename: str, *, name: str = "--data") -> list[str]:
    """The column names of a CSV or .mat file (units included), for a column-mapping step."""
    if _is_mat(data, filename):
        return list(_mat_columns(data, name, filename))
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(name, filename, "it is neither a text (CSV) file nor a MATLAB .mat file") from None
    return _csv_columns(text, name, filename)[0]


def _csv_column(rows, index: int, h: str, name: str, path) -> np.ndarray:
    values = []
    for k, row in enumerate(rows, start=1):
        cell = row[index].strip() if index < len(row) else ""
        where = f"column {h}, row {k} (line {k + 1})"
        if cell == "":
            raise DataError(name, path, f"{where} is empty")
        try:
            v = float(cell)
        except ValueError:
            raise DataError(name, path, f"{where}: {cell!r} is not a number") from None
        if not math.isfinite(v):
            raise DataError(name, path, f"{where}: {cell} is not finite")
        values.append(v)
    return np.asarray(values, dtype=float)


def read_data(source, columns: Sequence[str], *, name: str = "--data", filename: str | None = None,
              mapping: dict[str, str] | None = None, min_rows: int = 2) -> dict[str, np.ndarray]:
    """The named columns, in SI, of a CSV or ``.mat`` file.

    ``source``: a path, or the file's bytes (an upload; ``filename`` names it).
    ``mapping``: which of the file's columns holds each needed one (``{"x": "pos[mm]"}``);
    by default a column of the needed name, with or without a unit. Every problem
    is a :class:`DataError` naming the file, the column and the row.

    >>> csv_bytes = b"t[ms],x[mm]\\n0,1\\n1,2\\n2,3\\n"
    >>> d = read_data(csv_bytes, ("t", "x"), filename="run.csv")
    >>> d["t"].tolist(), d["x"].tolist()
    ([0.0, 0.001, 0.002], [0.001, 0.002, 0.003])
    """
    if isinstance(source, (bytes, bytearray)):
        data, path = bytes(source), filename or "upload"
    else:
        path = str(source)
        try:
            data = Path(source).read_bytes()
        except OSError as exc:
            raise DataError(name, path, f"it cannot be read ({exc.strerror or exc})") from None
    mapping = dict(mapping or {})
    if _is_mat(data, filename or path):
        table = _mat_columns(data, name, path)
        raw = {h: (arr, None) for h, arr in table.items()}
        n = None
    else:
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise DataError(name, path, "it is neither a text (CSV) file nor a MATLAB .mat file") from None
        header, rows = _csv_columns(text, name, path)
        raw = {h: (None, i) for i, h in enumerate(header)}
        n = len(rows)
    by_base = {}
    for h in raw:
        base, _ = _split_unit(h, name, path) if ("[" in h or "(" in h) else (h, 1.0)
        by_base.setdefault(base, h)
    chosen = {c: mapping.get(c) or (c if c in raw else by_base.get(c)) for c in columns}
    missing = [c for c, h in chosen.items() if h is None or h not in raw]
    if missing:
        have = ", ".join(raw) or "nothing"
        raise DataError(name, path, f"no column {', '.join(missing)}: the file has {have}; need "
                                    f"{', '.join(columns)} (rename them, or map them to the file's columns)")
    out = {}
    for c, h in chosen.items():
        _, scale = _split_unit(h, name, path)
        arr, index = raw[h]
        if arr is None:
            arr = _csv_column(rows, index, h, name, path)
        else:
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise DataError(name, path, f"column {h}, row {int(bad[0]) + 1}: {arr[bad[0]]} is not finite")
        out[c] = arr * scale
    sizes = {c: a.size for c, a in out.items()}
    if len(set(sizes.values())) > 1:
        raise DataError(name, path, "the columns differ in length: " + ", ".join(f"{c} {k}" for c, k in sizes.items()))
    count = n if n is not None else next(iter(sizes.values()))
    if count < min_rows:
        raise DataError(name, path, f"{count} row{'s' if count != 1 else ''} of data; need at least {min_rows}")
    return out


def write_data(columns: dict[str, np.ndarray], kind: str = "csv", units: dict[str, str] | None = None) -> bytes:
    """``columns`` (SI) as the bytes of a CSV (``name[unit]`` headers when ``units`` say) or ``.mat`` file,
    which :func:`read_data` reads back."""
    if kind == "mat":
        import scipy.io

        buf = io.BytesIO()
        scipy.io.savemat(buf, {k: np.asarray(v, dtype=float) for k, v in columns.items()})
        return buf.getvalue()
    units = units or {}
    names = list(columns)
    scales = {k: UNITS[units[k].lower()] if k in units else 1.0 for k in names}
    header = [f"{k}[{units[k]}]" if k in units else k for k in names]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    data = [np.asarray(columns[k], dtype=float) / scales[k] for k in names]
    for row in zip(*data, strict=True):
        w.writerow([f"{v:.10g}" for v in row])
    return buf.getvalue().encode()
