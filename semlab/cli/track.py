"""``semlab track``: track a target through a recorded sequence and write the CSV and its sidecar;
the checks of ``--param`` values and of the ROI."""

from __future__ import annotations

import json
import os
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from semlab.cli._common import (
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_ROI,
    EXIT_TRACKING,
    EXIT_USAGE,
    _check_output,
    _CLIError,
    _fmt_ps,
    _read,
    _sha256,
    _version,
    _write_atomically,
)
from semlab.environment import describe as describe_environment

TRACK_DESCRIPTION = """\
Track a target (a probe tip) through a recorded sequence of SEM frames and write one CSV row per
frame: frame, x, y, x_nm, y_nm, score, ok, file.

x, y (px) are where the ROI's centre point, (x + (w-1)/2, y + (h-1)/2) in frame 0, has moved to in
each frame; pixel centres are at integer coordinates, x to the right, y down. x_nm, y_nm = x, y times
the pixel size; they are empty when the pixel size is unknown (PNG/JPEG/video, TIFFs without vendor
metadata) and --pixel-size is not given. score is the tracker's match quality in [0, 1]; ok=False
(with empty x, y) marks frames where the target was lost or its answer was too uncertain to trust
(semlab's tracker, the default). --sigma adds sigma_x, sigma_y: each frame's standard uncertainty
(px) as the tracker estimates it. --reason adds reason, last: why a frame is not ok.

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
    res = _track_table(_run_tracker(args, seq, roi, params), seq, sigma=args.sigma, reason=args.reason)

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
    from semlab.tracking.run import track, track_with_reasons

    run = track_with_reasons if args.reason else track
    try:
        df = run(seq.frames, roi, method=args.method, progress=not args.no_progress, **params)
    except (TypeError, ValueError) as e:
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise _CLIError(
            EXIT_TRACKING, f"{seq.paths[0]}: tracking cannot start in ROI {roi}: {msg}"
        ) from None
    if len(df) != len(seq):
        raise _CLIError(EXIT_INTERNAL, f"tracker returned {len(df)} rows for {len(seq)} frames")
    return df


def _track_table(df, seq, *, sigma=False, reason=False):
    """The CSV's table: the track in px and nm, and each frame's file (and, with ``sigma``, each
    frame's standard uncertainty in px; with ``reason``, last, why a frame is not ok)."""
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
    if reason:
        table["reason"] = df["reason"].astype(str).to_numpy()
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
