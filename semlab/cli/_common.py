"""What every ``semlab`` command shares: exit codes and their help text, the error a command raises,
the parser classes, the option parsers, reading the input, and writing output through temporary
files."""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
from pathlib import Path

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


# ----------------------------------------------------------------------------------------------
# helpers


def _version() -> str:
    try:
        from semlab import __version__

        return __version__
    except ImportError:  # pragma: no cover
        return "unknown"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


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
