"""Image-based visual servo of a piezo axis with hysteresis feed-forward (paper, Fig. 8a, Fig. 9).

The loop runs at the frame rate. After frame ``k`` is grabbed the tracker measures the probe; the
controller computes a command that is applied at once and acts from frame ``k + 1`` -- one frame of
latency, which is what a real SEM imposes (the frame that shows the effect of a command can only be
scanned after the command was sent).

Command law (all quantities in px along the axis' image direction, the measured displacement ``y``):

* with feed-forward, the hysteresis model's inverse moves the probe to the target in one step and
  the PID only adds a small correction ``c``: ``u = model.inverse(y_goal + c)`` -- the model's memory
  keeps track of every reversal the corrections cause, so the loop sees an almost linear plant;
* without feed-forward the model only supplies the direction and the mean gain ``G`` (px/V):
  ``u = u_start + c / G``.

``c`` comes from :class:`PID` (derivative on a low-pass filtered measurement, anti-windup by
back-calculation, output and slew limits). :class:`AxisLoop` holds that law for one axis; the 1-D
:class:`VisualServo` and the 2-D :func:`semlab.pointing.move_probe_to` measure and feed it.

Safety rules: a frame where the tracker reports ``ok=False`` holds the last safe command and is flagged;
commands are clipped into the axis limits before :meth:`Axis.apply` (rows where that happened are
flagged ``at_limit``); a move is refused, before anything moves, only when the axis limits cannot reach
it (:func:`axis_reach`); NaN targets or measurements raise ValueError. The model's characterised range
is not a limit: beyond it the feed-forward uses the model's conservative extrapolation and the feedback
finishes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from semlab.hysteresis import axis_identity
from semlab.measure import default_tracker, read_result, start_point
from semlab.protocols import check_command

__all__ = [
    "PID",
    "AxisLoop",
    "VisualServo",
    "axis_reach",
    "check_in_frame",
    "move_to",
    "step_metrics",
    "step_response",
    "tracked_position",
]

RESPONSE_COLUMNS = ("frame", "t", "u", "x", "y", "displacement", "target", "ok")
# Warm-up frames from whose tracked positions the step's start point is fitted (a line, so that a
# slow creep drift does not bias it).
REFERENCE_FRAMES = 8


def _warmup_frames(value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"warmup_frames must be a non-negative integer, got {value!r}")
    return int(value)


@dataclass
class PID:
    """Discrete PID at the frame rate (gains per frame, output in px of displacement).

    .. math::
        c_k = k_p e_k + I_k - k_d(\\tilde m_k - \\tilde m_{k-1}),\\quad I_k = I_{k-1} + k_i e_k,\\quad
        \\tilde m_k = \\alpha\\tilde m_{k-1} + (1-\\alpha) m_k

    with ``e = setpoint - m``. The derivative acts on the filtered measurement (no kick when the
    setpoint jumps, less noise). The output is clipped to ``output_limits`` and may change by at most
    ``slew_limit`` per update; whenever the output is limited (here or later, see :meth:`track`), the
    integrator is back-calculated so that it does not wind up.

    Parameters
    ----------
    kp, ki, kd : float
        Proportional, integral (per frame) and derivative (x frame) gains.
    derivative_smoothing : float
        ``alpha`` in [0, 1) of the first-order low-pass on the measurement for the derivative.
    output_limits : (float, float)
    slew_limit : float
        Largest change of the output per update (``inf``: none).
    """

    kp: float = 0.0
    ki: float = 0.6
    kd: float = 0.0
    derivative_smoothing: float = 0.5
    output_limits: tuple = (-math.inf, math.inf)
    slew_limit: float = math.inf

    def __post_init__(self):
        for name in ("kp", "ki", "kd"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"PID gain {name}={v} must be finite and >= 0")
        if not 0.0 <= self.derivative_smoothing < 1.0:
            raise ValueError("derivative_smoothing must be in [0, 1)")
        if not self.slew_limit > 0:
            raise ValueError("slew_limit must be > 0")
        self.reset()

    def reset(self, output: float = 0.0) -> None:
        """Start again with the output at ``output`` (bumpless: the integrator takes it)."""
        self.integral = float(output)
        self.output = float(output)
        self._m_filt = None
        self._p = self._d = 0.0

    def set_limits(self, lo: float, hi: float) -> None:
        if not lo <= hi:
            raise ValueError(f"output limits ({lo}, {hi}) are empty")
        self.output_limits = (float(lo), float(hi))

    def update(self, setpoint: float, measurement: float) -> float:
        """One control step; returns the new output.

        Raises
        ------
        ValueError
            If the setpoint or the measurement is not finite.
        """
        if not math.isfinite(float(setpoint)):
            raise ValueError(f"PID setpoint {setpoint} is not finite")
        if not math.isfinite(float(measurement)):
            raise ValueError(f"PID measurement {measurement} is not finite; refusing to drive blind")
        e = float(setpoint) - float(measurement)
        a = self.derivative_smoothing
        m_prev = self._m_filt
        self._m_filt = float(measurement) if m_prev is None else a * m_prev + (1 - a) * float(measurement)
        self._d = 0.0 if m_prev is None else -self.kd * (self._m_filt - m_prev)
        self._p = self.kp * e
        lo, hi = self.output_limits
        integral = self.integral + self.ki * e
        # anti-windup (1): the integral never drives the output past its limits (back-calculation);
        # without an integrator (ki = 0) there is nothing to wind up and the integral keeps its value
        if self.ki > 0:
            integral = min(max(integral, lo - self._p - self._d), hi - self._p - self._d)
        raw = self._p + integral + self._d
        out = min(max(raw, lo), hi)
        slewed = min(max(out, self.output - self.slew_limit), self.output + self.slew_limit)
        # anti-windup (2): while the slew limit holds the output back, the integral is back-calculated
        # to the output given (it grows no faster than the output may), so P + I + D stays the output
        if slewed != out and self.ki > 0:
            integral = slewed - self._p - self._d
        self.integral = integral
        self.output = slewed
        return slewed

    def track(self, applied: float) -> None:
        """Tell the controller the output actually used after limits further downstream (axis limits,
        voltage slew): the integral is back-calculated so that it does not wind up against them."""
        applied = float(applied)
        if self.ki == 0:  # no integrator: nothing to wind up
            pass
        elif applied < self.output:
            self.integral = min(self.integral, applied - self._p - self._d)
        elif applied > self.output:
            self.integral = max(self.integral, applied - self._p - self._d)
        self.output = applied


#: A move is refused only when the axis limits cannot reach it even if the model underestimates the
#: axis by this fraction of the move to the limit (the models' open-loop errors are a few %, up to 6 %
#: on a piezo outside their family: ``benchmarks/bench_servo.py``)...
REACH_TOLERANCE = 0.1
#: ... and beyond the characterised range the axis is this many times steeper than the model's
#: extrapolation (the simulated Preisach axis reaches 1.2x it at its limit, 1.5x its in-range slope).
REACH_SLOPE_FACTOR = 2.0


def axis_reach(model, limits, *, generous: bool = False) -> tuple[float, float]:
    """Model displacements (px, model coordinates) at the two axis limits from the model's state.

    Parameters
    ----------
    model : HysteresisModel
        The shadow of the axis (its state is the axis' state).
    limits : (float, float)
        The axis limits (V).
    generous : bool
        False: the model's prediction (extrapolated beyond its characterised range). True: what the axis
        could reach if the model underestimated it (:data:`REACH_TOLERANCE`, :data:`REACH_SLOPE_FACTOR`):
        a move beyond that is refused, anything short of it is tried.
    """
    y_now, u_now = model.state.y, model.state.u
    u0, un = model.u_range
    s_lo, s_hi = model.extrapolation_slopes
    out = []
    for lim in (float(limits[0]), float(limits[1])):
        y_lim = model.displacement(lim)
        if generous:
            if lim > u_now:
                beyond = s_hi * max(0.0, lim - max(u_now, un))
            else:
                beyond = -s_lo * max(0.0, min(u_now, u0) - lim)
            y_lim = y_now + (1.0 + REACH_TOLERANCE) * (y_lim - y_now) + (REACH_SLOPE_FACTOR - 1.0) * beyond
        out.append(y_lim)
    return out[0], out[1]


def check_in_frame(roi, shift, frame_shape, what: str = "move") -> None:
    """Raise ValueError when the ROI moved by ``shift`` (dx, dy px) would leave a frame of
    ``frame_shape``: the tracker's template could not follow the probe there, so the servo would
    drive it blind (choose a smaller ROI, or a target further inside)."""
    rows, cols = frame_shape[:2]
    x, y, w, h = (float(v) for v in roi)
    dx, dy = (float(v) for v in shift)
    x0, y0 = x + dx, y + dy
    if not (x0 >= -0.5 and y0 >= -0.5 and x0 + w <= cols + 0.5 and y0 + h <= rows + 0.5):
        raise ValueError(f"the {what} would take the {w:.0f}x{h:.0f} ROI to ({x0:.1f}, {y0:.1f}), out of the "
                         f"{cols}x{rows} frame: the tracker could not follow the probe there")


def tracked_position(tracker, frame, index: int) -> tuple[float, float, bool]:
    """``(x, y, ok)`` of the tracker on ``frame`` (the ``index``-th of a run).

    Raises
    ------
    ValueError
        If the tracker reports ``ok=True`` with a non-finite position: a servo must not drive blind.
    """
    x, y, _, ok = read_result(tracker.update(frame))
    if ok and not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"tracker reported ok=True with a non-finite position ({x}, {y}) at frame {index}; "
                         "refusing to drive blind")
    return x, y, ok


class AxisLoop:
    """The control law of one axis (paper, Fig. 8a): feed-forward through the hysteresis model's inverse,
    a PID on the measured displacement along the axis' image direction, and the axis' safety limits.

    Used by :class:`VisualServo` (one axis, displacement projected on its direction) and by
    :func:`semlab.pointing.move_probe_to` (several axes, displacements from the image Jacobian). The
    caller measures; the loop computes and applies one command per frame.

    Parameters
    ----------
    axis : Axis
        Its ``limits`` bound every command (the model's characterised range does not).
    model : HysteresisModel
        Fitted on this axis; the shadow of the axis: its state must be the axis' current command and
        history (as after :func:`~semlab.hysteresis.fit_hysteresis` or a previous servo run). Every
        command is committed to it (the DAC-quantised one when the axis reports ``command``), so its
        reversal memory follows the axis across calls.
    frame_period : float
        s per frame (creep compensation).
    feedforward, pid, creep, ki_fine, fine_band_px, ff_margin, max_slew_v, max_step_px
        See :class:`VisualServo`.
    """

    def __init__(self, axis, model, *, frame_period: float, feedforward: bool = True, pid=None, creep=None,
                 ki_fine: float | None = None, fine_band_px: float = 0.5, ff_margin: float = 0.025,
                 max_slew_v: float | None = None, max_step_px: float | None = None):
        if model is None:
            raise ValueError("a hysteresis model is required (it supplies at least direction and gain)")
        model.check_axis(axis)
        self.axis, self.model = axis, model
        self.dt = float(frame_period)
        self.feedforward = bool(feedforward)
        self.pid = pid if pid is not None else (PID(ki=0.8) if feedforward else PID(ki=0.45))
        self._ki_coarse = self.pid.ki
        if ki_fine is not None and not (math.isfinite(ki_fine) and ki_fine > 0):
            raise ValueError(f"ki_fine={ki_fine} must be a positive number")
        self.ki_fine, self.fine_band_px = ki_fine, float(fine_band_px)
        if not 0.0 <= ff_margin < 0.5:
            raise ValueError(f"ff_margin={ff_margin} must be in [0, 0.5)")
        self.ff_margin = float(ff_margin)
        if creep is not None and not callable(getattr(creep, "predict", None)):
            raise TypeError("creep must be a CreepModel (predict/record/reset)")
        self.creep = creep if feedforward else None  # without feed-forward nothing to compensate
        if self.creep is not None:
            self.creep.reset()
        self._creep_ref = 0.0
        self._comp = 0.0
        self.max_slew_v = math.inf if max_slew_v is None else float(max_slew_v)
        self.max_step_px = math.inf if max_step_px is None else float(max_step_px)
        if not (self.max_slew_v > 0 and self.max_step_px > 0):
            raise ValueError("max_slew_v and max_step_px must be > 0")
        self.limits = tuple(float(v) for v in axis.limits)
        if not self.limits[0] < self.limits[1]:
            raise ValueError(f"axis limits {self.limits} are empty")
        m_lo, m_hi = model.u_range
        held = getattr(axis, "command", None)  # axes that report their command are cross-checked
        if held is not None and abs(float(held) - model.state.u) > 1e-3 * (m_hi - m_lo):
            raise ValueError(
                f"the model's state ({model.state.u:.6g} V) is out of step with the axis, which holds "
                f"{float(held):.6g} V: the feed-forward would jump blind. Drive the axis through the model "
                "(model.forward) or reset the model (model.reset(u, branch)) first"
            )
        self.u = float(model.state.u)
        self.at_limit = False
        self.target = 0.0

    def reach(self, y_meas: float, *, generous: bool = False) -> tuple[float, float]:
        """Displacements (px, measurement frame) the axis can reach from ``y_meas`` within its limits
        (:func:`axis_reach`)."""
        lo, hi = axis_reach(self.model, self.limits, generous=generous)
        y_model = self.model.state.y
        return y_meas + (lo - y_model), y_meas + (hi - y_model)

    def check_reach(self, target: float, y_meas: float, what: str = "target") -> None:
        """Raise ValueError (with the reason) when the axis limits cannot reach ``target``."""
        r_lo, r_hi = self.reach(y_meas, generous=True)
        if not r_lo <= target <= r_hi:
            u0, un = self.model.u_range
            lo, hi = self.limits
            beyond = (f" and an axis {REACH_SLOPE_FACTOR:g}x steeper than its extrapolation beyond the "
                      f"characterised {u0:.4g}-{un:.4g} V") if lo < u0 or hi > un else ""
            raise ValueError(
                f"{what} {target:.4g} px is outside what {axis_identity(self.axis)!r} can reach within its "
                f"limits [{lo:.4g}, {hi:.4g}] V: [{r_lo:.4g}, {r_hi:.4g}] px from here, allowing the model "
                f"{REACH_TOLERANCE:.0%} error{beyond}"
            )

    # -- one move -------------------------------------------------------------------------------
    def begin(self, target: float, y_meas: float, frame: int) -> None:
        """Start a move to ``target`` (px, measurement frame) from the measured ``y_meas`` at ``frame``.

        The feed-forward goal is the measured remaining distance added to the model's state, so the
        model is re-anchored to the measured position at every move and its error does not accumulate.
        """
        target = float(target)
        if not math.isfinite(target):
            raise ValueError(f"target {target} px is not finite")
        self.target = target
        model, pid = self.model, self.pid
        self.goal_model = model.state.y + (target - y_meas)
        self.u_ref = self.u
        # approach from one side: the feed-forward stops short by ff_margin of the move
        short = self.ff_margin * (self.goal_model - model.state.y) if self.feedforward else 0.0
        pid.reset(-short)
        pid.ki = self._ki_coarse
        if self.feedforward:
            lo, hi = axis_reach(model, self.limits)
            pid.set_limits(min(lo - self.goal_model, 0.0), max(hi - self.goal_model, 0.0))
        else:
            g = model.gain
            pid.set_limits((self.limits[0] - self.u_ref) * g, (self.limits[1] - self.u_ref) * g)
        # creep already present in the measurement the goal was computed from
        self._creep_ref = self._creep_at(frame + 0.5)
        self._ff_pos = model.state.y
        self._ff_goal = self.goal_model - short
        self._calm = 0

    def act(self, y_meas: float, frame: int) -> float:
        """One command, applied at once (it acts from frame ``frame + 1``); returns it.

        While the feed-forward move is under way (one frame, or several of ``max_step_px``) the
        measurement is not used; then the PID corrects the goal (with feed-forward) or the command.
        """
        if self.feedforward and self._ff_pos != self._ff_goal:
            self._ff_pos = self._ff_step(self._ff_pos, self._ff_goal, frame)
            return self.u
        pid = self.pid
        self._calm = self._calm + 1 if abs(self.target - y_meas) < self.fine_band_px else 0
        if self.ki_fine is not None and self._calm >= 2:
            pid.ki = self.ki_fine  # gain scheduling: settled, average the measurement noise
        c = pid.update(self.target, y_meas)
        if self.feedforward:
            u = self._apply_displacement(self.goal_model + c, frame)
        else:
            u = self._apply(self.u_ref + c / self.model.gain)
        lo, hi = pid.output_limits
        pid.track(min(max(self._achieved(u), lo), hi))
        return u

    def end(self) -> None:
        """The move is over: the PID's coarse gain back for the next one."""
        self.pid.ki = self._ki_coarse

    # -- actuation --------------------------------------------------------------------------------
    def _creep_at(self, frames: float, extra=None) -> float:
        if self.creep is None:
            return 0.0
        return self.creep.predict(frames * self.dt, extra)

    def _apply(self, u: float) -> float:
        """Slew limit, clip into the axis limits, apply, tell the shadow model; returns the command."""
        u = min(max(u, self.u - self.max_slew_v), self.u + self.max_slew_v)
        lo, hi = self.limits
        tol = 1e-9 * (hi - lo)  # an inverse that lands on a limit up to rounding is at the limit
        self.at_limit = not lo + tol < u < hi - tol
        u = min(max(u, lo), hi) if not self.at_limit else (lo if u < 0.5 * (lo + hi) else hi)
        u = check_command(u, self.limits, "servo")
        self.axis.apply(u)
        held = getattr(self.axis, "command", None)  # what the DAC really holds, when the axis says
        self.u = float(held) if held is not None and math.isfinite(float(held)) else u
        self.model.forward(self.u)
        return self.u

    def _achieved(self, u: float) -> float:
        """PID output that corresponds to the command actually applied (for anti-windup)."""
        if self.feedforward:
            return self.model.state.y + self._comp - self.goal_model
        return (u - self.u_ref) * self.model.gain

    def _apply_displacement(self, y_goal: float, frame: int) -> float:
        """Feed-forward: the command whose model displacement, plus the creep predicted for the next
        frame, is ``y_goal`` (creep compensation when a creep model is given)."""
        t_cmd = frame + 1.0  # the command acts from the start of the next frame
        comp = 0.0
        u = self.model.inverse(y_goal)
        if self.creep is not None:
            for _ in range(2):  # the step being commanded creeps too: a fixed-point iteration
                dy = self.model.displacement(min(max(u, self.limits[0]), self.limits[1])) - self.model.state.y
                comp = self._creep_at(frame + 1.5, (t_cmd * self.dt, dy)) - self._creep_ref
                u = self.model.inverse(y_goal - comp)
        y_before = self.model.state.y
        u = self._apply(u)
        if self.creep is not None:
            self.creep.record(t_cmd * self.dt, self.model.state.y - y_before)
        self._comp = comp
        return u

    def _ff_step(self, pos: float, goal: float, frame: int) -> float:
        step = goal - pos
        if abs(step) > self.max_step_px:
            step = math.copysign(self.max_step_px, step)
        pos = goal if abs(goal - pos - step) < 1e-12 else pos + step
        self._apply_displacement(pos, frame)
        return pos


class VisualServo:
    """Closed visual-servo loop on one axis (paper, Fig. 8a), used by :func:`step_response` and
    :func:`move_to`: the tracker measures the probe, the displacement along the axis' image direction
    goes to an :class:`AxisLoop`.

    Parameters
    ----------
    microscope, axis
        Protocol objects.
    model : HysteresisModel
        Fitted on this axis; it is the shadow of the axis (its state must be the axis' current command
        and history, as after :func:`~semlab.hysteresis.fit_hysteresis` or a previous servo run).
        Commands may leave its characterised range (it extrapolates); they never leave the axis limits.
    tracker : object, optional
        ``init/update`` tracker; default ``semlab.tracking.Tracker()`` (:func:`step_response` widens its
        search window to the size of the step so that the feed-forward jump stays inside it).
    feedforward : bool
        Use the model's inverse (True) or only its direction and mean gain (False).
    pid : PID, optional
        Default: ``PID(ki=0.8)`` with feed-forward (the model linearises the plant, so the integrator can
        remove 80 % of the residual per frame) or ``PID(ki=0.45)`` without (the plant's gain varies
        around the loop; tuned on the simulated rig, see ``benchmarks/bench_servo.py``).
    max_slew_v : float, optional
        Largest change of the command per frame (V).
    max_step_px : float, optional
        Largest feed-forward move per frame (px); keeps the probe within the tracker's search window.
    creep : CreepModel, optional
        With feed-forward: subtract the creep predicted for the next frame from the feed-forward goal
        (the steps commanded during this run are recorded in it; it is reset at construction).
    ki_fine : float or None
        Gain scheduling: once the error has been within ``fine_band_px`` for two frames, the integral
        gain drops to ``ki_fine`` (default None: never) so the loop averages the tracker noise instead
        of feeding it back to the probe. Off by default: the creep that follows a large step then
        pulls the probe out of the band faster than the low gain brings it back (with creep
        compensation, on both simulated piezo families, ``benchmarks/bench_servo.py`` history: worst
        17-22 frames to stay within +-0.5 px with 0.25 or 0.5, 3 without), while the full gain's
        response to the tracker noise stays well inside the 0.2 px final std.
    fine_band_px : float
        See ``ki_fine``.
    ff_margin : float
        The feed-forward aims short of the target by this fraction of the move (default 2.5 %): the
        probe then approaches from one side and a model error cannot turn into an overshoot; the PID
        starts from that offset and closes the gap (``benchmarks/bench_servo.py`` compares margins).
    warmup_frames : int
        Frames the tracker follows the still probe in :meth:`start` before anything moves (no command
        is sent; default 0). A researcher's tracker runs continuously, so a template matured before the
        step is legitimate; it costs ``warmup_frames * frame_period`` of waiting before the step command
        (response times still run from the step command). The start point is then the line fitted to
        the last ``REFERENCE_FRAMES`` warm-up positions, evaluated at the last warm-up frame (less noise
        than one frame, no lag from creep). With clutter around the start position the matured
        template holds clutter that no longer lies around the probe after a large step; it suits small
        moves, or a clean background (``benchmarks/bench_servo.py`` measures it).
    """

    def __init__(self, microscope, axis, model, *, tracker=None, feedforward: bool = True, pid=None,
                 max_slew_v: float | None = None, max_step_px: float | None = None, creep=None,
                 ki_fine: float | None = None, fine_band_px: float = 0.5, ff_margin: float = 0.025,
                 warmup_frames: int = 0):
        self.microscope = microscope
        self.dt = float(microscope.frame_period)
        self.loop = AxisLoop(axis, model, frame_period=self.dt, feedforward=feedforward, pid=pid, creep=creep,
                             ki_fine=ki_fine, fine_band_px=fine_band_px, ff_margin=ff_margin,
                             max_slew_v=max_slew_v, max_step_px=max_step_px)
        self.axis, self.model = axis, model
        self.tracker = default_tracker(tracker)
        self.warmup_frames = _warmup_frames(warmup_frames)
        self.direction = np.asarray(model.direction, dtype=float)
        self.rows: list[dict] = []
        self.frame = -1
        self.y_meas = 0.0
        self._u_effect = self.loop.u  # the command in effect during the frame being acquired

    feedforward = property(lambda self: self.loop.feedforward)
    pid = property(lambda self: self.loop.pid)
    creep = property(lambda self: self.loop.creep)
    u = property(lambda self: self.loop.u)

    # -- measurement --------------------------------------------------------------------------------
    def start(self, roi) -> VisualServo:
        """Grab the current frame, initialise the tracker on ``roi`` and let it follow the still probe
        for ``warmup_frames`` frames (command held); displacements are measured along the axis
        direction from the start point: the ROI centre without warm-up, else the line fitted to the
        last warm-up positions at the last warm-up frame, which becomes the step's frame 0.

        Raises
        ------
        RuntimeError
            If the tracker has lost the probe at the end of the warm-up (nothing has moved).
        """
        self.p0 = np.array(start_point(roi))
        self.roi = tuple(roi)
        frame = self.microscope.grab()
        self.frame_shape = np.shape(frame)
        self.tracker.init(frame, tuple(roi))
        self.warmup = self._warm_up(self.warmup_frames)
        self.frame = 0
        self.y_meas = 0.0
        self._record(self.p0[0], self.p0[1], True, target=0.0, stage="start", held=False)
        return self

    def _warm_up(self, n: int) -> dict:
        """Track ``n`` frames without commanding anything; move ``p0`` to the fitted start point."""
        info = {"warmup_frames": n, "warmup_s": n * self.dt, "warmup_lost": 0,
                "warmup_noise_px": float("nan"), "warmup_drift_px_per_frame": float("nan")}
        if n == 0:
            return info
        pts = []
        for _ in range(n):
            x, y, _, ok = read_result(self.tracker.update(self.microscope.grab()))
            pts.append((x, y) if ok and math.isfinite(x) and math.isfinite(y) else (math.nan, math.nan))
        pts = np.array(pts)
        good = np.isfinite(pts[:, 0])
        info["warmup_lost"] = int((~good).sum())
        if not good[-1]:
            raise RuntimeError(f"the tracker lost the probe at the end of the {n}-frame warm-up; "
                               "nothing was moved")
        k = np.arange(n)
        tail = (k >= n - REFERENCE_FRAMES) & good
        if tail.sum() < 3:
            self.p0 = pts[-1].copy()
            return info
        t = k[tail] - (n - 1)
        fit = np.polynomial.polynomial.polyfit(t, pts[tail], 1)  # (2, 2): intercept and slope of x, y
        self.p0 = fit[0].copy()
        along = (pts[tail] - fit[0] - np.outer(t, fit[1])) @ self.direction
        info["warmup_noise_px"] = float(np.sqrt(np.sum(along**2) / max(len(t) - 2, 1)))
        info["warmup_drift_px_per_frame"] = float(fit[1] @ self.direction)
        return info

    def _record(self, x, y, ok, *, target, stage, held):
        disp = float((np.array([x, y]) - self.p0) @ self.direction) if ok else float("nan")
        self.rows.append({"frame": self.frame, "t": self.frame * self.dt, "u": self._u_effect, "x": x,
                          "y": y, "displacement": disp, "target": float(target), "ok": bool(ok),
                          "held": bool(held), "stage": stage, "at_limit": bool(self._at_limit_effect)})

    _at_limit_effect = False

    def _grab_measure(self):
        """Grab the next frame (the last command is in effect) and measure; returns (x, y, ok)."""
        self._u_effect, self._at_limit_effect = self.loop.u, self.loop.at_limit
        frame = self.microscope.grab()
        self.frame += 1
        x, y, ok = tracked_position(self.tracker, frame, self.frame)
        if ok:
            self.y_meas = float((np.array([x, y]) - self.p0) @ self.direction)
        return x, y, ok

    # -- actuation ------------------------------------------------------------------------------------
    def reachable(self, *, generous: bool = False) -> tuple[float, float]:
        """Displacements (px, measurement frame) the axis can reach from here within its limits, per
        the model (``generous``: allowing for the model's error, see :func:`axis_reach`)."""
        return self.loop.reach(self.y_meas, generous=generous)

    def goto(self, target: float, n_frames: int, *, stage: str = "nano") -> None:
        """Servo to ``target`` px (measured from the start reference) for ``n_frames`` frames.

        Raises
        ------
        ValueError
            NaN target, or a target the axis limits cannot reach (:meth:`AxisLoop.check_reach`).
        """
        target = float(target)
        if not math.isfinite(target):
            raise ValueError(f"target {target} px is not finite")
        self.loop.check_reach(target, self.y_meas)
        self.loop.begin(target, self.y_meas, self.frame)
        # the first command is sent right after the latest frame (no frame is wasted); from then on
        # one command per frame, each acting from the next frame
        self.loop.act(self.y_meas, self.frame)
        for _ in range(int(n_frames)):
            x, y, ok = self._grab_measure()
            if not ok:  # safety: hold the last safe command, do not integrate, flag the row
                self._record(x, y, False, target=target, stage=stage, held=True)
                continue
            self._record(x, y, True, target=target, stage=stage, held=False)
            self.loop.act(self.y_meas, self.frame)
        self.loop.end()

    def macro_handover(self, target: float, macro, *, pixel_size_nm: float, chunk_px: float = 40.0,
                       settle_frames: int = 2, max_chunks: int = 200) -> None:
        """Move with the macro stepper so that ``target`` ends near the middle of the piezo's reach.

        The macro moves in chunks of at most ``chunk_px`` so the tracker can follow; the first chunk
        measures the stepper's image gain and sign (px per nm), nothing about it is assumed except the
        pixel size used for the first chunk's length. A chunk that would take the ROI out of the frame
        is not made (ValueError: the tracker could not follow).
        """
        if not (math.isfinite(pixel_size_nm) and pixel_size_nm > 0):
            raise ValueError(f"pixel_size_nm={pixel_size_nm} must be a positive number")
        r_lo, r_hi = self.reachable()
        mid = 0.5 * (r_lo + r_hi)
        needed = target - mid  # px the macro stage must move the probe
        nm_per_px = float(pixel_size_nm)
        m_lo, m_hi = (float(v) for v in macro.limits)
        for _ in range(max_chunks):
            r_lo, r_hi = self.reachable()
            mid = 0.5 * (r_lo + r_hi)
            needed = target - mid
            if abs(needed) <= 0.25 * (r_hi - r_lo):
                return
            step_px = math.copysign(min(abs(needed), chunk_px), needed)
            dest = float(macro.position_nm) + step_px * nm_per_px
            if not m_lo <= dest <= m_hi:
                raise ValueError(f"macro destination {dest:.6g} nm is outside its limits [{m_lo}, {m_hi}] nm")
            check_in_frame(self.roi, (self.y_meas + step_px) * self.direction, self.frame_shape, "macro hand-over")
            y_before = self.y_meas
            macro.move_to(dest)
            ok = False
            for _ in range(int(settle_frames)):
                x, y, ok = self._grab_measure()
                self._record(x, y, ok, target=target, stage="macro", held=not ok)
            if not ok:
                raise RuntimeError("the tracker lost the probe during a macro move; stopped the hand-over")
            moved = self.y_meas - y_before
            if abs(moved) < 0.2 * abs(step_px):
                raise RuntimeError(f"macro move of {step_px * nm_per_px:.4g} nm moved the probe only "
                                   f"{moved:.3g} px along the axis; wrong stage or direction?")
            nm_per_px = step_px * nm_per_px / moved
        raise RuntimeError("macro hand-over did not converge")

    def to_frame(self) -> pd.DataFrame:
        df = pd.DataFrame(self.rows)
        df.attrs.update(direction=tuple(self.direction), origin=tuple(self.p0), feedforward=self.feedforward,
                        model=self.model.kind, axis=self.model.axis, frame_period=self.dt,
                        **getattr(self, "warmup", {}))
        return df


def step_response(microscope, axis, roi, step_px, *, model, feedforward=True, n_frames=60, **params):
    """Response of the visual servo to a step of ``step_px`` pixels (paper, Fig. 9).

    Parameters
    ----------
    microscope, axis
        Protocol objects; ``axis`` must be the one ``model`` was fitted on.
    roi : (x, y, w, h)
        The probe's ROI in the current frame.
    step_px : float
        Desired displacement along the axis direction; ``> 0`` moves the probe the way rising voltage
        does.
    model : HysteresisModel
        Its state must match the axis (as after ``fit_hysteresis`` or a previous servo run); it follows
        the axis through the run (reversal memory), so the next call starts where this one left it.
        Its characterised range limits what the feed-forward predicts, not the move: the command may
        go anywhere within ``axis.limits``, never past them.
    feedforward : bool
        True: the model's inverse makes the move in one step and the PID removes the residual;
        False: PID only, the model supplies direction and gain.
    n_frames : int
        Rows in the result. Frame 0 is the last frame before the step command: the frame the ROI refers
        to, or, after a warm-up, the last warm-up frame.
    **params
        ``tracker``, ``pid`` (a :class:`PID`), ``max_slew_v``, ``max_step_px``, ``creep``, ``ki_fine``,
        ``fine_band_px``, ``ff_margin``, ``warmup_frames`` -- see :class:`VisualServo`. Warm-up frames
        (the tracker follows the still probe before the step command) are not rows of the result;
        ``df.attrs`` records ``warmup_frames``, ``warmup_s``, ``warmup_lost``, ``warmup_noise_px`` (the
        tracker's noise along the axis on the still probe) and ``warmup_drift_px_per_frame``.

    Returns
    -------
    DataFrame
        One row per frame: ``frame, t, u, x, y, displacement, target, ok`` (plus ``held``, ``stage``,
        ``at_limit``). ``u`` is the command in effect while the frame was acquired, ``displacement`` the
        tracked position projected on the axis direction relative to the start point (row 0: the ROI
        centre, or after a warm-up the fitted start point; NaN when ``ok`` is False), ``held`` marks
        frames where the tracker was lost and the last safe command was held, ``at_limit`` frames whose
        command the axis limits clipped (the probe could not go further that way).

    Raises
    ------
    ValueError
        NaN step, a step the axis limits cannot reach (:meth:`AxisLoop.check_reach`, with the reason) or
        that would take the ROI out of the frame (:func:`check_in_frame`; nothing has moved then), a model
        fitted on another axis, or a tracker that reports a NaN position as valid.

    Examples
    --------
    >>> resp = step_response(rig.microscope, axis, roi, 100.0, model=model)   # doctest: +SKIP
    >>> step_metrics(resp)[["response_time_0p5px_s", "overshoot_px", "final_std_px"]]  # doctest: +SKIP
    """
    step_px = float(step_px)
    if not math.isfinite(step_px):
        raise ValueError(f"step_px {step_px} is not finite")
    n_frames = int(n_frames)
    if n_frames < 2:
        raise ValueError("n_frames must be >= 2")
    allowed = {"tracker", "pid", "max_slew_v", "max_step_px", "creep", "ki_fine", "fine_band_px", "ff_margin",
               "warmup_frames"}
    unknown = set(params) - allowed
    if unknown:
        raise TypeError(f"step_response got unknown parameter(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    if params.get("tracker") is None:
        jump = abs(step_px) if params.get("max_step_px") is None else min(abs(step_px), params["max_step_px"])
        params["tracker"] = default_tracker(None, jump_px=jump, roi=roi)
    servo = VisualServo(microscope, axis, model, feedforward=feedforward, **params)
    servo.loop.check_reach(step_px, 0.0, "step of")  # refuse an unreachable step before anything moves
    servo.start(roi)
    check_in_frame(roi, step_px * servo.direction, servo.frame_shape, f"{step_px:.4g}-px step")
    servo.rows[0]["target"] = step_px
    servo.goto(step_px, n_frames - 1, stage="feedforward" if feedforward else "pid")
    return servo.to_frame()


def move_to(microscope, axis, roi, distance_px, *, model, macro=None, pixel_size_nm=None, feedforward=True,
            n_frames=30, **params):
    """Move the probe by ``distance_px`` along the axis, with a macro/nano hand-over when needed.

    When the piezo cannot reach the target from its current state (per the model), the macro stepper
    moves first, in tracked chunks, until the target lies near the middle of the piezo's reach; then
    the visual servo finishes with the piezo (paper: "MACRO and NANO" motions, control switched to the
    nanopositioner for the fine approach).

    Parameters
    ----------
    microscope, axis, roi, model, feedforward, **params
        As for :func:`step_response`.
    distance_px : float
        Desired displacement along the axis direction from the current position.
    macro : object, optional
        Macro stepper with ``limits`` (nm), ``position_nm`` and ``move_to(nm)``.
    pixel_size_nm : float, optional
        Image pixel size (first macro chunk's length); default ``microscope.pixel_size_nm``.
    n_frames : int
        Frames of the nano (piezo) servo phase.

    Returns
    -------
    DataFrame
        As :func:`step_response`, with ``stage`` = ``'start'``, ``'macro'`` or ``'nano'``.
    """
    distance_px = float(distance_px)
    if not math.isfinite(distance_px):
        raise ValueError(f"distance_px {distance_px} is not finite")
    servo = VisualServo(microscope, axis, model, feedforward=feedforward, **params)
    r_lo, r_hi = servo.reachable()
    needs_macro = macro is not None and not r_lo <= distance_px <= r_hi
    if macro is None:
        try:
            servo.loop.check_reach(distance_px, 0.0, "a move of")
        except ValueError as err:
            raise ValueError(f"{err}: it is beyond the piezo; pass macro= for a macro/nano hand-over") from None
    servo.start(roi)
    check_in_frame(roi, distance_px * servo.direction, servo.frame_shape, f"{distance_px:.4g}-px move")
    servo.rows[0]["target"] = distance_px
    if needs_macro:
        if pixel_size_nm is None:
            pixel_size_nm = getattr(microscope, "pixel_size_nm", None)
        if pixel_size_nm is None:
            raise ValueError("pixel_size_nm is required for a macro move")
        servo.macro_handover(distance_px, macro, pixel_size_nm=float(pixel_size_nm))
    servo.goto(distance_px, int(n_frames), stage="nano")
    return servo.to_frame()


def step_metrics(response: pd.DataFrame, *, final_frames: int = 30) -> pd.Series:
    """Summary of a step response (paper, Fig. 9).

    Parameters
    ----------
    response : DataFrame
        From :func:`step_response` (columns ``frame, t, displacement, target, ok``).
    final_frames : int
        Frames at the end used for the final mean and std (paper: the plateau).

    Returns
    -------
    Series
        ``response_time_1px_s``/``response_frames_1px`` and ``response_time_0p5px_s``/
        ``response_frames_0p5px`` -- time from the first row until the displacement enters and stays
        within ±1 px (±0.5 px) of the target (NaN if it never does); ``overshoot_px`` -- largest
        excursion beyond the target in the direction of the step (0 if none); ``final_mean_px``,
        ``final_std_px``, ``final_error_px`` over the last ``final_frames`` valid frames; ``n_lost``.
    """
    if not isinstance(response, pd.DataFrame):
        raise TypeError("response must be a DataFrame from step_response")
    missing = {"frame", "t", "displacement", "target", "ok"} - set(response.columns)
    if missing:
        raise ValueError(f"response lacks column(s) {sorted(missing)}")
    if len(response) < 2:
        raise ValueError("response has fewer than 2 rows")
    r = response.reset_index(drop=True)
    ok = r["ok"].to_numpy(bool) & np.isfinite(r["displacement"].to_numpy(float))
    target = r["target"].to_numpy(float)
    step = float(target[-1])
    err = r["displacement"].to_numpy(float) - target
    t = r["t"].to_numpy(float)
    fr = r["frame"].to_numpy(int)
    out = {"step_px": step}
    for tol, key in ((1.0, "1px"), (0.5, "0p5px")):
        bad = np.flatnonzero(ok & (np.abs(err) > tol))
        # only valid frames after the last violation count; the last valid frame must be inside
        if not ok.any() or (bad.size and bad[-1] == np.flatnonzero(ok)[-1]):
            out[f"response_time_{key}_s"], out[f"response_frames_{key}"] = np.nan, np.nan
            continue
        after = np.flatnonzero(ok & (np.arange(len(r)) > (bad[-1] if bad.size else -1)))
        i = after[0]
        out[f"response_time_{key}_s"] = float(t[i] - t[0])
        out[f"response_frames_{key}"] = int(fr[i] - fr[0])
    sgn = 1.0 if step >= 0 else -1.0
    out["overshoot_px"] = float(max(0.0, np.nanmax(np.where(ok, sgn * err, -np.inf)))) if ok.any() else np.nan
    d_ok = r["displacement"].to_numpy(float)[ok][-int(final_frames):]
    out["final_mean_px"] = float(np.mean(d_ok)) if d_ok.size else np.nan
    out["final_std_px"] = float(np.std(d_ok, ddof=1)) if d_ok.size > 1 else np.nan
    out["final_error_px"] = out["final_mean_px"] - step
    out["n_lost"] = int((~ok).sum())
    return pd.Series(out)


# drive_voltages, an experiment on the rig, moved to semlab.experiments; its old import path keeps working.
def __getattr__(name: str):
    if name == "drive_voltages":
        from semlab.experiments import drive_voltages

        return drive_voltages
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
