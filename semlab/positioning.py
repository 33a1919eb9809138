"""Closed-loop positioners servoed from the image: calibration and the move to a point.

A FIB/SEM manipulator (or stage) is moved by relative steps in nanometres along its own axes, which
the image sees through the scan rotation, the viewing geometry (tilt foreshortening, axis skew) and
the pixel size. To first order a move ``du`` (nm, the positioner's axes) shifts the tip in the image
by::

    dp = J du          J: 2x2 image Jacobian, px per nm

:func:`calibrate_positioner` measures ``J`` from small test moves of each axis and back, tracked
sub-pixel; :func:`move_positioner_to` is the image-based visual servo of the paper's Fig. 8a for
such an actuator (the resolved-rate law of image-based visual servoing): after frame ``k`` it sends

    du_k = g J^-1 (target - p_k)

with a gain ``g < 1`` (steppers overshoot, lag and couple their axes: a gain below one converges
through all of that as long as the product of the true and the calibrated Jacobians stays within a
factor ``2/g`` of the identity), nothing inside a dead band at the tracker's noise, no axis command
smaller than the positioner's resolution, and no command at all on a frame the tracker flags.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from semlab.measure import default_tracker, read_result, start_point
from semlab.protocols import Positioner, ScaledMicroscope, TimedMicroscope, as_finite, frame_time

__all__ = [
    "SERVO_COLUMNS",
    "CalibrationError",
    "PositionerCalibration",
    "calibrate_positioner",
    "move_positioner_to",
]

SERVO_COLUMNS = ("frame", "t", "x", "y", "target_x", "target_y", "error_px", "ok", "dx_nm", "dy_nm")
#: Image length (px) of a calibration test move when ``step_nm`` is not given: long against the
#: tracker's noise and its position-dependent bias (each ~0.1 px: ~0.5 % of the move), short enough to
#: stay well inside the tracker's search window (+-50 px by default) and near the start point, where
#: the mapping is linear.
TEST_MOVE_PX = 20.0
#: Frames grabbed after each test move before measuring: one for a move still settling.
SETTLE_FRAMES = 1
#: Frames averaged per measured position (the tracker's noise falls as 1/sqrt of it).
AVERAGE_FRAMES = 2
#: Still frames at the start: the reference position and the tracker's noise.
STILL_FRAMES = 6
#: A test move must shift the tip by this many noise standard deviations (and at least
#: MIN_MOVE_PX) to count as a move: below that the tip did not move (needle retracted, axis
#: disabled, a step below the resolution).
MIN_MOVE_SIGMAS = 10.0
MIN_MOVE_PX = 0.5
#: Largest RMS residual of the linear fit, as a fraction of the test move, for a calibration to be
#: accepted: a stepper's few % of shortfall or backlash stays below it; a slipping axis, a tip that
#: did not come back or a tracker that jumped to something else does not.
MAX_RESIDUAL_FRACTION = 0.1
#: Largest condition number of J: above it the two axes move the tip along (nearly) one image
#: direction and the image cannot steer the other.
MAX_CONDITION = 20.0
#: Fraction of the image error corrected per frame. Below one because steppers lag: with a fraction
#: ``l`` of each move showing a frame late the loop's poles solve ``z^2 - (1 - g(1 - l)) z + g l = 0``;
#: g = 0.7 keeps them within 0.46 of the origin from l = 0 to 0.3 (0.8 reaches 0.49 at l = 0.3 and rings
#: past a 0.5 px band on 60-px moves), and tolerates a calibration off by up to 2/g - 1 = 185 %.
DEFAULT_GAIN = 0.7
#: Frames the servo tracks the still tip before its first move. The tracker's template is the ROI of
#: one frame until it has averaged more (Tracker's template_frames), and along a needle's shaft a
#: one-frame template leaves registration errors of 0.3-0.9 px on the first frames after a 40-px move
#: (the Demo bridge, seed 1); four still frames average the template before anything moves.
WARMUP_FRAMES = 4
#: Inside this distance (px) of the target a correction waits for FINE_AVERAGE frames of the still tip:
#: the tracker's single-frame error along a needle's shaft (~0.15 px RMS on the Demo bridge) would
#: otherwise send noise as moves.
FINE_ZONE_PX = 1.0
FINE_AVERAGE = 2
#: Dead band in multiples of the tracker's 2-D RMS noise: the error of a still tip is Rayleigh
#: distributed, so noise alone leaves a band of 2 RMS on exp(-4) = 1.8 % of frames. Kept inside
#: [MIN_DEADBAND_PX, MAX_DEADBAND_PX]: the upper end keeps it well inside a 0.5 px tolerance.
DEADBAND_SIGMAS = 2.0
MIN_DEADBAND_PX = 0.05
MAX_DEADBAND_PX = 0.25


class CalibrationError(RuntimeError):
    """The positioner could not be calibrated (the message says why and what to check)."""


@dataclass(frozen=True)
class PositionerCalibration:
    """The measured mapping from positioner moves (nm, its own axes) to image shifts (px).

    Attributes
    ----------
    jacobian : (2, 2) ndarray
        ``J`` in px per nm: column ``j`` is the image shift per nm of axis ``j`` (x, y).
    jacobian_std : (2, 2) ndarray
        Standard error of each entry, from the residuals of the least-squares fit (moves taken as
        independent; a tracker bias that repeats at the same position does not show in the residuals,
        so the true error can reach a few of these).
    residual_px : float
        RMS residual (px) of the linear fit over all test moves.
    noise_px : float
        The tracker's 2-D RMS noise on a still tip (px per frame, ``sqrt(var_x + var_y)``), from the
        still frames before the test moves.
    step_nm : float
        Length of each test move.
    moves : DataFrame
        One row per test move: ``move, axis, dx_nm, dy_nm, dpx, dpy`` (measured image shift, px)
        and ``fit_dpx, fit_dpy`` (the fit's prediction).
    meta : dict
        What the calibration was run on (pixel size, frames, ROI).
    """

    jacobian: np.ndarray
    jacobian_std: np.ndarray
    residual_px: float
    noise_px: float
    step_nm: float
    moves: pd.DataFrame = field(repr=False)
    meta: dict = field(default_factory=dict, repr=False)

    @property
    def inverse(self) -> np.ndarray:
        """``J^-1``: nm per px."""
        return np.linalg.inv(self.jacobian)

    def to_image(self, d_nm) -> np.ndarray:
        """Image shift (px) of a move ``d_nm = (dx, dy)`` in the positioner's axes."""
        return self.jacobian @ np.asarray(d_nm, float)

    def to_positioner(self, d_px) -> np.ndarray:
        """The move (nm, positioner axes) that shifts the tip by ``d_px`` in the image."""
        return np.linalg.solve(self.jacobian, np.asarray(d_px, float))

    @property
    def axis_angles_deg(self) -> tuple[float, float]:
        """Image direction (deg, 0 = +x, 90 = down) of each axis' positive move."""
        j = self.jacobian
        return tuple(float(np.degrees(np.arctan2(j[1, i], j[0, i]))) for i in range(2))

    @property
    def scale_px_per_um(self) -> tuple[float, float]:
        """Image length (px) of a 1 um move along each axis."""
        return tuple(float(1e3 * np.hypot(*self.jacobian[:, i])) for i in range(2))

    @property
    def skew_deg(self) -> float:
        """Angle between the two axes' images minus 90 deg (0 for orthogonal, equally handed axes)."""
        ax, ay = self.axis_angles_deg
        return float((ay - ax + 180.0) % 360.0 - 180.0 - math.copysign(90.0, np.linalg.det(self.jacobian)))

    @property
    def condition(self) -> float:
        """Condition number of ``J`` (1 for orthogonal axes of equal scale)."""
        return float(np.linalg.cond(self.jacobian))

    def summary(self) -> pd.Series:
        """The figures a user checks: axis angles, scales, skew, residual, noise."""
        (ax, ay), (sx, sy) = self.axis_angles_deg, self.scale_px_per_um
        return pd.Series({"x axis angle (deg)": ax, "y axis angle (deg)": ay,
                          "x scale (px/um)": sx, "y scale (px/um)": sy, "skew (deg)": self.skew_deg,
                          "condition": self.condition, "fit residual (px)": self.residual_px,
                          "tracker noise (px)": self.noise_px, "test move (nm)": self.step_nm})

    def as_dict(self) -> dict:
        """JSON-ready record (provenance sidecars)."""
        return {"jacobian_px_per_nm": self.jacobian.tolist(),
                "jacobian_std_px_per_nm": self.jacobian_std.tolist(),
                "residual_px": self.residual_px, "noise_px": self.noise_px, "step_nm": self.step_nm,
                "axis_angles_deg": list(self.axis_angles_deg), "skew_deg": self.skew_deg,
                "n_moves": len(self.moves), **self.meta}


# ------------------------------------------------------------------------------------- helpers
def _check_positioner(positioner) -> None:
    if not isinstance(positioner, Positioner):
        raise TypeError(f"positioner must implement semlab.protocols.Positioner (move_by, limits, "
                        f"resolution_nm, position_nm); got {type(positioner).__name__}")


#: A calibration's measurement skips at most this many frames the tracker flags before it counts the
#: tip as lost (a flag is one frame's doubt; a lost tip stays lost).
MAX_FLAGGED_FRAMES = 3


class _Eye:
    """Grab and track; a frame that cannot be grabbed counts as lost (the instrument's message kept)."""

    def __init__(self, microscope, tracker, roi):
        self.microscope = microscope
        self.tracker = default_tracker(tracker)
        self.frames = 0
        frame = microscope.grab()
        self.shape = np.shape(frame)
        res = self.tracker.init(frame, roi)
        self.t0 = microscope.last_frame_time if isinstance(microscope, TimedMicroscope) else None
        self.first = res

    def look(self):
        """(x, y, score, ok, reason) of the next frame."""
        self.frames += 1
        try:
            frame = self.microscope.grab()
        except Exception as err:  # noqa: BLE001 -- any instrument failure is a frame we cannot see
            return np.nan, np.nan, 0.0, False, f"no frame: {type(err).__name__}: {err}"
        res = self.tracker.update(frame)
        x, y, score, flagged_ok = read_result(res)
        ok = flagged_ok and math.isfinite(x) and math.isfinite(y)
        reason = getattr(res, "reason", "") if not flagged_ok else ("" if ok else "non-finite position")
        return x, y, score, ok, reason

    def time(self) -> float:
        return frame_time(self.microscope, self.frames, self.t0)


# --------------------------------------------------------------------------------- calibration
def _default_step_nm(microscope, step_nm) -> float:
    if step_nm is not None:
        step = as_finite(step_nm, "step_nm")
        if not step > 0:
            raise ValueError(f"step_nm must be > 0, got {step_nm!r}")
        return step
    ps = microscope.pixel_size_nm if isinstance(microscope, ScaledMicroscope) else None
    if ps is None or not (math.isfinite(ps) and ps > 0):
        raise ValueError("the microscope does not report its pixel size: give step_nm, a test move "
                         f"of about {TEST_MOVE_PX:g} px in the image")
    return TEST_MOVE_PX * float(ps)


def _test_moves(step: float, repeats: int) -> list[tuple[str, float, float]]:
    """Each axis: +step, back, -step, back (backlash and shortfall show in both directions)."""
    out = []
    for _ in range(repeats):
        for axis, unit in (("x", (1.0, 0.0)), ("y", (0.0, 1.0))):
            for sign in (1.0, -1.0, -1.0, 1.0):
                out.append((axis, sign * step * unit[0], sign * step * unit[1]))
    return out


def _measure(eye, n_settle, n_average, what):
    """Mean position over ``n_average`` frames the tracker vouches for, after ``n_settle``.

    A frame the tracker flags (``ok=False``: too uncertain, inconsistent) is skipped, up to
    :data:`MAX_FLAGGED_FRAMES` of them: the tip stands still, so the next frame measures it as well.
    More than that, and the tip counts as lost: CalibrationError.
    """
    pts, flagged = [], 0
    for i in itertools.count():
        if len(pts) >= n_average:
            break
        x, y, _score, ok, reason = eye.look()
        if i < n_settle:
            continue
        if not ok:
            flagged += 1
            if flagged > MAX_FLAGGED_FRAMES:
                raise CalibrationError(f"the tracker lost the tip {what} (frame {eye.frames}: {reason}); "
                                       "a calibration needs every test move seen: check the ROI, the "
                                       "focus, and that the tip stays in view")
            continue
        pts.append((x, y))
    return np.mean(pts, axis=0), np.asarray(pts)


def calibrate_positioner(microscope, positioner, roi, *, step_nm=None, tracker=None, repeats: int = 1,
                         settle_frames: int = SETTLE_FRAMES, average_frames: int = AVERAGE_FRAMES,
                         progress: bool = False) -> PositionerCalibration:
    """Measure the image Jacobian of a positioner by tracking small test moves of each axis and back.

    Each axis is moved by ``+step_nm``, back, ``-step_nm`` and back (``repeats`` times); the tip is
    tracked sub-pixel (:class:`semlab.tracking.Tracker`) and ``dp = J du`` is fitted by least squares
    over all moves, which captures the scan rotation, the axes' skew and their scales. The positioner
    ends where it started (up to its own repeatability).

    Parameters
    ----------
    microscope : Microscope
        Frames; with a pixel size (:class:`~semlab.protocols.ScaledMicroscope`) ``step_nm`` may be left out.
    positioner : Positioner
    roi : (x, y, w, h)
        Around the tip in the current frame.
    step_nm : float, optional
        Length of each test move; default about :data:`TEST_MOVE_PX` px at the microscope's pixel size.
    tracker : optional
        An object with ``init(frame, roi)`` and ``update(frame)``; default ``Tracker()``.
    repeats : int
        Cycles of the 8 test moves.
    settle_frames, average_frames : int
        Frames skipped after each move, then averaged.
    progress : bool
        A tqdm bar over the moves.

    Returns
    -------
    PositionerCalibration

    Raises
    ------
    CalibrationError
        The tracker lost the tip; the tip did not move (an axis' shift below
        ``MIN_MOVE_SIGMAS`` noise deviations); the moves are not linear (fit residual above
        ``MAX_RESIDUAL_FRACTION`` of a test move); the two axes move the tip along one image line.
    ValueError, TypeError
        Bad ROI, step, or an object that is not a Positioner.
    """
    _check_positioner(positioner)
    step = _default_step_nm(microscope, step_nm)
    for name, v, lo in (("repeats", repeats, 1), ("settle_frames", settle_frames, 0),
                        ("average_frames", average_frames, 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    start_point(roi)  # a malformed ROI fails here, before anything moves
    eye = _Eye(microscope, tracker, roi)
    p_prev, still = _measure(eye, 0, STILL_FRAMES, "on the still frames")
    noise = float(np.sqrt(np.sum(np.var(still, axis=0, ddof=1))))
    rows = []
    moves = _test_moves(step, int(repeats))
    it = moves
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(moves, desc="calibrating", leave=False)
    for i, (axis, dx, dy) in enumerate(it):
        positioner.move_by(dx, dy)
        p, _ = _measure(eye, settle_frames, average_frames, f"after test move {i} ({axis} {dx + dy:+.4g} nm)")
        rows.append({"move": i, "axis": axis, "dx_nm": dx, "dy_nm": dy,
                     "dpx": p[0] - p_prev[0], "dpy": p[1] - p_prev[1]})
        p_prev = p
    moves_df = pd.DataFrame(rows)
    meta = {"roi": [int(v) if float(v).is_integer() else float(v) for v in roi],
            "frames": eye.frames + 1, "repeats": int(repeats), "settle_frames": int(settle_frames),
            "average_frames": int(average_frames),
            "pixel_size_nm": getattr(microscope, "pixel_size_nm", None)}
    return _fit_jacobian(moves_df, step, noise, meta)


def _fit_jacobian(moves: pd.DataFrame, step: float, noise: float, meta: dict) -> PositionerCalibration:
    """Least squares ``dp = J du`` over the test moves, with the refusals of :func:`calibrate_positioner`."""
    u = moves[["dx_nm", "dy_nm"]].to_numpy(float)
    d = moves[["dpx", "dpy"]].to_numpy(float)
    # one measured shift is a difference of two means of `average` frames: its 2-D RMS noise is
    # noise * sqrt(2 / average)
    move_noise = noise * math.sqrt(2.0 / meta["average_frames"])
    min_move = max(MIN_MOVE_PX, MIN_MOVE_SIGMAS * move_noise)
    for j, axis in enumerate("xy"):
        shifts = np.hypot(*d[u[:, j] != 0].T)
        if np.median(shifts) < min_move:
            raise CalibrationError(
                f"the tip did not move when the positioner's {axis} axis was moved by {step:.4g} nm "
                f"(median image shift {np.median(shifts):.3g} px, below {min_move:.3g} px = "
                f"max({MIN_MOVE_PX:g} px, {MIN_MOVE_SIGMAS:g} x the tracker's noise)): is the needle "
                "inserted and the axis enabled, is step_nm above its resolution, is the ROI on the tip?")
    sol, *_ = np.linalg.lstsq(u, d, rcond=None)
    jac = sol.T
    fit = u @ sol
    res = d - fit
    dof = max(1, len(u) - 2)
    rms = float(np.sqrt(np.mean(np.sum(res ** 2, axis=1))))
    test_px = float(np.median(np.hypot(*d.T)))
    if rms > MAX_RESIDUAL_FRACTION * test_px + 3.0 * move_noise:
        worst = int(np.argmax(np.hypot(*res.T)))
        raise CalibrationError(
            f"the tip moved inconsistently: the linear fit leaves {rms:.3g} px RMS on test moves of "
            f"{test_px:.3g} px (more than {MAX_RESIDUAL_FRACTION:.0%} of a move); worst is move {worst} "
            f"({moves['axis'].iloc[worst]} {u[worst].sum():+.4g} nm: measured {d[worst].round(2).tolist()} "
            f"px, fit {fit[worst].round(2).tolist()} px). An axis slipping or sticking, a tip that does "
            "not come back, or the tracker jumping to another feature")
    cov = np.linalg.inv(u.T @ u)
    # one residual variance pooled over both image coordinates (2 x dof degrees of freedom): with 8
    # moves, a per-coordinate estimate (6 dof) is itself uncertain by +-30 % and often far too small
    sig2 = np.sum(res ** 2) / (2 * dof)
    jac_std = np.sqrt(sig2 * np.tile(np.diag(cov), (2, 1)))
    moves = moves.assign(fit_dpx=fit[:, 0], fit_dpy=fit[:, 1])
    cal = PositionerCalibration(jac, jac_std, rms, noise, float(step), moves, meta)
    if not np.isfinite(cal.condition) or cal.condition > MAX_CONDITION:
        raise CalibrationError(
            f"the two axes move the tip along nearly one image direction (axis angles "
            f"{cal.axis_angles_deg[0]:.1f} and {cal.axis_angles_deg[1]:.1f} deg, condition "
            f"{cal.condition:.3g} > {MAX_CONDITION:g}): this view cannot steer both (is one axis along "
            "the beam? use the other beam's view or the other pair of axes)")
    return cal


# --------------------------------------------------------------------------------------- servo
def _check_target(target_xy, shape) -> np.ndarray:
    try:
        tx, ty = (as_finite(v, "target", "refusing to drive blind") for v in target_xy)
    except TypeError:
        raise ValueError(f"target_xy must be (x, y) px, got {target_xy!r}") from None
    rows, cols = shape[:2]
    if not (0 <= tx <= cols - 1 and 0 <= ty <= rows - 1):
        raise ValueError(f"target ({tx:.1f}, {ty:.1f}) px lies outside the {cols}x{rows} frame: the "
                         "servo can only drive the tip to where it can see it")
    return np.array([tx, ty])


def _servo_settings(calibration, gain, deadband_px, max_step_px, n_frames) -> float:
    """Validate; returns the dead band in px."""
    if not isinstance(calibration, PositionerCalibration):
        raise TypeError("calibration must be a PositionerCalibration (from semlab.calibrate_positioner), "
                        f"got {type(calibration).__name__}")
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise ValueError(f"n_frames must be a positive integer, got {n_frames!r}")
    if not 0 < as_finite(gain, "gain") < 1:
        raise ValueError(f"gain must lie in (0, 1): a stepper that overshoots or lags makes a gain of 1 "
                         f"or more ring or diverge; got {gain!r}")
    if not as_finite(max_step_px, "max_step_px") > 0:
        raise ValueError(f"max_step_px must be > 0, got {max_step_px!r}")
    if deadband_px is None:
        return float(np.clip(DEADBAND_SIGMAS * calibration.noise_px, MIN_DEADBAND_PX, MAX_DEADBAND_PX))
    band = as_finite(deadband_px, "deadband_px")
    if band < 0:
        raise ValueError(f"deadband_px must be >= 0, got {deadband_px!r}")
    return band


def _servo_command(positioner, calibration, error, gain, max_step_px):
    """The move (nm) for one image error (px): gain, step limit, resolution, travel limits.

    Returns ``(du, clipped, note)``; ``du`` is all zeros when nothing should be sent.
    """
    step_px = gain * error
    norm = float(np.hypot(*step_px))
    clipped = norm > max_step_px
    if clipped:
        step_px = step_px * (max_step_px / norm)
    du = calibration.to_positioner(step_px)
    res = float(positioner.resolution_nm or 0.0)
    du[np.abs(du) < res] = 0.0
    note = "" if np.any(du) else f"move below the positioner's resolution ({res:g} nm)"
    limits, pos = positioner.limits, positioner.position_nm
    if limits is not None and pos is not None and np.any(du):
        lo, hi = np.asarray(limits, float).T
        new = np.clip(np.asarray(pos, float) + du, lo, hi)
        if np.any(np.abs(new - pos - du) > 1e-9):
            du, clipped = new - np.asarray(pos, float), True
            note = "clipped at the positioner's travel limits"
    return du, clipped, note


class _ServoLoop:
    """One frame's decision: estimate, dead band, command, safety (see :func:`move_positioner_to`)."""

    def __init__(self, positioner, calibration, target, gain, band, max_step_px):
        self.positioner, self.calibration, self.target = positioner, calibration, target
        self.gain, self.band, self.max_step_px = gain, band, max_step_px
        self.still = []  # positions seen since the last move was sent: the tip has not been moved

    def observe(self, x, y, ok) -> None:
        if ok:
            self.still.append((x, y))

    def step(self, x, y, ok, reason, *, last: bool) -> dict:
        self.observe(x, y, ok)
        err = self.target - (x, y)
        est = self.target - np.mean(self.still, axis=0) if self.still else np.full(2, np.nan)
        du, clipped, held = np.zeros(2), False, False
        distance = float(np.hypot(*est))
        fine_wait = distance < FINE_ZONE_PX and len(self.still) < FINE_AVERAGE
        if not ok:
            held = True
        elif distance > self.band and not last and not fine_wait:  # a move after the last frame is never seen
            du, clipped, reason = _servo_command(self.positioner, self.calibration, est, self.gain,
                                                 self.max_step_px)
            if np.any(du):
                try:
                    self.positioner.move_by(float(du[0]), float(du[1]))
                    self.still = []
                except (ValueError, RuntimeError) as refusal:
                    du, held, reason = np.zeros(2), True, f"move refused: {refusal}"
        return {"error_px": float(np.hypot(*err)), "ok": ok, "dx_nm": float(du[0]), "dy_nm": float(du[1]),
                "error_x": float(err[0]), "error_y": float(err[1]), "estimate_error_px": distance,
                "averaged": len(self.still) if ok else 0, "held": held, "clipped": bool(clipped),
                "reason": reason}


def move_positioner_to(microscope, positioner, roi, target_xy, *, calibration, n_frames: int = 60,
                       gain: float = DEFAULT_GAIN, deadband_px: float | None = None, max_step_px: float = 40.0,
                       warmup_frames: int = WARMUP_FRAMES, tracker=None, progress: bool = False) -> pd.DataFrame:
    """Drive a positioner until the ROI's centre point sits at ``target_xy`` in the image.

    Image-based visual servo (paper, Fig. 8a) with the calibrated Jacobian: after frame ``k`` the move
    ``du = gain J^-1 (target - p_k)`` is sent (it shows from frame ``k + 1``), where ``p_k`` is the mean
    of the positions tracked since the last move (the tip has not been moved since, so averaging them
    beats the tracker's single-frame noise; within ``FINE_ZONE_PX`` of the target a correction waits
    for ``FINE_AVERAGE`` of them). Before the first move the tracker follows the still tip for
    ``warmup_frames`` frames (not rows of the result). Safety: a frame the
    tracker flags (``ok=False``: lost, blanked, unusable or no frame at all) sends nothing; inside the
    dead band nothing is sent; no axis command below ``positioner.resolution_nm``; moves are clipped
    into ``positioner.limits`` when the positioner reads its position, and a move the positioner
    refuses (ValueError/RuntimeError) is recorded and held, not retried blindly.

    Parameters
    ----------
    microscope : Microscope
    positioner : Positioner
    roi : (x, y, w, h)
        Around the tip in the current frame; its centre point is what is moved.
    target_xy : (float, float)
        Where the centre point should go, frame px.
    calibration : PositionerCalibration
        From :func:`calibrate_positioner` (the lead's ``semlab.move_probe_to`` passes it as ``model``).
    n_frames : int
        Rows in the result (frame 0 is the frame the ROI refers to).
    gain : float
        In (0, 1): the fraction of the error corrected per frame.
    deadband_px : float, optional
        Default: ``DEADBAND_SIGMAS`` times the calibration's tracker noise, within
        [``MIN_DEADBAND_PX``, ``MAX_DEADBAND_PX``].
    max_step_px : float
        Largest image shift asked for in one frame (stays inside the tracker's search window).
    warmup_frames : int
        Still frames tracked before the first move (:data:`WARMUP_FRAMES`).
    tracker : optional
        ``init(frame, roi)``/``update(frame)``; default ``Tracker()``.
    progress : bool

    Returns
    -------
    DataFrame
        One row per frame: ``frame, t, x, y, target_x, target_y, error_px, ok, dx_nm, dy_nm`` and
        ``score, error_x, error_y, estimate_error_px, averaged, held, clipped, reason``. Frame 0 is the
        last frame before the first move. ``x, y`` are the tracked position (NaN when ``ok`` is False),
        ``error_px`` its distance to the target, ``estimate_error_px`` the distance of the mean of the
        ``averaged`` positions seen since the last move (what the command is computed from),
        ``dx_nm, dy_nm`` the move sent after this frame (0 when none), ``held`` marks frames where the
        tracker's flag or a refused move withheld it, ``clipped`` a move shortened by ``max_step_px``
        or the limits. ``attrs`` holds the dead band, gain, step limit and warm-up.

    Raises
    ------
    ValueError
        NaN/inf or off-frame target, bad ROI or parameters (before anything moves).
    TypeError
        Not a Positioner or not a PositionerCalibration.
    """
    _check_positioner(positioner)
    band = _servo_settings(calibration, gain, deadband_px, max_step_px, n_frames)
    if not np.all(np.isfinite(np.asarray(target_xy, float))):
        raise ValueError(f"target {target_xy!r} is not finite: refusing to drive blind")
    start_point(roi)  # a malformed ROI fails here, before anything moves
    if isinstance(warmup_frames, bool) or not isinstance(warmup_frames, (int, np.integer)) or warmup_frames < 0:
        raise ValueError(f"warmup_frames must be a non-negative integer, got {warmup_frames!r}")
    eye = _Eye(microscope, tracker, roi)
    target = _check_target(target_xy, eye.shape)
    first = eye.first
    loop = _ServoLoop(positioner, calibration, target, gain, band, max_step_px)
    seen = (*read_result(first)[:3], True, "")
    for _ in range(int(warmup_frames)):  # the still tip: the tracker's template averages these
        loop.observe(*seen[:2], seen[3])
        seen = eye.look()
    rows = []
    it = range(int(n_frames))
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, desc="moving", leave=False)
    t0 = eye.time()  # of frame 0, the last frame before the first move
    for k in it:
        x, y, score, ok, reason = seen if k == 0 else eye.look()
        row = loop.step(x, y, ok, reason, last=k == n_frames - 1)
        rows.append({"frame": k, "t": eye.time() - t0, "x": x, "y": y,
                     "target_x": target[0], "target_y": target[1], "score": score, **row})
    df = pd.DataFrame(rows)
    df = df[list(SERVO_COLUMNS) + [c for c in df.columns if c not in SERVO_COLUMNS]]
    df.attrs.update(deadband_px=band, gain=float(gain), max_step_px=float(max_step_px),
                    warmup_frames=int(warmup_frames),
                    frame_period=float(microscope.frame_period))
    return df
