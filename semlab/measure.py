"""Measuring the probe with a visual tracker: what the experiments and the visual servo share.

:func:`default_tracker` supplies :class:`semlab.tracking.Tracker` (its window widened for a
feed-forward jump) or checks the tracker given, :func:`read_result` reads any tracker's answer,
and :func:`start_point` is where displacements are counted from: the ROI's centre.
"""

from __future__ import annotations

import math

from .protocols import VisualTracker
from .roi import roi_centre

__all__ = ["default_tracker", "read_result", "start_point"]

#: A default tracker's search window around a probe that jumps ``jump_px`` in one frame reaches
#: this factor of the jump, plus this many px, beyond the ROI on each side (the paper's
#: 300×300 window around a 200×200 ROI allows ±50 px).
JUMP_WINDOW_FACTOR = 1.1
JUMP_WINDOW_EXTRA_PX = 20.0


def default_tracker(tracker=None, *, jump_px: float | None = None, roi=None) -> VisualTracker:
    """The given tracker, or ``semlab.tracking.Tracker()``.

    When the caller is about to make the probe jump by ``jump_px`` in one frame (feed-forward),
    the default tracker's search window is widened so that the jump stays inside it.

    Raises
    ------
    TypeError
        ``tracker`` is not a :class:`~semlab.protocols.VisualTracker` (no ``init``/``update``).
    """
    if tracker is None:
        from .tracking import Tracker
        from .tracking.options import SEARCH_SIZE_PX

        if jump_px is not None and roi is not None:
            side = max(float(roi[2]), float(roi[3])) + 2.0 * math.ceil(
                JUMP_WINDOW_FACTOR * abs(jump_px) + JUMP_WINDOW_EXTRA_PX)
            return Tracker(search_size=int(max(SEARCH_SIZE_PX, side)))
        return Tracker()
    if not isinstance(tracker, VisualTracker):
        raise TypeError(f"tracker must have init(frame, roi) and update(frame); got {type(tracker).__name__}")
    return tracker


def read_result(res) -> tuple[float, float, float, bool]:
    """``(x, y, score, ok)`` from a tracker's result (attributes or a 4-tuple); score NaN if absent."""
    if all(hasattr(res, a) for a in ("x", "y", "ok")):
        x, y, ok = res.x, res.y, res.ok
        score = getattr(res, "score", float("nan"))
    else:
        x, y, score, ok = res
    return float(x), float(y), float(score) if score is not None else float("nan"), bool(ok)


def start_point(roi) -> tuple[float, float]:
    """Where a measurement's displacements are counted from: the centre of ``roi = (x, y, w, h)``
    (:func:`semlab.roi.roi_centre`).

    Raises
    ------
    ValueError
        ``roi`` is not four finite numbers with a positive size.
    """
    try:
        x, y, w, h = (float(v) for v in roi)
    except (TypeError, ValueError):
        raise ValueError(f"roi must be (x, y, w, h), got {roi!r}") from None
    if not (w > 0 and h > 0) or not all(map(math.isfinite, (x, y, w, h))):
        raise ValueError(f"roi {roi!r} must have finite coordinates and positive size")
    return roi_centre((x, y, w, h))
