"""The ``eha`` command: scripted and headless use, reports, and serving the app.

An interface layer on top of the core and the app, like the app itself: one
module per subcommand (``simulate``, ``linearize``, ``idinput``, ``identify``,
``reproduce``, ``serve``, ``exercise``, ``study``), each with ``add_parser`` and its handler, sharing
:mod:`eha_app.cli.common` (and :mod:`eha_app.cli.columns`, how ``--data`` finds a file's columns,
``--columns``). Heavy modules are imported inside the handlers, so
that ``eha --help`` and a refused argument are quick.

Every bad input ends with one line on stderr (``eha: error: NAME = VALUE is
not allowed: WHAT``, NAME the option as typed) and exit code 2, a computation
the inputs do not allow too (naming the typed values it follows from); a notice
from the core (a warning) is one plain line on stderr (``eha: note: ...``),
printed when the command completes. Ctrl-C ends any command with one line
(``eha study lse: interrupted``) and exit code 130. ``eha --version`` prints
the installed version.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from eha_core.errors import ComputationError, FieldError

from . import exercise, identify, idinput, linearize, reproduce, serve, simulate, study
from .common import EXIT_INTERRUPTED, EXIT_USAGE, Parser, UsageError, as_typed, computation_refused, typed_options

__all__ = ["main", "build_parser", "version", "EXIT_USAGE", "EXIT_INTERRUPTED", "UsageError"]


def version() -> str:
    """The installed distribution's version (the package's own when it is not installed)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("eha")
    except PackageNotFoundError:
        from eha_app import __version__

        return __version__


class _Version(argparse.Action):
    """``--version``, looked up only when asked for (importlib.metadata reads the installed files)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"eha {version()}")
        parser.exit()


def build_parser() -> Parser:
    parser = Parser(prog="eha", description="Electro-hydraulic actuator: simulation, identification and the "
                                            "classroom app.")
    parser.add_argument("--version", action=_Version, help="print the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for module in (simulate, linearize, idinput, identify, reproduce, serve, exercise, study):
        module.add_parser(sub)
    return parser


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except UsageError as exc:
            return _error(exc)
        if args.command is None:
            parser.print_help()
            return EXIT_USAGE
        args.typed = typed_options(argv)
        if args.command == "serve":
            # a server runs for hours: its warnings are not kept to be printed when it stops
            return _handle(args)[0]
        with warnings.catch_warnings(record=True) as notes:
            warnings.simplefilter("always")
            code, refusal = _handle(args)
        if not refusal:
            # a refused computation's notices (an overflow on its way) would bury the one line that says why
            for note in notes:
                print(f"eha: note: {_one_line(note.message)}", file=sys.stderr)
        return code
    except KeyboardInterrupt:
        # Ctrl-C is how a user stops a long study or report: one line, and the shell's code for it
        print(f"{_command_name(argv)}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _command_name(argv) -> str:
    """``eha study lse`` of ``eha study lse --seeds 9``: the subcommand as typed (known before it is parsed)."""
    words = []
    for word in argv:
        if word.startswith("-") or len(words) == 2:
            break
        words.append(word)
    return " ".join(["eha", *words])


def _handle(args) -> tuple[int, bool]:
    """Run the subcommand: its exit code, and whether it was a refusal (one line on stderr, exit code 2)."""
    try:
        return args.handler(args), False
    except UsageError as exc:
        return _error(exc), True
    except FieldError as exc:
        # the core names its field; the line names the option the user typed (the subcommand's `fields`)
        return _error(as_typed(exc, getattr(args, "fields", {}), args.typed)), True
    except (ComputationError, ValueError, ArithmeticError) as exc:
        # a computation these inputs do not allow (a simulation that diverged, a number that overflowed):
        # the line names what the user typed that it follows from (the subcommand's `inputs`)
        return _error(computation_refused(exc, getattr(args, "inputs", ()), args.typed)), True
    except MemoryError:
        return _error("the computation needs more memory than this machine has: ask for a smaller one"), True
    except BrokenPipeError:  # e.g. `eha simulate ... | head`
        return 0, False


def _error(exc) -> int:
    print(f"eha: error: {_one_line(exc)}", file=sys.stderr)
    return EXIT_USAGE
