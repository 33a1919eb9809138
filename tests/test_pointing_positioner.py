"""The positioner form of ``semlab.move_probe_to``: a closed-loop manipulator (protocol ``Positioner``) with
``model=`` its calibration, through fibsem's offline DemoMicroscope and semlab's simulated needle
(:class:`semlab.instruments.demo.SimulatedNeedle`: a rotated, skewed, foreshortened view and imperfect moves
that only the test knows). Needs ``fibsem`` (``make setup`` installs it); skips without it outside CI.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

# skips this module as well when fibsem is missing (outside CI)
import test_instruments_fibsem as adapter_tests

import semlab
from semlab.instruments.demo import SimulatedNeedle
from semlab.instruments.fibsem import FibsemManipulator, FibsemMicroscope
from semlab.pointing import POINT_COLUMNS, ProbeMove, move_probe_to, move_probes_to, point_metrics
from semlab.positioning import WARMUP_FRAMES, calibrate_positioner
from semlab.protocols import Positioner
from semlab.roi import roi_from_click

# fibsem's Demo, its manipulator at the origin for each test, its needle removed after: the adapter tests' fixtures
fib, demo = adapter_tests.fib, adapter_tests.demo

ROI = 200


def calibrated(demo, seed=0, limits=None, **needle):
    """The bridge, microscope, manipulator, ROI and calibration; the needle back at its start after."""
    bridge = SimulatedNeedle(demo, seed=seed, **needle)
    demo.semlab_needle = bridge  # removed by the fixture
    scope = FibsemMicroscope(demo, image_settings=adapter_tests.ImageSettings(**adapter_tests.SETTINGS))
    arm = FibsemManipulator(demo, limits=limits)
    roi = roi_from_click(scope.grab(), bridge.tip0, size=ROI)
    return bridge, scope, arm, roi, calibrate_positioner(scope, arm, roi)


def centre(roi):
    return np.array([roi[0] + (ROI - 1) / 2, roi[1] + (ROI - 1) / 2])


def true_errors(bridge, df, roi, target):
    """Ground truth: where the ROI's centre point really is at each row, minus the target."""
    truth = bridge.truth.iloc[-len(df):][["x", "y"]].to_numpy()
    return np.hypot(*(np.asarray(target) - (centre(roi) + truth - truth[0])).T)


def test_a_positioner_is_servoed_to_the_point_with_the_contract_columns(demo):
    bridge, scope, arm, roi, cal = calibrated(demo, seed=3, rotation_deg=-30.0, skew_deg=6.0)
    assert isinstance(arm, Positioner)
    target = centre(roi) + (-35.0, 22.0)
    df = semlab.move_probe_to(scope, arm, roi, tuple(target), model=cal, n_frames=13)
    # the contract's columns first, then one command column per axis, as for piezo axes
    assert tuple(df.columns[:len(POINT_COLUMNS)]) == POINT_COLUMNS
    assert list(df.columns[len(POINT_COLUMNS):len(POINT_COLUMNS) + 2]) == ["u_0", "u_1"]
    assert len(df) == 13 and list(df["frame"]) == list(range(13)) and df["ok"].all()
    assert df.attrs["form"] == "positioner" and (df["target_x"] == target[0]).all()
    # u_i is the offset commanded before the frame: the running sum of the moves sent after earlier frames
    assert df.loc[0, ["u_0", "u_1"]].tolist() == [0.0, 0.0]
    np.testing.assert_allclose(df["u_0"].iloc[1:], df["dx_nm"].cumsum().iloc[:-1], atol=1e-9)
    # by the truth within 0.5 px by frame 10 and staying (the Demo servo's figure, test_instruments_fibsem.py)
    err = true_errors(bridge, df, roi, target)
    first_in = int(np.argmax(err <= 0.5))
    assert (err[first_in:] <= 0.5).all() and first_in <= 10, err.round(2)
    # the measured offset along the axes, through the calibration, ends near the commanded one (within the
    # moves' few-% shortfall and coupling: 10 % of the ~1000-nm move per axis)
    end = df[["disp_0", "disp_1"]].iloc[-1].to_numpy()
    assert np.all(np.abs(end - df[["u_0", "u_1"]].iloc[-1].to_numpy()) < 0.1 * np.abs(end).max())
    assert point_metrics(df, final_frames=3)["final_error_px"] < 0.5  # the tracker agrees it is there


def test_a_positioner_holds_on_a_frame_the_tracker_flags(demo):
    bridge, scope, arm, roi, cal = calibrated(demo, seed=4)
    target = centre(roi) + (45.0, 10.0)
    bridge.schedule(blank=[WARMUP_FRAMES + 2], hide=[WARMUP_FRAMES + 3])  # servo frames 2 and 3
    df = move_probe_to(scope, arm, roi, target, model=cal, n_frames=12)
    flagged = df[~df["ok"]]
    assert list(flagged["frame"]) == [2, 3] and flagged["held"].all()
    assert (flagged[["dx_nm", "dy_nm"]] == 0).all().all() and flagged["error_px"].isna().all()
    # nothing was sent after them: the command in effect at frames 3 and 4 is frame 2's
    assert df.loc[2, ["u_0", "u_1"]].tolist() == df.loc[3, ["u_0", "u_1"]].tolist() == df.loc[4, ["u_0", "u_1"]].tolist()
    truth = bridge.truth.iloc[-len(df):].reset_index(drop=True)
    assert truth.loc[2, ["x_nm", "y_nm"]].tolist() == truth.loc[4, ["x_nm", "y_nm"]].tolist()


def test_a_positioner_refuses_a_nan_target_and_foreign_parameters_before_moving(demo):
    _bridge, scope, arm, roi, cal = calibrated(demo, seed=1)
    before = arm.position_nm
    with pytest.raises(ValueError, match="not finite"):
        move_probe_to(scope, arm, roi, (math.nan, 200.0), model=cal)
    with pytest.raises(TypeError, match="PositionerCalibration"):
        move_probe_to(scope, arm, roi, tuple(centre(roi) + 10), model=[cal, cal])
    with pytest.raises(TypeError, match="do not apply to a positioner"):
        move_probe_to(scope, arm, roi, tuple(centre(roi) + 10), model=cal, feedforward=True)
    with pytest.raises(TypeError, match="positioner"):
        move_probes_to(scope, [ProbeMove(arm, roi, tuple(centre(roi) + 10), cal)])
    assert arm.position_nm == pytest.approx(before)  # nothing moved


def test_a_positioner_is_refused_only_beyond_its_travel_and_never_driven_past_it(demo):
    # travel: 1500 nm to the right of the calibrated start, i.e. ~30 px along the x axis' image direction
    bridge, scope, _arm, roi, cal = calibrated(demo, seed=2, rotation_deg=0.0, skew_deg=0.0, scale=(1.0, 1.0))
    x0, y0 = FibsemManipulator(demo).position_nm
    limits = ((x0 - 5000.0, x0 + 1500.0), (y0 - 5000.0, y0 + 5000.0))
    arm = FibsemManipulator(demo, limits=limits)
    px_per_nm = cal.jacobian[0, 0]
    # 60 px needs 3000 nm: twice the travel, beyond any calibration error -> refused, with the reason
    with pytest.raises(ValueError, match=r"outside its travel .* calibration 10% error"):
        move_probe_to(scope, arm, roi, tuple(centre(roi) + (3000 * px_per_nm, 0.0)), model=cal, n_frames=4)
    assert arm.position_nm == pytest.approx((x0, y0))
    # a target at the limit itself is tried, not refused, and the manipulator never leaves its travel
    target = centre(roi) + (1500 * px_per_nm, 0.0)
    df = move_probe_to(scope, arm, roi, tuple(target), model=cal, n_frames=10)
    assert df["ok"].all()
    lo, hi = np.asarray(limits).T
    truth = bridge.truth.iloc[-len(df):][["x_nm", "y_nm"]].to_numpy()
    # the encoder reading obeys the limits (the 1-nm slack: float rounding of nm <-> m)
    assert np.all(np.asarray(arm.position_nm) <= hi + 1.0) and np.all(np.asarray(arm.position_nm) >= lo - 1.0)
    assert np.all(truth <= hi + 1.0) and np.all(truth >= lo - 1.0)  # at every frame, by the truth
    # it got as far as the travel lets it: within 1 px of the limit's image point by the truth
    assert true_errors(bridge, df, roi, target)[-1] < 1.0
