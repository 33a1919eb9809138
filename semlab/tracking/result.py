"""One frame's answer (:class:`TrackResult`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TrackResult"]


@dataclass(frozen=True)
class TrackResult:
    """One frame's answer: where the ROI's centre point has moved to.

    Attributes
    ----------
    x, y : float
        Position in px (pixel centres at integer coordinates); NaN when ``ok`` is False.
    score : float
        Match quality, 1 = perfect (``"ic"``, ``"ssd"``, ``"hb"``: normalised correlation with
        the template; ``"contour"``: fraction of contour pixels on an edge); 0 when lost.
    ok : bool
        False when the target is lost or the frame is unusable.
    reason : str
        Why ``ok`` is False ('' otherwise).
    """

    x: float
    y: float
    score: float
    ok: bool
    reason: str = ""
