"""Servo the probe tip to a point of the image with several axes at once, and several probes from one
frame stream.

The paper servoes one axis at a time; a researcher clicks where the tip should go. Each axis ``i`` of
a manipulator moves the tip along its own image direction ``d_i`` (measured by its characterisation,
:attr:`~semlab.hysteresis.HysteresisModel.direction`), by its model's displacement ``s_i`` (px along
``d_i``). So the image displacement is

.. math:: \\Delta p = J\\,s, \\qquad J = [d_0\\; d_1\\; \\dots]

the image Jacobian, whose columns need not be orthogonal (the view rotates and skews the manipulator's
axes). The servo inverts it (``s = J^+ \\Delta p``, the pseudo-inverse for more than two axes): the target
and every measured position become axis coordinates, and each axis runs its own one-axis law
(:class:`semlab.control.AxisLoop`: feed-forward through its hysteresis model, a PID on its coordinate,
its limits). With feed-forward every axis makes its part of the move in the same frame.

Several probes share the microscope's frames: :func:`move_probes_to` grabs each frame once and gives
it to every probe's own tracker and loops (:class:`PointServo`).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from semlab.control import REACH_TOLERANCE, AxisLoop, check_in_frame, tracked_position
from semlab.measure import default_tracker, start_point
from semlab.protocols import Positioner

__all__ = ["POINT_COLUMNS", "POSITIONER_PARAMS", "PointServo", "ProbeMove", "check_positioner_reach",
           "image_jacobian", "move_probe_to", "move_probes_to", "point_metrics"]

#: The contract's columns, first in every result (the command of each axis, ``u_0, u_1, ...``, follows).
POINT_COLUMNS = ("frame", "t", "x", "y", "target_x", "target_y", "error_px", "ok")
#: Two axes whose image directions are closer than this cannot place the tip at an arbitrary point:
#: the Jacobian's inverse would amplify the tracker's noise by 1/sin(angle) (5.8x at 10 deg).
MIN_AXIS_ANGLE_DEG = 10.0
#: Parameters of the one-axis law that move_probe_to passes on to each axis (see VisualServo).
LOOP_PARAMS = ("feedforward", "pid", "creep", "ki_fine", "fine_band_px", "ff_margin", "max_slew_v", "max_step_px")
#: Parameters of :func:`semlab.positioning.move_positioner_to` that the positioner form passes on.
POSITIONER_PARAMS = ("gain", "deadband_px", "max_step_px", "warmup_frames", "tracker", "progress")


def image_jacobian(models) -> np.ndarray:
    """The image Jacobian ``(2, N)``: column ``i`` is the unit image direction of axis ``i``.

    Parameters
    ----------
    models : sequence of HysteresisModel
        One per axis, each fitted on its own axis (its ``direction`` was measured there).

    Raises
    ------
    ValueError
        Fewer than two axes, or no two of them at least :data:`MIN_AXIS_ANGLE_DEG` apart in the image.
    """
    J = np.column_stack([np.asarray(m.direction, float) for m in models])
    if J.shape[1] < 2:
        raise ValueError("a point in the image needs at least two axes (got one); use step_response for one")
    sv = np.linalg.svd(J, compute_uv=False)
    # two unit columns at angle a: singular values sqrt(1 +- cos a), so sin(a) from their product
    sin_angle = min(1.0, sv[0] * sv[-1]) if J.shape[1] == 2 else sv[-1]
    if sin_angle < math.sin(math.radians(MIN_AXIS_ANGLE_DEG)):
        raise ValueError(
            f"the axes' image directions {[tuple(np.round(c, 3)) for c in J.T]} are nearly parallel "
            f"(less than {MIN_AXIS_ANGLE_DEG:g} deg apart): they cannot place the tip at an arbitrary point"
        )
    return J


def _target_point(target_xy) -> np.ndarray:
    try:
        t = np.asarray([float(v) for v in target_xy], float)
    except (TypeError, ValueError):
        raise ValueError(f"target_xy must be a point (x, y) in frame px, got {target_xy!r}") from None
    if t.shape != (2,):
        raise ValueError(f"target_xy must be a point (x, y) in frame px, got {target_xy!r}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"target_xy {target_xy!r} is not finite; refusing to drive blind")
    return t


def _per_axis(value, n: int, name: str) -> list:
    """One value per axis: a sequence of ``n`` as given, or one object copied for each axis (a PID or
    a creep model has state, so the axes must not share one)."""
    if isinstance(value, (list, tuple)):
        if len(value) != n:
            raise ValueError(f"{name} has {len(value)} entries for {n} axes")
        return list(value)
    return [copy.deepcopy(value) for _ in range(n)]


class PointServo:
    """One probe servoed to a point: its tracker, one :class:`~semlab.control.AxisLoop` per axis and
    its rows. It is fed frames from outside (:meth:`plan`, :meth:`start`, then :meth:`observe` once per
    frame), so several probes can share a frame stream.

    Parameters
    ----------
    axes : sequence of Axis
    models : sequence of HysteresisModel
        ``models[i]`` fitted on ``axes[i]`` and the shadow of it (see :class:`~semlab.control.AxisLoop`).
    frame_period : float
        s per frame.
    tracker : object, optional
        ``init/update`` tracker; default ``semlab.tracking.Tracker()`` with its search window widened
        to hold the feed-forward jump.
    **loop_params
        :data:`LOOP_PARAMS`, as for :class:`~semlab.control.VisualServo`; ``pid`` and ``creep`` may be
        sequences (one per axis), otherwise each axis gets its own copy.
    """

    def __init__(self, axes, models, *, frame_period: float, tracker=None, **loop_params):
        axes, models = list(axes), list(models)
        if len(axes) != len(models):
            raise ValueError(f"{len(axes)} axes but {len(models)} models: one fitted model per axis")
        unknown = set(loop_params) - set(LOOP_PARAMS)
        if unknown:
            raise TypeError(f"unknown parameter(s) {sorted(unknown)}; allowed: {sorted(LOOP_PARAMS)} and tracker")
        self.J = image_jacobian(models)
        self.J_inv = np.linalg.pinv(self.J)
        n = len(axes)
        per_axis = {k: _per_axis(loop_params.pop(k), n, k) for k in ("pid", "creep") if k in loop_params}
        self.loops = [AxisLoop(a, m, frame_period=frame_period, **loop_params,
                               **{k: v[i] for k, v in per_axis.items()}) for i, (a, m) in enumerate(zip(axes, models))]
        self.dt = float(frame_period)
        self._tracker = tracker
        self.rows: list[dict] = []
        self.frame = -1

    @property
    def n_axes(self) -> int:
        return len(self.loops)

    def plan(self, roi, target_xy) -> PointServo:
        """Check the move of the ROI's centre point to ``target_xy`` before anything moves.

        Raises
        ------
        ValueError
            A NaN target, or a move some axis cannot make within its limits.
        """
        self.roi = tuple(roi)
        self.p0 = np.array(start_point(roi))
        self.target = _target_point(target_xy)
        self.goals = self.J_inv @ (self.target - self.p0)
        for i, (loop, goal) in enumerate(zip(self.loops, self.goals)):
            loop.check_reach(float(goal), 0.0, f"axis {i}'s part of the move,")
        return self

    def check_frame(self, frame) -> None:
        """Raise ValueError if the move would take the ROI out of ``frame`` (the tracker could not
        follow the probe there)."""
        check_in_frame(self.roi, self.target - self.p0, np.shape(frame), "move to the target")

    def start(self, frame) -> PointServo:
        """Initialise the tracker on ``frame`` (frame 0, the ROI's) and send every axis its first
        command (:meth:`plan` first; the target is checked against the frame before anything moves)."""
        self.check_frame(frame)
        jump = float(np.hypot(*(self.target - self.p0)))
        self.tracker = default_tracker(self._tracker, jump_px=jump, roi=self.roi)
        self.tracker.init(frame, self.roi)
        self.frame = 0
        self.s_meas = np.zeros(self.n_axes)
        self._record(*self.p0, True, held=False)
        for loop, goal in zip(self.loops, self.goals):
            loop.begin(float(goal), 0.0, self.frame)
            loop.act(0.0, self.frame)
        return self

    def observe(self, frame) -> dict:
        """Measure the probe in the next frame (the last commands are in effect), record the row, and
        command every axis, or hold them all when the tracker lost the probe. Returns the row."""
        effect = ([lp.u for lp in self.loops], any(lp.at_limit for lp in self.loops))
        self.frame += 1
        x, y, ok = tracked_position(self.tracker, frame, self.frame)
        if ok:
            self.s_meas = self.J_inv @ (np.array([x, y]) - self.p0)
        row = self._record(x, y, ok, held=not ok, effect=effect)
        if ok:
            for loop, s in zip(self.loops, self.s_meas):
                loop.act(float(s), self.frame)
        return row

    def finish(self) -> None:
        for loop in self.loops:
            loop.end()

    def _record(self, x, y, ok, *, held, effect=None):
        us, at_limit = effect if effect is not None else ([lp.u for lp in self.loops], False)
        err = float(np.hypot(x - self.target[0], y - self.target[1])) if ok else float("nan")
        row = {"frame": self.frame, "t": self.frame * self.dt, "x": float(x), "y": float(y),
               "target_x": float(self.target[0]), "target_y": float(self.target[1]), "error_px": err,
               "ok": bool(ok)}
        row.update({f"u_{i}": float(u) for i, u in enumerate(us)})
        row.update({f"disp_{i}": float(s) if ok else float("nan") for i, s in enumerate(self.s_meas)})
        row.update(held=bool(held), at_limit=bool(at_limit), stage="start" if self.frame == 0 else "servo")
        self.rows.append(row)
        return row

    def to_frame(self) -> pd.DataFrame:
        df = pd.DataFrame(self.rows)
        df.attrs.update(jacobian=self.J.tolist(), origin=tuple(self.p0), target=tuple(self.target),
                        axes=[lp.model.axis for lp in self.loops], models=[lp.model.kind for lp in self.loops],
                        feedforward=self.loops[0].feedforward, frame_period=self.dt)
        return df


def _axes_and_models(actuator, model):
    if model is None:
        raise ValueError("model= is required: the fitted hysteresis model of each axis")
    try:
        axes, models = list(actuator), list(model)
    except TypeError:
        raise TypeError("actuator must be a sequence of axes (protocol Axis) and model the matching "
                        "sequence of fitted hysteresis models") from None
    for a in axes:
        if not callable(getattr(a, "apply", None)) or not hasattr(a, "limits"):
            raise TypeError(f"{a!r} is not an Axis (limits, apply(volts))")
    return axes, models


def move_probe_to(microscope, actuator, roi, target_xy, *, model, n_frames=60, **params) -> pd.DataFrame:
    """Servo the probe so that the ROI's centre point goes to ``target_xy``, all axes at once.

    Parameters
    ----------
    microscope : Microscope
    actuator : sequence of Axis, or Positioner
        The manipulator's axes that move the tip in the image (e.g. its x and y piezos), or a closed-loop
        positioner (:class:`semlab.protocols.Positioner`, relative moves in nm), servoed by
        :func:`semlab.positioning.move_positioner_to` with ``model`` its calibration.
    roi : (x, y, w, h)
        The probe's ROI in the current frame; its centre point is what goes to the target.
    target_xy : (float, float)
        Where the ROI's centre point should go, frame px.
    model : sequence of HysteresisModel
        ``model[i]`` fitted on ``actuator[i]`` (each characterised on its own axis): their measured image
        directions make the image Jacobian (:func:`image_jacobian`, not assumed orthogonal), their
        inverses the feed-forward. Each is the shadow of its axis and follows it through the move.
        For a positioner: its :class:`~semlab.positioning.PositionerCalibration`
        (:func:`semlab.calibrate_positioner`).
    n_frames : int
        Rows in the result; frame 0 is the frame the ROI refers to.
    **params
        ``tracker``, ``progress`` (a tqdm bar) and the one-axis law's :data:`LOOP_PARAMS`
        (``feedforward``, ``pid``, ``creep``, ``ki_fine``, ``fine_band_px``, ``ff_margin``,
        ``max_slew_v``, ``max_step_px``; see :class:`~semlab.control.VisualServo`). For a positioner
        :data:`POSITIONER_PARAMS` (``gain``, ``deadband_px``, ``max_step_px``, ``warmup_frames``,
        ``tracker``, ``progress``).

    Returns
    -------
    DataFrame
        One row per frame: ``frame, t, x, y, target_x, target_y, error_px, ok`` (:data:`POINT_COLUMNS`),
        ``u_0, u_1, ...`` the command of each axis in effect while the frame was acquired, then
        ``disp_0, ...`` (the measured displacement along each axis, px), ``held`` (tracker lost: every
        axis held its last command), ``at_limit`` (an axis limit clipped a command), ``stage``.
        ``error_px`` is the distance from the measured position to the target (NaN when ``ok`` is
        False). ``attrs``: ``jacobian, origin, target, axes, models, feedforward, frame_period``.
        For a positioner the same columns: ``u_0, u_1`` are the commanded offset (nm, the positioner's
        axes, from frame 0) in effect while the frame was acquired, ``disp_0, disp_1`` the measured one
        (nm, through the calibration), then ``move_positioner_to``'s own columns (``dx_nm, dy_nm`` the
        move sent after the frame, ``clipped``, ``reason``, ...).

    Raises
    ------
    ValueError
        A NaN target, a move that would take the ROI out of the frame, a move some axis cannot make within
        its limits (before anything moves, with the reason), nearly parallel axes, models fitted on other
        axes, or a tracker that reports a NaN position as valid.
    TypeError
        An actuator that is neither a sequence of axes nor a positioner, a positioner without a
        calibration, or parameters the actuator's servo does not take.

    Examples
    --------
    >>> axes = [rig.axis(0, "x"), rig.axis(0, "y")]                                  # doctest: +SKIP
    >>> resp = move_probe_to(rig.microscope, axes, roi, (300.0, 240.0), model=[mx, my])  # doctest: +SKIP
    >>> point_metrics(resp)[["response_frames_0p5px", "final_error_px"]]              # doctest: +SKIP
    """
    if isinstance(actuator, Positioner):  # a closed-loop stepper: its own servo, model= its calibration
        return _move_positioner_to(microscope, actuator, roi, target_xy, model, _n_frames(n_frames), params)
    axes, models = _axes_and_models(actuator, model)
    n_frames = _n_frames(n_frames)
    progress = bool(params.pop("progress", False))
    servo = PointServo(axes, models, frame_period=microscope.frame_period, tracker=params.pop("tracker", None),
                       **params)
    servo.plan(roi, target_xy).start(microscope.grab())
    for _ in _progress(range(n_frames - 1), progress, "moving the probe"):
        servo.observe(microscope.grab())
    servo.finish()
    return servo.to_frame()


def check_positioner_reach(positioner, calibration, roi, target_xy) -> None:
    """Raise ValueError (with the reason) when the positioner's travel limits cannot reach the target.

    The move is ``J^-1 (target - centre)`` through the calibration; it is refused only when it leaves the
    travel by more than :data:`~semlab.control.REACH_TOLERANCE` of its length on some axis (the
    calibration can be that far off; anything short of it is tried, and the servo clips at the limit).
    Nothing is checked when the positioner does not know its limits or its position.
    """
    limits, pos = getattr(positioner, "limits", None), getattr(positioner, "position_nm", None)
    if limits is None or pos is None:
        return
    du = calibration.to_positioner(np.asarray(target_xy, float) - start_point(roi))
    lo, hi = np.asarray(limits, float).T
    end = np.asarray(pos, float) + du
    slack = REACH_TOLERANCE * np.abs(du)
    for i, name in enumerate("xy"):
        if not lo[i] - slack[i] <= end[i] <= hi[i] + slack[i]:
            raise ValueError(
                f"the target needs the positioner's {name} axis at {end[i]:.6g} nm (a move of {du[i]:+.6g} nm "
                f"from {pos[i]:.6g}), outside its travel [{lo[i]:.6g}, {hi[i]:.6g}] nm even allowing the "
                f"calibration {REACH_TOLERANCE:.0%} error"
            )


def _move_positioner_to(microscope, positioner, roi, target_xy, calibration, n_frames, params) -> pd.DataFrame:
    """The positioner form of :func:`move_probe_to`: checks, then
    :func:`semlab.positioning.move_positioner_to`, its rows given the contract's columns."""
    from semlab.positioning import PositionerCalibration, move_positioner_to

    if not isinstance(calibration, PositionerCalibration):
        raise TypeError("for a positioner, model= is its PositionerCalibration (semlab.calibrate_positioner), "
                        f"got {type(calibration).__name__}")
    unknown = set(params) - set(POSITIONER_PARAMS)
    if unknown:
        raise TypeError(f"parameter(s) {sorted(unknown)} do not apply to a positioner; "
                        f"allowed: {sorted(POSITIONER_PARAMS)}")
    target = _target_point(target_xy)
    check_positioner_reach(positioner, calibration, roi, target)
    df = move_positioner_to(microscope, positioner, roi, target, calibration=calibration, n_frames=n_frames,
                            **params)
    sent = df[["dx_nm", "dy_nm"]].cumsum().shift(1, fill_value=0.0).to_numpy()  # in effect at each frame
    p = df[["x", "y"]].to_numpy(float)
    disp = calibration.to_positioner((p - p[0]).T).T
    extra = {"u_0": sent[:, 0], "u_1": sent[:, 1], "disp_0": disp[:, 0], "disp_1": disp[:, 1]}
    extra["at_limit"] = df["reason"].astype(str).str.contains("travel limits").to_numpy()
    extra["stage"] = np.where(df["frame"].to_numpy() == 0, "start", "servo")
    rest = [c for c in df.columns if c not in POINT_COLUMNS and c not in extra]
    out = pd.concat([df[list(POINT_COLUMNS)], pd.DataFrame(extra, index=df.index), df[rest]], axis=1)
    out.attrs.update(df.attrs, jacobian=calibration.jacobian.tolist(), origin=tuple(start_point(roi)),
                     target=tuple(target), axes=["x", "y"], models=["positioner calibration"],
                     feedforward=False, form="positioner")
    return out


def _n_frames(n_frames) -> int:
    if isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < 2:
        raise ValueError(f"n_frames must be an integer >= 2, got {n_frames!r}")
    return int(n_frames)


def _progress(iterable, enabled, desc):
    if not enabled:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, desc=desc, leave=False)


@dataclass
class ProbeMove:
    """One probe's move for :func:`move_probes_to`: as the arguments of :func:`move_probe_to`."""

    actuator: list
    roi: tuple
    target_xy: tuple
    model: list
    params: dict = field(default_factory=dict)


def move_probes_to(microscope, moves, *, n_frames=60, progress=False, **params) -> pd.DataFrame:
    """Servo several probes at once from one frame stream: each frame is grabbed once and every probe's
    own tracker measures it, then every probe's own loops command its axes.

    Parameters
    ----------
    microscope : Microscope
    moves : sequence of ProbeMove
        One per probe (disjoint axes); ``ProbeMove.params`` override ``params`` for that probe.
    n_frames : int
        Frames (rows per probe).
    **params
        As for :func:`move_probe_to`, for every probe.

    Returns
    -------
    DataFrame
        The rows of :func:`move_probe_to` for every probe, with a ``probe`` column (its index in
        ``moves``) first. Every probe's move is checked before anything moves.
    """
    moves = list(moves)
    if not moves:
        raise ValueError("no probe to move")
    n_frames = _n_frames(n_frames)
    seen = set()
    servos = []
    for k, mv in enumerate(moves):
        if not isinstance(mv, ProbeMove):
            raise TypeError(f"moves[{k}] must be a ProbeMove, got {type(mv).__name__}")
        if isinstance(mv.actuator, Positioner):
            raise TypeError(f"moves[{k}] drives a positioner: move_probes_to servoes piezo axes; move a "
                            "positioner with move_probe_to")
        axes, models = _axes_and_models(mv.actuator, mv.model)
        if seen & {id(a) for a in axes}:
            raise ValueError(f"moves[{k}] drives an axis another probe drives too")
        seen |= {id(a) for a in axes}
        p = {**params, **mv.params}
        servo = PointServo(axes, models, frame_period=microscope.frame_period, tracker=p.pop("tracker", None), **p)
        servos.append((servo.plan(mv.roi, mv.target_xy), mv))
    frame = microscope.grab()
    for servo, _ in servos:
        servo.check_frame(frame)
    for servo, _ in servos:
        servo.start(frame)
    for _ in _progress(range(n_frames - 1), progress, f"moving {len(servos)} probes"):
        frame = microscope.grab()
        for servo, _ in servos:
            servo.observe(frame)
    frames = []
    for k, (servo, _) in enumerate(servos):
        servo.finish()
        frames.append(servo.to_frame().assign(probe=k))
    out = pd.concat(frames, ignore_index=True)
    return out[["probe", *[c for c in out.columns if c != "probe"]]]


def point_metrics(response: pd.DataFrame, *, final_frames: int = 30, tolerance_px: float = 0.5) -> pd.Series:
    """Summary of a move to a point, the 2-D counterpart of :func:`semlab.control.step_metrics`.

    Parameters
    ----------
    response : DataFrame
        From :func:`move_probe_to` (columns ``frame, t, x, y, target_x, target_y, ok``); for several
        probes, one probe's rows.
    final_frames : int
        Frames at the end for the final mean and std.
    tolerance_px : float
        The band of ``response_frames`` (the issue's ±0.5 px).

    Returns
    -------
    Series
        ``distance_px`` (start to target); ``response_frames``/``response_time_s`` -- from the first row
        until the distance to the target enters and stays within ``tolerance_px`` (NaN if it never
        does); ``response_frames_1px``/``response_time_1px_s`` the same within 1 px; ``overshoot_px`` --
        the largest excursion beyond the target along the move's direction (0 if none);
        ``lateral_px`` -- the largest distance from the straight line start-target;
        ``final_error_px`` -- distance of the mean of the last ``final_frames`` valid positions from the
        target; ``final_std_px`` -- the larger of their x and y standard deviations; ``n_lost``.
    """
    if not isinstance(response, pd.DataFrame):
        raise TypeError("response must be a DataFrame from move_probe_to")
    missing = {"frame", "t", "x", "y", "target_x", "target_y", "ok"} - set(response.columns)
    if missing:
        raise ValueError(f"response lacks column(s) {sorted(missing)}")
    if len(response) < 2:
        raise ValueError("response has fewer than 2 rows")
    r = response.reset_index(drop=True)
    p = r[["x", "y"]].to_numpy(float)
    tgt = r[["target_x", "target_y"]].to_numpy(float)[-1]
    ok = r["ok"].to_numpy(bool) & np.all(np.isfinite(p), axis=1)
    err = np.hypot(*(p - tgt).T)
    t, fr = r["t"].to_numpy(float), r["frame"].to_numpy(int)
    move = tgt - p[0]
    dist = float(np.hypot(*move))
    out = {"distance_px": dist}
    for tol, suffix in ((float(tolerance_px), ""), (1.0, "_1px")):
        bad = np.flatnonzero(ok & (err > tol))
        if not ok.any() or (bad.size and bad[-1] == np.flatnonzero(ok)[-1]):
            out[f"response_frames{suffix}"], out[f"response_time{suffix}_s"] = np.nan, np.nan
            continue
        i = np.flatnonzero(ok & (np.arange(len(r)) > (bad[-1] if bad.size else -1)))[0]
        out[f"response_frames{suffix}"], out[f"response_time{suffix}_s"] = int(fr[i] - fr[0]), float(t[i] - t[0])
    unit = move / dist if dist > 0 else np.zeros(2)
    along = (p - tgt) @ unit
    lateral = (p - p[0]) @ np.array([-unit[1], unit[0]])
    out["overshoot_px"] = float(max(0.0, np.max(along[ok]))) if ok.any() and dist > 0 else 0.0
    out["lateral_px"] = float(np.max(np.abs(lateral[ok]))) if ok.any() else np.nan
    tail = p[ok][-int(final_frames):]
    if tail.shape[0]:
        out["final_error_px"] = float(np.hypot(*(tail.mean(axis=0) - tgt)))
        out["final_std_px"] = float(np.max(np.std(tail, axis=0, ddof=1))) if tail.shape[0] > 1 else np.nan
    else:
        out["final_error_px"] = out["final_std_px"] = np.nan
    out["n_lost"] = int((~ok).sum())
    return pd.Series(out)
