"""``--data FILE`` and ``--columns``: which of a file's columns is each one a command needs, as the web app
reads an upload.

A file whose columns have the needed names (``t``, ``x[mm]``, ``p1[MPa]``: units in brackets are
converted) is read as it is, and so is every file the app writes. Otherwise the columns are guessed as
the app guesses them (:func:`eha_core.data.guess_columns`: by name, ``position[mm]`` is x, then by unit),
and the command says which it took in one note line (``eha: note: columns taken from run.csv: t=time,
x=position[mm], ... (override with --columns)``); a column that cannot be guessed is refused in one line
that says how to give it. ``--columns t=time,x=position[mm]`` says which column is which; a needed column
it leaves out is read by its name, or guessed.

>>> parse_columns("t=time, x=position[mm]", ("t", "x", "v"))
{'t': 'time', 'x': 'position[mm]'}
>>> parse_columns("q=time", ("t", "x", "v"))
Traceback (most recent call last):
...
eha_app.cli.common.UsageError: --columns = q=time is not allowed: q is not a column this command needs; use t, x, v
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

from .common import refused, refused_file, terminal_text

__all__ = ["COLUMNS_GRAMMAR", "add_columns_option", "parse_columns", "checked_columns", "read_with_columns"]

#: The one grammar of ``--columns``, which every command's help gives.
COLUMNS_GRAMMAR = ("with --data: which of the file's columns is each needed one, as NEEDED=COLUMN joined by commas, "
                   "COLUMN as the file's header names it (its unit in brackets may be left out; units are converted "
                   "as the web app converts them); quote it for the shell, e.g. --columns "
                   "'t=time,x=position[mm]'. A needed column not given is read by its name; a file whose names "
                   "differ has its columns guessed from the names and units, as the web app does, and a note says "
                   "which it took")


def add_columns_option(parser, needed: str) -> None:
    """``--columns`` on ``parser``, whose ``--data`` needs the columns ``needed`` (text: ``t, u, y``)."""
    parser.add_argument("--columns", metavar="NEEDED=COLUMN,...",
                        help=f"{COLUMNS_GRAMMAR}. NEEDED is one of {needed}")


def parse_columns(text: str, needed: Sequence[str], *, option: str = "--columns") -> dict[str, str]:
    """``--columns`` as ``{needed name: the file's column as typed}``, its form checked (the columns are
    checked against the file by :func:`read_with_columns`).

    A refusal names the part as typed: one without ``=`` or a side, a name not in ``needed``, or one given
    twice.
    """
    usage = f"give NEEDED=COLUMN joined by commas, NEEDED one of {', '.join(needed)}, e.g. {needed[-1]}=COLUMN"
    out: dict[str, str] = {}
    for part in str(text).split(","):
        name, eq, column = part.partition("=")
        name, column, typed = name.strip(), column.strip(), part.strip() or "(empty)"
        if not eq or not name or not column:
            raise refused(option, typed, usage, value_text=typed)
        if name not in needed:
            raise refused(option, typed, f"{name} is not a column this command needs; use {', '.join(needed)}",
                          value_text=typed)
        if name in out:
            raise refused(option, typed, f"{name} is given twice", value_text=typed)
        out[name] = column
    return out


def checked_columns(args, needed: Sequence[str]) -> dict[str, str]:
    """``--columns`` of ``args`` checked before anything heavy: its form, and that ``--data`` is given
    (``{}`` when it is not typed)."""
    if args.columns is None:
        return {}
    if not args.data:
        raise refused("--columns", args.columns, "it says which of a file's columns is which; give the file "
                                                 "with --data", context="without --data")
    return parse_columns(args.columns, needed)


def _unit_left_out(header: str) -> str:
    """``position`` of ``position[mm]`` or ``position (mm)``: a header without its unit."""
    h = header.strip()
    for open_, close in (("[", "]"), ("(", ")")):
        if h.endswith(close) and open_ in h:
            return h[: h.rindex(open_)].strip()
    return h


def _header(path: str, option: str) -> list[str]:
    """The column names of the file ``path`` (CSV or .mat), units included."""
    from eha_core.data import DataError, check_data_size, file_columns

    try:
        check_data_size(Path(path).stat().st_size, path, name=option)
        data = Path(path).read_bytes()
    except OSError as exc:
        raise DataError(option, path, f"it cannot be read ({exc.strerror or exc})") from None
    return file_columns(data, path, name=option)


def _in_file(given: dict[str, str], available: Sequence[str], path: str) -> dict[str, str]:
    """Each column of ``--columns`` as the file's header names it: the same name, or the one column whose
    name without its unit it is (``position`` for ``position[mm]``)."""
    from eha_core.data import columns_text

    have = terminal_text(columns_text(available))
    out = {}
    for name, column in given.items():
        typed = f"{name}={column}"
        if column in available:
            out[name] = column
            continue
        like = [h for h in available if _unit_left_out(h) == column]
        if len(like) == 1:
            out[name] = like[0]
        elif like:
            raise refused("--columns", typed, f"{column} names {len(like)} columns of {path}: "
                                              f"{terminal_text(columns_text(like))}; give one with its unit",
                          value_text=typed)
        else:
            raise refused("--columns", typed, f"{column} is not a column of {path}; it has {have}", value_text=typed)
    return out


def read_with_columns(read: Callable[[dict[str, str] | None], object], path: str, needed: Sequence[str],
                      given: dict[str, str] | None = None, *, aliases: dict[str, Sequence[str]] | None = None,
                      also: tuple[Callable[[], object], str] | None = None, option: str = "--data"):
    """What ``read(mapping)`` reads of the file ``path``, its ``needed`` columns found as the web app finds them.

    ``read(None)`` reads the columns of the needed names; ``read({"x": "position[mm]"})`` the file's
    columns for the needed ones named (the others by name). Each raises a
    :class:`~eha_core.data.DataError` with ``missing_columns`` for a column the file does not have.

    Parameters
    ----------
    read : callable
        Reads the file with a mapping of the needed names to the file's columns (or None).
    path : str
        The file's name, as typed.
    needed : sequence of str
        The columns ``read`` needs, by the project's names.
    given : dict of str to str, optional
        ``--columns`` (:func:`parse_columns`): checked against the file's columns, then read.
    aliases : dict of str to sequence of str, optional
        More names a needed column may go by when the columns are guessed (as the app's form has them).
    also : (callable, str), optional
        Another set of names read by name when the needed ones are missing and ``--columns`` is not given
        (the frequency tab's t, r, x for t, u, y), and how the refusal writes it (``"t, r, x"``).
    option : str
        The option that gave the file.

    Returns
    -------
    object
        What ``read`` returned. When the columns were guessed, a warning (the command's note line) says
        which column was taken for each.
    """
    from eha_core.data import DataError, columns_text, guess_columns

    explicit = _in_file(given, _header(path, option), path) if given else {}
    try:
        return read(explicit or None)
    except DataError as exc:
        if not exc.missing_columns:
            raise
        first = exc
    if also is not None and not explicit:
        try:
            return also[0]()
        except DataError as exc:
            if not exc.missing_columns:
                raise
    available = list(first.file_columns)
    rest = [c for c in needed if c not in explicit]
    guesses = guess_columns([h for h in available if h not in explicit.values()], rest, aliases)
    missing = [c for c in rest if guesses[c] is None]
    if missing:
        wanted = ", ".join(needed) + (f" (or {also[1]})" if also is not None else "")
        raise refused_file(option, path, f"no column {', '.join(missing)}: the file has "
                                         f"{terminal_text(columns_text(available))}; need {wanted}: say which "
                                         f"column is which with --columns, e.g. --columns {missing[0]}=COLUMN")
    mapping = {c: explicit.get(c) or guesses[c] for c in needed}
    result = read(mapping)
    taken = ", ".join(f"{c}={terminal_text(mapping[c])}" for c in needed)
    warnings.warn(f"columns taken from {path}: {taken} (override with --columns)", stacklevel=2)
    return result
