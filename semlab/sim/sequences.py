"""Ready-made frame sequences with ground truth, after the paper's experiments.

* ``"static"``: the probe stands still for 100 frames -- the paper's repeatability test
  (0.2268 px standard deviation at 3,000x, "Tracking Performance").
* ``"moves_200px"``: manipulator 0 moves its probe from A to B, 200 px, and back, five
  times, ramping over a few frames and dwelling at A and B (the paper's Fig. 7).
* ``"low_dose"``: the scene at a fifth of the beam current.
* ``"gray_fluctuation"``: strong per-frame gain/offset fluctuation and fast charging.
* ``"clutter_occluder"``: dense static clutter, drifting particles and an out-of-focus
  foreground object passing over the probe's shaft, 45 px behind the tip when it crosses
  (~frame 48 at 13 frames/s; for a sweeping probe, behind where the sweep is planned to
  have taken the tip by then, from the ground-truth hysteresis model).

In the last three the probe MOVES by default (``motion="sweep"``): manipulator 0's x piezo
is driven with a raised-cosine voltage ``u_k = u_peak (1 - cos(2 pi k / P)) / 2`` (``P`` =
``sweep_period_frames``, 80), starting at rest at 0 V in frame 0; ``u_peak`` puts the tip
``2 x sweep_amplitude_px`` (2 x 30 px) along +x on the piezo's ascending hysteresis branch,
so the probe sweeps about +-30 px around +30 px, forward along its own shaft, at most
~3 px per frame (the ascending branch is convex; the descending one lies above it and
creep adds a little, all in the ground truth). The paper's Eq. (3) motion ``mu = (u, v)``
is then far from zero in most frames: a tracker biased towards "no motion" cannot score
below the Cramér–Rao bound as it can on a still probe. ``motion="still"`` keeps the probe
still (only the image drift of :class:`SEMNoise` moves it, ~0.05 px/s); ``"static"`` is
always still.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..roi import clip_window
from .crb import translation_crb
from .noise import SEMNoise
from .rig import SimulatedRig, default_hysteresis
from .scene import Clutter

__all__ = ["MOTIONS", "SEQUENCE_KINDS", "Sequence", "make_sequence"]

SEQUENCE_KINDS = ("static", "moves_200px", "low_dose", "gray_fluctuation", "clutter_occluder")
_RIG_KEYS = {"n_manipulators", "pixel_size_nm", "noise", "clutter", "probe", "width", "height",
             "frame_period", "base_positions", "view_angles_deg", "probe_angles_deg", "piezo",
             "z_view", "dtype", "beam_sigma_px"}
_SEQ_KEYS = {"roi_size", "step_px", "n_cycles", "move_frames", "dwell_frames", "progress",
             "motion", "sweep_amplitude_px", "sweep_period_frames"}
_SWEEP_KINDS = ("low_dose", "gray_fluctuation", "clutter_occluder")
MOTIONS = ("still", "sweep")
_NOISE_KEYS = {f.name for f in dataclasses.fields(SEMNoise)}
_CLUTTER_KEYS = {f.name for f in dataclasses.fields(Clutter)}


@dataclass
class Sequence:
    """Frames with ground truth.

    Attributes
    ----------
    frames : (N, H, W) ndarray
        The frames (uint8 by default).
    truth : pandas.DataFrame
        ``frame, t, x, y, visible`` of probe 0's tip (px, image drift included).
    roi : (x, y, w, h)
        200x200 (``roi_size``) around probe 0's tip in frame 0, inside the frame.
    crb : (float, float)
        Cramér–Rao bound ``(sigma_x, sigma_y)`` in px of one frame's translation
        estimate in ``roi`` (:func:`semlab.sim.translation_crb`), computed for FRAME 0
        (the probe at rest where the ROI was taken). When the probe moves, later frames
        see the same probe over another patch of background: the bound of the ROI moved
        with the probe differs slightly (the probe's edges carry most of the information;
        ``benchmarks/bench_tracking.py`` states by how much along the default sweep).
    meta : dict
        ``kind``, ``seed``, ``pixel_size_nm``, ``frame_period``, ``noise``, ``clutter``
        (parameter dicts), ``motion`` (``"still"``, ``"steps"`` for ``"moves_200px"``,
        or ``"sweep"``) and kind-specific entries (for a sweep ``sweep_amplitude_px``,
        ``sweep_period_frames``, ``u_peak``).
    truth_all : pandas.DataFrame
        Ground truth of all probes (column ``probe`` added).
    commands : pandas.DataFrame
        ``frame, u`` -- the x-axis voltage of manipulator 0 in effect in each frame.
    """

    frames: np.ndarray
    truth: pd.DataFrame
    roi: tuple
    crb: tuple
    meta: dict
    truth_all: pd.DataFrame = field(repr=False, default=None)
    commands: pd.DataFrame = field(repr=False, default=None)

    def __len__(self):
        return len(self.frames)


def _kind_defaults(kind):
    noise, clutter = SEMNoise(), Clutter()
    if kind == "low_dose":
        noise = noise.replace(beam_current_pA=10.0)
    elif kind == "gray_fluctuation":
        noise = noise.replace(gain_fluctuation=0.15, offset_fluctuation_gray=15.0,
                              fluctuation_memory=0.6, charging_amplitude=0.5, charging_time_s=3.0)
    elif kind == "clutter_occluder":
        clutter = Clutter(n_static=120, n_drifting=8, occluder=True, occluder_radius_px=22.0)
    return noise, clutter


def _voltage_for_displacement(target_px, pixel_size_nm, seed, travel_nm, view_deg, what="step_px"):
    """Voltage on manipulator 0's x axis that moves its probe ``target_px`` from 0 V.

    Uses the ascending branch of the ground-truth Preisach model (creep neglected).
    """
    proj = math.cos(math.radians(view_deg))
    lo, hi = 0.0, 1.0
    want = target_px * pixel_size_nm / (travel_nm * proj)
    if want >= 1.0:
        raise ValueError(f"{what}: {target_px} px exceeds the x piezo's travel at {pixel_size_nm} nm/px")
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        hyst = default_hysteresis(0, "x", seed)
        if hyst.update(mid) < want:
            lo = mid
        else:
            hi = mid
    return 100.0 * 0.5 * (lo + hi)


def _sweep_peak_voltage(rig, seed, amplitude_px):
    """x-piezo voltage of manipulator 0 for ``2 x amplitude_px`` on the ascending branch."""
    return _voltage_for_displacement(2.0 * amplitude_px, rig.sem.pixel_size_nm, seed,
                                     rig.axis(0, "x").travel_nm, rig.view_angles_deg[0],
                                     what=f"sweep_amplitude_px={amplitude_px} (travel 2 x amplitude)")


def _sweep_voltages(u_peak, period, k):
    """The raised-cosine sweep: ``u_peak (1 - cos(2 pi k / period)) / 2`` at frames ``k``."""
    return u_peak * 0.5 * (1.0 - np.cos(2.0 * np.pi * np.asarray(k, float) / period))


def _sweep_displacement_px(rig, seed, amplitude_px, period, k):
    """Planned image displacement (dx, dy) px of probe 0 in frame ``k`` of the sweep.

    The ground-truth Preisach model along the schedule (lag, creep and position noise
    neglected: ~1 px), rotated by manipulator 0's view angle.
    """
    u_peak = _sweep_peak_voltage(rig, seed, amplitude_px)
    hyst = default_hysteresis(0, "x", seed)
    y = 0.0
    for u in _sweep_voltages(u_peak, period, np.arange(k + 1)):
        y = hyst.update(min(max(u / 100.0, 0.0), 1.0))
    th = math.radians(rig.view_angles_deg[0])
    r = y * rig.axis(0, "x").travel_nm / rig.sem.pixel_size_nm
    return np.array([r * math.cos(th), r * math.sin(th)])


def _check_motion(kind, opts):
    """The probe motion of ``kind`` from the overrides: ``(motion, (amplitude, period))``."""
    motion = opts.get("motion")
    has_sweep = [k for k in ("sweep_amplitude_px", "sweep_period_frames") if k in opts]
    if kind == "static":
        if motion not in (None, "still"):
            raise ValueError(f"motion={motion!r}: the 'static' sequence has a still probe; "
                             f"give one of {_SWEEP_KINDS} for a moving probe")
        motion = "still"
    elif kind == "moves_200px":
        if motion not in (None, "steps"):
            raise ValueError(f"motion={motion!r}: 'moves_200px' has its own A-B steps "
                             "(step_px, n_cycles, move_frames, dwell_frames)")
        motion = "steps"
    else:
        motion = "sweep" if motion is None else motion
        if not isinstance(motion, str) or motion not in MOTIONS:
            raise ValueError(f"unknown motion {motion!r} for {kind!r}; choose one of {MOTIONS}")
    if has_sweep and motion != "sweep":
        raise ValueError(f"{has_sweep} only apply to motion='sweep', not to {kind!r} with "
                         f"motion={motion!r}")
    if motion != "sweep":
        return motion, None
    amp = opts.get("sweep_amplitude_px", 30.0)
    period = opts.get("sweep_period_frames", 80)
    try:
        amp = float(amp)
        period = float(period)
    except (TypeError, ValueError):
        raise ValueError("sweep_amplitude_px and sweep_period_frames must be numbers, got "
                         f"{opts.get('sweep_amplitude_px')!r}, {opts.get('sweep_period_frames')!r}") from None
    if not (math.isfinite(amp) and amp > 0):
        raise ValueError(f"sweep_amplitude_px must be > 0, got {amp!r}")
    if not (math.isfinite(period) and period >= 2):
        raise ValueError(f"sweep_period_frames must be >= 2 frames, got {period!r}")
    return motion, (amp, period)


def make_sequence(kind: str, n_frames: int | None = None, seed: int = 0, **overrides) -> Sequence:
    """Simulate one of the standard sequences.

    Parameters
    ----------
    kind : {"static", "moves_200px", "low_dose", "gray_fluctuation", "clutter_occluder"}
        See the module docstring.
    n_frames : int or None
        Number of frames; default 100 for the other kinds and the full five A-B-A
        cycles (192 frames) for ``"moves_200px"`` (fewer frames truncate, more repeat).
    seed : int
        Seeds the scene, the noise and the rig.
    **overrides
        Any :class:`SimulatedRig` argument (``noise``, ``clutter``, ``pixel_size_nm``,
        ``n_manipulators``, ``width``, ``height``, ``dtype``, ...); any
        :class:`SEMNoise` or :class:`Clutter` field (applied on top of the kind's
        defaults, e.g. ``beam_current_pA=20``); and ``roi_size`` (200), ``step_px``
        (200), ``n_cycles`` (5), ``move_frames`` (6), ``dwell_frames`` (12),
        ``progress`` (False: show a tqdm bar); for ``"low_dose"``,
        ``"gray_fluctuation"`` and ``"clutter_occluder"``: ``motion`` (``"sweep"``,
        the default, or ``"still"``), ``sweep_amplitude_px`` (30: half the travel) and
        ``sweep_period_frames`` (80) -- see the module docstring.

    Returns
    -------
    Sequence

    Raises
    ------
    ValueError
        Unknown kind or override, bad ``n_frames``, ROI larger than the frame, an
        unknown ``motion`` or one the kind does not have (``"static"`` is still,
        ``"moves_200px"`` has its own steps), sweep parameters with ``motion="still"``,
        a non-positive amplitude or period, or an amplitude beyond the piezo's travel.
    """
    if kind not in SEQUENCE_KINDS:
        raise ValueError(f"unknown sequence kind {kind!r}; choose one of {SEQUENCE_KINDS}")
    unknown = set(overrides) - _RIG_KEYS - _SEQ_KEYS - _NOISE_KEYS - _CLUTTER_KEYS
    if unknown:
        raise ValueError(f"unknown override(s) {sorted(unknown)} for make_sequence")
    if n_frames is not None and (int(n_frames) != n_frames or n_frames < 1):
        raise ValueError(f"n_frames must be a positive integer, got {n_frames!r}")

    noise, clutter, seq_opts, rig_kwargs = _split_overrides(kind, overrides)
    roi_size = int(seq_opts.get("roi_size", 200))
    motion, sweep = _check_motion(kind, seq_opts)
    if kind == "clutter_occluder" and clutter.occluder and clutter.occluder_path is None:
        clutter = _occluder_behind_the_tip(clutter, seed, motion, sweep, rig_kwargs)

    rig = SimulatedRig(seed=seed, noise=noise, clutter=clutter, **rig_kwargs)
    sem = rig.sem
    if roi_size > min(sem.width, sem.height):
        raise ValueError(f"roi_size {roi_size} does not fit in the {sem.width}x{sem.height} frame")
    schedule, n_frames, meta_kind = _voltage_schedule(kind, motion, sweep, seq_opts, rig, seed, n_frames)
    frames, us, truth_all, tips0, t0 = _simulate(rig, schedule, n_frames, kind, bool(seq_opts.get("progress", False)))
    truth = truth_all[truth_all["probe"] == 0].drop(columns="probe").reset_index(drop=True)
    roi = _roi_around(tips0[0], roi_size, sem)
    crb = translation_crb(sem, tips0, roi, probe=0, t=t0)

    meta = dict(kind=kind, seed=seed, n_frames=n_frames, pixel_size_nm=sem.pixel_size_nm,
                frame_period=sem.frame_period, width=sem.width, height=sem.height,
                dose_e_per_px=sem.dose, beam_sigma_px=sem.beam_sigma_px,
                noise=noise.as_dict(), clutter=dataclasses.asdict(clutter),
                n_manipulators=rig.n_manipulators, **meta_kind)
    commands = pd.DataFrame({"frame": np.arange(n_frames), "u": us})
    return Sequence(frames=frames, truth=truth, roi=roi, crb=crb, meta=meta,
                    truth_all=truth_all, commands=commands)


def _split_overrides(kind, overrides):
    """``(noise, clutter, sequence options, rig keywords)``: the kind's defaults with the overrides."""
    overrides = dict(overrides)
    noise, clutter = _kind_defaults(kind)
    if "noise" in overrides:
        noise = overrides.pop("noise")
    if "clutter" in overrides:
        clutter = overrides.pop("clutter")
    nz_changes = {k: overrides.pop(k) for k in list(overrides) if k in _NOISE_KEYS}
    cl_changes = {k: overrides.pop(k) for k in list(overrides) if k in _CLUTTER_KEYS}
    if nz_changes:
        noise = noise.replace(**nz_changes)
    if cl_changes:
        clutter = dataclasses.replace(clutter, **cl_changes)
    seq_opts = {k: overrides.pop(k) for k in list(overrides) if k in _SEQ_KEYS}
    return noise, clutter, seq_opts, overrides


def _occluder_behind_the_tip(clutter, seed, motion, sweep, rig_kwargs):
    """The occluder's path across probe 0's shaft, 45 px behind its tip (behind where the tip is
    planned to be when the occluder crosses, for a sweeping probe)."""
    probe_rig = SimulatedRig(seed=seed, noise=SEMNoise.off(), clutter=Clutter.none(),
                             **{k: v for k, v in rig_kwargs.items() if k != "dtype"})
    tip = probe_rig.base_positions[0]
    ang = math.radians(probe_rig.sem.probe_angles_deg[0])
    d = np.array([math.cos(ang), math.sin(ang)])
    perp = np.array([-d[1], d[0]])
    period_s = 2 * 150 * 2 / 40.0  # ~40 px/s; a pass takes ~7.5 s
    if motion == "sweep":
        # it crosses the middle of its path a quarter period in: frame (t / T) - 1/2
        k_cross = int(period_s / 4 / probe_rig.sem.frame_period - 0.5)
        tip = tip + _sweep_displacement_px(probe_rig, seed, *sweep, k_cross)
    p = tip - 45.0 * d
    return dataclasses.replace(clutter, occluder_path=(tuple(p - 150 * perp), tuple(p + 150 * perp)),
                               occluder_period_s=period_s)


def _voltage_schedule(kind, motion, sweep, seq_opts, rig, seed, n_frames):
    """Manipulator 0's x-axis voltage per frame (None: untouched), the number of frames and the
    kind's entries of ``meta``."""
    sem = rig.sem
    if kind == "moves_200px":
        step_px = float(seq_opts.get("step_px", 200.0))
        n_cycles = int(seq_opts.get("n_cycles", 5))
        move = int(seq_opts.get("move_frames", 6))
        dwell = int(seq_opts.get("dwell_frames", 12))
        if move < 1 or dwell < 1 or n_cycles < 1:
            raise ValueError("move_frames, dwell_frames and n_cycles must be >= 1")
        u_b = _voltage_for_displacement(step_px, sem.pixel_size_nm, seed,
                                        rig.axis(0, "x").travel_nm, rig.view_angles_deg[0])
        ramp = list(u_b * np.arange(1, move + 1) / move)
        cycle = ramp + [u_b] * dwell + ramp[::-1][1:] + [0.0] + [0.0] * dwell
        schedule = [0.0] * dwell + cycle * n_cycles
        if n_frames is None:
            n_frames = len(schedule)
        while len(schedule) < n_frames:
            schedule += cycle
        meta_kind = {"motion": motion, "step_px": step_px, "u_A": 0.0, "u_B": u_b,
                     "n_cycles": n_cycles, "move_frames": move, "dwell_frames": dwell}
        return schedule[:n_frames], n_frames, meta_kind
    n_frames = 100 if n_frames is None else int(n_frames)
    if motion == "sweep":
        amp, period = sweep
        u_peak = _sweep_peak_voltage(rig, seed, amp)
        schedule = list(_sweep_voltages(u_peak, period, np.arange(n_frames)))
        return schedule, n_frames, {"motion": motion, "sweep_amplitude_px": amp, "sweep_period_frames": period,
                                    "u_peak": u_peak}
    return None, n_frames, {"motion": motion}


def _simulate(rig, schedule, n_frames, kind, progress):
    """Grab ``n_frames`` frames, applying the schedule: ``frames, commands, truth of all probes,
    the tips in frame 0 and frame 0's time``."""
    sem = rig.sem
    frames = np.empty((n_frames, sem.height, sem.width), dtype=sem.dtype)
    ax = rig.axis(0, "x")
    us = np.zeros(n_frames)
    truths = []
    iterator = range(n_frames)
    if progress:
        from tqdm.auto import tqdm
        iterator = tqdm(iterator, desc=f"simulating {kind}")
    for k in iterator:
        if schedule is not None:
            ax.apply(schedule[k])
        us[k] = ax.command
        frames[k] = rig.microscope.grab()
        truths.append(rig.truth)
        if k == 0:
            tips0 = rig.truth[["x", "y"]].to_numpy()
            t0 = float(rig.truth["t"].iloc[0])
    return frames, us, pd.concat(truths, ignore_index=True), tips0, t0


def _roi_around(tip, roi_size, sem):
    """The ``roi_size`` ROI around probe 0's tip in frame 0, shifted to lie inside the frame."""
    tx, ty = tip
    if not (0 <= tx <= sem.width - 1 and 0 <= ty <= sem.height - 1):
        raise ValueError(f"probe 0's tip ({tx:.1f}, {ty:.1f}) px is off the {sem.width}x{sem.height} "
                         "frame in frame 0; check base_positions")
    return clip_window(tx, ty, roi_size, roi_size, (sem.height, sem.width))
