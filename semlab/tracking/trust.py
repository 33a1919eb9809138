"""Whether a followed answer can be trusted: the flags that report it ``ok=False``, with the reason.

A method that judges its answers (``"ic"``: :attr:`~semlab.tracking.method.Method.flags_uncertain`)
follows every frame it can; :class:`Judge` then says, from the frame's
:class:`~semlab.tracking.uncertainty.Uncertainty` and the track's state, whether the answer may be
reported. The checks and their limits are the :class:`~semlab.tracking.options.LossOptions`; each
test is a function of :mod:`semlab.tracking.uncertainty` or :mod:`semlab.tracking.consistency`,
where its constant is measured. A flag judges, it does not steer: the tracker follows a flagged
answer all the same.
"""

from __future__ import annotations

import numpy as np

from .consistency import inconsistent
from .method import Method
from .options import LossOptions
from .uncertainty import (
    Uncertainty,
    ambiguous_jump,
    ambiguous_jump_limit,
    slid_on_texture,
    too_uncertain,
    unexplained,
    unresolved,
)

__all__ = ["DOUBT_FRAMES", "Judge", "JumpDoubt"]

#: After an ambiguous jump, the answers that stay away from where the track was last trusted are flagged
#: for this many followed frames: a second minimum the track jumped to can match as well as the object
#: for a few frames (the static particle at a thin apex; something bright while the occluder hides the
#: tip), until the object, moving on, is found again, or the new place holds and is trusted. Measured on
#: clutter's spare seeds 240-339: the wrong places held 1-2 frames; every frame flagged beyond that was
#: right (the object found again after the occluder, the probe moved on meanwhile).
DOUBT_FRAMES = 2


class Judge:
    """The flags on one track.

    Parameters
    ----------
    loss : LossOptions
        Which checks run (None: that check never flags) and their limits.
    contrast_noise : float
        Frame 0's object contrast over the smoothed noise (:attr:`~semlab.tracking.Tracker.contrast_noise`).
    method : Method
        The track's method: whether it judges its answers, and its match scores.
    """

    def __init__(self, loss: LossOptions, contrast_noise: float, method: Method):
        self.loss, self.contrast_noise, self.method = loss, contrast_noise, method

    def distrust(self, uncertainty: Uncertainty | None) -> str | None:
        """Why a followed answer is not to be trusted, or None: the frame's precision too poor ("too
        uncertain"), one part of its band moving it alone ("inconsistent"), frame 0's object not
        resolved above the noise ("unresolved"), or the track's frames not explained by its template
        ("unexplained")."""
        if uncertainty is None or not self.method.flags_uncertain:
            return None
        loss = self.loss
        if loss.max_sigma is not None and too_uncertain(uncertainty.precision, loss.max_sigma):
            p = uncertainty.precision
            return (f"too uncertain: the frame and its recent ones allow ({p[0]:.2f}, {p[1]:.2f}) px "
                    f"> max_sigma {loss.max_sigma:g} px")
        if loss.max_influence is not None and inconsistent(uncertainty.influence, loss.max_influence):
            pull = uncertainty.influence
            return (f"inconsistent: one quadrant of the band moves the answer {pull.shift_px:.2f} px "
                    f"> max_influence {loss.max_influence:g} px (chi2 {pull.chi2:.0f})")
        if loss.min_resolved_contrast is not None and unresolved(self.contrast_noise, loss.min_resolved_contrast):
            return (f"unresolved: frame 0's object stands {self.contrast_noise:.1f} noise standard deviations above "
                    f"its background < min_resolved_contrast {loss.min_resolved_contrast:g}")
        track_score = self.method.track_score()
        if loss.min_track_score is not None and unexplained(track_score, loss.min_track_score):
            return (f"unexplained: the track's frames match its template at a median score of {track_score:.2f} "
                    f"< min_track_score {loss.min_track_score:g}")
        return None

    def doubt_jump(self, jump: float, expected: float, score: float, *, drifted: bool = False) -> str | None:
        """Why an answer ``jump`` px off the track, at a match of ``score``, is ambiguous, or None:
        farther than ``max_poor_jump`` and than the ``expected`` move
        (:meth:`~semlab.tracking.method.Motion.record_miss`), at a match under the track's typical one,
        or at any match when the registration ``drifted`` from it (:attr:`~semlab.tracking.method.Verdict.drifted`:
        its score is a correlation's, not a registration's, and runs higher); or,
        before the track has one, farther than
        :func:`~semlab.tracking.uncertainty.ambiguous_jump_limit` at any match
        (:func:`~semlab.tracking.uncertainty.ambiguous_jump`)."""
        if self.loss.max_poor_jump is None or not self.method.flags_uncertain:
            return None
        limit, typical = max(self.loss.max_poor_jump, expected), self.method.typical_score()
        if not ambiguous_jump(jump, score, typical, limit):
            if drifted and jump > limit:
                return (f"ambiguous: re-acquired {jump:.1f} px off the track > {limit:.1f} px (max_poor_jump or "
                        f"the expected move), where the registration matches but drifts away")
            return None
        if typical is None:
            return (f"ambiguous: the coarse search's answer, {jump:.1f} px off the track > "
                    f"{ambiguous_jump_limit(typical, limit):.1f} px, with no typical score yet to vouch for it")
        return (f"ambiguous: {jump:.1f} px off the track > {limit:.1f} px (max_poor_jump or the "
                f"expected move), at a match scoring {score:.2f} < the track's typical {typical:.2f}")

    def doubt_match(self, score: float) -> str | None:
        """Why an answer matching at ``score`` over a strongly textured substrate (the method's
        :attr:`~semlab.tracking.method.Method.flatten`) has slid onto the substrate, or None: more than
        ``max_textured_drop`` under the track's first frames' median
        (:func:`~semlab.tracking.uncertainty.slid_on_texture`)."""
        limit = self.loss.max_textured_drop
        if limit is None or not (self.method.flags_uncertain and self.method.flatten):
            return None
        track_score = self.method.track_score()
        if not slid_on_texture(score, track_score, limit):
            return None
        return (f"slid: over a strongly textured substrate the match scores {score:.2f}, more than "
                f"max_textured_drop {limit:g} under the track's first frames' {track_score:.2f}")


class JumpDoubt:
    """The doubt an ambiguous jump leaves on the track that follows it.

    The track follows a flagged answer (a flag judges, it does not steer), so after an ambiguous jump the
    next frames are registered from the place it jumped to, where they match as well as they did there:
    judged one by one, nothing tells them from the object's. They stay in doubt until an answer comes back
    within reach of where the track was last trusted (``limit`` px, or its speed then if larger: one
    frame's expected move), or for :data:`DOUBT_FRAMES` followed frames.

    Places are positions in the frame (px).

    Parameters
    ----------
    limit : float
        The reach (px) around the last trusted place: the loss option ``max_poor_jump``.
    start : (2,) array_like
        Frame 0's position: trusted by definition.
    """

    def __init__(self, limit: float, start=(0.0, 0.0)):
        self.limit = float(limit)
        self.anchor: np.ndarray | None = None
        self.trusted, self.speed = np.array(start, float), 0.0
        self.frames = 0

    def trust(self, position, speed: float) -> None:
        """The track was trusted at ``position``, moving ``speed`` px a frame."""
        self.trusted, self.speed = np.array(position, float), float(speed)

    def start(self) -> None:
        """An ambiguous jump: the doubt starts (again) from the last trusted place."""
        if self.anchor is None:
            self.anchor = self.trusted.copy()
        self.frames = 0

    def judge(self, position) -> str | None:
        """Why a followed answer at ``position`` is in doubt, or None (no doubt, or it is over)."""
        if self.anchor is None:
            return None
        self.frames += 1
        off = float(np.hypot(*(np.asarray(position, float) - self.anchor)))
        reach = max(self.limit, self.speed)
        if off <= reach or self.frames > DOUBT_FRAMES:
            self.anchor = None
            return None
        return (f"in doubt: {off:.1f} px from where the track was last trusted (> {reach:.1f} px), "
                f"{self.frames} frame(s) after an ambiguous jump")
