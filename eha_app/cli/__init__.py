"""The ``eha`` command: scripted and headless use, reports, and serving the app.

An interface layer on top of the core and the app, like the app itself: one
module per subcommand (``simulate``, ``linearize``, ``idinput``, ``identify``,
``reproduce``, ``serve``, ``exercise``), each with ``add_parser`` and its handler, sharing
:mod:`eha_app.cli.common`. Heavy modules are imported inside the handlers, so
that ``eha --help`` and a refused argument are quick.

Every bad input ends with one line on stderr (``eha: error: NAME = VALUE is
not allowed: WHAT``) and exit code 2; a notice from the core (a warning) is one
plain line on stderr (``eha: note: ...``).
"""

from __future__ import annotations

import sys
import warnings

from eha_core.data import DataError
from eha_core.params import ParameterError

from . import exercise, identify, idinput, linearize, reproduce, serve, simulate, study
from .common import EXIT_USAGE, Parser, UsageError

__all__ = ["main", "build_parser", "EXIT_USAGE", "UsageError"]


def build_parser() -> Parser:
    parser = Parser(prog="eha", description="Electro-hydraulic actuator: simulation, identification and the "
                                            "classroom app.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for module in (simulate, linearize, idinput, identify, reproduce, serve, exercise, study):
        module.add_parser(sub)
    return parser


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        return _error(exc)
    if args.command is None:
        parser.print_help()
        return EXIT_USAGE
    if args.command == "serve":
        # a server runs for hours: its warnings are not kept to be printed when it stops
        return _handle(args)
    with warnings.catch_warnings(record=True) as notes:
        warnings.simplefilter("always")
        try:
            return _handle(args)
        finally:
            for note in notes:
                print(f"eha: note: {_one_line(note.message)}", file=sys.stderr)


def _handle(args) -> int:
    """Run the subcommand; a refusal is one line on stderr and exit code 2."""
    try:
        return args.handler(args)
    except (UsageError, ParameterError, DataError) as exc:
        return _error(exc)
    except ValueError as exc:
        # a ValueError of the core names the argument, its value and what is allowed
        return _error(exc)
    except MemoryError:
        return _error("the computation needs more memory than this machine has: ask for a smaller one")
    except BrokenPipeError:  # e.g. `eha simulate ... | head`
        return 0


def _error(exc) -> int:
    print(f"eha: error: {_one_line(exc)}", file=sys.stderr)
    return EXIT_USAGE
