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
    sigma_x, sigma_y : float
        The position's standard uncertainty (px, 1 σ) along x and y: what the frame's fit, the
        origin's and the measured model error allow (see :mod:`semlab.tracking.uncertainty`);
        NaN when ``ok`` is False.
    """

    x: float
    y: float
    score: float
    ok: bool
    reason: str = ""
    sigma_x: float = float("nan")
    sigma_y: float = float("nan")
