"""The flags on a followed answer (semlab.tracking.trust.Judge, issue 14)."""

from __future__ import annotations

from semlab.tracking.consistency import Influence
from semlab.tracking.options import LossOptions
from semlab.tracking.trust import Judge
from semlab.tracking.uncertainty import Uncertainty


class _Method:
    """What the judge asks of a method: whether it judges its answers, and its scores."""

    def __init__(self, flags=True, track=0.9, typical=0.8):
        self.flags_uncertain, self._track, self._typical = flags, track, typical

    def track_score(self):
        return self._track

    def typical_score(self):
        return self._typical


def _uncertainty(precision=(0.1, 0.1), influence=None):
    return Uncertainty(precision, precision, influence)


def test_a_sharp_consistent_resolved_explained_answer_stands():
    assert Judge(LossOptions(), 20.0, _Method()).distrust(_uncertainty()) is None


def test_each_check_flags_with_its_reason_in_turn():
    judge = Judge(LossOptions(), 20.0, _Method())
    assert judge.distrust(_uncertainty((0.1, 0.5))).startswith("too uncertain")
    assert judge.distrust(_uncertainty(influence=Influence(0.8, 50.0))).startswith("inconsistent")
    assert Judge(LossOptions(), 4.0, _Method()).distrust(_uncertainty()).startswith("unresolved")
    assert Judge(LossOptions(), 20.0, _Method(track=0.4)).distrust(_uncertainty()).startswith("unexplained")
    # The first reason that holds is the one given: precision before the track's score.
    assert Judge(LossOptions(), 20.0, _Method(track=0.4)).distrust(_uncertainty((0.6, 0.1))).startswith(
        "too uncertain")


def test_a_check_set_to_none_never_flags():
    loose = LossOptions(max_sigma=None, max_influence=None, min_resolved_contrast=None, min_track_score=None)
    judge = Judge(loose, 1.0, _Method(track=0.1))
    assert judge.distrust(_uncertainty((5.0, 5.0), Influence(3.0, 1e3))) is None


def test_a_method_that_does_not_judge_its_answers_is_never_flagged():
    judge = Judge(LossOptions(), 1.0, _Method(flags=False, track=0.1))
    assert judge.distrust(_uncertainty((5.0, 5.0))) is None
    assert judge.doubt_jump(50.0, 0.0, 0.1) is None
    assert Judge(LossOptions(), 20.0, _Method()).distrust(None) is None


def test_a_far_jump_at_a_poor_match_is_ambiguous_unless_expected_or_well_matched():
    judge = Judge(LossOptions(), 20.0, _Method(typical=0.8))
    assert judge.doubt_jump(10.0, 0.0, 0.7).startswith("ambiguous")
    assert judge.doubt_jump(10.0, 12.0, 0.7) is None  # the track expected a move that large
    assert judge.doubt_jump(10.0, 0.0, 0.85) is None  # the match vouches for it
    assert judge.doubt_jump(2.0, 0.0, 0.1) is None  # within a change of speed's reach
    before = Judge(LossOptions(), 20.0, _Method(typical=None))  # frame 1 found by the coarse search
    assert "no typical score" in before.doubt_jump(1.5, 0.0, 0.95)
    assert before.doubt_jump(0.9, 0.0, 0.1) is None  # within a steady pixel of frame 0


def test_a_re_acquisition_the_registration_drifts_from_is_ambiguous_beyond_the_limit_whatever_its_score():
    # Its score is the correlation's, which runs above the registration's typical one: a slide along
    # a shaft scores 0.88 where the track's frames score 0.77 (clutter development seed 106).
    judge = Judge(LossOptions(), 20.0, _Method(typical=0.8))
    assert judge.doubt_jump(10.0, 0.0, 0.95) is None
    assert "drifts away" in judge.doubt_jump(10.0, 0.0, 0.95, drifted=True)
    assert judge.doubt_jump(10.0, 12.0, 0.95, drifted=True) is None  # the track expected a move that large
    assert judge.doubt_jump(2.0, 0.0, 0.95, drifted=True) is None  # within a change of speed's reach
    assert Judge(LossOptions(max_poor_jump=None), 20.0, _Method()).doubt_jump(50.0, 0.0, 0.9, drifted=True) is None
