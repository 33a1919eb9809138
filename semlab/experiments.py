"""Experiments that drive a rig while the visual tracker measures (paper, Fig. 8b and the creep hold).

* :func:`characterisation_voltages` -- the voltage path of Fig. 8b, with inner loops, labelled by
  hysteresis branch (:func:`label_branches`);
* :func:`drive_voltages` -- a voltage path applied one increment per frame, the tracker following;
* :func:`characterise_hysteresis` -- the experiment of Fig. 8b on any
  :class:`~semlab.protocols.Microscope` / :class:`~semlab.protocols.Axis` pair, with inner loops, the
  displacement measured by the tracker (fit the models of :mod:`semlab.hysteresis` to it);
* :func:`characterise_creep` -- one open-loop feed-forward step held for a while (fit
  :class:`~semlab.creep.CreepModel` to it).

The rig is reached only through the protocols and the tracker (:class:`~semlab.protocols.VisualTracker`),
so the same calls run on :class:`semlab.sim.SimulatedRig` and on a real SEM.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .creep import CreepModel, fit_creep
from .hysteresis import axis_identity
from .measure import default_tracker, read_result, start_point
from .protocols import as_finite, check_command

__all__ = ["DEFAULT_INNER_TURNS", "characterisation_voltages", "characterise_creep", "characterise_hysteresis",
           "drive_voltages", "label_branches"]

#: Default turning points (fractions of the range) after the major loop. The path reverses on the
#: ascending branch (mirror of eq. 11), nests a second and third-order loop that closes again, then
#: reverses on the descending branch (eq. 11 itself) and nests once more.
DEFAULT_INNER_TURNS = (0.75, 0.25, 0.6, 0.4, 1.0, 0.3, 0.8, 0.5, 0.0)


def label_branches(voltages, u_min: float, u_max: float) -> list[str]:
    """Label each voltage of a path with its hysteresis branch, using the wiping-out rule.

    A point is on a major branch (``'ascending'``/``'descending'``) when no reversal point inside the
    range is remembered, otherwise on an inner curve (``'inner_ascending'``/``'inner_descending'``).
    The path is assumed to start at ``u_min`` after a descent (the preconditioned state).
    """
    u_prev, rising, stack = float(u_min), True, []
    labels = []
    for u in np.asarray(voltages, dtype=float):
        if u != u_prev:
            now_rising = u > u_prev
            if now_rising != rising and u_min < u_prev < u_max:
                stack.append(u_prev)
            rising = now_rising
            # wiping-out: passing the remembered turning point of the opposite kind closes the loop
            while len(stack) >= 2 and ((rising and u >= stack[-2]) or (not rising and u <= stack[-2])):
                del stack[-2:]
            if u <= u_min or u >= u_max:
                stack.clear()
            u_prev = float(u)
        major = not stack
        labels.append(("" if major else "inner_") + ("ascending" if rising else "descending"))
    return labels


def characterisation_voltages(u_min: float, u_max: float, n_steps: int = 30, inner_loops=True) -> pd.DataFrame:
    """The voltage path of a characterisation (paper, Fig. 8b), without applying it.

    Parameters
    ----------
    u_min, u_max : float
        ``U0`` and ``Un`` in volts.
    n_steps : int
        Increments per major branch (the step is ``(Un - U0) / n_steps``).
    inner_loops : bool or sequence of float
        ``True`` appends :data:`DEFAULT_INNER_TURNS` (turning points as fractions of the range) after
        the major loop, ``False`` only the major loop; a sequence gives the turning points explicitly.

    Returns
    -------
    DataFrame
        Columns ``step, segment, u, branch``. Segment 0 is the ascending major branch, 1 the
        descending one, 2... the inner-loop segments.
    """
    u_min, u_max = as_finite(u_min, "u_min"), as_finite(u_max, "u_max")
    if not u_min < u_max:
        raise ValueError(f"u_min={u_min} must be below u_max={u_max}")
    n_steps = int(n_steps)
    if n_steps < 2:
        raise ValueError(f"n_steps={n_steps}: at least 2 increments per branch are needed")
    turns = [1.0, 0.0]
    if inner_loops is True:
        turns += list(DEFAULT_INNER_TURNS)
    elif inner_loops not in (False, None):
        turns += [float(f) for f in inner_loops]
    if any(not 0.0 <= f <= 1.0 for f in turns):
        raise ValueError(f"inner-loop turning points must be fractions in [0, 1], got {turns}")
    span = u_max - u_min
    us, segs = [], []
    f_prev = 0.0
    for seg, f in enumerate(turns):
        n = max(1, round(abs(f - f_prev) * n_steps))
        fr = np.linspace(f_prev, f, n + 1)[1:]
        us.extend(u_min + fr * span)
        segs.extend([seg] * n)
        f_prev = f
    # the very first point: U0 itself, on the ascending major branch
    us = [u_min] + us
    segs = [0] + segs
    u = np.clip(np.asarray(us), u_min, u_max)
    return pd.DataFrame(
        {"step": np.arange(len(u)), "segment": segs, "u": u, "branch": label_branches(u, u_min, u_max)}
    )


def _progress(iterable, enabled, desc, total=None):
    if not enabled:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, desc=desc, total=total, leave=False)


def drive_voltages(microscope, axis, tracker, voltages, *, settle_frames: int = 1, model=None,
                   progress: bool = False, desc: str = "driving") -> pd.DataFrame:
    """Apply a voltage path one increment per frame while an initialised tracker follows the probe.

    Parameters
    ----------
    microscope, axis
        :class:`~semlab.protocols.Microscope` and :class:`~semlab.protocols.Axis`.
    tracker
        Already initialised (``init`` called on the current frame).
    voltages : (N,) array_like
        Commands in volts; each must lie within ``axis.limits``.
    settle_frames : int
        Frames grabbed per command; the last one's measurement is recorded.
    model : HysteresisModel, optional
        Shadow model that is told every command (keeps its reversal memory in step with the axis).

    Returns
    -------
    DataFrame
        ``frame, t, u, x, y, score, ok``, one row per command (``frame`` counts grabs since the call).
    """
    volts = np.asarray(voltages, dtype=float).ravel()
    lim = tuple(float(v) for v in axis.limits)
    for v in volts:
        check_command(v, lim, "drive_voltages")
    dt = float(microscope.frame_period)
    rows, n = [], 0
    for u in _progress(volts, progress, desc):
        axis.apply(float(u))
        if model is not None:
            model.forward(axis.command if getattr(axis, "command", None) is not None else float(u))
        for _ in range(int(settle_frames)):
            frame = microscope.grab()
            n += 1
            x, y, score, ok = read_result(tracker.update(frame))
        ok = ok and math.isfinite(x) and math.isfinite(y)
        rows.append((n, n * dt, float(u), x, y, score, ok))
    return pd.DataFrame(rows, columns=["frame", "t", "u", "x", "y", "score", "ok"])


def _lead_in(u_start: float, u_min: float, u_max: float, n_steps: int, precondition: bool) -> list:
    """The unrecorded commands before the plan: a ramp from ``u_start`` to U0 in increments (so the
    tracker follows the probe), then, with ``precondition``, one major loop ending at U0 after a
    descent (the state :func:`~semlab.hysteresis.fit_hysteresis` assumes)."""
    step_v = (u_max - u_min) / int(n_steps)
    pre = list(np.linspace(u_start, u_min, max(1, math.ceil(abs(u_start - u_min) / step_v)) + 1)[1:])
    if precondition:
        up = np.linspace(u_min, u_max, int(n_steps) + 1)[1:]
        pre += list(up) + list(up[::-1][1:]) + [u_min]
    return pre


def _project_on_axis(df: pd.DataFrame) -> dict:
    """The axis' image direction by a principal-component fit of the tracked positions, and the
    displacement along it (``df["displacement"]``, 0 at the first valid point, rising with the
    voltage); returns the ``attrs`` the fit measured."""
    ok = df["ok"].to_numpy(bool) & np.isfinite(df["x"].to_numpy(float)) & np.isfinite(df["y"].to_numpy(float))
    df["ok"] = ok
    pts = df.loc[ok, ["x", "y"]].to_numpy(float)
    if pts.shape[0] < 3:
        raise ValueError(f"the tracker followed the probe in only {pts.shape[0]} frame(s); nothing to fit")
    centre = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
    direction = vt[0]
    proj = (pts - centre) @ direction
    if np.corrcoef(df.loc[ok, "u"].to_numpy(float), proj)[0, 1] < 0:
        direction = -direction
    origin = pts[0]
    disp = np.full(len(df), np.nan)
    disp[ok] = (pts - origin) @ direction
    df["displacement"] = disp
    off_axis = (pts - centre) @ np.array([-direction[1], direction[0]])
    return {"direction": (float(direction[0]), float(direction[1])), "origin": (float(origin[0]), float(origin[1])),
            "off_axis_rms_px": float(np.sqrt(np.mean(off_axis ** 2))), "n_lost": int((~ok).sum())}


def characterise_hysteresis(microscope, axis, roi, *, u_min=None, u_max=None, n_steps: int = 30,
                            inner_loops=True, settle_frames: int = 1, u_start=None,
                            precondition: bool = True, tracker=None, axis_name=None,
                            progress: bool = False) -> pd.DataFrame:
    """Characterise the hysteresis of one actuator axis with the visual tracker (paper, Fig. 8b).

    Voltages are applied incrementally from U0 to Un and back (then along inner loops), one increment
    per frame; each command acts from the next frame, so after ``settle_frames`` grabbed frames the probe
    position measured by the tracker is recorded. The image direction of the axis is measured by a
    principal-component fit of the tracked positions, and the displacement is projected on it.

    Parameters
    ----------
    microscope : Microscope
        Source of frames (``frame_period``, ``grab()``).
    axis : Axis
        Actuator channel (``limits``, ``apply(volts)``).
    roi : (x, y, w, h)
        Probe's ROI in the current frame.
    u_min, u_max : float, optional
        U0 and Un (default: the axis limits). A sub-range keeps the probe in view.
    n_steps : int
        Increments per major branch.
    inner_loops : bool or sequence of float
        See :func:`characterisation_voltages`.
    settle_frames : int
        Frames grabbed per increment (>= 1); the last one is measured.
    u_start : float, optional
        The command the axis holds now (default: ``axis.command`` if the axis reports it, else U0).
        The axis is ramped from there to U0 in increments so the tracker follows the probe.
    precondition : bool
        Run one unrecorded major loop first, so the recorded path starts on a known state (U0 after a
        descent) -- the state :func:`~semlab.hysteresis.fit_hysteresis` assumes.
    tracker : VisualTracker, optional
        Anything with ``init(frame, roi)`` and ``update(frame) -> (x, y, score, ok)``; default
        ``semlab.tracking.Tracker()``.
    axis_name : str, optional
        Identity stored with the data (default :func:`~semlab.hysteresis.axis_identity`).
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    DataFrame
        One row per increment: ``step, segment, u, branch, frame, t, x, y, score, ok, displacement``
        (px along the measured direction, 0 at the first valid U0 point, rising with the voltage).
        ``attrs``: ``axis, direction, origin, u_min, u_max, frame_period, settle_frames,
        preconditioned, off_axis_rms_px, n_lost``.
    """
    lo, hi = (float(v) for v in axis.limits)
    u_min = lo if u_min is None else as_finite(u_min, "u_min")
    u_max = hi if u_max is None else as_finite(u_max, "u_max")
    if not lo <= u_min < u_max <= hi:
        raise ValueError(f"need axis limit {lo} <= u_min={u_min} < u_max={u_max} <= axis limit {hi}")
    if int(settle_frames) < 1:
        raise ValueError("settle_frames must be >= 1 (commands act from the next frame)")
    plan = characterisation_voltages(u_min, u_max, n_steps, inner_loops)
    if u_start is None:
        u_start = getattr(axis, "command", None)
    u_start = u_min if u_start is None else as_finite(u_start, "u_start")
    pre = _lead_in(u_start, u_min, u_max, n_steps, precondition)
    tracker = default_tracker(tracker)
    tracker.init(microscope.grab(), roi)
    volts = np.concatenate([pre, plan["u"].to_numpy()])
    run = drive_voltages(microscope, axis, tracker, volts, settle_frames=settle_frames, progress=progress,
                         desc="characterising hysteresis")
    rec = run.iloc[len(pre):].reset_index(drop=True)
    df = plan.copy()
    for c in ("frame", "t", "x", "y", "score", "ok"):
        df[c] = rec[c].to_numpy()
    measured = _project_on_axis(df)
    df.attrs.update(
        axis=axis_name if axis_name is not None else axis_identity(axis),
        direction=measured["direction"], origin=measured["origin"],
        u_min=u_min, u_max=u_max, frame_period=float(microscope.frame_period),
        settle_frames=int(settle_frames), preconditioned=bool(precondition),
        off_axis_rms_px=measured["off_axis_rms_px"], n_lost=measured["n_lost"],
    )
    return df


def characterise_creep(microscope, axis, roi, *, model, step_px: float, n_frames: int = 40,
                       tracker=None) -> tuple[CreepModel, pd.DataFrame]:
    """Measure creep: one open-loop feed-forward step of ``step_px``, held for ``n_frames`` frames.

    The step is made through ``model`` (its memory is updated). Returns the fitted
    :class:`~semlab.creep.CreepModel` and the hold as a DataFrame
    ``frame, t, u, x, y, ok, displacement``.
    """
    model.check_axis(axis)
    # the default tracker's window is widened to hold the step (a 300-px window loses a 100-px jump)
    tracker = default_tracker(tracker, jump_px=abs(float(step_px)), roi=roi)
    d = np.asarray(model.direction)
    p0 = np.array(start_point(roi))
    frame = microscope.grab()
    tracker.init(frame, tuple(roi))
    y_before = model.state.y
    u = model.inverse(y_before + float(step_px))
    axis.apply(u)
    dy = model.forward(u) - y_before
    T = float(microscope.frame_period)
    rows = []
    for k in range(1, int(n_frames) + 1):
        x, y, _, ok = read_result(tracker.update(microscope.grab()))
        ok = ok and math.isfinite(x) and math.isfinite(y)
        disp = float((np.array([x, y]) - p0) @ d) if ok else float("nan")
        rows.append((k, (k - 0.5) * T, u, x, y, ok, disp))
    df = pd.DataFrame(rows, columns=["frame", "t", "u", "x", "y", "ok", "displacement"])
    return fit_creep(df["t"], df["displacement"], dy), df
