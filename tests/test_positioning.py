"""Calibration of a closed-loop positioner and the servo to a point, on semlab's simulated SEM.

The positioner here is a stepper the test builds: a true view Jacobian (rotated, skewed, foreshortened)
times a move error (short, cross-coupled), plus jitter and optionally lag; only the test knows them.
The same loop through fibsem's DemoMicroscope is in test_instruments_fibsem.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from semlab.positioning import (
    WARMUP_FRAMES,
    CalibrationError,
    PositionerCalibration,
    calibrate_positioner,
    move_positioner_to,
)
from semlab.protocols import Microscope, Positioner, ScaledMicroscope, TimedMicroscope, frame_time
from semlab.sim import SimulatedSEM

PIXEL_NM = 50.0
SIZE = (400, 300)
ROI = 120
TIP0 = np.array([200.0, 150.0])


def view(rotation_deg=25.0, skew_deg=4.0, scale=(1.0, 0.87)):
    th, ty = math.radians(rotation_deg), math.radians(rotation_deg + 90 + skew_deg)
    return np.array([[scale[0] * math.cos(th), scale[1] * math.cos(ty)],
                     [scale[0] * math.sin(th), scale[1] * math.sin(ty)]]) / PIXEL_NM


class StepperRig:
    """A simulated SEM looking at a needle on an imperfect two-axis stepper."""

    def __init__(self, seed=0, jacobian=None, shortfall=0.04, coupling=0.03, jitter_nm=2.0,
                 jitter_fraction=0.01, lag=0.0, resolution_nm=0.0, limits=None, slip=0.0):
        self.sem = SimulatedSEM(*SIZE, PIXEL_NM, 1 / 13, seed=seed, probe_angles_deg=(10.0,))
        self.frame_period = self.sem.frame_period
        self.pixel_size_nm = PIXEL_NM
        self.view = view() if jacobian is None else np.asarray(jacobian, float)
        self.error = np.array([[1 - shortfall, coupling], [coupling, 1 - shortfall]])
        self.jitter = (jitter_nm, jitter_fraction)
        self.lag, self.slip = lag, slip
        self.resolution_nm, self.limits = resolution_nm, limits
        self.rng = np.random.default_rng([seed, 99])
        self.pos = np.zeros(2)      # true position, nm
        self.pending = np.zeros(2)  # the lagging part of the last move
        self.blank = 0
        self.moves = []
        self.asked = []
        self.truth = []

    @property
    def jacobian_true(self):
        """What a commanded nm does in the image: the view times the move error."""
        return self.view @ self.error

    # Microscope
    def grab(self):
        frame = self.sem.acquire(TIP0 + self.view @ self.pos)
        self.truth.append(self.sem.last_tips[0].copy())
        self.pos = self.pos + self.pending
        self.pending = np.zeros(2)
        if self.blank:
            self.blank -= 1
            return np.full_like(frame, 30)
        return frame

    # Positioner
    @property
    def position_nm(self):
        return None if self.limits is None else tuple(self.pos)

    def move_by(self, dx_nm, dy_nm):
        cmd = np.array([dx_nm, dy_nm], float)
        if not np.all(np.isfinite(cmd)):
            raise ValueError("not finite")
        self.moves.append(cmd)
        self.asked.append(self.pos + cmd)  # where the encoder said the move would end
        real = self.error @ cmd
        real += (self.jitter[0] + self.jitter[1] * np.abs(cmd)) * self.rng.standard_normal(2) * (cmd != 0)
        if self.slip:
            real *= self.rng.uniform(1 - self.slip, 1 + self.slip)
        self.pos = self.pos + (1 - self.lag) * real
        self.pending = self.pending + self.lag * real


def roi_at(xy):
    return (round(xy[0] - (ROI - 1) / 2), round(xy[1] - (ROI - 1) / 2), ROI, ROI)


def true_errors(rig, df, target, roi):
    """Ground-truth distance of the tracked point (the ROI centre point) to the target per row."""
    truth = np.array(rig.truth[-len(df):])
    centre0 = np.array([roi[0] + (ROI - 1) / 2, roi[1] + (ROI - 1) / 2])
    point = centre0 + truth - truth[0]
    return np.hypot(*(np.asarray(target) - point).T)


def test_the_rig_meets_the_protocols():
    rig = StepperRig()
    assert isinstance(rig, Microscope) and isinstance(rig, ScaledMicroscope) and isinstance(rig, Positioner)
    assert not isinstance(rig, TimedMicroscope)
    assert frame_time(rig, 3) == pytest.approx(3 / 13)


@pytest.mark.parametrize("seed", [0, 1])
def test_calibration_recovers_the_jacobian(seed):
    rig = StepperRig(seed=seed)
    cal = calibrate_positioner(rig, rig, roi_at(TIP0))
    true = rig.jacobian_true
    # Each test move (20 px = 1000 nm) carries 2 nm + 1 % = 12 nm of jitter per axis (0.24 px) and the
    # difference of two 2-frame means of the tracker (~0.1 px): per entry sigma_J ~ 0.26 px / (1000 nm
    # * sqrt(4 moves)) = 1.3e-4 px/nm. 4 sigma (and a little for the tracker's repeatable bias):
    assert np.abs(cal.jacobian - true).max() < 5.6e-4
    # the reported uncertainty is of that order (not 0, not 10x off)
    assert 2e-5 < cal.jacobian_std.max() < 5e-4
    true_angle = math.degrees(math.atan2(true[1, 0], true[0, 0]))
    assert cal.axis_angles_deg[0] == pytest.approx(true_angle, abs=1.5)
    assert 0 < cal.residual_px < 0.5 and 0 < cal.noise_px < 0.3
    # the positioner is back where it started (8 moves summing to 0), up to its jitter: 12 nm per move
    # and axis, sqrt(8) * 12 = 34 nm per axis; 3.5 sigma of the 2-D distance
    assert np.hypot(*rig.pos) < 120.0
    assert len(cal.moves) == 8 and set(cal.summary().index) >= {"skew (deg)", "fit residual (px)"}


def test_calibration_refuses_a_tip_that_does_not_move():
    rig = StepperRig()
    rig.move_by = lambda dx, dy: None  # the needle is not inserted: commands go nowhere
    with pytest.raises(CalibrationError, match="did not move"):
        calibrate_positioner(rig, rig, roi_at(TIP0))


def test_calibration_refuses_an_axis_that_slips():
    rig = StepperRig(slip=0.6)  # each move's length random within +-60 %
    with pytest.raises(CalibrationError, match="inconsistently"):
        calibrate_positioner(rig, rig, roi_at(TIP0))


def test_calibration_refuses_axes_seen_along_one_line():
    j = view()
    rig = StepperRig(jacobian=np.column_stack([j[:, 0], 1.05 * j[:, 0]]))
    with pytest.raises(CalibrationError, match="one image direction"):
        calibrate_positioner(rig, rig, roi_at(TIP0))


def test_calibration_needs_a_step_without_a_pixel_size():
    rig = StepperRig()
    rig.pixel_size_nm = None
    with pytest.raises(ValueError, match="step_nm"):
        calibrate_positioner(rig, rig, roi_at(TIP0))


@pytest.fixture(scope="module")
def calibrated():
    rig = StepperRig(seed=3)
    return calibrate_positioner(rig, rig, roi_at(TIP0))


@pytest.mark.parametrize("offset, lag", [((40.0, -25.0), 0.0), ((-15.0, 14.0), 0.0), ((0.0, 58.0), 0.3)])
def test_servo_lands_within_half_a_pixel_in_ten_frames(calibrated, offset, lag):
    # a fresh rig of the same kind: calibration error, jitter and lag are all in the loop
    rig = StepperRig(seed=3, lag=lag)
    roi = roi_at(TIP0)
    target = TIP0 + offset
    df = move_positioner_to(rig, rig, roi, target, calibration=calibrated, n_frames=16)
    err = true_errors(rig, df, target, roi)
    within = err <= 0.5
    first = int(np.argmax(within))
    assert within.any() and within[first:].all(), err.round(2)
    assert first <= 10
    # the clock: frame k at k frame periods after frame 0 (the rig has no time stamps)
    assert df["t"].to_numpy() == pytest.approx(np.arange(len(df)) / 13)
    assert df["ok"].all() and set(df.columns) >= {"frame", "t", "x", "y", "target_x", "target_y",
                                                  "error_px", "ok", "dx_nm", "dy_nm"}


def test_a_flagged_frame_sends_nothing(calibrated):
    rig = StepperRig(seed=3)
    roi = roi_at(TIP0)
    rig.blank = 0
    original = rig.grab
    calls = {"n": 0}

    def grab():  # servo frames 1 and 2 come back blank (the beam blanked); grab 1 is the ROI's frame
        calls["n"] += 1
        if calls["n"] - WARMUP_FRAMES in (2, 3):
            rig.blank = 1
        return original()

    rig.grab = grab
    df = move_positioner_to(rig, rig, roi, TIP0 + (30.0, 20.0), calibration=calibrated, n_frames=8)
    flagged = df[~df["ok"]]
    assert list(flagged["frame"]) == [1, 2]
    assert (flagged[["dx_nm", "dy_nm"]] == 0).all().all() and flagged["held"].all()
    # moves were sent after frame 0 and again once the tip was seen, none on the blank frames
    assert len(rig.moves) == int((df[["dx_nm", "dy_nm"]] != 0).any(axis=1).sum()) >= 2


@pytest.mark.parametrize("target, words", [((np.nan, 10.0), "not finite"), ((5000.0, 10.0), "outside"),
                                           ((10.0, math.inf), "not finite")])
def test_bad_targets_are_refused_before_anything_moves(calibrated, target, words):
    rig = StepperRig()
    with pytest.raises(ValueError, match=words):
        move_positioner_to(rig, rig, roi_at(TIP0), target, calibration=calibrated, n_frames=3)
    assert rig.moves == []


@pytest.mark.parametrize("gain", [1.0, 0.0, 1.5])
def test_gain_must_be_below_one(calibrated, gain):
    rig = StepperRig()
    with pytest.raises(ValueError, match="gain"):
        move_positioner_to(rig, rig, roi_at(TIP0), TIP0 + 20, calibration=calibrated, gain=gain)


def test_wrong_objects_are_type_errors(calibrated):
    rig = StepperRig()
    with pytest.raises(TypeError, match="Positioner"):
        move_positioner_to(rig, object(), roi_at(TIP0), TIP0, calibration=calibrated)
    with pytest.raises(TypeError, match="PositionerCalibration"):
        move_positioner_to(rig, rig, roi_at(TIP0), TIP0, calibration=np.eye(2))


def test_travel_limits_are_respected(calibrated):
    # x may travel only 300 nm either way: a target 40 px along the x axis needs ~2000 nm
    rig = StepperRig(seed=3, limits=((-300.0, 300.0), (-5000.0, 5000.0)))
    target = TIP0 + calibrated.to_image((2000.0, 0.0))
    df = move_positioner_to(rig, rig, roi_at(TIP0), target, calibration=calibrated, n_frames=8)
    asked = np.array(rig.asked)
    assert np.all(np.abs(asked[:, 0]) <= 300.0 + 1e-6)
    assert df["clipped"].any() and df["reason"].str.contains("limits").any()


def test_no_command_below_the_resolution(calibrated):
    rig = StepperRig(seed=3, resolution_nm=200.0)  # 200 nm ~ 4 px: the last corrections are impossible
    df = move_positioner_to(rig, rig, roi_at(TIP0), TIP0 + (30.0, 0.0), calibration=calibrated, n_frames=10)
    sent = np.abs(np.array(rig.moves))
    assert np.all((sent == 0) | (sent >= 200.0))
    assert df["reason"].str.contains("resolution").any()


def test_a_refused_move_is_held_and_recorded(calibrated):
    rig = StepperRig(seed=3)

    def refuse(dx, dy):
        raise ValueError("outside the travel")

    rig.move_by = refuse
    df = move_positioner_to(rig, rig, roi_at(TIP0), TIP0 + (25.0, 0.0), calibration=calibrated, n_frames=4)
    assert df["held"].iloc[:-1].all() and df["reason"].str.contains("refused").iloc[0]
    assert (df[["dx_nm", "dy_nm"]] == 0).all().all()


def test_calibration_maps_both_ways(calibrated):
    d = np.array([123.0, -45.0])
    assert calibrated.to_positioner(calibrated.to_image(d)) == pytest.approx(d)
    assert isinstance(calibrated, PositionerCalibration) and calibrated.condition < 2


def test_a_frame_that_cannot_be_grabbed_holds(calibrated):
    rig = StepperRig(seed=3)
    original, calls = rig.grab, {"n": 0}

    def grab():  # servo frame 2: the instrument times out
        calls["n"] += 1
        if calls["n"] - WARMUP_FRAMES == 3:
            raise TimeoutError("acquisition timed out")
        return original()

    rig.grab = grab
    df = move_positioner_to(rig, rig, roi_at(TIP0), TIP0 + (20.0, 5.0), calibration=calibrated, n_frames=6)
    row = df.iloc[2]
    assert not row["ok"] and row["held"] and "timed out" in row["reason"]
    assert row["dx_nm"] == 0 and row["dy_nm"] == 0


class TupleTracker:
    """semlab's Tracker answering ``(x, y, score, ok)`` tuples, as the VisualTracker protocol allows."""

    def __init__(self):
        from semlab.tracking import Tracker

        self.inner = Tracker()

    def init(self, frame, roi):
        r = self.inner.init(frame, roi)
        return r.x, r.y, r.score, r.ok

    def update(self, frame):
        r = self.inner.update(frame)
        return r.x, r.y, r.score, r.ok


def test_a_tracker_answering_tuples_calibrates_and_servoes_alike(calibrated):
    # the same frames (same seed) through the same tracker: the same Jacobian and the same moves, exactly
    rig = StepperRig(seed=3)
    cal = calibrate_positioner(rig, rig, roi_at(TIP0), tracker=TupleTracker())
    assert np.array_equal(cal.jacobian, calibrated.jacobian)
    runs = []
    for tracker in (None, TupleTracker()):
        rig = StepperRig(seed=3)
        runs.append(move_positioner_to(rig, rig, roi_at(TIP0), TIP0 + (20.0, 5.0), calibration=calibrated,
                                       n_frames=6, tracker=tracker))
    assert runs[0][["x", "y", "dx_nm", "dy_nm", "ok"]].equals(runs[1][["x", "y", "dx_nm", "dy_nm", "ok"]])


def test_a_malformed_roi_is_refused_before_anything_moves(calibrated):
    rig = StepperRig()
    for bad in ((1, 2, 3), (0, 0, -5, 5), (0, np.nan, 5, 5)):
        with pytest.raises(ValueError, match="roi"):
            move_positioner_to(rig, rig, bad, TIP0, calibration=calibrated, n_frames=3)
    with pytest.raises(TypeError, match="init"):
        calibrate_positioner(rig, rig, roi_at(TIP0), tracker=object())
    assert rig.moves == []


class _Doubting:
    """semlab's default tracker, but frames in ``doubt`` (counted from 1) come back flagged."""

    def __init__(self, doubt):
        from semlab.tracking import Tracker

        self.inner, self.doubt, self.n = Tracker(), doubt, 0

    def init(self, frame, roi):
        return self.inner.init(frame, roi)

    def update(self, frame):
        from semlab.tracking import TrackResult

        self.n += 1
        result = self.inner.update(frame)
        if self.doubt(self.n):
            return TrackResult(float("nan"), float("nan"), result.score, False, "inconsistent: a test's doubt")
        return result


def test_calibration_skips_a_few_flagged_frames_of_a_still_tip():
    # One frame in nine flagged: every measurement still finds its frames (the tip stands still).
    rig = StepperRig()
    cal = calibrate_positioner(rig, rig, roi_at(TIP0), tracker=_Doubting(lambda n: n % 9 == 0))
    assert 0 < cal.residual_px < 0.5 and len(cal.moves) == 8


def test_calibration_gives_up_on_a_tip_the_tracker_keeps_flagging():
    rig = StepperRig()
    with pytest.raises(CalibrationError, match="lost the tip"):
        calibrate_positioner(rig, rig, roi_at(TIP0), tracker=_Doubting(lambda n: n > 12))
