"""Tracking error against ground truth (the paper's "Tracking Performance" figures, and more).

The tracker reports where the ROI's centre point has moved to; the simulator reports where the
probe tip is. Both are compared as displacements from frame 0::

    error = (x_track − roi_centre_x) − (x_true − x_true[frame 0])

so the choice of the ROI (which need not be centred on the tip) does not matter.

Definitions used throughout semlab (2-D unless the name ends in ``_x``/``_y``):

- ``rmse``: ``sqrt(mean(ex² + ey²))`` over the frames with a position;
- ``std``: ``sqrt(var(ex) + var(ey))`` — the repeatability, the paper's "standard deviation";
- ``mean_error``: ``|mean(e)|``, the length of the mean error vector — the paper's "average error";
- ``loss_rate``: fraction of the frames where the target is visible but the tracker gave no
  position or was more than ``loss_px`` (2 px) off;
- ``crb``: ``sqrt(σx² + σy²)`` of the Cramér–Rao bound ``(σx, σy)`` of one frame's translation
  estimate, comparable with ``rmse`` and ``std``.

Frame 0 defines the origin of both displacements (its error is 0 by construction) and is left
out of the statistics.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from .roi import roi_centre

__all__ = ["LOSS_PX", "run_tracker", "summarise_errors", "summarize_errors", "tracking_errors"]

#: An error above this many px counts as a lost target (the issue's loss criterion).
LOSS_PX = 2.0


def tracking_errors(result: pd.DataFrame, truth: pd.DataFrame, roi) -> pd.DataFrame:
    """Per-frame displacement error of a tracking result against ground truth.

    Parameters
    ----------
    result : pandas.DataFrame
        ``frame, x, y, ok`` as :func:`semlab.tracking.track` returns it (one target).
    truth : pandas.DataFrame
        ``frame, x, y`` (and optionally ``visible``) of the true tip, e.g. ``seq.truth``.
    roi : (x, y, w, h)
        The ROI given to the tracker in frame 0; its centre point is the tracker's origin.

    Returns
    -------
    pandas.DataFrame
        ``frame, ex, ey, error, ok, visible``: the error components and length in px (NaN
        where the tracker gave no position).

    Raises
    ------
    ValueError
        If the frames of ``result`` and ``truth`` do not match or frame 0 is missing.
    """
    res = result.set_index("frame").sort_index()
    tru = truth.set_index("frame").sort_index()
    if 0 not in res.index or 0 not in tru.index:
        raise ValueError("both the result and the truth need frame 0 (the origin of displacements)")
    missing = res.index.difference(tru.index)
    if len(missing):
        raise ValueError(f"no ground truth for frames {list(missing[:5])}")
    tru = tru.loc[res.index]
    cx, cy = roi_centre(roi)
    x0, y0 = float(tru.loc[0, "x"]), float(tru.loc[0, "y"])
    ex = (res["x"].to_numpy(float) - cx) - (tru["x"].to_numpy(float) - x0)
    ey = (res["y"].to_numpy(float) - cy) - (tru["y"].to_numpy(float) - y0)
    visible = tru["visible"].to_numpy(bool) if "visible" in tru else np.ones(len(tru), bool)
    ok = res["ok"].to_numpy(bool) if "ok" in res else np.isfinite(ex)
    return pd.DataFrame({"frame": res.index.to_numpy(), "ex": ex, "ey": ey, "error": np.hypot(ex, ey),
                         "ok": ok, "visible": visible})


def _error_statistics(errors: pd.DataFrame, crb, loss_px: float) -> tuple[dict, tuple[float, float]]:
    """The statistics of :func:`summarize_errors`, and the mean error's components ``(x, y)``."""
    e = errors[(errors["frame"] != 0) & errors["visible"].astype(bool)]
    n = len(e)
    have = e[np.isfinite(e["ex"]) & np.isfinite(e["ey"])]
    ex, ey = have["ex"].to_numpy(float), have["ey"].to_numpy(float)
    nan = float("nan")

    def rms(a):
        return float(np.sqrt(np.mean(a * a))) if a.size else nan

    def sd(a):
        return float(np.std(a)) if a.size > 1 else nan

    lost = (~np.isfinite(e["error"].to_numpy(float))) | (e["error"].to_numpy(float) > loss_px)
    out = {
        "n": n,
        "rmse": math.hypot(rms(ex), rms(ey)) if ex.size else nan,
        "rmse_x": rms(ex),
        "rmse_y": rms(ey),
        "std": math.hypot(sd(ex), sd(ey)) if ex.size > 1 else nan,
        "std_x": sd(ex),
        "std_y": sd(ey),
        "mean_error": math.hypot(float(np.mean(ex)), float(np.mean(ey))) if ex.size else nan,
        "max_error": float(np.max(np.hypot(ex, ey))) if ex.size else nan,
        "loss_rate": float(np.mean(lost)) if n else nan,
        "flagged_rate": float(np.mean(~e["ok"].to_numpy(bool))) if n else nan,
    }
    if crb is not None:
        sx, sy = (float(v) for v in crb)
        c = math.hypot(sx, sy)
        out.update(crb=c, crb_x=sx, crb_y=sy, rmse_over_crb=out["rmse"] / c, std_over_crb=out["std"] / c)
    means = (float(np.mean(ex)), float(np.mean(ey))) if ex.size else (nan, nan)
    return out, means


def summarize_errors(errors: pd.DataFrame, crb=None, *, loss_px: float = LOSS_PX) -> dict:
    """RMSE, standard deviation, mean error and loss rate of :func:`tracking_errors`' output.

    Parameters
    ----------
    errors : pandas.DataFrame
        From :func:`tracking_errors`.
    crb : (float, float) or None
        The Cramér–Rao bound ``(σx, σy)`` px of the sequence (``seq.crb``).
    loss_px : float
        Error above which a frame counts as lost.

    Returns
    -------
    dict
        ``n, rmse, rmse_x, rmse_y, std, std_x, std_y, mean_error, max_error, loss_rate,
        flagged_rate`` and, with ``crb``, ``crb, crb_x, crb_y, rmse_over_crb, std_over_crb``.
        ``flagged_rate`` is the fraction of frames with ``ok=False`` (whatever the error).

    Examples
    --------
    >>> import pandas as pd
    >>> e = pd.DataFrame({"frame": [0, 1, 2], "ex": [0.0, 0.3, -0.1], "ey": [0.0, 0.0, 0.0],
    ...                   "error": [0.0, 0.3, 0.1], "ok": True, "visible": True})
    >>> round(summarize_errors(e)["rmse"], 4)
    0.2236
    """
    return _error_statistics(errors, crb, loss_px)[0]


def summarise_errors(errors: pd.DataFrame, crb=None, *, loss_px: float = LOSS_PX) -> dict:
    """:func:`summarize_errors` with every length suffixed ``_px`` (the benchmark tables' columns),
    and the mean error's components.

    Returns
    -------
    dict
        ``n, rmse_px, rmse_x_px, rmse_y_px, std_px, std_x_px, std_y_px, mean_err_px,
        mean_err_x_px, mean_err_y_px, max_err_px, loss_rate, flagged_rate`` (and the CRB entries).
    """
    s, (mean_x, mean_y) = _error_statistics(errors, crb, loss_px)
    out = {"n": s["n"]}
    for k in ("rmse", "rmse_x", "rmse_y", "std", "std_x", "std_y"):
        out[f"{k}_px"] = s[k]
    out["mean_err_px"] = s["mean_error"]
    out["mean_err_x_px"], out["mean_err_y_px"] = mean_x, mean_y
    out["max_err_px"] = s["max_error"]
    out["loss_rate"] = s["loss_rate"]
    out["flagged_rate"] = s["flagged_rate"]
    for k in ("crb", "crb_x", "crb_y"):
        if k in s:
            out[f"{k}_px"] = s[k]
    return out


#: run_tracker's columns: track()'s, and why a frame is flagged (notebooks 02 and 06 count "too uncertain").
_RUN_COLUMNS = ["frame", "x", "y", "score", "ok", "reason", "sigma_x", "sigma_y"]


def run_tracker(tracker, frames, roi) -> tuple[pd.DataFrame, float]:
    """Run any ``init/update`` tracker over ``frames``; return its track and ms per ``update``.

    Parameters
    ----------
    tracker : VisualTracker
        e.g. :class:`semlab.tracking.Tracker` or a :mod:`semlab.peers` tracker (``update`` returns a
        :class:`~semlab.tracking.TrackResult`); the frame loop is :func:`semlab.tracking.track`'s.
    frames : (N, H, W) ndarray or sequence of (H, W) arrays
    roi : (x, y, w, h)

    Returns
    -------
    (pandas.DataFrame, float)
        ``frame, x, y, score, ok, reason, sigma_x, sigma_y`` per frame (``reason``: why ``ok`` is
        False, e.g. "too uncertain ..."; ``sigma_x, sigma_y``: the tracker's own 1-σ uncertainty, NaN
        for a tracker that reports none), and the mean wall time of ``update`` in ms. When the
        tracker refuses to start (``init`` raises ``ValueError``, e.g. no object above the noise in
        the ROI), every row is ``ok=False`` with NaN position, the reason is kept in
        ``df.attrs["init_error"]`` and the time is NaN: in a sweep a refusal counts as a loss.
    """
    from .tracking.run import follow_frames, start_trackers

    try:
        rows = start_trackers([tracker], frames[0], [roi])
    except ValueError as err:
        nan = float("nan")
        df = pd.DataFrame([(i, nan, nan, 0.0, False, f"refused: {err}", nan, nan) for i in range(len(frames))],
                          columns=_RUN_COLUMNS)
        df.attrs["init_error"] = str(err)
        return df, nan
    t0 = time.perf_counter()
    rows += follow_frames([tracker], (frames[i] for i in range(1, len(frames))))
    ms = (time.perf_counter() - t0) * 1e3 / max(len(frames) - 1, 1)
    return pd.DataFrame([(i, r.x, r.y, r.score, r.ok, getattr(r, "reason", ""), getattr(r, "sigma_x", math.nan),
                          getattr(r, "sigma_y", math.nan)) for i, _, r in rows], columns=_RUN_COLUMNS), ms
