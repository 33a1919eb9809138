"""The control law of one axis (AxisLoop, paper Fig. 8a) and step_response around it, in a world where the model is exact: a linear
axis y = G (u - U0) / (Un - U0) px, no hysteresis, no noise, the command acting from the next frame.

There the loop's output is known in closed form from its documented law -- the feed-forward stops
short by ``ff_margin`` of the move, then ``y[k+1] = goal + c[k]`` (feed-forward) or ``y[k+1] = c[k]``
(PID only) with ``c`` a :class:`PID` on the measurement -- so the displacements must match that
recursion to rounding (1e-9 px on moves of ~20 px: a few model inversions, each exact to 1e-12 of the
range). The PID itself is checked against python-control in ``test_pid_oracle.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import servo_fakes

from semlab.control import (
    PID,
    REACH_SLOPE_FACTOR,
    REACH_TOLERANCE,
    AxisLoop,
    move_to,
    step_response,
)
from semlab.hysteresis import PolynomialHysteresis

G = 400.0  # px over the characterised range
RANGE = (0.0, 100.0)
GAIN = G / (RANGE[1] - RANGE[0])  # px/V
ATOL = 1e-9


class LinearAxis:
    """An axis with limits that reports the command it holds (optionally quantised, like a DAC)."""

    name = "lin 0 x"

    def __init__(self, u, limits=RANGE, step_v=None):
        self.limits, self.step_v, self.u = limits, step_v, float(u)
        self.sent = []

    def apply(self, volts):
        assert self.limits[0] <= volts <= self.limits[1]
        self.sent.append(float(volts))
        self.u = float(volts) if self.step_v is None else round(volts / self.step_v) * self.step_v

    @property
    def command(self):
        return self.u


def exact_model(u_start):
    m = PolynomialHysteresis([0.0, G], [0.0, G], RANGE, axis="lin 0 x")
    m.reset(u_start)
    return m


def run(loop, axis, target, n, u_start, *, measure=None):
    """Drive ``loop`` for ``n`` frames; the measurement of frame k+1 is the truth of the command of frame
    k, from the start position. Returns the measured displacements of frames 0..n."""
    truth = measure or (lambda u: GAIN * (u - u_start))
    ys = [truth(axis.u)]
    loop.begin(target, ys[0], 0)
    for k in range(n):
        loop.act(ys[-1], k)
        ys.append(truth(axis.u))
    return np.array(ys)


def feedforward_law(step, kp, ki, margin, n, u0):
    """Measured displacements of frames 0..n: the feed-forward lands short by margin * step, then
    y[k+1] = step + c[k] with c the PID on the measurement (limits: the model at the axis limits)."""
    pid = PID(kp=kp, ki=ki)
    pid.reset(-margin * step)
    pid.set_limits(GAIN * RANGE[0] - G * u0 / 100 - step, GAIN * RANGE[1] - G * u0 / 100 - step)
    ys = [0.0, step * (1 - margin)]
    for _ in range(n - 1):
        c = pid.update(step, ys[-1])
        pid.track(c)
        ys.append(step + c)
    return np.array(ys), pid


@pytest.mark.parametrize("kp, ki, margin", [(0.0, 0.8, 0.025), (0.3, 0.5, 0.1), (0.6, 0.2, 0.0)])
def test_feedforward_then_pid_on_the_goal_follows_its_law(kp, ki, margin):
    u0, step = 30.0, 20.0
    axis = LinearAxis(u0)
    loop = AxisLoop(axis, exact_model(u0), frame_period=0.1, pid=PID(kp=kp, ki=ki), ff_margin=margin)
    ys = run(loop, axis, step, 30, u0)
    expected, pid = feedforward_law(step, kp, ki, margin, 30, u0)
    np.testing.assert_allclose(ys, expected, atol=ATOL)
    assert abs(ys[-1] - step) < 1e-3 * step  # integral action: no steady-state error
    assert loop.pid.output_limits == pytest.approx(pid.output_limits)


def test_pid_only_moves_the_command_by_the_pid_output_over_the_gain():
    u0, step = 60.0, -15.0
    axis = LinearAxis(u0)
    loop = AxisLoop(axis, exact_model(u0), frame_period=0.1, feedforward=False, pid=PID(kp=0.2, ki=0.4))
    ys = run(loop, axis, step, 25, u0)
    pid = PID(kp=0.2, ki=0.4)  # reset(0): no feed-forward, nothing to stop short of
    pid.set_limits((RANGE[0] - u0) * GAIN, (RANGE[1] - u0) * GAIN)
    expected = [0.0]
    for _ in range(25):
        c = pid.update(step, expected[-1])
        pid.track(c)
        expected.append(c)  # y[k+1] = G (u_ref + c/G - u_ref)
    np.testing.assert_allclose(ys, expected, atol=ATOL)
    np.testing.assert_allclose(axis.sent, u0 + np.array(expected[1:]) / GAIN, atol=ATOL)
    assert loop.pid.output_limits == pytest.approx(pid.output_limits)


def test_default_gains_with_and_without_feedforward():
    assert AxisLoop(LinearAxis(50.0), exact_model(50.0), frame_period=0.1).pid.ki == 0.8
    assert AxisLoop(LinearAxis(50.0), exact_model(50.0), frame_period=0.1, feedforward=False).pid.ki == 0.45


def test_reach_is_the_model_at_the_limits_and_the_generous_reach_its_documented_allowance():
    u0 = 30.0
    model = exact_model(u0)
    loop = AxisLoop(LinearAxis(u0, limits=(-10.0, 110.0)), model, frame_period=0.1)
    y_model = model.state.y
    s_lo, s_hi = model.extrapolation_slopes
    lo_m, hi_m = model.displacement(-10.0), model.displacement(110.0)
    y_meas = 5.0  # any measurement frame: the reach is relative to it
    assert loop.reach(y_meas) == pytest.approx((y_meas + lo_m - y_model, y_meas + hi_m - y_model), abs=ATOL)
    # generous: (1 + tolerance) times the predicted distance, plus (factor - 1) times the slope of the
    # extrapolation beyond the characterised range (10 V each side here)
    g_hi = y_meas + (1 + REACH_TOLERANCE) * (hi_m - y_model) + (REACH_SLOPE_FACTOR - 1) * s_hi * 10.0
    g_lo = y_meas + (1 + REACH_TOLERANCE) * (lo_m - y_model) - (REACH_SLOPE_FACTOR - 1) * s_lo * 10.0
    assert loop.reach(y_meas, generous=True) == pytest.approx((g_lo, g_hi), abs=ATOL)
    loop.check_reach(g_hi - 1e-6, y_meas)
    loop.check_reach(g_lo + 1e-6, y_meas)
    with pytest.raises(ValueError, match=r"outside what 'lin 0 x' can reach.*steeper than its extrapolation"):
        loop.check_reach(g_hi + 1e-6, y_meas)
    with pytest.raises(ValueError, match="outside what"):
        loop.check_reach(g_lo - 1e-6, y_meas)


def test_reach_within_the_characterised_range_allows_the_tolerance_only():
    u0 = 90.0  # 10 V = 40 px below the upper limit, which is the end of the characterised range
    loop = AxisLoop(LinearAxis(u0), exact_model(u0), frame_period=0.1)
    assert loop.reach(0.0, generous=True)[1] == pytest.approx(40.0 * (1 + REACH_TOLERANCE), abs=ATOL)
    with pytest.raises(ValueError, match=r"outside what .* allowing the model 10% error$"):
        loop.check_reach(44.01, 0.0)


def test_a_target_beyond_the_limit_holds_the_axis_exactly_at_it_and_flags_it():
    u0 = 90.0
    axis = LinearAxis(u0)
    loop = AxisLoop(axis, exact_model(u0), frame_period=0.1)
    ys = run(loop, axis, 43.0, 10, u0)  # within the generous reach (44 px), beyond the real one (40 px)
    assert axis.sent[-1] == RANGE[1] and loop.at_limit
    assert ys[-1] == pytest.approx(40.0, abs=ATOL)
    assert max(axis.sent) == RANGE[1]
    # the correction never winds up past what the limit allows: the next move leaves the limit at once
    loop.end()
    ys2 = run(loop, axis, ys[-1] - 10.0, 1, u0)
    assert ys2[-1] == pytest.approx(ys[-1] - 10.0 * (1 - loop.ff_margin), abs=ATOL)
    assert not loop.at_limit


def test_slew_limit_bounds_every_command_change():
    u0, step, slew = 30.0, 20.0, 2.0  # 19.5 px of feed-forward = 4.875 V: three slewed commands
    axis = LinearAxis(u0)
    loop = AxisLoop(axis, exact_model(u0), frame_period=0.1, max_slew_v=slew)
    ys = run(loop, axis, step, 40, u0)
    du = np.diff([u0] + axis.sent)
    assert np.all(np.abs(du) <= slew + 1e-12)
    np.testing.assert_allclose(du[:2], [slew, slew], atol=ATOL)
    assert ys[1] == pytest.approx(GAIN * slew, abs=ATOL)
    assert abs(ys[-1] - step) < 1e-3 * step


def test_feedforward_in_steps_of_max_step_px_ignores_the_measurement_meanwhile():
    u0, step = 30.0, 20.0  # feed-forward 19.5 px in steps of 6: 6, 12, 18, 19.5
    axis = LinearAxis(u0)
    loop = AxisLoop(axis, exact_model(u0), frame_period=0.1, max_step_px=6.0)
    loop.begin(step, 0.0, 0)
    for k in range(4):
        loop.act(math.nan if k else 0.0, k)  # not read while the feed-forward move is under way
    np.testing.assert_allclose(GAIN * (np.array(axis.sent) - u0), [6.0, 12.0, 18.0, 19.5], atol=ATOL)
    with pytest.raises(ValueError, match="not finite"):  # then it is: the PID refuses to drive blind
        loop.act(math.nan, 4)


def test_fine_gain_after_two_frames_in_the_band_and_coarse_again_at_the_end():
    u0 = 30.0
    axis = LinearAxis(u0)
    loop = AxisLoop(axis, exact_model(u0), frame_period=0.1, pid=PID(ki=0.8), ki_fine=0.1, fine_band_px=0.5)
    loop.begin(20.0, 0.0, 0)
    loop.act(0.0, 0)  # the feed-forward
    for y, ki in ((19.0, 0.8), (19.6, 0.8), (19.7, 0.1), (18.0, 0.1)):  # 0.4 and 0.3 px off: in the band
        loop.act(y, 1)
        assert loop.pid.ki == ki
    loop.end()
    assert loop.pid.ki == 0.8


def test_the_dac_s_command_is_what_the_model_remembers():
    u0 = 30.0
    axis = LinearAxis(u0, step_v=0.01)  # a 10 mV DAC
    model = exact_model(u0)
    loop = AxisLoop(axis, model, frame_period=0.1)
    run(loop, axis, 7.003, 1, u0)  # 7.003 * 0.975 px / 4 px/V = 1.70698 V asked: the DAC holds 1.71 V
    assert axis.sent[0] == pytest.approx(30.0 + 7.003 * 0.975 / GAIN, abs=ATOL)
    assert axis.u == pytest.approx(31.71, abs=1e-12)
    assert loop.u == axis.u and model.state.u == axis.u


def test_a_move_that_ends_on_a_limit_up_to_rounding_is_at_the_limit():
    # 40 px from 90 V is exactly 100 V; the inverse lands there up to rounding (within the 1e-9 of the
    # range that counts as the limit) and the limit itself is sent, flagged
    axis = LinearAxis(90.0)
    loop = AxisLoop(axis, exact_model(90.0), frame_period=0.1, ff_margin=0.0)
    run(loop, axis, 40.0, 1, 90.0)
    assert axis.sent == [100.0] and loop.at_limit
    axis = LinearAxis(90.0)
    loop = AxisLoop(axis, exact_model(90.0), frame_period=0.1, ff_margin=0.0)
    run(loop, axis, 39.9996, 1, 90.0)  # 1e-4 V short of it: a command like any other
    assert axis.sent == [pytest.approx(99.9999, abs=1e-9)] and not loop.at_limit


@pytest.mark.parametrize("kw, err", [
    ({"ki_fine": 0.0}, "ki_fine"), ({"ki_fine": math.nan}, "ki_fine"), ({"ff_margin": 0.5}, "ff_margin"),
    ({"ff_margin": -0.01}, "ff_margin"), ({"max_slew_v": 0.0}, "max_slew_v"), ({"max_step_px": 0.0}, "max_step_px"),
])
def test_bad_loop_parameters(kw, err):
    with pytest.raises(ValueError, match=err):
        AxisLoop(LinearAxis(50.0), exact_model(50.0), frame_period=0.1, **kw)


def test_bad_axes_models_and_creep():
    AxisLoop(LinearAxis(50.0), exact_model(50.0), frame_period=0.1, ff_margin=0.0)  # the ends that are allowed
    with pytest.raises(ValueError, match="are empty"):
        AxisLoop(LinearAxis(50.0, limits=(50.0, 50.0)), exact_model(50.0), frame_period=0.1)
    with pytest.raises(ValueError, match="model is required"):
        AxisLoop(LinearAxis(50.0), None, frame_period=0.1)
    with pytest.raises(TypeError, match="CreepModel"):
        AxisLoop(LinearAxis(50.0), exact_model(50.0), frame_period=0.1, creep=object())
    # out of step: the model's state more than 1e-3 of the range (0.1 V) from the axis' command
    AxisLoop(LinearAxis(50.09), exact_model(50.0), frame_period=0.1)
    with pytest.raises(ValueError, match="out of step with the axis, which holds 50.11 V"):
        AxisLoop(LinearAxis(50.11), exact_model(50.0), frame_period=0.1)
    loop = AxisLoop(LinearAxis(50.0), exact_model(50.0), frame_period=0.1)
    with pytest.raises(ValueError, match="not finite"):
        loop.begin(math.inf, 0.0, 0)


# ---------------------------------------------------------------------------------------------
# step_response / move_to around the loop: the rows are the law's, with the tracker's view of it
# ---------------------------------------------------------------------------------------------

DIRECTION = np.array([0.6, 0.8])
ROI = (100, 100, 41, 41)  # centre (120, 120)


class World:
    """A microscope whose probe moves along DIRECTION by GAIN px/V of the axis' command from u0."""

    frame_period = 0.1

    def __init__(self, u0, **axis_kw):
        self.axis, self.u0, self.frame = LinearAxis(u0, **axis_kw), u0, -1
        self.model = exact_model(u0)
        self.model.direction = tuple(DIRECTION)

    def grab(self):
        self.frame += 1
        return np.full((400, 400), self.frame, dtype=np.int32)  # the fake tracker reads the index

    def position(self):
        return np.array([500.0, 300.0]) + GAIN * (self.axis.u - self.u0) * DIRECTION

    def tracker(self, **kw):
        return servo_fakes.FakeTracker(position=self.position, **kw)


def test_step_response_rows_are_the_feedforward_law_seen_by_the_tracker():
    w = World(30.0)
    resp = step_response(w, w.axis, ROI, 20.0, model=w.model, pid=PID(kp=0.3, ki=0.5), tracker=w.tracker(),
                         n_frames=12)
    expected, _ = feedforward_law(20.0, 0.3, 0.5, 0.025, 11, 30.0)
    np.testing.assert_allclose(resp["displacement"], expected, atol=ATOL)
    centre = np.array([120.0, 120.0])
    np.testing.assert_allclose(resp[["x", "y"]], centre + np.outer(expected, DIRECTION), atol=ATOL)
    assert list(resp["frame"]) == list(range(12))
    np.testing.assert_allclose(resp["t"], 0.1 * np.arange(12), atol=1e-12)
    # u: the command in effect while the frame was taken (row 0: the start; then one frame late)
    np.testing.assert_allclose(resp["u"], [30.0] + w.axis.sent[:11], atol=1e-12)
    np.testing.assert_allclose(resp["u"].iloc[1:], 30.0 + expected[1:] / GAIN, atol=ATOL)
    assert (resp["target"] == 20.0).all() and resp["ok"].all() and not resp["held"].any()
    assert not resp["at_limit"].any()
    assert list(resp["stage"]) == ["start"] + ["feedforward"] * 11
    assert resp.attrs["direction"] == pytest.approx(tuple(DIRECTION)) and resp.attrs["origin"] == (120.0, 120.0)
    assert resp.attrs["feedforward"] is True and resp.attrs["frame_period"] == 0.1
    assert resp.attrs["model"] == "polynomial" and resp.attrs["axis"] == "lin 0 x"
    assert resp.attrs["warmup_frames"] == 0 and resp.attrs["warmup_lost"] == 0


def test_a_lost_frame_holds_the_command_and_the_law_resumes_one_frame_later():
    w = World(30.0)
    resp = step_response(w, w.axis, ROI, 20.0, model=w.model, pid=PID(kp=0.3, ki=0.5),
                         tracker=w.tracker(lose={4}), n_frames=12)
    expected, _ = feedforward_law(20.0, 0.3, 0.5, 0.025, 10, 30.0)
    d = resp["displacement"].to_numpy()
    assert np.isnan(d[4]) and not resp["ok"][4] and resp["held"][4] and resp["held"].sum() == 1
    # no command after the lost frame: frame 5 sees frame 4's position, then the law goes on
    np.testing.assert_allclose(np.r_[d[:4], d[5:]], expected, atol=ATOL)
    assert resp["u"][5] == resp["u"][4]


def test_pid_only_step_and_move_to_follow_their_law():
    w = World(60.0)
    resp = step_response(w, w.axis, ROI, -15.0, model=w.model, feedforward=False, pid=PID(kp=0.2, ki=0.4),
                         tracker=w.tracker(), n_frames=8)
    pid = PID(kp=0.2, ki=0.4)
    pid.set_limits((RANGE[0] - 60.0) * GAIN, (RANGE[1] - 60.0) * GAIN)
    expected = [0.0]
    for _ in range(7):
        c = pid.update(-15.0, expected[-1])
        pid.track(c)
        expected.append(c)
    np.testing.assert_allclose(resp["displacement"], expected, atol=ATOL)
    assert list(resp["stage"]) == ["start"] + ["pid"] * 7 and resp.attrs["feedforward"] is False
    w = World(30.0)
    moved = move_to(w, w.axis, ROI, 20.0, model=w.model, pid=PID(kp=0.3, ki=0.5), tracker=w.tracker(), n_frames=11)
    np.testing.assert_allclose(moved["displacement"], feedforward_law(20.0, 0.3, 0.5, 0.025, 11, 30.0)[0],
                               atol=ATOL)
    assert list(moved["stage"]) == ["start"] + ["nano"] * 11 and (moved["target"] == 20.0).all()


def test_step_response_refuses_before_anything_moves():
    w = World(90.0)  # 40 px of reach upwards, 44 px generous
    with pytest.raises(ValueError, match="step of 45 px is outside"):
        step_response(w, w.axis, ROI, 45.0, model=w.model, tracker=w.tracker())
    with pytest.raises(ValueError, match="not finite"):
        step_response(w, w.axis, ROI, math.nan, model=w.model, tracker=w.tracker())
    with pytest.raises(ValueError, match="^n_frames must be >= 2$"):
        step_response(w, w.axis, ROI, 1.0, model=w.model, tracker=w.tracker(), n_frames=1)
    with pytest.raises(TypeError, match=r"unknown parameter\(s\) \['gain'\]"):
        step_response(w, w.axis, ROI, 1.0, model=w.model, tracker=w.tracker(), gain=2.0)
    # 40 px along (0.6, 0.8) takes the 41-px ROI at (100, 100) to (124, 132): inside a 400x400 frame;
    # a 41-px ROI at (340, 100) would go to x = 364 + 41 > 400.5: refused, nothing sent
    with pytest.raises(ValueError, match="out of the 400x400 frame"):
        step_response(w, w.axis, (340, 100, 41, 41), 40.0, model=w.model, tracker=w.tracker())
    with pytest.raises(ValueError, match=r"^a move of 45 px is outside .*: it is beyond the piezo; pass macro="):
        move_to(w, w.axis, ROI, 45.0, model=w.model, tracker=w.tracker())
    assert w.axis.sent == []


class StaleTracker:
    """Reports the last position it saw, flagged lost, on the frames in ``stale`` (a tracker that keeps
    its previous answer when it fails): the row's displacement must not be that stale number."""

    def __init__(self, world, stale):
        self.inner, self.stale, self.last = world.tracker(), set(stale), None

    def init(self, frame, roi):
        self.inner.init(frame, roi)

    def update(self, frame):
        if int(frame[0, 0]) in self.stale:
            return (*self.last[:2], 0.0, False)
        self.last = self.inner.update(frame)
        return self.last


def test_a_frame_flagged_lost_with_a_stale_position_has_no_displacement():
    w = World(30.0)
    resp = step_response(w, w.axis, ROI, 20.0, model=w.model, tracker=StaleTracker(w, {3}), n_frames=6)
    assert np.isfinite(resp["x"][3]) and np.isnan(resp["displacement"][3])
    assert not resp["ok"][3] and resp["held"][3]


def test_warm_up_counts_its_lost_frames():
    w = World(30.0)
    resp = step_response(w, w.axis, ROI, 20.0, model=w.model, tracker=w.tracker(lose={1, 4}), n_frames=4,
                         warmup_frames=10)
    assert resp.attrs["warmup_frames"] == 10 and resp.attrs["warmup_lost"] == 2
    assert resp.attrs["warmup_s"] == pytest.approx(1.0)
    # a still probe: the line through the last warm-up positions is flat, the start is the ROI centre
    assert resp.attrs["warmup_drift_px_per_frame"] == pytest.approx(0.0, abs=1e-9)
    assert resp.attrs["origin"] == pytest.approx((120.0, 120.0), abs=1e-9)


def test_the_servo_s_reach_is_its_loop_s_from_the_measured_position():
    from semlab.control import VisualServo

    w = World(90.0)
    servo = VisualServo(w, w.axis, w.model, tracker=w.tracker())
    servo.start(ROI)
    assert servo.reachable() == pytest.approx((-360.0, 40.0), abs=ATOL)  # 0 .. 100 V from 90 V, 4 px/V
    assert servo.reachable(generous=True) == pytest.approx((-396.0, 44.0), abs=ATOL)  # + REACH_TOLERANCE


class Macro:
    """A macro stepper: +1 nm moves the probe 0.01 px along DIRECTION (100 nm per px)."""

    limits = (0.0, 1e6)

    def __init__(self):
        self.position_nm = 5e5

    def move_to(self, nm):
        self.position_nm = float(nm)


def test_macro_hand_over_in_chunks_then_the_piezo_finishes():
    w = World(50.0)  # the piezo reaches -200 .. +200 px from here: 300 px needs the macro stage
    macro = Macro()
    base = w.position
    w.position = lambda: base() + 0.01 * (macro.position_nm - 5e5) * DIRECTION
    w.pixel_size_nm = 100.0  # read from the microscope when not given
    resp = move_to(w, w.axis, ROI, 300.0, model=w.model, macro=macro, tracker=w.tracker(), n_frames=30)
    m = resp[resp["stage"] == "macro"]
    # chunks of 40 px until the target is within a quarter of the reach (100 px) of its middle: 5 chunks,
    # each with 2 settle frames, every one tracked
    assert len(m) == 10 and m["ok"].all() and not m["held"].any()
    np.testing.assert_allclose(m["displacement"], np.repeat([40.0, 80.0, 120.0, 160.0, 200.0], 2), atol=ATOL)
    assert macro.position_nm == pytest.approx(5e5 + 200.0 * 100.0)
    nano = resp[resp["stage"] == "nano"]
    # then the law: the feed-forward lands 2.5 % of the remaining 100 px short, the PID (ki = 0.8, kp = 0)
    # takes e[k+1] = (1 - ki) e[k]: 2.5 px x 0.2^28 is far below 1e-6 px at the end
    assert len(nano) == 30 and abs(nano["displacement"].iloc[-1] - 300.0) < 1e-6


def test_step_response_passes_max_step_px_on_to_the_loop():
    w = World(30.0)
    resp = step_response(w, w.axis, ROI, 20.0, model=w.model, tracker=w.tracker(), n_frames=6, max_step_px=6.0)
    # the feed-forward's 19.5 px in steps of 6 px (one per frame), the measurement unused meanwhile
    np.testing.assert_allclose(resp["displacement"][:5], [0.0, 6.0, 12.0, 18.0, 19.5], atol=ATOL)
