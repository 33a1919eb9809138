"""One tracker on one sequence: per-frame errors and the corpus's row of figures.

Definitions (2-D as :mod:`semlab.metrics`; errors are displacements from frame 0, which is the
origin of both the track and the truth and is left out of every statistic):

- ``rmse_px``: ``sqrt(mean(ex² + ey²))`` over the frames where the tip is visible and the
  tracker gave a position; ``std_px``: ``sqrt(var(ex) + var(ey))`` over the same frames (the
  paper's repeatability on a still probe); ``median_err_px``, ``p90_err_px``, ``max_err_px``:
  of ``|e|`` over the same frames;
- ``crb_px``: ``sqrt(crb_x² + crb_y²)`` of the sequence's single-frame bound (``seq.crb``);
  ``rmse_over_crb``, ``std_over_crb``;
- ``lost_fraction``: of the frames where the tip is visible, those flagged (``ok`` False, or no
  position) or more than :data:`LOST_PX` off;
- ``silent_fraction``: of all frames, those more than :data:`SILENT_PX` off while ``ok`` is True
  (a wrong answer that says it is right: the worst outcome for a servo);
- ``flagged_fraction``: of the visible frames, those with ``ok`` False;
- ``coverage95``: of the visible frames with ``ok`` and a reported ``sigma_x, sigma_y`` (read
  from the tracker's results when they have them), those inside their own 95 % ellipse
  ``(ex/σx)² + (ey/σy)² <= χ²₂(0.95)``; NaN when the tracker reports no sigmas;
- ``ms_per_frame``: mean wall time of ``update`` (frame 0's ``init`` excluded);
- ``bias_px``: ``|mean(e)|`` over the frames of ``rmse_px``, the part of the error every frame
  shares (an origin off by that much: frame 0's own registration);
- ``held_fraction``: ``h`` of the least-squares fit ``e = b − h·t`` over the same frames, ``t`` the
  probe's true displacement: the fraction of its own motion the track did not follow (0: followed,
  1: held where it started, by something that does not move with the probe), apart from a constant
  ``b``; NaN when the probe moved less than :data:`HELD_MIN_MOTION_PX` (rms about its mean) or the
  truth is not known.

The per-frame table (:data:`PER_FRAME_COLUMNS`) ends with each frame's ``reason``: why it was flagged
(the tracker's ``TrackResult.reason``; a refused start's or a crashed ``update``'s message), '' for an
ok frame, for frame 0 and for a tracker that says nothing.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd
from scipy.stats import chi2

from semlab.metrics import tracking_errors

__all__ = ["COLUMNS", "HELD_MIN_MOTION_PX", "LOST_PX", "PER_FRAME_COLUMNS", "SILENT_PX", "frame_errors", "held_fraction",
           "run_tracker", "score"]

#: An error above this many px counts as lost (the issue's loss criterion).
LOST_PX = 2.0
#: An ok frame further off than this is a silent error.
SILENT_PX = 1.0
#: ``held_fraction`` needs the probe to move at least this much (px, rms about its mean position).
HELD_MIN_MOTION_PX = 1.0
#: 95 % quantile of the chi-square distribution with 2 degrees of freedom (a 2-D error ellipse).
CHI2_95_2D = float(chi2.ppf(0.95, 2))

#: The result columns, the contract first.
COLUMNS = ["family", "seed", "split", "tracker", "rmse_px", "crb_px", "lost_fraction", "silent_fraction",
           "ms_per_frame", "n_frames", "rmse_over_crb", "std_px", "std_over_crb", "median_err_px",
           "p90_err_px", "max_err_px", "flagged_fraction", "coverage95", "crb_x_px", "crb_y_px",
           "n_visible", "bias_px", "held_fraction", "error"]
#: The per-frame columns, the contract first; ``reason`` last (see the module docstring).
PER_FRAME_COLUMNS = ["family", "seed", "tracker", "frame", "ex", "ey", "ok", "sigma_x", "sigma_y", "visible",
                     "reason"]
#: :func:`run_tracker`'s track.
_TRACK_COLUMNS = ["frame", "x", "y", "ok", "sigma_x", "sigma_y", "reason"]


def _sigma(result, name: str) -> float:
    v = getattr(result, name, float("nan"))
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _reason(result) -> str:
    """Why ``result`` is flagged: its ``reason`` ('' when it is ok or gives none)."""
    if bool(result.ok):
        return ""
    v = getattr(result, "reason", "")
    return "" if v is None else str(v)


def run_tracker(factory, frames, roi) -> tuple[pd.DataFrame, float, str]:
    """Run a fresh tracker from ``factory`` over ``frames`` from ``roi``.

    Returns
    -------
    (track, ms_per_frame, error)
        ``track``: ``frame, x, y, ok, sigma_x, sigma_y, reason`` (``reason``: why the frame is
        flagged, '' for an ok frame and frame 0); the mean ``update`` time in ms; and '' or why the
        run was cut short. A tracker that refuses to start (``init`` raises
        ``ValueError``/``TypeError``) or crashes there (any other exception) gives every frame
        ``ok=False`` with the message as its reason;
        one that raises in ``update`` gets that frame ``ok=False`` with the exception as its reason,
        and the first such message is kept (a crash is a bug in the tracker, and the corpus reports
        it rather than dying on it).
    """
    nan = float("nan")
    n = len(frames)
    rows = []
    error = ""
    try:
        tracker = factory()
        first = tracker.init(frames[0], roi)
    except Exception as e:  # noqa: BLE001 - a refusal (ValueError, TypeError) or a crash: the rows say which
        error = (f"init refused: {type(e).__name__}: {e}" if isinstance(e, (ValueError, TypeError))
                 else f"init raised: {type(e).__name__}: {e}")
        rows = [(k, nan, nan, False, nan, nan, error) for k in range(n)]
        return pd.DataFrame(rows, columns=_TRACK_COLUMNS), nan, error
    # frame 0 is the origin: nothing to flag
    rows.append((0, float(first.x), float(first.y), bool(first.ok), _sigma(first, "sigma_x"), _sigma(first, "sigma_y"),
                 ""))
    elapsed = 0.0
    for k in range(1, n):
        t0 = time.perf_counter()
        try:
            r = tracker.update(frames[k])
        except Exception as e:  # noqa: BLE001 - reported in the row, see the docstring
            elapsed += time.perf_counter() - t0
            crash = f"{type(e).__name__}: {e}"
            if not error:
                error = f"update raised at frame {k}: {crash}"
            rows.append((k, nan, nan, False, nan, nan, crash))
            continue
        elapsed += time.perf_counter() - t0
        rows.append((k, float(r.x), float(r.y), bool(r.ok), _sigma(r, "sigma_x"), _sigma(r, "sigma_y"), _reason(r)))
    ms = elapsed * 1e3 / max(n - 1, 1)
    return pd.DataFrame(rows, columns=_TRACK_COLUMNS), ms, error


def frame_errors(track: pd.DataFrame, truth: pd.DataFrame, roi) -> pd.DataFrame:
    """``frame, ex, ey, ok, sigma_x, sigma_y, visible, reason, true_dx, true_dy`` of one run
    (:func:`semlab.metrics.tracking_errors`; ``reason``: the track's, '' where it has none; ``true_dx,
    true_dy``: the truth's displacement from frame 0)."""
    e = tracking_errors(track[["frame", "x", "y", "ok"]], truth, roi)
    out = e[["frame", "ex", "ey", "ok"]].copy()
    out["sigma_x"] = track["sigma_x"].to_numpy(float)
    out["sigma_y"] = track["sigma_y"].to_numpy(float)
    out["visible"] = e["visible"].to_numpy(bool)
    out["reason"] = track["reason"].fillna("").astype(str).to_numpy() if "reason" in track else ""
    true = truth.set_index("frame").loc[out["frame"], ["x", "y"]].to_numpy(float)
    first = truth.set_index("frame").loc[0, ["x", "y"]].to_numpy(float)
    out["true_dx"], out["true_dy"] = true[:, 0] - first[0], true[:, 1] - first[1]
    return out


def held_fraction(ex, ey, tx, ty) -> float:
    """``h`` of the least-squares fit ``e = b − h·t`` (``b`` a constant 2-vector): the fraction of
    the true displacement ``t`` the track did not follow; NaN when ``t`` spreads less than
    :data:`HELD_MIN_MOTION_PX` (rms about its mean)."""
    ex, ey, tx, ty = (np.asarray(v, float) for v in (ex, ey, tx, ty))
    if ex.size < 2:
        return float("nan")
    cx, cy = tx - tx.mean(), ty - ty.mean()
    spread = float(np.sum(cx * cx + cy * cy))
    if spread < ex.size * HELD_MIN_MOTION_PX**2:
        return float("nan")
    return float(-np.sum((ex - ex.mean()) * cx + (ey - ey.mean()) * cy) / spread)


def score(errors: pd.DataFrame, crb, ms_per_frame: float) -> dict:
    """The row of figures (see the module docstring) from :func:`frame_errors`' output."""
    nan = float("nan")
    e = errors[errors["frame"] != 0]
    ex, ey = e["ex"].to_numpy(float), e["ey"].to_numpy(float)
    err = np.hypot(ex, ey)
    ok = e["ok"].to_numpy(bool)
    vis = e["visible"].to_numpy(bool)
    have = np.isfinite(err)
    used = vis & have
    eu, ex_u, ey_u = err[used], ex[used], ey[used]
    crb_x, crb_y = (float(v) for v in crb)
    crb_px = math.hypot(crb_x, crb_y)
    rmse = float(np.sqrt(np.mean(eu**2))) if eu.size else nan
    std = float(math.hypot(np.std(ex_u), np.std(ey_u))) if eu.size > 1 else nan
    n_vis = int(vis.sum())
    lost = (~ok | ~have | (np.where(have, err, 0.0) > LOST_PX))[vis]
    silent = ok & have & (np.where(have, err, 0.0) > SILENT_PX)
    sx, sy = e["sigma_x"].to_numpy(float), e["sigma_y"].to_numpy(float)
    judged = used & ok & np.isfinite(sx) & np.isfinite(sy) & (sx > 0) & (sy > 0)
    if judged.any():
        d2 = (ex[judged] / sx[judged]) ** 2 + (ey[judged] / sy[judged]) ** 2
        coverage = float(np.mean(d2 <= CHI2_95_2D))
    else:
        coverage = nan
    return {
        "rmse_px": rmse,
        "crb_px": crb_px,
        "lost_fraction": float(np.mean(lost)) if n_vis else nan,
        "silent_fraction": float(np.mean(silent)) if len(e) else nan,
        "ms_per_frame": float(ms_per_frame),
        "n_frames": len(errors),
        "rmse_over_crb": rmse / crb_px if crb_px > 0 else nan,
        "std_px": std,
        "std_over_crb": std / crb_px if crb_px > 0 else nan,
        "median_err_px": float(np.median(eu)) if eu.size else nan,
        "p90_err_px": float(np.percentile(eu, 90)) if eu.size else nan,
        "max_err_px": float(np.max(eu)) if eu.size else nan,
        "flagged_fraction": float(np.mean(~ok[vis])) if n_vis else nan,
        "coverage95": coverage,
        "crb_x_px": crb_x,
        "crb_y_px": crb_y,
        "n_visible": n_vis,
        "bias_px": float(math.hypot(np.mean(ex_u), np.mean(ey_u))) if eu.size else nan,
        "held_fraction": (held_fraction(ex_u, ey_u, e["true_dx"].to_numpy(float)[used],
                                        e["true_dy"].to_numpy(float)[used]) if "true_dx" in e else nan),
    }
