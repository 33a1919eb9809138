"""The per-frame state machine (:class:`semlab.tracking.stepper.Stepper`) on a scripted method.

The method here answers from a script, so each test states which states a frame goes through
(followed, searched, re-acquired), what the motion becomes and what is reported: the Tracker's
contract with any :class:`~semlab.tracking.method.Method`, independent of images.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from semlab.tracking.method import Method, Verdict
from semlab.tracking.options import LossOptions, TrackerOptions
from semlab.tracking.stepper import Stepper
from semlab.tracking.trust import Judge
from semlab.tracking.uncertainty import Uncertainty

ROI = (10, 20, 40, 30)
CENTRE0 = (29.5, 34.5)
FRAME = np.zeros((120, 160), np.float32)


class Scripted(Method):
    """A method whose follow, search and re-acquisition answers are given; it logs the states it is asked."""

    name = "scripted"
    flags_uncertain = True
    widens_search = False

    def __init__(self, followed=None, searched=None, reacquired=None, acceptable=True, sigma=(0.1, 0.2),
                 precision=(0.1, 0.2), origin=(0.0, 0.0)):
        super().__init__(TrackerOptions())
        self.followed, self.searched, self.reacquired = followed, searched, reacquired
        self.is_acceptable, self.uncertainty = acceptable, Uncertainty(sigma, precision)
        self.origin = np.asarray(origin, float)
        self.calls = []

    def follow(self, arr, predicted, motion):
        self.calls.append("follow")
        return self.followed

    def good(self, found):
        return found is not None and found is self.followed

    def search(self, arr, window, predicted, found):
        self.calls.append("search")
        return self.searched if self.searched is not None else found

    def acceptable(self, found):
        return found is not None and self.is_acceptable

    def reacquire(self, arr, window, predicted):
        self.calls.append("reacquire")
        return self.reacquired

    def verdict(self, arr, found, predicted):
        self.calls.append("verdict")
        return Verdict.lose("nothing found") if found is None else Verdict.accept(found, 0.9)

    def sigma(self, verdict):
        return self.uncertainty


def stepper(method, max_sigma=0.35):
    loss = LossOptions(max_sigma=max_sigma, max_poor_jump=None)
    return Stepper(method, Judge(loss, contrast_noise=30.0, method=method), ROI, 300, None, CENTRE0)


def test_a_good_follow_is_not_searched_and_reports_its_position_and_sigma():
    method = Scripted(followed=np.array([2.0, -1.0]), origin=(0.5, 0.25))
    s = stepper(method)
    r = s.step(FRAME)
    assert method.calls == ["follow", "verdict"]
    assert r.ok and (r.x, r.y) == pytest.approx((CENTRE0[0] + 2.0 - 0.5, CENTRE0[1] - 1.0 - 0.25))
    assert (r.sigma_x, r.sigma_y) == pytest.approx((0.1, 0.2))
    np.testing.assert_allclose(s.motion.shift, [2.0, -1.0])
    np.testing.assert_allclose(s.motion.velocity, [2.0, -1.0])


def test_a_poor_follow_is_searched_and_an_unacceptable_one_reacquired():
    searched = np.array([5.0, 5.0])
    method = Scripted(followed=None, searched=searched, acceptable=False,
                      reacquired=Verdict.accept([4.0, 3.0], 0.7, reacquired=True))
    s = stepper(method)
    r = s.step(FRAME)
    assert method.calls == ["follow", "search", "reacquire"]
    assert r.ok and (r.x, r.y) == pytest.approx((CENTRE0[0] + 4.0, CENTRE0[1] + 3.0))
    assert s.motion.prediction_error == math.inf  # a re-acquired answer's prediction error is unknown


def test_a_lost_frame_stops_the_motion_and_the_next_one_is_searched_not_followed():
    method = Scripted(followed=np.array([1.0, 1.0]))
    s = stepper(method)
    s.step(FRAME)
    method.followed, method.searched = None, None
    r = s.step(FRAME)
    assert not r.ok and math.isnan(r.x) and r.reason == "nothing found"
    assert s.motion.lost and s.motion.n_lost == 1
    np.testing.assert_array_equal(s.motion.velocity, [0.0, 0.0])
    method.calls.clear()
    method.searched = np.array([3.0, 1.0])
    r = s.step(FRAME)
    assert method.calls == ["search", "verdict"]  # lost: no follow, no re-acquisition
    assert r.ok and not s.motion.lost
    np.testing.assert_array_equal(s.motion.velocity, [0.0, 0.0])  # no speed across a loss


def test_an_untrusted_answer_is_flagged_but_followed():
    method = Scripted(followed=np.array([2.0, 0.0]), sigma=(0.5, 0.5), precision=(0.5, 0.1))
    s = stepper(method, max_sigma=0.35)
    r = s.step(FRAME)
    assert not r.ok and math.isnan(r.x) and r.reason.startswith("too uncertain")
    assert r.score == pytest.approx(0.9)
    np.testing.assert_allclose(s.motion.shift, [2.0, 0.0])  # the next frame starts from here
    assert not s.motion.lost


def test_a_moved_origin_moves_the_motion_not_the_position():
    class Refreshing(Scripted):
        def after_accept(self, arr, verdict):
            self.origin = self.origin + [0.5, 0.0]
            return np.array([0.5, 0.0])

    method = Refreshing(followed=np.array([2.0, 0.0]))
    s = stepper(method)
    r = s.step(FRAME)
    assert (r.x, r.y) == pytest.approx((CENTRE0[0] + 2.0, CENTRE0[1]))
    np.testing.assert_allclose(s.motion.shift, [2.5, 0.0])
    assert (CENTRE0[0] + s.motion.shift[0] - method.origin[0]) == pytest.approx(r.x)


def test_answers_that_follow_an_ambiguous_jump_stay_flagged_until_the_track_comes_back():
    class Scored(Scripted):
        """Followed answers match at 0.9, searched ones at 0.7: under the track's typical 0.8."""

        def typical_score(self):
            return 0.8

        def verdict(self, arr, found, predicted):
            return Verdict.accept(found, 0.9 if found is self.followed else 0.7)

    method = Scored(followed=np.array([1.0, 0.0]))
    s = Stepper(method, Judge(LossOptions(max_poor_jump=3.0), contrast_noise=30.0, method=method), ROI, 300,
                3.0, CENTRE0)
    assert s.step(FRAME).ok
    method.followed = None  # the follow fails; the search finds something 10 px off, at a poor match
    method.searched = np.array([11.0, 0.0])
    assert s.step(FRAME).reason.startswith("ambiguous")
    method.followed, method.searched = np.array([11.5, 0.0]), None  # followed from there: it matches well
    r = s.step(FRAME)
    assert not r.ok and r.reason.startswith("in doubt")
    np.testing.assert_allclose(s.motion.shift, [11.5, 0.0])  # followed all the same
    method.followed = np.array([2.0, 0.0])  # the object again, 1 px from where the track was last trusted
    assert s.step(FRAME).ok
