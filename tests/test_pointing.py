"""Servo to a point: two axes at once through the image Jacobian, several probes from one frame stream.

Most tests run on the fake stage of ``servo_fakes``: probes whose two piezo axes move the tip along
rotated, non-orthogonal image directions, each an independent hysteresis in neither model family.
"""

from __future__ import annotations

import inspect
import math

import numpy as np
import pandas as pd
import pytest
from servo_fakes import (
    FRAME_PERIOD,
    FakePiezo,
    FakeStage,
    FakeTracker,
    characterise,
    roi_at,
    set_voltages,
)

import semlab
from semlab.control import PID
from semlab.hysteresis import characterise_hysteresis, fit_hysteresis
from semlab.pointing import ProbeMove, image_jacobian, move_probe_to, move_probes_to, point_metrics


@pytest.fixture(scope="module")
def characterised():
    stage = FakeStage()
    return stage, [characterise(stage, 0), characterise(stage, 1)]


@pytest.fixture
def stage_at_mid(characterised):
    """A fresh stage whose probes sit mid-range, with copies of the fitted models as shadows."""
    _, fitted = characterised
    stage = FakeStage()
    models = [[m.copy() for m in ms] for ms in fitted]
    for ms in models:
        for m in ms:
            m.reset()  # the fresh stage is at 0 V after a descent, as the models' reset state
    for k in range(2):
        set_voltages(stage, k, models[k], [45.0, 50.0])
    return stage, models


# ---------------------------------------------------------------------------------------------
# contract
# ---------------------------------------------------------------------------------------------


def test_move_probe_to_contract_signature_and_export():
    assert semlab.move_probe_to is move_probe_to
    params = inspect.signature(move_probe_to).parameters
    assert list(params)[:4] == ["microscope", "actuator", "roi", "target_xy"]
    assert params["model"].kind is inspect.Parameter.KEYWORD_ONLY
    assert params["n_frames"].kind is inspect.Parameter.KEYWORD_ONLY and params["n_frames"].default == 60


def test_result_columns_rows_and_one_frame_latency(stage_at_mid):
    stage, models = stage_at_mid
    roi = roi_at(stage, 0)
    p0 = stage.position(0).copy()
    target = (p0[0] + 30.0, p0[1] - 20.0)
    u_before = [a.command for a in stage.axes(0)]
    resp = move_probe_to(stage, stage.axes(0), roi, target, model=models[0], n_frames=20,
                         tracker=FakeTracker(stage, 0))
    assert list(resp.columns[:10]) == ["frame", "t", "x", "y", "target_x", "target_y", "error_px", "ok", "u_0", "u_1"]
    assert len(resp) == 20 and resp["frame"].tolist() == list(range(20))
    np.testing.assert_allclose(resp["t"], np.arange(20) * FRAME_PERIOD)
    assert (resp["target_x"] == target[0]).all() and (resp["target_y"] == target[1]).all()
    # frame 0 is the ROI's frame, nothing has moved; both axes' feed-forward shows from frame 1
    assert resp["error_px"].iloc[0] == pytest.approx(math.hypot(30.0, 20.0))
    assert [resp["u_0"].iloc[0], resp["u_1"].iloc[0]] == u_before
    assert resp["u_0"].iloc[1] != u_before[0] and resp["u_1"].iloc[1] != u_before[1]
    np.testing.assert_allclose(resp["error_px"], np.hypot(resp.x - target[0], resp.y - target[1]))
    assert resp.attrs["axes"] == ["probe 0 x", "probe 0 y"]


# ---------------------------------------------------------------------------------------------
# accuracy with non-orthogonal axes (the fake tracker is the truth plus noise)
# ---------------------------------------------------------------------------------------------


def test_the_jacobian_is_the_measured_directions_not_orthogonal_axes(characterised):
    stage, fitted = characterised
    J = image_jacobian(fitted[0])
    np.testing.assert_allclose(J, np.column_stack([a.d for a in stage.axes(0)]), atol=1e-9)
    assert math.degrees(math.acos(J[:, 0] @ J[:, 1])) == pytest.approx(75.0, abs=1e-6)


@pytest.mark.parametrize("offset", [(25.0, 0.0), (0.0, -40.0), (-50.0, 35.0), (60.0, 55.0), (-30.0, 60.0)])
def test_two_axes_bring_the_tip_to_the_point(stage_at_mid, offset):
    stage, models = stage_at_mid
    roi = roi_at(stage, 0)
    p0 = stage.position(0).copy()
    target = p0 + np.array(offset)
    noise = 0.05
    resp = move_probe_to(stage, stage.axes(0), roi, tuple(target), model=models[0], n_frames=30,
                         tracker=FakeTracker(stage, 0, noise_px=noise))
    m = point_metrics(resp, final_frames=15)
    # the measured figures of the issue: in the band within 6 frames, no overshoot, still at the end
    assert m["response_frames"] <= 6 and m["overshoot_px"] <= 0.5 and m["final_std_px"] <= 0.2
    # ground truth: the tip is where it was asked to be, within the noise averaged by the integrator
    # (an integrator of 0.8 per frame passes sqrt(0.8 / 1.2) = 0.8 sigma of it to the probe, so the
    # mean of the last 15 frames is within ~0.1 sigma) plus the loop's lag behind the hysteresis
    assert np.hypot(*(stage.position(0) - target)) < 0.3
    # the feed-forward made both parts of the move in the first frame: within the 2.5 % margin plus
    # the PI model's error on a piezo outside its family (assuming orthogonal axes would miss by
    # sin(15 deg) ~ 26 % of the move)
    assert resp["error_px"].iloc[1] < 0.1 * np.hypot(*offset)


# ---------------------------------------------------------------------------------------------
# safety
# ---------------------------------------------------------------------------------------------


def test_lost_frames_hold_every_axis(stage_at_mid):
    stage, models = stage_at_mid
    f0 = stage.frame + 1
    lost = {f0 + 3, f0 + 4, f0 + 5}
    target = tuple(stage.position(0) + (40.0, 30.0))
    resp = move_probe_to(stage, stage.axes(0), roi_at(stage, 0), target, model=models[0], n_frames=30,
                         tracker=FakeTracker(stage, 0, lose=lost, noise_px=0.05))
    held = resp.index[~resp["ok"]]
    assert list(held) == [3, 4, 5] and resp.loc[held, "held"].all() and resp.loc[held, "error_px"].isna().all()
    for col in ("u_0", "u_1"):  # the commands in effect during and right after the lost frames
        assert resp[col].iloc[3] == resp[col].iloc[4] == resp[col].iloc[5] == resp[col].iloc[6]
    assert point_metrics(resp)["n_lost"] == 3
    assert np.hypot(*(stage.position(0) - target)) < 0.3


def test_nan_targets_and_nan_positions_are_refused(stage_at_mid):
    stage, models = stage_at_mid
    axes = stage.axes(0)
    for a in axes:
        a.sent.clear()
    with pytest.raises(ValueError, match="not finite"):
        move_probe_to(stage, axes, roi_at(stage, 0), (float("nan"), 3.0), model=models[0],
                      tracker=FakeTracker(stage, 0))
    with pytest.raises(ValueError, match="point"):
        move_probe_to(stage, axes, roi_at(stage, 0), (1.0, 2.0, 3.0), model=models[0], tracker=FakeTracker(stage, 0))
    assert all(a.sent == [] for a in axes)
    f0 = stage.frame + 1
    with pytest.raises(ValueError, match="non-finite position"):
        move_probe_to(stage, axes, roi_at(stage, 0), tuple(stage.position(0) + 10.0), model=models[0],
                      n_frames=10, tracker=FakeTracker(stage, 0, nan_ok={f0 + 2}))


def test_a_target_outside_the_frame_is_refused_before_anything_moves(characterised):
    _, fitted = characterised
    stage = FakeStage(n_probes=1)
    models = [m.copy() for m in fitted[0]]
    for m in models:
        m.reset()
    set_voltages(stage, 0, models, [45.0, 50.0])
    stage.frame_shape = (int(stage.position(0)[1]) + 30, 640)  # the probe 30 px above the bottom edge
    for a in stage.axes(0):
        a.sent.clear()
    target = tuple(stage.position(0) + (0.0, 40.0))  # reachable by the y axis, below the view
    with pytest.raises(ValueError, match="out of the 640x"):
        move_probe_to(stage, stage.axes(0), roi_at(stage, 0), target, model=models, tracker=FakeTracker(stage, 0))
    assert all(a.sent == [] for a in stage.axes(0))


def test_refused_only_beyond_an_axis_limit_and_never_driven_past_one(characterised):
    # characterised over 20-80 V of the 0-100 V axes: moves beyond that range are made
    _, _ = characterised
    stage = FakeStage(n_probes=1, frame_shape=(900, 900))  # a view that holds every move here
    models = characterise(stage, 0, (20.0, 80.0))
    set_voltages(stage, 0, models, [25.0, 50.0])
    x_axis = stage.axes(0)[0]
    p0 = stage.position(0).copy()
    # a move along the x axis' direction that needs about 15 V below the characterised 20 V
    target = p0 - 45.0 * x_axis.d
    resp = move_probe_to(stage, stage.axes(0), roi_at(stage, 0), tuple(target), model=models, n_frames=25,
                         tracker=FakeTracker(stage, 0))
    assert min(x_axis.sent) < 20.0 and np.hypot(*(stage.position(0) - target)) < 0.1
    assert not resp["at_limit"].any()
    # beyond what the x axis can do at 0 V: refused, naming the axis, before anything moves
    for a in stage.axes(0):
        a.sent.clear()
    with pytest.raises(ValueError, match="axis 0's part of the move.*'probe 0 x' can reach within its limits"):
        move_probe_to(stage, stage.axes(0), roi_at(stage, 0), tuple(stage.position(0) - 200.0 * x_axis.d),
                      model=models, tracker=FakeTracker(stage, 0))
    assert all(a.sent == [] for a in stage.axes(0))
    # an aggressive PID with noise near the top of the y axis: every command stays within the limits
    set_voltages(stage, 0, models, [50.0, 95.0])
    y_axis = stage.axes(0)[1]
    top = FakePiezo(stage, "top", y_axis.gain, 0.0)
    top.apply(100.0)
    top._latch()
    resp = move_probe_to(stage, stage.axes(0), roi_at(stage, 0),
                         tuple(stage.position(0) + (top.disp - y_axis.disp + 1.0) * y_axis.d), model=models,
                         n_frames=25, feedforward=False, pid=PID(kp=1.5, ki=1.5),
                         tracker=FakeTracker(stage, 0, noise_px=0.3))
    for a in stage.axes(0):
        assert all(a.limits[0] <= v <= a.limits[1] for v in a.sent)
    assert resp["at_limit"].any() and resp["u_1"].max() == 100.0


def test_bad_inputs():
    stage = FakeStage(n_probes=1)
    axes = stage.axes(0)
    models = characterise(stage, 0)
    with pytest.raises(ValueError, match="one fitted model per axis"):
        move_probe_to(stage, axes, roi_at(stage, 0), (10.0, 10.0), model=models[:1], tracker=FakeTracker(stage, 0))
    with pytest.raises(ValueError, match="fitted on axis"):
        move_probe_to(stage, axes, roi_at(stage, 0), (10.0, 10.0), model=models[::-1], tracker=FakeTracker(stage, 0))
    with pytest.raises(TypeError, match="unknown parameter"):
        move_probe_to(stage, axes, roi_at(stage, 0), (10.0, 10.0), model=models, gain=2.0)
    with pytest.raises(TypeError, match="not an Axis"):
        move_probe_to(stage, [object(), axes[1]], roi_at(stage, 0), (10.0, 10.0), model=models)
    with pytest.raises(ValueError, match="n_frames"):
        move_probe_to(stage, axes, roi_at(stage, 0), (10.0, 10.0), model=models, n_frames=1)
    parallel = [m.copy() for m in models]
    parallel[1].direction = tuple(np.array(parallel[0].direction) * -1.0 + [0.0, 0.05])
    with pytest.raises(ValueError, match="nearly parallel"):
        image_jacobian(parallel)


# ---------------------------------------------------------------------------------------------
# several probes, one frame stream
# ---------------------------------------------------------------------------------------------


def _two_probe_moves(stage, models, targets, trackers):
    return [ProbeMove(stage.axes(k), roi_at(stage, k), tuple(stage.position(k) + targets[k]), models[k],
                      {"tracker": trackers[k]}) for k in range(2)]


def test_probes_share_each_frame_and_each_reaches_its_point(stage_at_mid):
    stage, models = stage_at_mid
    trackers = [FakeTracker(stage, k, noise_px=0.05, seed=k) for k in range(2)]
    moves = _two_probe_moves(stage, models, [np.array([40.0, -30.0]), np.array([-55.0, 20.0])], trackers)
    grabs = stage.grabs
    resp = move_probes_to(stage, moves, n_frames=30)
    assert stage.grabs - grabs == 30  # each frame grabbed once for both probes
    assert [t.updates for t in trackers] == [29, 29]  # and measured once by each probe's tracker
    assert list(resp.columns[:9]) == ["probe", "frame", "t", "x", "y", "target_x", "target_y", "error_px", "ok"]
    for k, mv in enumerate(moves):
        m = point_metrics(resp[resp.probe == k], final_frames=15)
        assert m["response_frames"] <= 6 and m["overshoot_px"] <= 0.5
        assert np.hypot(*(stage.position(k) - mv.target_xy)) < 0.3


def test_moving_one_probe_does_not_disturb_the_loop_of_another(characterised):
    _, fitted = characterised

    def run(move_a):
        stage = FakeStage()
        models = [[m.copy() for m in ms] for ms in fitted]
        for ms in models:
            for m in ms:
                m.reset()
        for k in range(2):
            set_voltages(stage, k, models[k], [45.0, 50.0])
        moves = _two_probe_moves(stage, models, [np.array([60.0, -45.0]) if move_a else np.zeros(2),
                                                 np.array([-35.0, 25.0])],
                                 [FakeTracker(stage, 0), FakeTracker(stage, 1, noise_px=0.05, seed=1)])
        return stage, move_probes_to(stage, moves, n_frames=25)

    _, with_a = run(True)
    _, without_a = run(False)
    a = with_a[with_a.probe == 0]
    assert a["error_px"].iloc[-1] < 0.3 and a["error_px"].iloc[0] > 70  # probe 0 did move
    b_with = with_a[with_a.probe == 1].reset_index(drop=True)
    b_without = without_a[without_a.probe == 1].reset_index(drop=True)
    # probe 1's measurements, commands and errors are the same whether probe 0 moved or not
    pd.testing.assert_frame_equal(b_with, b_without)
    # and a probe told to stay (seen by an exact tracker) holds its commands exactly
    still = without_a[without_a.probe == 0]
    assert still["u_0"].nunique() == 1 and still["u_1"].nunique() == 1


def test_a_move_one_probe_cannot_make_stops_every_probe_before_anything_moves(stage_at_mid):
    stage, models = stage_at_mid
    x_axis = stage.axes(1)[0]
    moves = [ProbeMove(stage.axes(0), roi_at(stage, 0), tuple(stage.position(0) + 30.0), models[0]),
             ProbeMove(stage.axes(1), roi_at(stage, 1), tuple(stage.position(1) + 500.0 * x_axis.d), models[1])]
    for k in range(2):
        for a in stage.axes(k):
            a.sent.clear()
    grabs = stage.grabs
    with pytest.raises(ValueError, match="'probe 1 x' can reach"):
        move_probes_to(stage, moves, n_frames=10, tracker=None)
    assert all(a.sent == [] for k in range(2) for a in stage.axes(k)) and stage.grabs == grabs


def test_probes_must_not_share_an_axis(stage_at_mid):
    stage, models = stage_at_mid
    moves = [ProbeMove(stage.axes(0), roi_at(stage, 0), tuple(stage.position(0)), models[0]),
             ProbeMove(stage.axes(0), roi_at(stage, 0), tuple(stage.position(0)), models[0])]
    with pytest.raises(ValueError, match="another probe drives"):
        move_probes_to(stage, moves, n_frames=5, tracker=None)


# ---------------------------------------------------------------------------------------------
# integration: the simulated rig and the real tracker, judged by the ground truth
# ---------------------------------------------------------------------------------------------


def _rig_ready(seed):
    """A simulated rig whose probe 0 is characterised on both axes and parked mid-range; its ROI."""
    from semlab.roi import roi_from_click
    from semlab.sim import SimulatedRig

    rig = SimulatedRig(seed=seed)
    frame = rig.microscope.grab()
    tip = rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0]
    roi = roi_from_click(frame, tip, size=160)
    axes = [rig.axis(0, "x"), rig.axis(0, "y")]
    models = []
    for axis, (lo, hi) in zip(axes, [(0.0, 30.0), (0.0, 100.0)]):
        char = characterise_hysteresis(rig.microscope, axis, roi, u_min=lo, u_max=hi, n_steps=10)
        models.append(fit_hysteresis(char, kind="pi"))
        frame = rig.microscope.grab()
        tip = rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0]
        roi = roi_from_click(frame, tip, size=160)
    for axis, model, v in zip(axes, models, (15.0, 50.0)):
        for u in np.linspace(axis.command, v, 6)[1:]:
            axis.apply(u)
            model.forward(u)
            rig.microscope.grab()
    frame = rig.microscope.grab()
    tip0 = rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0]
    roi = roi_from_click(frame, tip0, size=160)
    centre = np.array([roi[0] + (roi[2] - 1) / 2, roi[1] + (roi[3] - 1) / 2])
    return rig, axes, models, roi, centre, tip0


def test_simulated_rig_two_axes_to_a_point_by_the_truth():
    rig, axes, models, roi, centre, tip0 = _rig_ready(5)
    offset = np.array([35.0, -30.0])
    resp = move_probe_to(rig.microscope, axes, roi, tuple(centre + offset), model=models, n_frames=25)
    moved = rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0] - tip0
    assert resp["ok"].all()
    # the truth within 0.5 px: the tracker's error after a 46-px move on this scene is ~0.1-0.3 px
    assert np.hypot(*(moved - offset)) < 0.5


def test_frames_the_tracker_finds_too_uncertain_hold_every_axis():
    # The tracker flags a frame whose position it cannot vouch for (sigma above max_sigma) with ok=False and
    # no position: the servo must not act on it. A max_sigma no fit reaches flags every frame after the first.
    from semlab.tracking import Tracker

    rig, axes, models, roi, centre, tip0 = _rig_ready(6)
    for feedforward in (True, False):
        resp = move_probe_to(rig.microscope, axes, roi, tuple(centre + (30.0, 20.0)), model=models, n_frames=8,
                             tracker=Tracker(max_sigma=1e-9), feedforward=feedforward)
        assert not resp["ok"].iloc[1:].any() and resp["held"].iloc[1:].all()
        assert resp[["x", "y", "error_px"]].iloc[1:].isna().all().all()
        # only the command sent on frame 0 (from the ROI the caller gave): nothing after a flagged frame
        for col, axis in zip(("u_0", "u_1"), axes):
            assert resp[col].iloc[1:].nunique() == 1 and axis.command == resp[col].iloc[-1]
        tip = rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0]
        roi = (roi[0] + round(tip[0] - tip0[0]), roi[1] + round(tip[1] - tip0[1]), roi[2], roi[3])
        centre, tip0 = centre + np.round(tip - tip0), tip
