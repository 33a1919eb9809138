"""The ``semlab`` command: track a recorded SEM sequence, or describe image files.

Installed as the console script ``semlab`` (``pyproject.toml``) and runnable as ``python -m semlab``.
:func:`main` takes an argument list and returns the exit code, so tests call it in-process.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from semlab.environment import describe as describe_environment

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

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_INPUT = 3
EXIT_ROI = 4
EXIT_TRACKING = 5
EXIT_OUTPUT = 6
#: ``semlab evaluate``: the dask scheduler could not be reached.
EXIT_SCHEDULER = 7
EXIT_INTERRUPTED = 130

EXIT_CODES = f"""\
exit codes:
  {EXIT_OK}    success (frames where the target was lost are rows with ok=False, not an error)
  {EXIT_INTERNAL}    internal error (a bug: please report it; set SEMLAB_DEBUG=1 for the traceback)
  {EXIT_USAGE}    usage error: bad or missing options, malformed --roi/--click values, unknown
       --param keys or values of the wrong type (checked before anything is read)
  {EXIT_INPUT}    input error: missing file, empty folder, pattern without matches, unsupported
       format, unreadable or truncated image, frames of different sizes or pixel types
  {EXIT_ROI}    ROI error: --roi or --click (with --roi-size) not inside the frames, or too small
  {EXIT_TRACKING}    tracking failure: the tracker cannot start from the first frame and ROI
       (e.g. a featureless ROI, no contour in it)
  {EXIT_OUTPUT}    output error: the output file or its sidecar cannot be written
  {EXIT_SCHEDULER}    scheduler error (semlab evaluate): the dask scheduler cannot be reached
  {EXIT_INTERRUPTED}  interrupted (Ctrl-C)
Errors are one line on stderr: 'semlab: error: <file>: <reason>'. Output files are written under a
temporary name and renamed only when complete, so a failed run leaves no partial output.
"""

#: Every subcommand with its one-line description, as ``semlab --help`` lists them: each fits one
#: line of an 80-column terminal (argparse indents it 14 characters, so 64 at most).
COMMAND_HELP = {
    "track": "track a target through a recorded sequence (CSV + JSON sidecar)",
    "info": "print size, dtype, frames and pixel size (nm) of image files",
    "evaluate": "run trackers on the scene-family corpus (CSV + JSON sidecar)",
}

TRACK_DESCRIPTION = """\
Track a target (a probe tip) through a recorded sequence of SEM frames and write one CSV row per
frame: frame, x, y, x_nm, y_nm, score, ok, file.

x, y (px) are where the ROI's centre point, (x + (w-1)/2, y + (h-1)/2) in frame 0, has moved to in
each frame; pixel centres are at integer coordinates, x to the right, y down. x_nm, y_nm = x, y times
the pixel size; they are empty when the pixel size is unknown (PNG/JPEG/video, TIFFs without vendor
metadata) and --pixel-size is not given. score is the tracker's match quality in [0, 1]; ok=False
(with empty x, y) marks frames where the target was lost or its answer was too uncertain to trust
(semlab's tracker, the default). --sigma adds sigma_x, sigma_y: each frame's standard uncertainty
(px) as the tracker estimates it.

Next to OUT the command writes OUT.json: semlab version, command line, method and parameters, ROI,
pixel size and where it came from, every input file with its SHA-256, frame count, times, and the
SHA-256 of the CSV.

INPUT is any mix of image files (PNG, TIFF, JPEG, BMP), multi-page TIFFs, videos (AVI, MP4, ...),
folders and glob patterns ('run/frame_*.png'). All files are tracked in natural order (frame_2 before
frame_10), also when the shell expanded a pattern as frame_0, frame_1, frame_10, frame_2; the command
says on stderr when it re-ordered the files it was given (--keep-order keeps them as given). Colour is
converted to luminance; 16-bit frames stay 16-bit.
"""

TRACK_EXAMPLES = """\
examples:
  semlab track data/real-sem/contact_brightness_seq/ --roi 400,180,160,200 --out tracks.csv
  semlab track 'run/frame_*.png' --click 512,300 --roi-size 200 --pixel-size 6.6 --out run.csv
  semlab track stack.tif --roi 50,151,200,200 --method contour --param sigma=1.5 --out t.csv
"""

INFO_DESCRIPTION = """\
Print what semlab reads from image files: format, number of frames, size, pixel type, grey-level
range and the pixel size in nm with where it came from (FEI/Thermo Fisher or Zeiss TIFF metadata,
ImageJ calibration), or 'unknown'. FILE may be a file, a folder or a quoted glob pattern; a folder
or pattern is described as one sequence.
"""


class _CLIError(Exception):
    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises instead of exiting, so main() can return the code."""

    def exit(self, status=0, message=None):
        if message:
            sys.stderr.write(message)
        raise _ParserExit(status)


class _ParserExit(Exception):
    def __init__(self, status):
        super().__init__(status)
        self.status = status


# ----------------------------------------------------------------------------------------------
# argument parsing


def _numbers(text: str, n: int, what: str, cast=float):
    parts = [p.strip() for p in text.replace(";", ",").split(",")]
    if len(parts) != n:
        raise argparse.ArgumentTypeError(f"{what} needs {n} comma-separated numbers, got {text!r}")
    try:
        values = [cast(float(p)) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} needs numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{what} needs finite numbers, got {text!r}")
    return tuple(values)


def _roi_arg(text: str):
    x, y, w, h = _numbers(text, 4, "--roi X,Y,W,H")
    if any(v != int(v) for v in (x, y, w, h)):
        raise argparse.ArgumentTypeError(f"--roi needs whole pixels, got {text!r}")
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"--roi width and height must be positive, got {text!r}")
    return tuple(int(v) for v in (x, y, w, h))


def _click_arg(text: str):
    return _numbers(text, 2, "--click X,Y")


def _size_arg(text: str):
    t = text.lower().replace("x", ",")
    parts = t.split(",")
    if len(parts) == 1:
        parts = parts * 2
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--roi-size needs N or WxH in px, got {text!r}") from None
    if w < 8 or h < 8:
        raise argparse.ArgumentTypeError(f"--roi-size must be at least 8 px, got {text!r}")
    return (w, h)


def _pixel_size_arg(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--pixel-size needs a number of nm, got {text!r}"
        ) from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(
            f"--pixel-size must be a positive number of nm, got {text!r}"
        )
    return v


def _param_arg(text: str):
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"--param needs KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    key = key.strip()
    if not key.isidentifier():
        raise argparse.ArgumentTypeError(f"--param key {key!r} is not a parameter name")
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        parsed = {"none": None, "true": True, "false": False}.get(value.strip().lower(), value)
    return key, parsed


def _accepts(annotation, value) -> bool:
    """Whether ``value`` (parsed from JSON or text) has the type a Tracker keyword is annotated with."""
    import types
    import typing

    if annotation is typing.Any or annotation is None:
        return annotation is typing.Any or value is None
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        return any(_accepts(a, value) for a in typing.get_args(annotation))
    if annotation is type(None):
        return value is None
    if annotation is bool:
        return isinstance(value, bool)
    if annotation is int:  # 3 and 3.0 are whole numbers; True is not a count
        return (isinstance(value, int) and not isinstance(value, bool)) or (
            isinstance(value, float) and value.is_integer())
    if annotation is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if isinstance(annotation, type):
        return isinstance(value, annotation)
    return True  # an annotation this check does not know: the Tracker decides


def _type_name(annotation) -> str:
    import typing

    args = typing.get_args(annotation)
    if args:
        return " or ".join(_type_name(a) for a in args)
    return {type(None): "none"}.get(annotation, getattr(annotation, "__name__", str(annotation)))


def _check_params(method: str, params: dict) -> None:
    """Reject unknown ``--param`` keys, values of the wrong type and values the Tracker refuses (exit 2).

    Types come from the annotations of :class:`semlab.Tracker`'s keywords, so a new keyword is checked
    without a change here; the Tracker's own checks (ranges, choices) run after.
    """
    import inspect
    import typing

    from semlab.tracking import Tracker

    hints = typing.get_type_hints(Tracker.__init__)
    keywords = [n for n, p in inspect.signature(Tracker.__init__).parameters.items()
                if p.kind is inspect.Parameter.KEYWORD_ONLY]
    for key, value in params.items():
        if key not in keywords:
            raise _CLIError(EXIT_USAGE, f"--param {key}: not a tracker parameter; known: "
                            + ", ".join(keywords))
        if key in hints and not _accepts(hints[key], value):
            raise _CLIError(EXIT_USAGE, f"--param {key}={json.dumps(value)}: {key} needs "
                            f"{_type_name(hints[key])}, got {type(value).__name__}")
    try:
        Tracker(method, **params)
    except (TypeError, ValueError) as e:
        raise _CLIError(EXIT_USAGE, f"invalid tracker parameter: {e}") from None


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


def _version() -> str:
    try:
        from semlab import __version__

        return __version__
    except ImportError:  # pragma: no cover
        return "unknown"


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


# ----------------------------------------------------------------------------------------------
# helpers


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _fmt_nm(v) -> str:
    return "unknown" if v is None else f"{v:.4g} nm"


def _fmt_ps(v, source: str) -> str:
    """'97.66 nm (from ...)' or 'unknown (reason)'."""
    if v is None:
        return "unknown (" + source.removeprefix("unknown: ") + ")"
    return f"{v:.4g} nm ({source})"


def _tmp_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.partial-{os.getpid()}")


def _check_output(out: Path) -> None:
    if out.exists() and out.is_dir():
        raise _CLIError(EXIT_OUTPUT, f"{out}: is a folder; --out needs a file name")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise _CLIError(EXIT_OUTPUT, f"{out}: output folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise _CLIError(EXIT_OUTPUT, f"{out}: output folder {parent} is not writable")


def _read(inputs, pixel_size_nm=None, progress=False, order="natural"):
    from semlab.io import FrameReadError, read_frames

    try:
        seq = read_frames(inputs, pixel_size_nm=pixel_size_nm, progress=progress, order=order)
    except FrameReadError as e:
        raise _CLIError(EXIT_INPUT, str(e)) from None
    except MemoryError:
        raise _CLIError(EXIT_INPUT, f"{inputs[0]}: not enough memory to hold the frames") from None
    seq.pixel_size_source = _cli_words(seq.pixel_size_source)
    return seq


def _cli_words(text: str) -> str:
    """A library message in the words of the command line: the flag a user types, not the keyword."""
    from semlab.io import PIXEL_SIZE_HINT

    return (text.replace(PIXEL_SIZE_HINT, "pass --pixel-size NM")
            .replace("explicit pixel_size_nm", "--pixel-size"))


def _note_reordering(seq) -> None:
    """Say on stderr when natural order changed the order the files were given in."""
    if not seq.meta.get("reordered"):
        return
    given = [Path(p).name for p in seq.meta["given_order"]]
    used = [p.name for p in seq.files]
    shown = ", ".join(used[:4]) + (", ..." if len(used) > 4 else "")
    print(
        f"semlab: note: the {len(given)} input files were not in natural order (given: "
        f"{', '.join(given[:4])}{', ...' if len(given) > 4 else ''}); tracking them in natural "
        f"order: {shown} (--keep-order keeps the order given)",
        file=sys.stderr,
    )


def _check_roi(roi, shape, first: Path) -> None:
    x, y, w, h = roi
    rows, cols = shape
    if w < 8 or h < 8:
        raise _CLIError(EXIT_ROI, f"{first}: ROI {x},{y},{w},{h} is smaller than 8x8 px")
    if x < 0 or y < 0 or x + w > cols or y + h > rows:
        raise _CLIError(
            EXIT_ROI,
            f"{first}: ROI {x},{y},{w},{h} is not inside the {cols}x{rows} px frame "
            f"(needs 0 <= X, X+W <= {cols}, 0 <= Y, Y+H <= {rows})",
        )


# ----------------------------------------------------------------------------------------------
# commands


def _cmd_info(args) -> int:
    import numpy as np

    reports = []
    for item in args.files:
        seq = _read([item])
        n, h, w = seq.frames.shape
        formats = sorted(set(seq.meta["format"].values()))
        ps = seq.pixel_size_nm
        report = {
            "input": item,
            "files": len(seq.files),
            "format": ", ".join(formats),
            "vendor": seq.meta.get("vendor"),
            "frames": n,
            "width_px": w,
            "height_px": h,
            "dtype": str(seq.frames.dtype),
            "min": float(np.min(seq.frames)),
            "max": float(np.max(seq.frames)),
            "pixel_size_nm": ps,
            "pixel_size_source": seq.pixel_size_source,
            "field_of_view_um": None if ps is None else [w * ps / 1e3, h * ps / 1e3],
        }
        if seq.meta.get("converted"):
            report["converted"] = seq.meta["converted"]
        if seq.meta.get("fps"):
            report["fps"] = seq.meta["fps"]
        reports.append(report)
    if args.json:
        print(json.dumps(reports if len(reports) > 1 else reports[0], indent=1))
        return EXIT_OK
    for r in reports:
        fmt = r["format"] + (f" ({r['vendor']} metadata)" if r["vendor"] else "")
        lines = [
            r["input"],
            f"  format      {fmt}" + (f", {r['files']} files" if r["files"] > 1 else ""),
            f"  frames      {r['frames']}" + (f" at {r['fps']:.4g} fps" if r.get("fps") else ""),
            f"  size        {r['width_px']} x {r['height_px']} px (width x height)",
            f"  dtype       {r['dtype']} (grey levels {r['min']:g} to {r['max']:g})",
            f"  pixel size  {_fmt_ps(r['pixel_size_nm'], r['pixel_size_source'])}",
        ]
        if r["field_of_view_um"]:
            fw, fh = r["field_of_view_um"]
            lines.append(f"  field       {fw:.4g} x {fh:.4g} um")
        if r.get("converted"):
            lines.append(f"  converted   {r['converted']}")
        print("\n".join(lines))
    return EXIT_OK


def _cmd_track(args, argv) -> int:
    started = time.time()
    out = Path(args.out)
    sidecar = out.with_name(out.name + ".json")
    _check_output(out)
    params = dict(args.param)
    _check_params(args.method, params)  # unknown or mistyped parameters: exit 2, before reading
    seq = _read(args.inputs, pixel_size_nm=args.pixel_size, progress=not args.no_progress,
                order="given" if args.keep_order else "natural")
    _note_reordering(seq)
    roi, roi_source = _track_roi(args, seq)
    res = _track_table(_run_tracker(args, seq, roi, params), seq, sigma=args.sigma)

    def record(tmp_csv: Path) -> dict:
        return _track_record(args, argv, params, seq, res, roi, roi_source, out, tmp_csv, started)

    written = _write_atomically(res, out, sidecar, record)
    if not args.quiet:
        _print_track_summary(args, seq, res, roi, written, out, sidecar)
    return EXIT_OK


def _track_roi(args, seq) -> tuple[tuple, str]:
    """The ROI (``--roi``, or ``--click`` with ``--roi-size``) checked against the frames, and how it was given."""
    first = seq.paths[0]
    if args.click is not None:
        from semlab.roi import roi_from_click

        try:
            roi = tuple(
                int(v) for v in roi_from_click(seq.frames[0], args.click, size=args.roi_size)
            )
        except ValueError as e:
            raise _CLIError(
                EXIT_ROI, f"{first}: --click {args.click[0]:g},{args.click[1]:g}: {e}"
            ) from None
        roi_source = f"--click {args.click[0]:g},{args.click[1]:g} with --roi-size {args.roi_size[0]}x{args.roi_size[1]}"
    else:
        roi = args.roi
        roi_source = "--roi"
    _check_roi(roi, seq.frames.shape[1:], first)
    return roi, roi_source


def _run_tracker(args, seq, roi, params):
    from semlab.tracking import track

    try:
        df = track(seq.frames, roi, method=args.method, progress=not args.no_progress, **params)
    except (TypeError, ValueError) as e:
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise _CLIError(
            EXIT_TRACKING, f"{seq.paths[0]}: tracking cannot start in ROI {roi}: {msg}"
        ) from None
    if len(df) != len(seq):
        raise _CLIError(EXIT_INTERNAL, f"tracker returned {len(df)} rows for {len(seq)} frames")
    return df


def _track_table(df, seq, *, sigma=False):
    """The CSV's table: the track in px and nm, and each frame's file (and, with ``sigma``, each
    frame's standard uncertainty in px)."""
    import numpy as np
    import pandas as pd

    scale = np.nan if seq.pixel_size_nm is None else seq.pixel_size_nm
    table = pd.DataFrame(
        {
            "frame": df["frame"].astype(int).to_numpy(),
            "x": df["x"].astype(float).to_numpy(),
            "y": df["y"].astype(float).to_numpy(),
            "x_nm": df["x"].astype(float).to_numpy() * scale,
            "y_nm": df["y"].astype(float).to_numpy() * scale,
            "score": df["score"].astype(float).to_numpy(),
            "ok": df["ok"].astype(bool).to_numpy(),
            "file": [p.name for p in seq.paths],
        }
    )
    if sigma:
        for axis in ("sigma_x", "sigma_y"):
            table[axis] = df[axis].astype(float).to_numpy()
    return table


def _track_record(args, argv, params, seq, res, roi, roi_source, out, tmp_csv, started) -> dict:
    """The JSON sidecar: how the CSV was made (command, parameters, inputs and their hashes)."""
    shape = seq.frames.shape[1:]
    from semlab.roi import roi_centre

    n_ok = int(res["ok"].sum())
    return {
        "semlab_version": _version(),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": ["semlab", *argv],
        "cwd": os.getcwd(),
        "method": args.method,
        "params": params,
        "input_order": "given" if args.keep_order else "natural",
        "roi": list(roi),
        "roi_source": roi_source,
        "roi_centre_px": list(roi_centre(roi)),
        "click": None if args.click is None else list(args.click),
        "pixel_size_nm": seq.pixel_size_nm,
        "pixel_size_source": seq.pixel_size_source,
        "n_frames": len(res),
        "n_ok": n_ok,
        "n_lost": len(res) - n_ok,
        "frame_size_px": [int(shape[1]), int(shape[0])],
        "dtype": str(seq.frames.dtype),
        "inputs": [
            {
                "path": str(Path(f).resolve()),
                "sha256": _sha256(f),
                "bytes": Path(f).stat().st_size,
                "frames": int(sum(1 for p in seq.paths if p == f)),
            }
            for f in seq.files
        ],
        "output": {
            "csv": out.name,
            "sha256": _sha256(tmp_csv),
            "columns": list(res.columns),
            "units": {"x": "px", "y": "px", "x_nm": "nm", "y_nm": "nm", "score": "1"},
        },
        "conventions": "x, y: where the ROI centre point of frame 0 has moved to; pixel "
        "centres at integer coordinates, x right, y down; x_nm = x * pixel_size_nm",
        "environment": describe_environment(),
        "elapsed_s": round(time.time() - started, 3),
    }


def _write_atomically(res, out: Path, sidecar: Path, make_record) -> dict:
    """Write the CSV and its sidecar (``make_record(csv written so far)``) through temporary files,
    so that a failure leaves neither half-written; returns the record."""
    tmp_csv, tmp_json = _tmp_name(out), _tmp_name(sidecar)
    try:
        try:
            res.to_csv(tmp_csv, index=False, float_format="%.6f", lineterminator="\n")
            record = make_record(tmp_csv)
            tmp_json.write_text(json.dumps(record, indent=1, default=str) + "\n")
            os.replace(tmp_json, sidecar)
            os.replace(tmp_csv, out)
        except OSError as e:
            raise _CLIError(
                EXIT_OUTPUT, f"{out}: cannot write output ({e.strerror or e})"
            ) from None
    finally:
        for tmp in (tmp_csv, tmp_json):
            if tmp.exists():
                tmp.unlink()
    return record


def _print_track_summary(args, seq, res, roi, record, out, sidecar) -> None:
    ps = seq.pixel_size_nm
    ok = res["ok"]
    n_ok = int(ok.sum())
    print(
        f"tracked {len(res)} frames from {len(seq.files)} file(s) with method {args.method!r}, ROI {roi}"
    )
    print(f"pixel size: {_fmt_ps(ps, seq.pixel_size_source)}")
    if n_ok:
        last = res[ok].iloc[-1]
        dx, dy = last.x - record["roi_centre_px"][0], last.y - record["roi_centre_px"][1]
        line = f"ok in {n_ok}/{len(res)} frames; last ok frame {int(last.frame)}: x={last.x:.3f}, y={last.y:.3f} px"
        line += f", displacement ({dx:+.3f}, {dy:+.3f}) px"
        if ps is not None:
            line += f" = ({dx * ps:+.1f}, {dy * ps:+.1f}) nm"
        print(line)
    if n_ok < len(res):
        lost = res.loc[~ok, "frame"].tolist()
        shown = ", ".join(map(str, lost[:10])) + (" ..." if len(lost) > 10 else "")
        print(f"target lost (ok=False) in {len(lost)} frame(s): {shown}")
    print(f"wrote {out} and {sidecar.name}")


# ----------------------------------------------------------------------------------------------
# semlab evaluate: the scene-family corpus (issue 13)

EVALUATE_DESCRIPTION = """\
Run trackers on the scene-family corpus (semlab.evaluation) and write one CSV row per family x seed
x tracker: family, seed, split, tracker, rmse_px, crb_px, lost_fraction, silent_fraction,
ms_per_frame, and more (n_frames, rmse_over_crb, std_px, std_over_crb, median/p90/max_err_px,
flagged_fraction, coverage95, crb_x_px, crb_y_px, n_visible, error). Prints the summary per family
(median, p90 and worst RMSE / Cramer-Rao bound, lost and silent rates, ms/frame) with the trackers
side by side.

Seeds: the test seeds 0-9 by default (report these); --split dev selects the dev seeds 100-119
(tune on these). Tasks (one per family x seed) run on a dask LocalCluster on this machine, or on an
existing cluster with --scheduler tcp://HOST:PORT ('dask scheduler' + 'dask worker', semlab
installed on the workers), or in this process with --scheduler inline.

Next to OUT the command writes OUT.json: semlab version, command line, families with their
parameter ranges, seeds, trackers and parameters, scheduler, the parameters drawn for every
sequence, times, and the SHA-256 of the CSV. Everything is written under temporary names and
renamed when complete: an interrupted run leaves no output that looks complete.
"""

EVALUATE_EXAMPLES = f"""\
examples:
  semlab evaluate --out corpus.csv                                   # all families, test seeds, 5 trackers
  semlab evaluate --families still,semi_real --seeds 0-1 --out small.csv
  semlab evaluate --split dev --trackers semlab --param huber=3 --out dev.csv
  semlab evaluate --scheduler tcp://127.0.0.1:8786 --out corpus.csv --figure corpus.png
exit codes: {EXIT_OK} success, {EXIT_USAGE} usage (unknown family/tracker, bad seeds or --param),
  {EXIT_OUTPUT} output not writable, {EXIT_SCHEDULER} dask scheduler unreachable, {EXIT_INTERRUPTED} interrupted
"""


def _seeds_arg(text: str) -> list[int]:
    from semlab.evaluation.runner import parse_seeds

    try:
        return parse_seeds(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"--seeds: {e}") from None


def _add_evaluate_parser(sub, fmt) -> None:
    e = sub.add_parser("evaluate", help=COMMAND_HELP["evaluate"],
                       description=EVALUATE_DESCRIPTION, epilog=EVALUATE_EXAMPLES, formatter_class=fmt)
    e.add_argument("--families", metavar="NAME,...", help="families (default: all; see semlab.evaluation.FAMILIES)")
    seeds = e.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=_seeds_arg, metavar="0-9", help="seeds, e.g. 0-9 or 0,3,5-8 (default: test)")
    seeds.add_argument("--split", choices=("test", "dev"), help="the split's seeds: test 0-9, dev 100-119")
    e.add_argument("--trackers", metavar="NAME,...",
                   help="trackers (default semlab,ncc,sqdiff,ecc,phasecorr; also 'paper')")
    e.add_argument("--param", type=_param_arg, action="append", default=[], metavar="KEY=VALUE",
                   help="a semlab.Tracker parameter for the 'semlab' tracker (repeatable)")
    e.add_argument("--scheduler", metavar="ADDRESS",
                   help="tcp://HOST:PORT of a running dask scheduler, or 'inline' (default: a LocalCluster)")
    e.add_argument("--workers", type=int, metavar="N", help="LocalCluster workers (default: the cores, at most 2)")
    e.add_argument("--out", "-o", required=True, metavar="OUT.csv", help="output CSV; OUT.csv.json beside it")
    e.add_argument("--per-frame", metavar="FRAMES.csv", help="also write the per-frame errors")
    e.add_argument("--summary", metavar="SUMMARY.csv", help="also write the per-family summary")
    e.add_argument("--figure", metavar="FIG.png", help="also save the figure (RMSE / bound per family)")
    e.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    e.add_argument("--quiet", "-q", action="store_true", help="no summary on stdout")


def _cmd_evaluate(args, argv) -> int:
    started = time.time()
    out = Path(args.out)
    sidecar = out.with_name(out.name + ".json")
    extras = [Path(p) for p in (args.per_frame, args.summary, args.figure) if p]
    for path in (out, *extras):
        _check_output(path)
    params = dict(args.param)

    from semlab import evaluation as ev
    from semlab.evaluation.runner import resolve_families, resolve_seeds
    from semlab.evaluation.trackers import resolve_trackers

    try:  # every name and parameter checked before any work
        families = resolve_families(args.families)
        seeds = resolve_seeds(args.seeds, args.split)
        resolve_trackers(args.trackers, params)
    except ValueError as e:
        raise _CLIError(EXIT_USAGE, str(e)) from None
    if args.workers is not None and args.workers < 1:
        raise _CLIError(EXIT_USAGE, f"--workers must be >= 1, got {args.workers}")
    try:
        result = ev.evaluate(families, seeds, args.trackers, params=params, scheduler=args.scheduler,
                             n_workers=args.workers, per_frame=bool(args.per_frame), progress=not args.no_progress)
        df, frames = result if args.per_frame else (result, None)
    except ev.SchedulerUnreachable as e:
        raise _CLIError(EXIT_SCHEDULER, str(e)) from None
    summary = ev.summarise(df)

    temps = []  # (temporary, final), the CSV last: a complete CSV means everything else is there
    try:
        try:
            if args.per_frame:
                temps.append((_tmp_name(Path(args.per_frame)), Path(args.per_frame)))
                frames.to_csv(temps[-1][0], index=False, float_format="%.6g", lineterminator="\n")
            if args.summary:
                temps.append((_tmp_name(Path(args.summary)), Path(args.summary)))
                summary.to_csv(temps[-1][0], index=False, float_format="%.6g", lineterminator="\n")
            if args.figure:
                temps.append((_tmp_name(Path(args.figure)), Path(args.figure)))
                _save_corpus_figure(summary, temps[-1][0], Path(args.figure).suffix)
            tmp_csv, tmp_json = _tmp_name(out), _tmp_name(sidecar)
            df.to_csv(tmp_csv, index=False, float_format="%.6g", lineterminator="\n")
            record = {
                "semlab_version": _version(),
                "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
                "command": ["semlab", *argv],
                "cwd": os.getcwd(),
                "families": {f: {"title": ev.FAMILIES[f].title,
                                 "ranges": {k: str(v) for k, v in ev.FAMILIES[f].ranges.items()}} for f in families},
                "seeds": seeds,
                "splits": {str(s): ev.split_of(s) for s in seeds},
                "trackers": list(dict.fromkeys(df["tracker"])),
                "params": params,
                "scheduler": df.attrs.get("scheduler"),
                "sequences": df.attrs.get("sequences"),
                "output": {"csv": out.name, "sha256": _sha256(tmp_csv), "columns": list(df.columns), "rows": len(df)},
                "environment": {**describe_environment(), **_dask_versions()},
                "elapsed_s": round(time.time() - started, 3),
            }
            tmp_json.write_text(json.dumps(record, indent=1, default=str) + "\n")
            temps += [(tmp_json, sidecar), (tmp_csv, out)]
            for tmp, final in temps:
                os.replace(tmp, final)
        except OSError as e:
            raise _CLIError(EXIT_OUTPUT, f"{out}: cannot write output ({e.strerror or e})") from None
    finally:
        for tmp, _ in temps:
            if tmp.exists():
                tmp.unlink()
        for tmp in (_tmp_name(out), _tmp_name(sidecar)):
            if tmp.exists():
                tmp.unlink()

    if not args.quiet:
        print(ev.summary_markdown(summary))
        print(f"\n{len(df)} rows ({len(families)} families x {len(seeds)} seeds x "
              f"{df['tracker'].nunique()} trackers) on {df.attrs.get('scheduler')} in {time.time() - started:.0f} s; "
              f"wrote {out} and {sidecar.name}")
    return EXIT_OK


def _dask_versions() -> dict:
    import dask
    import distributed

    return {"dask": dask.__version__, "distributed": distributed.__version__}


def _save_corpus_figure(summary, path: Path, suffix: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from semlab.evaluation.figures import plot_corpus

    fig, ax = plt.subplots(figsize=(11, 4.5), layout="constrained")
    plot_corpus(summary, ax)
    fig.savefig(path, format=(suffix.lstrip(".") or "png"), dpi=120)
    plt.close(fig)


# ----------------------------------------------------------------------------------------------
# entry point


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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
