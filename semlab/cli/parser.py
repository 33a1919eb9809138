"""The ``semlab`` argument parser: the commands, their options and help texts."""

from __future__ import annotations

import argparse

from semlab.cli._common import (
    COMMAND_HELP,
    EXIT_CODES,
    _click_arg,
    _param_arg,
    _Parser,
    _pixel_size_arg,
    _roi_arg,
    _size_arg,
    _version,
)
from semlab.cli.evaluate import _add_evaluate_parser
from semlab.cli.info import INFO_DESCRIPTION
from semlab.cli.track import TRACK_DESCRIPTION, TRACK_EXAMPLES


def _tracker_methods() -> tuple[tuple[str, ...], str]:
    """Methods of semlab.tracking and the best measured one (``Tracker()``'s default), the CLI's default.

    ``semlab.track`` keeps the paper's ``"contour"`` as its default by contract; a command run on a
    recording should use the method that measured best (``benchmarks/bench_tracking.py``).
    """
    try:
        from semlab import tracking

        return tuple(tracking.METHODS), tracking.DEFAULT_METHOD
    except (ImportError, AttributeError, KeyError):  # pragma: no cover - tracker not importable
        return ("ic", "contour", "ssd"), "ic"


def build_parser() -> argparse.ArgumentParser:
    """The ``semlab`` argument parser (exposed for documentation and tests)."""
    fmt = argparse.RawDescriptionHelpFormatter
    parser = _Parser(
        prog="semlab",
        description="semlab: sub-pixel visual tracking in a scanning electron microscope "
        "(after Ru et al., 2012).",
        epilog=EXIT_CODES + "\nRun 'semlab COMMAND --help' for the options of a command.",
        formatter_class=fmt,
    )
    parser.add_argument("--version", action="version", version=f"semlab {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    methods, default_method = _tracker_methods()
    t = sub.add_parser(
        "track",
        help=COMMAND_HELP["track"],
        description=TRACK_DESCRIPTION,
        epilog=TRACK_EXAMPLES + "\n" + EXIT_CODES,
        formatter_class=fmt,
    )
    t.add_argument(
        "inputs", nargs="+", metavar="INPUT", help="image/video files, folders or glob patterns"
    )
    where = t.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--roi",
        type=_roi_arg,
        metavar="X,Y,W,H",
        help="ROI in the first frame: top-left pixel column X, row Y, width W, height H (px)",
    )
    where.add_argument(
        "--click",
        type=_click_arg,
        metavar="X,Y",
        help="a point on the target in the first frame; the ROI is --roi-size centred on it "
        "(semlab.roi.roi_from_click), shifted to lie inside the frame",
    )
    t.add_argument(
        "--roi-size",
        type=_size_arg,
        default=(200, 200),
        metavar="N|WxH",
        help="ROI size for --click (default 200, the paper's 200x200 px at 3,000x)",
    )
    t.add_argument(
        "--method",
        choices=methods,
        default=default_method,
        help=f"tracking method (default {default_method!r}): 'contour' is the paper's contour-template "
        "matching, 'ssd' conventional template matching, 'ic' semlab's robust sub-pixel tracker",
    )
    t.add_argument(
        "--param",
        type=_param_arg,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a tracker parameter (semlab.Tracker keyword, e.g. sigma=1.5, search_size=300, "
        "threshold=none); VALUE is read as JSON, else as text, and must have the keyword's type; "
        "repeatable",
    )
    t.add_argument(
        "--keep-order",
        action="store_true",
        help="track the files in the order given instead of natural order (frame_2 before frame_10)",
    )
    t.add_argument(
        "--pixel-size",
        type=_pixel_size_arg,
        metavar="NM",
        help="pixel size in nm; overrides the file metadata (default: from FEI/Zeiss/ImageJ metadata)",
    )
    t.add_argument(
        "--out",
        "-o",
        required=True,
        metavar="OUT.csv",
        help="output CSV; OUT.csv.json is written beside it",
    )
    t.add_argument(
        "--sigma",
        action="store_true",
        help="add each frame's standard uncertainty: columns sigma_x, sigma_y (px) after the others "
        "(empty where the frame is not ok)",
    )
    t.add_argument(
        "--reason",
        action="store_true",
        help="add why each frame is not ok (lost, or flagged: too uncertain, ambiguous, ...): column reason, "
        "last (empty where the frame is ok)",
    )
    t.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    t.add_argument("--quiet", "-q", action="store_true", help="no summary on stdout")

    i = sub.add_parser(
        "info",
        help=COMMAND_HELP["info"],
        description=INFO_DESCRIPTION,
        epilog=EXIT_CODES,
        formatter_class=fmt,
    )
    i.add_argument(
        "files", nargs="+", metavar="FILE", help="image/video files, folders or glob patterns"
    )
    i.add_argument("--json", action="store_true", help="print one JSON document instead of text")
    _add_evaluate_parser(sub, fmt)
    return parser
