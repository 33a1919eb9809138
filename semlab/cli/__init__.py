"""The ``semlab`` command: track a recorded SEM sequence, or describe image files.

Installed as the console script ``semlab`` (``pyproject.toml``) and runnable as ``python -m semlab``.
:func:`main` takes an argument list and returns the exit code, so tests call it in-process.

One module per concern: ``_common`` (exit codes, errors, option parsers, reading the input, atomic
writes), ``parser`` (:func:`build_parser`), ``info``, ``track`` and ``evaluate`` (the commands).
Every name of the former single module ``semlab/cli.py`` is still importable from here.
"""

from __future__ import annotations

# The modules and names semlab.cli had at module level (tests patch ``semlab.cli.os.replace``).
import argparse  # noqa: F401
import hashlib  # noqa: F401
import json  # noqa: F401
import math  # noqa: F401
import os
import sys
import time  # noqa: F401
from datetime import UTC, datetime  # noqa: F401
from pathlib import Path  # noqa: F401

from semlab.cli._common import (  # noqa: F401
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
    _check_output,
    _cli_words,
    _click_arg,
    _CLIError,
    _fmt_nm,
    _fmt_ps,
    _numbers,
    _param_arg,
    _Parser,
    _ParserExit,
    _pixel_size_arg,
    _read,
    _roi_arg,
    _sha256,
    _size_arg,
    _tmp_name,
    _version,
    _write_atomically,
)
from semlab.cli.evaluate import (  # noqa: F401
    EVALUATE_DESCRIPTION,
    EVALUATE_EXAMPLES,
    _add_evaluate_parser,
    _cmd_evaluate,
    _dask_versions,
    _save_corpus_figure,
    _seeds_arg,
)
from semlab.cli.info import INFO_DESCRIPTION, _cmd_info  # noqa: F401
from semlab.cli.parser import _tracker_methods, build_parser  # noqa: F401
from semlab.cli.track import (  # noqa: F401
    TRACK_DESCRIPTION,
    TRACK_EXAMPLES,
    _accepts,
    _check_params,
    _check_roi,
    _cmd_track,
    _note_reordering,
    _print_track_summary,
    _run_tracker,
    _track_record,
    _track_roi,
    _track_table,
    _type_name,
)
from semlab.environment import describe as describe_environment  # noqa: F401

__all__ = [
    "EXIT_INPUT",
    "EXIT_INTERNAL",
    "EXIT_OK",
    "EXIT_OUTPUT",
    "EXIT_ROI",
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
