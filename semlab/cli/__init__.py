"""The ``semlab`` command: track a recorded SEM sequence, or describe image files.

Installed as the console script ``semlab`` (``pyproject.toml``) and runnable as ``python -m semlab``.
:func:`main` takes an argument list and returns the exit code, so tests call it in-process.

One module per concern: ``_common`` (exit codes, errors, option parsers, reading the input, atomic
writes), ``parser`` (:func:`build_parser`), ``info``, ``track`` and ``evaluate`` (the commands).
"""

from __future__ import annotations

# ``os`` as a module attribute: the tests patch ``semlab.cli.os.replace`` (the same module object the
# atomic write in ``_common`` calls).
import os
import sys

from semlab.cli._common import (
    COMMAND_HELP,
    EXIT_CODES,
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_ROI,
    EXIT_SCHEDULER,
    EXIT_TRACKING,
    EXIT_USAGE,
    _CLIError,
    _ParserExit,
)
from semlab.cli.evaluate import _cmd_evaluate
from semlab.cli.info import _cmd_info
from semlab.cli.parser import build_parser
from semlab.cli.track import _cmd_track

__all__ = [
    "COMMAND_HELP",
    "EXIT_CODES",
    "EXIT_INPUT",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_OUTPUT",
    "EXIT_ROI",
    "EXIT_SCHEDULER",
    "EXIT_TRACKING",
    "EXIT_USAGE",
    "build_parser",
    "main",
]


def main(argv: list[str] | None = None) -> int:
    """Run the ``semlab`` command line; return the exit code (see ``semlab --help``)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _ParserExit as e:
        return int(e.status or 0)
    if args.command is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    try:
        if args.command == "info":
            return _cmd_info(args)
        if args.command == "evaluate":
            return _cmd_evaluate(args, argv)
        return _cmd_track(args, argv)
    except _CLIError as e:
        print(f"semlab: error: {e.message}", file=sys.stderr)
        return e.code
    except KeyboardInterrupt:
        print("semlab: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as e:  # a bug: one line, the traceback on request
        if os.environ.get("SEMLAB_DEBUG"):
            raise
        print(
            f"semlab: internal error: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''} "
            "(set SEMLAB_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL
