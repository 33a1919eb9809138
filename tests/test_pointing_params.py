"""move_probe_to's per-axis parameters and the Jacobian it records, on the fake stage of ``servo_fakes``
(two hysteretic axes at 75 deg in the image, the fake tracker reporting the truth): fast, no images."""

from __future__ import annotations

import numpy as np
import pytest
import servo_fakes

from semlab.control import PID, check_in_frame
from semlab.pointing import image_jacobian, move_probe_to


@pytest.fixture(scope="module")
def fitted():
    return servo_fakes.characterise(servo_fakes.FakeStage(1), 0)


def fresh(fitted):
    stage = servo_fakes.FakeStage(1)
    models = [m.copy() for m in fitted]
    for m in models:
        m.reset()  # the fresh stage is at 0 V after a descent, the models' reset state
    servo_fakes.set_voltages(stage, 0, models, [45.0, 50.0])
    return stage, models


def move(fitted, **params):
    stage, models = fresh(fitted)
    roi = servo_fakes.roi_at(stage, 0)
    target = np.array(stage.position(0)) + (12.0, -9.0)
    return move_probe_to(stage, stage.axes(0), roi, target, model=models, tracker=servo_fakes.FakeTracker(stage, 0),
                         n_frames=8, **params), models


def test_one_pid_per_axis_given_or_copied(fitted):
    shared, models = move(fitted, pid=PID(kp=0.1, ki=0.5))
    each, _ = move(fitted, pid=[PID(kp=0.1, ki=0.5), PID(kp=0.1, ki=0.5)])
    # a copied PID and two equal PIDs are the same law on each axis: the same run to rounding
    np.testing.assert_allclose(each[["x", "y"]], shared[["x", "y"]], atol=1e-9)
    np.testing.assert_allclose(shared.attrs["jacobian"], image_jacobian(models), atol=1e-12)
    with pytest.raises(ValueError, match="pid has 3 entries for 2 axes"):
        move(fitted, pid=[PID(), PID(), PID()])


def test_the_roi_may_reach_the_frame_edge_to_half_a_pixel():
    # the ROI covers pixels [x0, x0 + w): it may end on the last pixel's outer half (cols + 0.5)
    check_in_frame((359.5, -0.5, 41, 41), (0.0, 0.0), (400, 400))
    check_in_frame((0.0, 0.0, 41, 41), (359.5, 359.5), (400, 400))
    for roi, shift in (((359.6, 0, 41, 41), (0, 0)), ((0, 359.6, 41, 41), (0, 0)), ((0, 0, 41, 41), (-0.6, 0)),
                       ((0, 0, 41, 41), (0, -0.6))):
        with pytest.raises(ValueError, match=r"out of the 400x400 frame"):
            check_in_frame(roi, shift, (400, 400))
