"""The flags on a followed answer (semlab.tracking.trust.Judge, issue 14)."""

from __future__ import annotations

from semlab.tracking.consistency import Influence
from semlab.tracking.options import LossOptions
from semlab.tracking.trust import DOUBT_FRAMES, Judge, JumpDoubt
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


def test_after_an_ambiguous_jump_answers_away_from_the_last_trusted_place_are_in_doubt_for_a_few_frames():
    doubt = JumpDoubt(limit=3.0)
    assert doubt.judge([40.0, 0.0]) is None  # no jump, no doubt
    doubt.trust([10.0, 0.0], speed=1.0)
    doubt.start()
    for k in range(1, DOUBT_FRAMES + 1):
        reason = doubt.judge([14.0, 0.0])  # 4 px from the last trusted place, > 3 px
        assert reason is not None and reason.startswith("in doubt") and f"{k} frame(s)" in reason
    assert doubt.judge([14.0, 0.0]) is None  # the new place held: trusted again
    assert doubt.judge([40.0, 0.0]) is None  # and no doubt is left


def test_an_answer_back_within_reach_of_the_last_trusted_place_ends_the_doubt():
    doubt = JumpDoubt(limit=3.0)
    doubt.trust([10.0, 0.0], speed=5.0)
    doubt.start()
    assert doubt.judge([16.0, 0.0]) is not None  # 6 px: beyond one frame's expected move (5 px)
    assert doubt.judge([14.9, 0.0]) is None  # within it: the object found again
    assert doubt.judge([30.0, 0.0]) is None


def test_a_second_ambiguous_jump_restarts_the_count_from_the_first_jumps_trusted_place():
    doubt = JumpDoubt(limit=3.0)
    doubt.trust([0.0, 0.0], speed=0.0)
    doubt.start()
    assert doubt.judge([20.0, 0.0]) is not None
    doubt.trust([20.0, 0.0], speed=0.0)  # not called by the Stepper on a doubted answer, but harmless
    doubt.start()
    for _ in range(DOUBT_FRAMES):
        assert doubt.judge([20.0, 0.0]) is not None  # still measured from (0, 0)
    assert doubt.judge([20.0, 0.0]) is None


def test_a_track_that_jumped_to_something_else_while_the_tip_was_hidden_is_not_reported_there():
    # Clutter spare seed 334: the occluder hides the tip from frame 23; frame 25 is lost, frame 26's search
    # finds something 22.5 px off at a poorer match (flagged "ambiguous"), and the track, following it,
    # registered frames 27 and 28 there as well as it had (29-30 px off the tip). Those two frames are in doubt.
    import dataclasses

    import numpy as np
    import pandas as pd

    from semlab.evaluation import make_family_sequence
    from semlab.evaluation.scoring import frame_errors
    from semlab.tracking import Tracker

    seq = make_family_sequence("clutter", 334)
    frames = seq.frames[:30]
    t = Tracker()
    results = [t.init(frames[0], seq.roi)] + [t.update(frame) for frame in frames[1:]]
    rows = pd.DataFrame([dataclasses.asdict(r) for r in results]).rename_axis("frame").reset_index()
    errors = frame_errors(rows, seq.truth[seq.truth["frame"] < len(frames)], seq.roi)
    err = np.hypot(errors["ex"], errors["ey"])
    assert results[26].reason.startswith("ambiguous")
    assert [results[k].reason.split(":")[0] for k in (27, 28)] == ["in doubt", "in doubt"]
    assert not (errors["ok"] & (err > 2.0)).any()  # no ok frame far off: the jump's place is never reported


def test_the_readmes_table_of_flags_names_every_check_with_its_default():
    # README.md, "Using semlab from a script": one row per flag, its keyword and default as LossOptions has them.
    import dataclasses
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| ([a-z ]+) \| .+ \| `(\w+)`(?: \(([\d.]+)(?: px)?\))? \|$", readme,
                      flags=re.MULTILINE)
    defaults = {f.name: f.default for f in dataclasses.fields(LossOptions)}
    named = {keyword: value for _, keyword, value in rows if value}
    assert set(named) == set(defaults) - {"min_score", "min_relative_score"}
    assert all(float(value) == defaults[keyword] for keyword, value in named.items())
    assert [reason for reason, _, _ in rows] == ["too uncertain", "inconsistent", "unresolved", "unexplained",
                                                  "ambiguous", "in doubt", "slid"]
