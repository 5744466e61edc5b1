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
import struct
import zlib
from array import array
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from ._checks import FieldError

__all__ = ["DataError", "guess_columns", "COLUMN_ALIASES",
           "read_columns", "read_data", "write_data", "sample_time", "UNITS", "file_columns",
           "columns_text", "MAX_DATA_BYTES", "check_data_size", "csv_cell", "signal_units", "SIGNAL_UNITS"]

#: The most a data file may hold as it is read: the bytes of a CSV, the decompressed bytes of a
#: .mat (a 10 minute record at 1 kHz is about 2 MB of CSV).
MAX_DATA_BYTES = 20_000_000

#: Units a column name may carry, as ``name[unit]``, and their factor to SI.
UNITS = {"s": 1.0, "ms": 1e-3, "m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "m/s": 1.0, "mm/s": 1e-3,
         "pa": 1.0, "kpa": 1e3, "mpa": 1e6, "bar": 1e5, "v": 1.0, "n": 1.0, "kn": 1e3,
         "rad/s": 1.0, "db": 1.0, "deg": 1.0, "samples": 1.0}

#: The SI unit of each signal the project writes (a column ``x_resim`` or ``x_estimate`` is in x's).
SIGNAL_UNITS = {"t": "s", "x": "m", "v": "m/s", "p1": "Pa", "p2": "Pa", "u": "V", "r": "m", "d": "N", "y": "m",
                "w": "rad/s", "lag": "samples"}


def signal_units(names) -> dict[str, str]:
    """The unit of each of ``names`` that is a signal of the project (``x_resim``: m, ``estimate_db``: dB),
    for the ``name[unit]`` headers of a written file.

    >>> signal_units(["t", "x_resim", "estimate_db", "eq24_deg", "autocorrelation"])
    {'t': 's', 'x_resim': 'm', 'estimate_db': 'dB', 'eq24_deg': 'deg'}
    """
    out = {}
    for n in names:
        base = n.split("_")[0]
        if n in SIGNAL_UNITS:
            out[n] = SIGNAL_UNITS[n]
        elif n.endswith("_db"):
            out[n] = "dB"
        elif n.endswith("_deg"):
            out[n] = "deg"
        elif base in SIGNAL_UNITS:
            out[n] = SIGNAL_UNITS[base]
    return out


#: Names a needed column may go by in a file (compared lowercase, without unit, spaces or
#: punctuation: "Pressure_A [bar]" is "pressurea"), and the units that mark its kind.
COLUMN_ALIASES = {
    "t": (("t", "time", "times", "timestamp", "zeit"), ("s", "ms")),
    "x": (("x", "pos", "position", "displacement", "stroke", "xp"), ("m", "mm", "um", "µm")),
    "v": (("v", "vel", "velocity", "speed", "xdot", "dx"), ("m/s", "mm/s")),
    "p1": (("p1", "pa", "pressurea", "pcap", "pap", "pchamber1", "pa1"), ("pa", "kpa", "mpa", "bar")),
    "p2": (("p2", "pb", "pressureb", "prod", "pbp", "pchamber2", "pb2"), ("pa", "kpa", "mpa", "bar")),
    "u": (("u", "valve", "cmd", "command", "uv", "voltage", "valvecmd", "valvecommand", "input"), ("v",)),
    "r": (("r", "ref", "reference", "setpoint", "xref", "rin"), ("m", "mm")),
    "y": (("y", "out", "output", "x", "pos", "position"), ("m", "mm")),
}


def _key(header: str) -> tuple[str, str | None]:
    """("pressurea", "bar") for "Pressure_A [bar]": the name as compared with the aliases, and its unit."""
    h = header.strip()
    unit = None
    for open_, close in (("[", "]"), ("(", ")")):
        if h.endswith(close) and open_ in h:
            h, unit = h[: h.rindex(open_)], h[h.rindex(open_) + 1:-1].strip().lower()
            break
    return "".join(ch for ch in h.lower() if ch.isalnum()), unit


def guess_columns(available: Sequence[str], needed: Sequence[str],
                  aliases: dict[str, Sequence[str]] | None = None) -> dict[str, str | None]:
    """Which of a file's columns is each needed one, guessed from the names, then from the units.

    Each column goes to one need at most; a need without a guess maps to None.
    First a column whose name is one of the need's :data:`COLUMN_ALIASES`
    (``position[mm]`` is x, ``pA[bar]`` p1, ``valve[V]`` u); then, for the needs
    left, the first free column whose unit marks that kind (two pressure
    columns in bar: p1 and p2 in their order). ``aliases`` adds names a need
    may go by (a record's input u may be the loop's reference r).

    Parameters
    ----------
    available : sequence of str
        The file's column names, units included (``"pA[bar]"``).
    needed : sequence of str
        The columns wanted, by the project's names (``"t"``, ``"x"``, ``"p1"``...).
    aliases : dict of str to sequence of str, optional
        More names each needed column may go by, tried after :data:`COLUMN_ALIASES`.

    Examples
    --------
    >>> guess_columns(["time", "position[mm]", "velocity[mm/s]", "pA[bar]", "pB[bar]", "valve[V]"],
    ...               ["t", "x", "v", "p1", "p2", "u"])
    {'t': 'time', 'x': 'position[mm]', 'v': 'velocity[mm/s]', 'p1': 'pA[bar]', 'p2': 'pB[bar]', 'u': 'valve[V]'}
    >>> guess_columns(["s[ms]", "c1[bar]", "c2[bar]"], ["t", "p1", "p2", "u"])
    {'t': 's[ms]', 'p1': 'c1[bar]', 'p2': 'c2[bar]', 'u': None}
    """
    keys = {h: _key(h) for h in available}
    out: dict[str, str | None] = {c: None for c in needed}
    used: set[str] = set()
    for c in needed:
        names = COLUMN_ALIASES.get(c, ((c,), ()))[0] + tuple(
            "".join(ch for ch in a.lower() if ch.isalnum()) for a in (aliases or {}).get(c, ()))
        for alias in (c, *names):
            hit = next((h for h in available if h not in used and keys[h][0] == alias), None)
            if hit is not None:
                out[c] = hit
                used.add(hit)
                break
    for c in needed:
        if out[c] is not None:
            continue
        units = COLUMN_ALIASES.get(c, ((), ()))[1]
        hit = next((h for h in available if h not in used and keys[h][1] in units), None)
        if hit is not None:
            out[c] = hit
            used.add(hit)
    return out


class DataError(FieldError):
    """A data file that cannot be used, with what is wrong and where (a :class:`~eha_core._checks.FieldError`).

    Its field is ``name`` (the option or the form's name for the file), its value
    the file's name ``path``, written quoted.

    Attributes
    ----------
    name, path, what : str
        The field, the file's name, and what is wrong (column, row).
    missing_columns : tuple of str
        The needed columns the file does not have (empty when the problem is
        something else): a caller offers a mapping of the file's columns then.
    file_columns : tuple of str
        The file's column names, when ``missing_columns`` are; see :func:`columns_text`.
    """

    def __init__(self, name: str, path, what: str, *, missing_columns=(), file_columns=()):
        self.name = name
        self.path = str(path)
        self.missing_columns = tuple(missing_columns)
        self.file_columns = tuple(file_columns)
        super().__init__(name, self.path, what, value_text=repr(self.path))


def read_columns(path, columns: Sequence[str], *, name: str = "--data", min_rows: int = 2,
                 mapping: dict[str, str] | None = None) -> dict[str, np.ndarray]:
    """The named columns of a CSV (or ``.mat``) file as float arrays in SI: :func:`read_data`
    for a file name or an open file.

    Parameters
    ----------
    path : str, path or file-like
        The file's name, or an open file or buffer (text or bytes; its ``name``, if any, names it).
    columns : sequence of str
        The columns to read, by name without unit.
    name : str
        What the user called the file (an option, a form's field), the field of a :class:`DataError`.
    min_rows : int
        Fewest data rows accepted.
    mapping : dict of str to str, optional
        Which of the file's columns holds each needed one, as for :func:`read_data`.
    """
    if hasattr(path, "read"):             # an open file or a buffer
        data = path.read()
        data = data.encode() if isinstance(data, str) else data
        return read_data(data, columns, name=name, filename=getattr(path, "name", "data"), min_rows=min_rows,
                         mapping=mapping)
    return read_data(path, columns, name=name, min_rows=min_rows, mapping=mapping)


def sample_time(t: np.ndarray, *, name: str = "--data", path="data", rtol: float = 1e-6) -> float:
    """The sample interval of uniformly sampled times, or a :class:`DataError` at the first bad row.

    Parameters
    ----------
    t : array
        The times [s], at least 2, increasing.
    name : str
        The field of a :class:`DataError` (the option or form's name for the file).
    path : str
        The file's name, as the error writes it.
    rtol : float
        Largest departure of a step from the median step, relative to the larger of the
        median step and ``|t[-1]|``.

    Returns
    -------
    float
        ``(t[-1] - t[0]) / (len(t) - 1)`` [s].
    """
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


_FORMULA_START = ("=", "+", "-", "@", "\t", "\r", "\n")


def csv_cell(value) -> str:
    r"""A cell as every CSV of the project writes it: text that a spreadsheet would run as a
    formula (``=HYPERLINK(...)``, ``+cmd``, ``@SUM``) gets a leading ``'``; numbers stay numbers.
    ``value`` is any object, written as ``str(value)``; None is an empty cell.

    >>> csv_cell('=HYPERLINK("http://x")'), csv_cell("-1.5e3"), csv_cell("ada"), csv_cell(None)
    ('\'=HYPERLINK("http://x")', '-1.5e3', 'ada', '')
    """
    text = "" if value is None else str(value)
    if text.startswith(_FORMULA_START):
        try:
            float(text)
            return text
        except ValueError:
            return "'" + text
    return text


def check_data_size(size: int, path, *, name: str = "--data") -> None:
    """Refuse a file of more than :data:`MAX_DATA_BYTES`, naming it and its size, before reading it.

    Parameters
    ----------
    size : int
        The file's size [bytes].
    path : str
        The file's name, as the error writes it.
    name : str
        The field of the :class:`DataError` (the option or form's name for the file).
    """
    if size > MAX_DATA_BYTES:
        raise DataError(name, path, f"it has {size / 1e6:.1f} MB; at most {MAX_DATA_BYTES / 1e6:g} MB")


def _is_mat(data: bytes, filename: str) -> bool:
    return filename.lower().endswith(".mat") or data[:6] == b"MATLAB"


#: MATLAB classes read as columns; cells, structs, strings, sparse and objects are never loaded.
_MAT_NUMERIC = {"double": 8, "single": 4, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4,
                "uint32": 4, "int64": 8, "uint64": 8, "logical": 1}
_MI_COMPRESSED = 15


def _too_big(what: str) -> str:
    return f"it holds more than {MAX_DATA_BYTES / 1e6:g} MB {what}; at most {MAX_DATA_BYTES / 1e6:g} MB are read"


def _expanded_mat(data: bytes, name: str, path) -> bytes:
    """A MATLAB v5 file with its compressed variables expanded, never past :data:`MAX_DATA_BYTES` in all.

    A v5 file is a 128-byte header, then one element per variable: an 8-byte
    tag (type, byte count) and its bytes; type 15 is a zlib stream of a whole
    element. Each stream is inflated only up to what is left of the limit, so
    a small file that inflates to gigabytes (a decompression bomb) is refused
    after reading 20 MB of it, not 1.6 GB. v4 files are never compressed.
    """
    if len(data) < 128 or data[126:128] not in (b"IM", b"MI"):
        return data                       # MATLAB v4 (or not a .mat: scipy says so)
    order = "<" if data[126:128] == b"IM" else ">"
    if struct.unpack(order + "H", data[124:126])[0] == 0x0200:
        raise DataError(name, path, "it is a MATLAB v7.3 (HDF5) file, which this app does not read; save it "
                                    "with save('run.mat', 't', 'u', ..., '-v7')")
    parts, total, pos = [data[:128]], 128, 128
    while pos + 8 <= len(data):
        mdtype, nbytes = struct.unpack(order + "II", data[pos:pos + 8])
        end = pos + 8 + nbytes
        if mdtype == _MI_COMPRESSED:
            inflate = zlib.decompressobj()
            budget = MAX_DATA_BYTES - total
            try:
                element = inflate.decompress(data[pos + 8:end], budget + 1)
            except zlib.error:
                raise DataError(name, path, "a compressed variable in it is damaged") from None
            if len(element) > budget or inflate.unconsumed_tail:
                raise DataError(name, path, _too_big("once decompressed"))
        else:
            element = data[pos:end]
        parts.append(element)
        total += len(element)
        if total > MAX_DATA_BYTES:
            raise DataError(name, path, _too_big("once decompressed"))
        pos = end
    return b"".join(parts)


def _mat_columns(data: bytes, name: str, path) -> dict[str, np.ndarray]:
    """The numeric vectors of a .mat file, by name: each variable's declared size is checked
    before anything is loaded, and only numeric variables are loaded."""
    import scipy.io

    def unreadable(exc) -> DataError:
        return DataError(name, path, f"it is not a MATLAB .mat file scipy can read ({type(exc).__name__}: "
                                     f"{' '.join(str(exc).split())[:120]})")

    data = _expanded_mat(data, name, path)
    try:
        listed = scipy.io.whosmat(io.BytesIO(data))
    except Exception as exc:  # noqa: BLE001 - scipy raises several kinds for a bad file
        raise unreadable(exc) from None
    wanted = []
    for var, shape, cls in listed:
        size = _MAT_NUMERIC.get(cls)
        if size is None or var.startswith("__"):
            continue
        if math.prod(shape) * max(size, 8) > MAX_DATA_BYTES:      # read as float64
            raise DataError(name, path, f"variable {var} is declared {' x '.join(map(str, shape))}: "
                                        + _too_big("as numbers"))
        wanted.append(var)
    try:
        mat = scipy.io.loadmat(io.BytesIO(data), squeeze_me=True, variable_names=wanted) if wanted else {}
    except Exception as exc:  # noqa: BLE001 - scipy raises several kinds for a bad file
        raise unreadable(exc) from None
    out = {}
    for key, value in mat.items():
        if key.startswith("__"):
            continue
        arr = np.asarray(value)
        if arr.dtype.kind in "fiub" and arr.ndim == 1 and arr.size >= 1:
            out[key] = arr.astype(float)
    if not out:
        raise DataError(name, path, "it holds no numeric vector; save one vector per column, "
                                    "e.g. save('run.mat', 't', 'x', 'v', 'p1', 'p2', 'u')")
    return out


def _short(text: str, limit: int = 40) -> str:
    """A file's text as a message repeats it: whole, or its start when it is long."""
    return text if len(text) <= limit else text[:limit] + "…"


def _csv_rows(data: bytes, name: str, path) -> Iterator[list[str]]:
    """The rows of a CSV file, decoded as they are read: no copy of the whole text (a 20 MB file
    read through one string cost 130 MB)."""
    text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig", newline="")
    try:
        yield from csv.reader(text)
    except UnicodeDecodeError:
        raise DataError(name, path, "it is neither a text (CSV) file nor a MATLAB .mat file") from None
    except csv.Error as exc:
        raise DataError(name, path, f"it is not a CSV file this app can read ({exc})") from None


def _csv_header(data: bytes, name: str, path) -> tuple[list[str], Iterator[list[str]]]:
    """The header's names and the rows after it."""
    rows = _csv_rows(data, name, path)
    if data.strip(b" \t\r\n,;\xef\xbb\xbf"):
        for row in rows:                    # the first line, as line numbers in messages count it
            return [h.strip() for h in row], rows
    raise DataError(name, path, "it is empty; need a header line and one row per sample")


def columns_text(names) -> str:
    """A file's column names (``names``, any iterable of str) as a message lists them: the first 20,
    each cut to 40 characters.

    >>> columns_text(["t", "u", "y"]), columns_text([])
    ('t, u, y', 'nothing')
    """
    names = list(names)
    shown = [_short(h) for h in names[:20]] + ([f"and {len(names) - 20} more"] if len(names) > 20 else [])
    return ", ".join(shown) or "nothing"


def file_columns(data: bytes, filename: str, *, name: str = "--data") -> list[str]:
    """The column names of a CSV or .mat file (units included), for a column-mapping step.

    Parameters
    ----------
    data : bytes
        The file's content.
    filename : str
        The file's name: a ``.mat`` one (or content starting ``MATLAB``) is read as MATLAB's.
    name : str
        The field of a :class:`DataError` (the option or form's name for the file).
    """
    check_data_size(len(data), filename, name=name)
    if _is_mat(data, filename):
        return list(_mat_columns(data, name, filename))
    return _csv_header(data, name, filename)[0]


def _csv_numbers(rows: Iterator[list[str]], wanted: dict[str, tuple[int, str]], name: str,
                 path) -> tuple[dict[str, np.ndarray], int]:
    """Read the data rows once, keeping only the wanted columns (``{name: (index, header)}``) as
    numbers: a 20 MB file costs its numbers' memory, not a list of every cell. Returns them with
    the count of rows (trailing blank rows not counted), or raises the first problem of the first
    wanted column that has one."""
    values = {c: array("d") for c in wanted}
    problems: dict[str, str] = {}
    blank_from = None               # the first of blank rows: a problem only if data follow them
    count = 0
    for k, row in enumerate(rows, start=1):
        if not any(cell.strip() for cell in row):
            blank_from = k if blank_from is None else blank_from
            continue
        if blank_from is not None:
            for c, (_, h) in wanted.items():
                problems.setdefault(c, f"column {h}, row {blank_from} (line {blank_from + 1}) is empty")
            blank_from = None
        count = k
        for c, (index, h) in wanted.items():
            if c in problems:
                continue
            cell = row[index].strip() if index < len(row) else ""
            where = f"column {h}, row {k} (line {k + 1})"
            try:
                v = float(cell)
            except ValueError:
                problems[c] = f"{where} is empty" if cell == "" else f"{where}: {_short(cell)!r} is not a number"
                continue
            if not math.isfinite(v):
                problems[c] = f"{where}: {_short(cell)} is not finite"
                continue
            values[c].append(v)
    for c in wanted:
        if c in problems:
            raise DataError(name, path, problems[c])
    return {c: np.frombuffer(v, dtype=float) for c, v in values.items()}, count


def read_data(source, columns: Sequence[str], *, name: str = "--data", filename: str | None = None,
              mapping: dict[str, str] | None = None, min_rows: int = 2) -> dict[str, np.ndarray]:
    """The named columns, in SI, of a CSV or ``.mat`` file.

    Every problem is a :class:`DataError` naming the file, the column and the row.

    Parameters
    ----------
    source : str, path or bytes
        A path, or the file's bytes (an upload; ``filename`` names it).
    columns : sequence of str
        The needed columns, by name without unit.
    name : str
        What the user called the file (an option, a form's field), the field of a :class:`DataError`.
    filename : str, optional
        The name of a file given as bytes (default ``"upload"``); a ``.mat`` one is read as MATLAB's.
    mapping : dict of str to str, optional
        Which of the file's columns holds each needed one (``{"x": "pos[mm]"}``);
        by default a column of the needed name, with or without a unit.
    min_rows : int
        Fewest data rows accepted.

    Examples
    --------
    >>> csv_bytes = b"t[ms],x[mm]\\n0,1\\n1,2\\n2,3\\n"
    >>> d = read_data(csv_bytes, ("t", "x"), filename="run.csv")
    >>> d["t"].tolist(), d["x"].tolist()
    ([0.0, 0.001, 0.002], [0.001, 0.002, 0.003])
    """
    if isinstance(source, (bytes, bytearray)):
        data, path = bytes(source), filename or "upload"
        check_data_size(len(data), path, name=name)
    else:
        path = str(source)
        try:
            check_data_size(Path(source).stat().st_size, path, name=name)
            data = Path(source).read_bytes()
        except OSError as exc:
            raise DataError(name, path, f"it cannot be read ({exc.strerror or exc})") from None
    mapping = dict(mapping or {})
    if _is_mat(data, filename or path):
        table = _mat_columns(data, name, path)
        raw = {h: (arr, None) for h, arr in table.items()}
        rows = n = None
    else:
        header, rows = _csv_header(data, name, path)
        raw = {h: (None, i) for i, h in enumerate(header)}
    by_base = {}
    for h in raw:
        base, _ = _split_unit(h, name, path) if ("[" in h or "(" in h) else (h, 1.0)
        by_base.setdefault(base, h)
    chosen = {c: mapping.get(c) or (c if c in raw else by_base.get(c)) for c in columns}
    missing = [c for c, h in chosen.items() if h is None or h not in raw]
    if missing:
        raise DataError(name, path, f"no column {', '.join(missing)}: the file has {columns_text(raw)}; need "
                                    f"{', '.join(columns)} (rename them, or map them to the file's columns)",
                        missing_columns=missing, file_columns=raw)
    scales = {c: _split_unit(h, name, path)[1] for c, h in chosen.items()}
    if rows is None:                        # a .mat file: its vectors
        numbers = {c: raw[h][0] for c, h in chosen.items()}
        for c, h in chosen.items():
            bad = np.flatnonzero(~np.isfinite(numbers[c]))
            if bad.size:
                raise DataError(name, path, f"column {h}, row {int(bad[0]) + 1}: {numbers[c][bad[0]]} is not finite")
    else:
        numbers, n = _csv_numbers(rows, {c: (raw[h][1], h) for c, h in chosen.items()}, name, path)
    out = {c: numbers[c] * scales[c] for c in chosen}
    sizes = {c: a.size for c, a in out.items()}
    if len(set(sizes.values())) > 1:
        raise DataError(name, path, "the columns differ in length: " + ", ".join(f"{c} {k}" for c, k in sizes.items()))
    count = n if n is not None else next(iter(sizes.values()))
    if count < min_rows:
        raise DataError(name, path, f"{count} row{'s' if count != 1 else ''} of data; need at least {min_rows}")
    return out


def write_data(columns: dict[str, np.ndarray], kind: str = "csv", units: dict[str, str] | str | None = None) -> bytes:
    """``columns`` (SI) as the bytes of a CSV or ``.mat`` file, which :func:`read_data` reads back.

    Parameters
    ----------
    columns : dict of str to array
        The columns by name, in SI units.
    kind : {'csv', 'mat'}
        The file's format.
    units : dict of str to str, or 'si', optional
        CSV only: the unit of each column's ``name[unit]`` header, one of :data:`UNITS`
        (values are converted from SI into it); ``"si"``: each known signal's SI unit
        (:func:`signal_units`); default none (bare names, SI values).
    """
    if kind == "mat":
        import scipy.io

        buf = io.BytesIO()
        scipy.io.savemat(buf, {k: np.asarray(v, dtype=float) for k, v in columns.items()})
        return buf.getvalue()
    names = list(columns)
    units = signal_units(names) if units == "si" else (units or {})
    scales = {k: UNITS[units[k].lower()] if k in units else 1.0 for k in names}
    header = [f"{k}[{units[k]}]" if k in units else k for k in names]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([csv_cell(h) for h in header])
    data = [np.asarray(columns[k], dtype=float) / scales[k] for k in names]
    for row in zip(*data, strict=True):
        w.writerow([f"{v:.10g}" for v in row])
    return buf.getvalue().encode()
