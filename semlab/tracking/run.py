"""Tracking a sequence: :func:`track`, and the frame loop it shares with :func:`semlab.metrics.run_tracker`."""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import pandas as pd

from ..protocols import VisualTracker
from .frames import is_roi_list, iter_frames
from .options import DEFAULT_METHOD
from .result import TrackResult
from .tracker import Tracker

__all__ = ["follow_frames", "start_trackers", "track", "track_with_reasons"]

#: Sequences longer than this show a progress bar unless told otherwise.
PROGRESS_FROM_FRAMES = 50


def start_trackers(trackers: list[VisualTracker], first, rois) -> list[tuple[int, int, TrackResult]]:
    """``init`` every tracker on frame 0 with its ROI: ``(0, target, result)`` per tracker."""
    return [(0, k, t.init(first, r)) for k, (t, r) in enumerate(zip(trackers, rois))]


def follow_frames(trackers: list[VisualTracker], frames: Iterable, first_index: int = 1
                  ) -> Iterator[tuple[int, int, TrackResult]]:
    """``update`` every tracker on each frame: ``(frame index, target, result)``, frame by frame."""
    for i, frame in enumerate(frames, start=first_index):
        for k, t in enumerate(trackers):
            yield i, k, t.update(frame)


def track(frames, roi, *, method: str = DEFAULT_METHOD, progress: bool | None = None, **params) -> pd.DataFrame:
    """Track the ROI's centre point through a sequence of frames.

    Parameters
    ----------
    frames : iterable of (H, W) array_like, or (N, H, W) ndarray
        uint8, uint16 or float gray frames.
    roi : (x, y, w, h), or a list of them
        ROI in frame 0 (top-left pixel and size). A list tracks several targets (e.g. the four
        probes) in one pass over the frames, one :class:`Tracker` each, and adds a ``target``
        column (the index in the list).
    method : {"ic", "contour", "ssd", "hb"}
        ``"ic"`` (the default, as for :class:`Tracker`, the CLI and the widgets) is semlab's method,
        the best measured (``benchmarks/bench_corpus.py``); ``"contour"`` is the paper's method,
        ``"ssd"`` the conventional baseline it improves on, ``"hb"`` its parametric SSD tracker; see
        :mod:`semlab.tracking`.
    progress : bool or None
        tqdm progress bar; ``None`` shows it for sequences longer than 50 frames.
    **params
        Passed to :class:`Tracker`.

    Returns
    -------
    pandas.DataFrame
        One row per frame (and target): ``frame, x, y, score, ok, sigma_x, sigma_y``. ``x, y`` is
        where the ROI's centre point has moved to, px; ``sigma_x, sigma_y`` its standard
        uncertainty (px, 1 σ; :mod:`semlab.tracking.uncertainty`). NaN with ``ok=False`` where the
        target was lost or the answer too uncertain to trust.

    Raises
    ------
    TypeError, ValueError
        Bad first frame or ROI (from :meth:`Tracker.init`), no frames, or bad parameters; later
        bad frames only flag their rows.

    Examples
    --------
    >>> import numpy as np
    >>> yy, xx = np.mgrid[:240, :320]
    >>> frames = [np.where((xx - 150 - k) ** 2 + (yy - 120) ** 2 < 30 ** 2, 200, 60).astype(np.uint8)
    ...           for k in range(3)]
    >>> df = track(frames, (100, 70, 100, 100))
    >>> df["x"].round(1).tolist(), bool(df["ok"].all())
    ([149.5, 150.5, 151.5], True)
    """
    return _track(frames, roi, method, progress, params, reasons=False)


def _track(frames, roi, method: str, progress: bool | None, params: dict, *, reasons: bool) -> pd.DataFrame:
    """:func:`track` (with ``reasons``: :func:`track_with_reasons`)."""
    rois = list(roi) if is_roi_list(roi) else None
    iterator, n = iter_frames(frames)
    try:
        first = next(iterator)
    except StopIteration:
        raise ValueError("frames is empty") from None
    trackers = [Tracker(method, **params) for _ in (rois or [roi])]
    rows = start_trackers(trackers, first, rois or [roi])
    show = (n is not None and n > PROGRESS_FROM_FRAMES) if progress is None else bool(progress)
    if show:
        from tqdm.auto import tqdm

        iterator = tqdm(iterator, total=None if n is None else n - 1, desc=f"tracking ({method})")
    rows += follow_frames(trackers, iterator)
    df = pd.DataFrame([(i, k, r.x, r.y, r.score, r.ok, r.sigma_x, r.sigma_y, "" if r.ok else (r.reason or ""))
                       for i, k, r in rows],
                      columns=["frame", "target", "x", "y", "score", "ok", "sigma_x", "sigma_y", "reason"])
    df["ok"] = df["ok"].astype(bool)
    if rois is None:
        df = df.drop(columns="target")
    else:
        df = df.sort_values(["frame", "target"], kind="stable").reset_index(drop=True)
    return df if reasons else df.drop(columns="reason")


def track_with_reasons(frames, roi, *, method: str = DEFAULT_METHOD, progress: bool | None = None,
                       **params) -> pd.DataFrame:
    """:func:`track`'s table with a last column ``reason``: why a frame's ``ok`` is False (the
    :class:`~semlab.tracking.result.TrackResult`'s: lost, or a flag of :mod:`semlab.tracking.trust`), ''
    where it is ok. Parameters, returns and raises as :func:`track`'s."""
    return _track(frames, roi, method, progress, params, reasons=True)
