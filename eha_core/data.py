"""Reading measured data from a CSV file: one reader, one form of message.

Identification (the least squares and the transfer-function estimate) reads
the same kind of file: a header of column names, then one row per sample, the
time ``t`` uniformly sampled. A problem is reported as
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

__all__ = ["DataError", "read_columns", "sample_time"]


class DataError(ValueError):
    """A data file that cannot be used, with what is wrong and where."""

    def __init__(self, name: str, path, what: str):
        self.name = name
        self.path = str(path)
        self.what = what
        super().__init__(f"{name} = {str(path)!r} is not allowed: {what}")


def read_columns(path, columns: Sequence[str], *, name: str = "--data", min_rows: int = 2) -> dict[str, np.ndarray]:
    """The named columns of a CSV file as float arrays.

    ``path`` is a file name or an open text file. Other columns are ignored.
    Raises :class:`DataError` naming the file, and the column and row of the
    first bad cell (not a number, not finite, or missing), or the missing
    columns, or too few rows.
    """
    if hasattr(path, "read"):             # an open file or a buffer
        text = path.read()
        text = text.decode("utf-8-sig") if isinstance(text, bytes) else text.lstrip("\ufeff")
        path = getattr(path, "name", "data")
    else:
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise DataError(name, path, f"it cannot be read ({exc.strerror or exc})") from None
        except UnicodeDecodeError:
            raise DataError(name, path, "it is not a text (CSV) file") from None
    rows = list(csv.reader(io.StringIO(text)))
    while rows and not any(cell.strip() for cell in rows[-1]):
        rows.pop()
    if not rows:
        raise DataError(name, path, f"it is empty; need a header with {', '.join(columns)} and one row per sample")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DataError(name, path, f"no column {', '.join(missing)}: the header has {', '.join(header) or 'nothing'}; "
                                    f"need {', '.join(columns)}")
    index = {c: header.index(c) for c in columns}
    values: dict[str, list[float]] = {c: [] for c in columns}
    for k, row in enumerate(rows[1:], start=1):
        for c in columns:
            cell = row[index[c]].strip() if index[c] < len(row) else ""
            where = f"column {c}, row {k} (line {k + 1})"
            if cell == "":
                raise DataError(name, path, f"{where} is empty")
            try:
                v = float(cell)
            except ValueError:
                raise DataError(name, path, f"{where}: {cell!r} is not a number") from None
            if not math.isfinite(v):
                raise DataError(name, path, f"{where}: {cell} is not finite")
            values[c].append(v)
    n = len(rows) - 1
    if n < min_rows:
        raise DataError(name, path, f"{n} row{'s' if n != 1 else ''} of data; need at least {min_rows}")
    return {c: np.asarray(v, dtype=float) for c, v in values.items()}


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
