"""One frame through the :class:`~semlab.tracking.Tracker`'s states: predicted → (followed) → searched →
re-acquired → verdict, then judged (:mod:`semlab.tracking.trust`) and reported.

The :class:`Stepper` holds what changes from frame to frame (the :class:`~semlab.tracking.method.Motion`)
and drives the track's :class:`~semlab.tracking.method.Method` through the states; what each state
means is the method's. The Tracker makes one at :meth:`~semlab.tracking.Tracker.init`, from frame 0's
set-up, and hands it every later frame.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .method import Method, Motion, Verdict
from .result import TrackResult
from .search import search_window
from .trust import Judge, JumpDoubt

__all__ = ["Stepper"]


class Stepper:
    """The per-frame state machine of one track.

    Parameters
    ----------
    method : Method
        The track's method, started on frame 0.
    judge : Judge
        Whether a followed answer may be reported.
    roi : (x, y, w, h)
        Frame 0's ROI.
    search_size : int
        Side of the search window around the prediction (px).
    max_poor_jump : float or None
        The loss option: a re-acquired answer farther than this from the track is a miss (px).
    centre0 : (2,) array_like
        Frame 0's answer, the ROI's centre: positions are ``centre0 + shift − origin``.
    """

    def __init__(self, method: Method, judge: Judge, roi, search_size: int, max_poor_jump: float | None, centre0):
        self.method, self.judge, self.roi = method, judge, roi
        self.search_size, self.max_poor_jump = search_size, max_poor_jump
        self.centre0 = np.asarray(centre0, float)
        self.motion = Motion()
        #: The doubt an ambiguous jump leaves on the frames that follow it (None: the loss option is off).
        self.doubt = (JumpDoubt(max_poor_jump, self.centre0) if max_poor_jump is not None and method.flags_uncertain
                      else None)

    def step(self, arr) -> TrackResult:
        """The answer in ``arr`` (a checked frame on the tracker's gray scale): predicted → (followed) →
        searched → re-acquired → verdict."""
        method, motion = self.method, self.motion
        predicted = method.predict(motion)
        raw, arr = arr, method.prepare(arr, predicted, motion)
        window = search_window(self.roi, self.search_size, predicted, arr.shape, whole=motion.lost)
        found = None if motion.lost else method.follow(arr, predicted, motion)
        widened = False
        if not method.good(found):
            found = method.search(arr, window, predicted, found)
            if method.widens_search and not motion.lost and not method.good(found):
                found, widened = self._search_whole_frame(arr, window, predicted, found)
        # A match from the whole frame that is poorer than the track's typical one competes with the
        # re-acquisition in the window: a whole frame holds many such matches of texture that is not
        # the object (the real needle at contact, where its gray levels jump).
        if not motion.lost:
            acceptable = method.acceptable(found)
            if not acceptable or (widened and not method.good(found)):
                verdict = method.reacquire(arr, window, predicted)
                if verdict is not None and (not acceptable or verdict.score > found.score):
                    return self._conclude(raw, verdict, predicted)
        return self._conclude(raw, method.verdict(arr, found, predicted), predicted)

    def lose(self, reason: str) -> TrackResult:
        """A lost frame: the next one is searched over the whole image, with no speed to extrapolate."""
        motion = self.motion
        motion.prediction_error = motion.miss = np.inf
        motion.lost = True
        motion.n_lost += 1
        motion.velocity[:] = 0.0
        return TrackResult(float("nan"), float("nan"), 0.0, False, reason)

    def _search_whole_frame(self, arr, window, predicted, found):
        """``(found, widened)`` after a search of the whole frame, for a window that gave no good match.

        The object may be farther than the window reaches (a feed-forward step, the paper's 200-px
        moves in two frames). When the window's match is not acceptable, the whole frame's stands in
        for it, rather than a lost frame. When it is acceptable but poor, it may be something else
        that looks partly like the object (after a jump out of the window), and the whole frame's
        match replaces it only when clearly better.
        """
        method = self.method
        whole = search_window(self.roi, self.search_size, predicted, arr.shape, whole=True)
        if whole == window:
            return found, False
        if not method.acceptable(found):
            return method.search(arr, whole, predicted, found), True
        other = method.search(arr, whole, predicted, None)
        return (other, True) if method.clearly_better(other, found) else (found, False)

    def _conclude(self, arr, verdict: Verdict, predicted) -> TrackResult:
        """The reported result of a ``verdict``: lost, flagged (followed but not trusted) or the answer
        with its sigma."""
        if not verdict.ok:
            return self.lose(verdict.reason)
        motion = self.motion
        jump, expected = motion.record_miss(verdict.shift, predicted, verdict.reacquired, self.max_poor_jump or 0.0)
        result = self._accept(verdict.shift, verdict.score)
        uncertainty = self.method.sigma(verdict)
        moved = self.method.after_accept(arr, verdict)
        if moved is not None:  # the template's origin moved: the state follows (the position stays)
            motion.shift = motion.shift + moved
        ambiguous = self.judge.doubt_jump(jump, expected, verdict.score, drifted=verdict.drifted)
        reason = self.judge.distrust(uncertainty) or ambiguous or self.judge.doubt_match(verdict.score)
        reason = self._doubted((result.x, result.y), ambiguous, reason, expected)
        if reason is not None:
            # Followed (the motion moves on, the next frame starts from here; a frame that
            # registered well still improves the template) but not trusted: a flag is better than
            # a number that may be a pixel off.
            return TrackResult(float("nan"), float("nan"), result.score, False, reason)
        if uncertainty is None:
            return result
        sx, sy = uncertainty.sigma
        return dataclasses.replace(result, sigma_x=float(sx), sigma_y=float(sy))

    def _doubted(self, position, ambiguous, reason, speed):
        """``reason``, or why the answer at ``position`` (px in the frame: a template refreshed since does
        not move it) is in doubt after an ambiguous jump (:class:`~semlab.tracking.trust.JumpDoubt`); a
        trusted answer (``speed``: the move the track expected) becomes the place the doubt measures from."""
        doubt = self.doubt
        if doubt is None:
            return reason
        if ambiguous is not None:
            doubt.start()
            return reason
        doubted = doubt.judge(position)
        reason = reason or doubted
        if reason is None:
            doubt.trust(position, speed)
        return reason

    def _accept(self, shift, score) -> TrackResult:
        """The motion moved on to ``shift``; the answer it makes, unjudged."""
        motion = self.motion
        shift = np.asarray(shift, float)
        motion.velocity = shift - motion.shift if not motion.lost else np.zeros(2)
        motion.shift = shift
        motion.lost = False
        x, y = self.centre0 + shift - self.method.origin
        return TrackResult(float(x), float(y), float(score), True)
