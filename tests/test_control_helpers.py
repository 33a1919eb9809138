"""semlab.control outside the servo loop: drive_voltages and the argument checks every servo entry
point goes through. A scripted rig records what was sent, so each row of the result can be checked
against the command that produced it (no tolerance: the fakes are exact)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from semlab.control import drive_voltages
from semlab.hysteresis import PolynomialHysteresis

FRAME_PERIOD = 0.08


class ScriptedRig:
    """The probe's x position is 10 px per volt of the command applied before the frame."""

    def __init__(self, limits=(0.0, 50.0)):
        self.limits, self.sent, self.u, self.grabs = limits, [], 0.0, 0
        self.frame_period = FRAME_PERIOD

    # Axis
    def apply(self, volts):
        self.sent.append(float(volts))
        self.u = float(volts)

    # Microscope
    def grab(self):
        self.grabs += 1
        return np.full((4, 4), self.grabs)


class Tracker:
    def __init__(self, rig, *, lose=(), nan=(), as_tuple=False, score=None):
        self.rig, self.lose, self.nan, self.as_tuple, self.score = rig, set(lose), set(nan), as_tuple, score

    def update(self, frame):
        k = int(frame[0, 0])
        x = math.nan if k in self.nan else 10.0 * self.rig.u
        ok = k not in self.lose
        if self.as_tuple:
            return (x, 5.0, self.score, ok)
        return SimpleNamespace(x=x, y=5.0, ok=ok, **({} if self.score is None else {"score": self.score}))


def test_drive_voltages_records_one_row_per_command():
    rig = ScriptedRig()
    volts = [0.0, 2.5, 5.0, 7.5]
    df = drive_voltages(rig, rig, Tracker(rig, score=0.9), volts)
    assert list(df.columns) == ["frame", "t", "u", "x", "y", "score", "ok"]
    assert rig.sent == volts
    np.testing.assert_array_equal(df["frame"], [1, 2, 3, 4])
    np.testing.assert_allclose(df["t"], FRAME_PERIOD * np.arange(1, 5))
    np.testing.assert_allclose(df["x"], 10.0 * np.asarray(volts))
    assert df["ok"].all() and (df["score"] == 0.9).all() and (df["y"] == 5.0).all()


def test_settle_frames_grab_several_frames_and_keep_the_last():
    rig = ScriptedRig()
    df = drive_voltages(rig, rig, Tracker(rig, lose={1, 3}), [1.0, 2.0], settle_frames=2)
    assert rig.grabs == 4
    np.testing.assert_array_equal(df["frame"], [2, 4])
    np.testing.assert_allclose(df["t"], [2 * FRAME_PERIOD, 4 * FRAME_PERIOD])
    assert df["ok"].all()  # frames 1 and 3 were lost, but the recorded (last) ones were not


def test_lost_and_nan_frames_are_flagged_and_a_tuple_result_is_read():
    rig = ScriptedRig()
    df = drive_voltages(rig, rig, Tracker(rig, lose={2}, nan={3}, as_tuple=True), [1.0, 2.0, 3.0, 4.0])
    assert list(df["ok"]) == [True, False, False, True]  # a NaN position is never a valid one
    assert np.isnan(df["score"]).all()  # a tracker that reports no score: NaN, not 0
    no_score = drive_voltages(rig, rig, Tracker(rig), [1.0])
    assert np.isnan(no_score["score"].iloc[0])


def test_commands_outside_the_limits_are_refused_before_anything_moves():
    rig = ScriptedRig(limits=(0.0, 10.0))
    for bad in ([1.0, 10.5], [-0.1], [1.0, math.nan]):
        with pytest.raises(ValueError, match=r"^drive_voltages: command"):
            drive_voltages(rig, rig, Tracker(rig), bad)
    assert rig.sent == [] and rig.grabs == 0
    df = drive_voltages(rig, rig, Tracker(rig), np.array([[0.0, 10.0]]))  # limits inclusive, any shape
    assert list(df["u"]) == [0.0, 10.0]


def test_the_shadow_model_sees_every_command_beyond_its_range_too():
    rig = ScriptedRig(limits=(-5.0, 60.0))
    model = PolynomialHysteresis([0.0, 40.0], [0.0, 40.0], (0.0, 50.0), axis="x")  # linear: 0.8 px/V
    reference = model.copy()
    drive_voltages(rig, rig, Tracker(rig), [10.0, 55.0], model=model)
    # 55 V is beyond the model's range: extrapolated (1.25 times the steepest slope), not clipped
    assert model.state.u == 55.0 and model.state.y == pytest.approx(40.0 + 5.0 * 1.25 * 0.8)
    drive_voltages(rig, rig, Tracker(rig), [20.0, -5.0, 25.0], model=model)
    assert model.state.u == 25.0
    assert model.state.y == pytest.approx(reference.predict([10.0, 55.0, 20.0, -5.0, 25.0])[-1])


def test_drive_voltages_with_a_progress_bar_gives_the_same_rows(capsys):
    rig = ScriptedRig()
    plain = drive_voltages(rig, rig, Tracker(rig), [1.0, 2.0])
    assert capsys.readouterr().err == ""  # no bar unless asked for (a script's log stays clean)
    rig2 = ScriptedRig()
    shown = drive_voltages(rig2, rig2, Tracker(rig2), [1.0, 2.0], progress=True)
    err = capsys.readouterr().err
    assert "driving: " in err and "/2 " in err and "XX" not in err  # the bar, labelled, with its total
    pd.testing.assert_frame_equal(plain, shown)
