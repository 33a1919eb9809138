"""semlab.pointing.point_metrics on a hand-built 2-D move whose figures are known by construction, and
image_jacobian's angle rule from the singular values of two unit columns (sqrt(1 +- cos a)).

The path is written in the move's own frame (s along start -> target, l across it) and rotated into the
image, so every figure is a number chosen here; the only tolerance is float rounding (1e-9 px).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from semlab.hysteresis import PolynomialHysteresis
from semlab.pointing import MIN_AXIS_ANGLE_DEG, image_jacobian, point_metrics

DT = 0.1
START, TARGET = np.array([100.0, 200.0]), np.array([130.0, 240.0])  # 50 px along (0.6, 0.8)
UNIT, PERP = np.array([0.6, 0.8]), np.array([-0.8, 0.6])
# frame: (s along, l across); frame 7 is lost (reported far away: it must not count)
PATH = [(0.0, 0.0), (30.0, 2.0), (48.0, -1.5), (51.2, 0.3), (50.7, 0.0), (49.8, 0.0), (50.3, 0.0),
        (None, None), (50.6, 0.0)] + [(50.1 if k % 2 else 49.9, 0.2) for k in range(12)]


def response(path=PATH, *, first_frame=100, t0=5.0, target=TARGET):
    rows = []
    for k, (s, l) in enumerate(path):
        ok = s is not None
        p = START + s * UNIT + l * PERP if ok else np.array([1e3, 1e3])
        rows.append({"frame": first_frame + k, "t": t0 + DT * k, "x": p[0], "y": p[1], "target_x": target[0],
                     "target_y": target[1], "ok": ok})
    return pd.DataFrame(rows, index=np.arange(len(rows)) * 3 + 7)  # an index that is not 0..n-1


def test_figures_of_a_hand_built_move():
    m = point_metrics(response(), final_frames=10)
    assert m["distance_px"] == pytest.approx(50.0, abs=1e-9)
    # last valid frame beyond 0.5 px: frame 8 (0.6 px off); beyond 1 px: frame 3 (hypot(1.2, 0.3))
    assert (m["response_frames"], m["response_time_s"]) == (9, pytest.approx(0.9, abs=1e-9))
    assert (m["response_frames_1px"], m["response_time_1px_s"]) == (4, pytest.approx(0.4, abs=1e-9))
    assert m["overshoot_px"] == pytest.approx(1.2, abs=1e-9)  # frame 3, along the move
    assert m["lateral_px"] == pytest.approx(2.0, abs=1e-9)  # frame 1, across it
    # the last 10 valid frames alternate 49.9 / 50.1 along, 0.2 across: mean 0.2 px off the target;
    # std along = 0.1 sqrt(10/9) (ddof=1), of which y carries 0.8 and x 0.6: the larger is y's
    assert m["final_error_px"] == pytest.approx(0.2, abs=1e-9)
    assert m["final_std_px"] == pytest.approx(0.08 * math.sqrt(10 / 9), abs=1e-9)
    assert m["n_lost"] == 1
    # within 0.65 px frame 8 (0.6) is in, frame 4 (0.7) the last one out
    assert point_metrics(response(), final_frames=10, tolerance_px=0.65)["response_frames"] == 5


def test_a_move_that_never_settles_or_ends_outside_the_band():
    last_off = PATH + [(50.7, 0.0)]  # the last valid frame is 0.7 px off: not settled within 0.5 px
    m = point_metrics(response(last_off))
    assert math.isnan(m["response_frames"]) and math.isnan(m["response_time_s"])
    assert m["response_frames_1px"] == 4
    # a lost frame after the last valid one changes nothing
    m = point_metrics(response(PATH + [(None, None)]), final_frames=10)
    assert m["response_frames"] == 9 and m["n_lost"] == 2
    never = [(0.0, 0.0), (20.0, 0.0), (40.0, 0.0)]
    m = point_metrics(response(never))
    assert math.isnan(m["response_frames_1px"]) and m["overshoot_px"] == 0.0
    assert m["final_error_px"] == pytest.approx(math.hypot(*(TARGET - START - 20.0 * UNIT)), abs=1e-9)


def test_no_move_and_no_valid_frame():
    still = point_metrics(response([(0.0, 0.0), (0.0, 0.3), (0.0, -0.1)], target=START))
    assert still["distance_px"] == 0.0 and still["overshoot_px"] == 0.0 and still["response_frames"] == 0
    lost = point_metrics(response([(None, None), (None, None)]))
    assert math.isnan(lost["response_frames"]) and math.isnan(lost["lateral_px"])
    assert math.isnan(lost["final_error_px"]) and math.isnan(lost["final_std_px"]) and lost["n_lost"] == 2
    one = point_metrics(response([(None, None), (50.0, 0.0)]))
    assert one["final_error_px"] == pytest.approx(0.0, abs=1e-9) and math.isnan(one["final_std_px"])


def test_bad_responses():
    with pytest.raises(TypeError, match="DataFrame"):
        point_metrics(response().to_dict())
    with pytest.raises(ValueError, match=r"lacks column\(s\) \['target_y'\]"):
        point_metrics(response().drop(columns="target_y"))
    with pytest.raises(ValueError, match="fewer than 2 rows"):
        point_metrics(response()[:1])


def model_along(deg):
    return PolynomialHysteresis([0.0, 1.0], [0.0, 1.0], (0.0, 1.0),
                                direction=(math.cos(math.radians(deg)), math.sin(math.radians(deg))))


@pytest.mark.parametrize("second_deg, ok", [(MIN_AXIS_ANGLE_DEG + 0.1, True), (MIN_AXIS_ANGLE_DEG - 0.1, False),
                                             (180.0 - MIN_AXIS_ANGLE_DEG - 0.1, True),
                                             (180.0 - MIN_AXIS_ANGLE_DEG + 0.1, False), (90.0, True)])
def test_two_axes_must_be_at_least_the_minimum_angle_apart_either_way(second_deg, ok):
    models = [model_along(30.0), model_along(30.0 + second_deg)]
    if ok:
        J = image_jacobian(models)
        np.testing.assert_allclose(J, np.column_stack([m.direction for m in models]), atol=1e-15)
    else:
        with pytest.raises(ValueError, match="nearly parallel"):
            image_jacobian(models)


def test_three_axes_and_one_axis():
    image_jacobian([model_along(0.0), model_along(5.0), model_along(60.0)])  # two of them far enough apart
    with pytest.raises(ValueError, match="nearly parallel"):
        image_jacobian([model_along(0.0), model_along(4.0), model_along(8.0)])
    with pytest.raises(ValueError, match="at least two axes"):
        image_jacobian([model_along(0.0)])
