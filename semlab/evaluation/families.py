"""The scene families of the evaluation corpus: generators with randomised parameters per seed.

Every family is a function of ``(family, seed)`` only: its generator is seeded from both, every
parameter is drawn from the ranges in :data:`FAMILIES` (``FAMILIES[name].ranges``), and the
drawn values are kept in ``seq.meta["params"]``. A sequence carries exact ground truth (the
point the tracker follows, ``seq.truth``: ``frame, t, x, y, visible``) and the single-frame
Cramér–Rao bound of a translation inside the ROI (``seq.crb``: the RMS over sampled frames of
each frame's bound with the ROI moved along with the probe, the per-frame values in
``seq.meta["crb_frames"]``).

None of the families renders a shift the way a tracker models one: the simulated ones evaluate
:mod:`semlab.sim`'s analytic scene at the true (continuous) position; the semi-real one moves a
real needle by exact Fourier shifts (:mod:`semlab.evaluation.semireal`). Seeds: report
:data:`TEST_SEEDS`, tune on :data:`DEV_SEEDS`, never the other way round.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from semlab.roi import clip_window
from semlab.sim import Clutter, ProbeGeometry, SEMNoise, SimulatedSEM, translation_crb
from semlab.sim.sequences import Sequence
from semlab.sim.shapes import AFMTip, BluntProbe, GripperJaws
from semlab.sim.substrate import textured_substrate

from . import motion
from .draws import Choice, Draws, Int, Uniform

__all__ = ["DEV_SEEDS", "FAMILIES", "FAMILY_NAMES", "TEST_SEEDS", "Family", "make_family_sequence",
           "split_of"]

#: Seeds every reported figure comes from (README, notebooks, issue notes). Never tune on them.
TEST_SEEDS = range(10)
#: Seeds to tune defaults and constants on.
DEV_SEEDS = range(100, 120)
#: Side (px) of the square ROI around the tip in frame 0 (the paper's 200x200 px at 3,000x).
ROI_SIZE = 200
#: Frames at which the bound is evaluated (evenly spaced, first and last included): the bound
#: changes along a sequence (the probe over other background, charging, clutter) but slowly.
CRB_SAMPLES = 4
#: What ``make_family_sequence(..., without=...)`` can take out of a scene drawn through the
#: simulator's :class:`~semlab.sim.Clutter`, every other draw kept (an ablation: which part of a
#: scene makes a tracker fail).
SCENE_ABLATIONS = ("texture", "occluder")
#: What it can take out of the noise of a scene drawn through :class:`~semlab.sim.SEMNoise`:
#: ``"line_noise"`` (the scan line's correlation, per-line offsets and jitter), ``"photometric_jitter"``
#: (the frames' gain and offset fluctuations and jumps, the probe's charging), ``"noise"`` (both, and
#: the shot and read noise nearly all: what is left of a tracker's error is its systematic part).
NOISE_ABLATIONS = ("line_noise", "photometric_jitter", "noise")
#: Every part ``without`` can name (each family says which of them it can take out).
ABLATIONS = SCENE_ABLATIONS + NOISE_ABLATIONS
#: ``"noise"``: the dose this many times the drawn one (the shot noise's sd 1/√50 ≈ 1/7 of it) and the
#: read noise this fraction of it. Not 0: the trackers measure the noise, and a noise-free frame
#: is not a frame a tracker meets.
ABLATED_DOSE_FACTOR = 50.0
ABLATED_READ_NOISE_FRACTION = 0.1
#: The texture's amplitude when it is taken out: not 0, so the substrate still makes the texture's
#: random draws and every particle, and the noise, stay as drawn (0 skips them).
ABLATED_TEXTURE = 1e-9

#: Beam blur (px) of ``noise_free`` sequences (the ground-truth tests).
NOISE_FREE_BLUR_PX = 1.0
#: The simulator's frame period (s): the paper's 13 frames/s.
FRAME_PERIOD = 1 / 13


def split_of(seed: int) -> str:
    """``"test"``, ``"dev"`` or ``"other"``: which split a seed belongs to."""
    if seed in TEST_SEEDS:
        return "test"
    if seed in DEV_SEEDS:
        return "dev"
    return "other"


def family_rng(name: str, seed: int) -> np.random.Generator:
    """The generator of one (family, seed): seeded from both (crc32 of the name: stable across runs)."""
    return np.random.default_rng([zlib.crc32(name.encode()), int(seed)])


@dataclass(frozen=True)
class Family:
    """One scene family.

    Attributes
    ----------
    name : str
    title : str
        What it models, in a line.
    ranges : dict
        Parameter name -> range (:mod:`semlab.evaluation.draws`); every parameter drawn.
    build : callable ``(Draws) -> Sequence``
    ablations : tuple of str
        The parts of its scenes ``make_family_sequence(..., without=...)`` can take out
        (:data:`ABLATIONS`; the scene's parts only where the substrate is the simulator's clutter,
        none where neither scene nor noise is the simulator's).
    """

    name: str
    title: str
    ranges: dict
    build: Callable = field(repr=False)
    ablations: tuple = ABLATIONS


# ------------------------------------------------------------------ the simulated rig's draws
#: Ranges every simulated family draws from unless it overrides them (the paper's rig at
#: 3,000x with the spread of probes, operators' settings and samples one meets).
RIG = {
    "pixel_size_nm": Uniform(50.0, 80.0),
    "beam_current_pA": Uniform(30.0, 80.0),
    "contrast": Uniform(170.0, 200.0),
    "black_level": Uniform(25.0, 35.0),
    "read_noise_gray": Uniform(1.0, 3.0),
    "line_correlation": Uniform(0.3, 0.6),
    "line_offset_gray": Uniform(0.5, 2.0),
    "line_jitter_px": Uniform(0.03, 0.12),
    "gain_fluctuation": Uniform(0.005, 0.03),
    "offset_fluctuation_gray": Uniform(0.5, 3.0),
    "charging_amplitude": Uniform(0.0, 0.1),
    "drift_px_per_s": Uniform(0.0, 0.1),
    "tip_diameter_nm": Uniform(150.0, 300.0),
    "half_angle_deg": Uniform(5.0, 12.0),
    "probe_yield": Uniform(0.45, 0.6),
    "rim_amplitude": Uniform(0.15, 0.35),
    "rim_width_nm": Uniform(35.0, 65.0),
    "shading": Uniform(0.05, 0.25),
    "probe_angle_deg": Uniform(0.0, 360.0),
    "n_static": Int(10, 60),
    "texture": Uniform(0.01, 0.05),
    "start_offset_x_px": Uniform(-20.0, 20.0),
    "start_offset_y_px": Uniform(-20.0, 20.0),
}
WANDER = {
    "speed_px_per_frame": Uniform(0.5, 2.5),
    "persistence": Uniform(0.7, 0.95),
    "radius_px": Uniform(30.0, 70.0),
}


def _ranges(*parts, drop=(), **changes) -> dict:
    """The union of ``parts`` and ``changes`` without the names in ``drop`` (the family sets them)."""
    out = {}
    for p in parts:
        out.update(p)
    out.update(changes)
    for name in drop:
        del out[name]
    return out


def _noise(d: Draws, **fixed) -> SEMNoise:
    """The SEM noise from the rig's draws; ``fixed`` sets fields directly (not drawn)."""
    names = {"beam_current_pA": "beam_current_pA", "contrast": "contrast", "brightness": "black_level",
             "read_noise_gray": "read_noise_gray", "line_correlation": "line_correlation",
             "line_offset_gray": "line_offset_gray", "line_jitter_px": "line_jitter_px",
             "gain_fluctuation": "gain_fluctuation", "offset_fluctuation_gray": "offset_fluctuation_gray",
             "charging_amplitude": "charging_amplitude", "drift_px_per_s": "drift_px_per_s"}
    kw = {f: d(r) for f, r in names.items() if f not in fixed}
    kw.update(fixed)
    return SEMNoise(**kw)


def _probe(d: Draws, shape=None, **fixed) -> ProbeGeometry:
    kw = {"tip_diameter_nm": "tip_diameter_nm", "half_angle_deg": "half_angle_deg", "brightness": "probe_yield",
          "rim_amplitude": "rim_amplitude", "rim_width_nm": "rim_width_nm", "shading": "shading"}
    values = {f: d(r) for f, r in kw.items() if f not in fixed}
    values.update(fixed)
    return ProbeGeometry(shape=shape, **values)


def _clutter(d: Draws, **fixed) -> Clutter:
    kw = {"n_static": d("n_static") if "n_static" not in fixed else fixed.pop("n_static"),
          "texture": d("texture") if "texture" not in fixed else fixed.pop("texture")}
    kw.update(fixed)
    return Clutter(**kw)


def moved_roi(roi, dx: float, dy: float, width: int, height: int):
    """``roi`` moved by the probe's displacement (rounded), kept inside the frame."""
    x, y, w, h = roi
    return (int(min(max(x + round(dx), 0), width - w)), int(min(max(y + round(dy), 0), height - h)), w, h)


def crb_sample_frames(n_frames: int) -> list[int]:
    """Frames at which the bound is evaluated (:data:`CRB_SAMPLES`, evenly spaced)."""
    return sorted({round(v) for v in np.linspace(0, n_frames - 1, min(CRB_SAMPLES, n_frames))})


def combine_bounds(per_frame: list[tuple[int, float, float]]) -> tuple[float, float]:
    """RMS of per-frame bounds: the bound on an RMSE over frames is the RMS of the frames' bounds."""
    sx = math.sqrt(float(np.mean([s[1] ** 2 for s in per_frame])))
    sy = math.sqrt(float(np.mean([s[2] ** 2 for s in per_frame])))
    return sx, sy


def _ablated(d: Draws, clutter: Clutter, visible) -> tuple[Clutter, Callable | None]:
    """``(clutter, visible)`` with what ``d.without`` names taken out (:data:`ABLATIONS`)."""
    without = getattr(d, "without", ())
    if "texture" in without:
        clutter = dataclasses.replace(clutter, texture=min(clutter.texture, ABLATED_TEXTURE))
    if "occluder" in without:
        clutter, visible = dataclasses.replace(clutter, occluder=False), None
    return clutter, visible


def _ablated_noise(d: Draws, noise: SEMNoise, frame_period: float, n_pixels: int) -> SEMNoise:
    """``noise`` with what ``d.without`` names of it taken out (:data:`NOISE_ABLATIONS`)."""
    without = set(getattr(d, "without", ()))
    if "noise" in without:
        without |= {"line_noise", "photometric_jitter"}
        noise = noise.replace(dose_e_per_px=ABLATED_DOSE_FACTOR * noise.dose(frame_period, n_pixels),
                              read_noise_gray=ABLATED_READ_NOISE_FRACTION * noise.read_noise_gray)
    if "line_noise" in without:
        noise = noise.replace(line_correlation=0.0, line_offset_gray=0.0, line_jitter_px=0.0)
    if "photometric_jitter" in without:
        noise = noise.replace(gain_fluctuation=0.0, offset_fluctuation_gray=0.0, gain_jitter=0.0,
                              offset_jitter_gray=0.0, charging_amplitude=0.0)
    return noise


def _simulate(d: Draws, width: int, height: int, path: np.ndarray, *, noise: SEMNoise,
              probe: ProbeGeometry, clutter: Clutter, background=None, visible=None,
              angle_deg=None) -> Sequence:
    """Frames of ``path`` (displacements from the start) through a :class:`SimulatedSEM`.

    The path is centred on the frame (its mid-range, plus a drawn offset). ``visible(sem, t, tip)
    -> bool`` may hide the tip (an occluder over it) in the ground truth; ``angle_deg`` is the
    probe's direction when the family chose it (else drawn).
    """
    pixel_size = d("pixel_size_nm")
    angle = d("probe_angle_deg") if angle_deg is None else angle_deg
    beam_sigma = None  # from the pixel size (semlab.sim.optics)
    clutter, visible = _ablated(d, clutter, visible)
    noise = _ablated_noise(d, noise, FRAME_PERIOD, width * height)
    if getattr(d, "noise_free", False):
        # the ground-truth tests' view: the probe alone, no noise, blurred by 1 px (a sampled
        # centroid then aliases by < 2e-3 px: tests/test_sim_render.py)
        noise, clutter, visible, beam_sigma = SEMNoise.off(), Clutter.none(), None, NOISE_FREE_BLUR_PX
        background = np.full((height, width), 0.2, np.float32)
    sem = SimulatedSEM(width, height, pixel_size_nm=pixel_size, frame_period=FRAME_PERIOD, noise=noise,
                       clutter=clutter, probe=probe, seed=int(d.rng.integers(2**31 - 1)),
                       probe_angles_deg=(angle,), background=background, beam_sigma_px=beam_sigma)
    start = np.array([width / 2 + d("start_offset_x_px"), height / 2 + d("start_offset_y_px")])
    start -= 0.5 * (path.min(axis=0) + path.max(axis=0))  # the path's mid-range at the centre
    n = len(path)
    frames = np.empty((n, height, width), np.uint8)
    rows = []
    for k in range(n):
        frames[k] = sem.acquire(start + path[k])
        tx, ty = sem.last_tips[0]
        inside = 0 <= tx <= width - 1 and 0 <= ty <= height - 1
        shown = inside and (visible is None or visible(sem, sem.last_time, (tx, ty)))
        rows.append((k, sem.last_time, float(tx), float(ty), bool(shown)))
    truth = pd.DataFrame(rows, columns=["frame", "t", "x", "y", "visible"])
    x0, y0 = truth.loc[0, ["x", "y"]]
    roi = clip_window(x0, y0, ROI_SIZE, ROI_SIZE, (height, width))  # around the tip, inside the frame
    bounds = []
    for k in crb_sample_frames(n):
        if not truth.loc[k, "visible"]:
            continue
        tip = truth.loc[k, ["x", "y"]].to_numpy(float)
        t = float(truth.loc[k, "t"])
        roi_k = moved_roi(roi, tip[0] - x0, tip[1] - y0, width, height)
        sx, sy = translation_crb(sem, tip[None, :], roi_k, t=t, charge=noise.charging_factor(t))
        bounds.append((k, sx, sy))
    meta = {"width": width, "height": height, "pixel_size_nm": pixel_size, "frame_period": FRAME_PERIOD,
            "dose_e_per_px": sem.dose, "beam_sigma_px": sem.beam_sigma_px,
            "crb_frames": [{"frame": k, "crb_x_px": sx, "crb_y_px": sy} for k, sx, sy in bounds]}
    return Sequence(frames=frames, truth=truth, roi=roi, crb=combine_bounds(bounds), meta=meta)


def _wander(d: Draws, n: int, along=None, along_fraction=0.5) -> np.ndarray:
    return motion.wander(n, d.rng, speed_px=d("speed_px_per_frame"), persistence=d("persistence"),
                         radius_px=d("radius_px"), along=along, along_fraction=along_fraction)


# ------------------------------------------------------------------ the families
def _still(d: Draws) -> Sequence:
    n = d("n_frames")
    return _simulate(d, 512, 384, motion.still(n), noise=_noise(d), probe=_probe(d), clutter=_clutter(d))


def _moves(d: Draws) -> Sequence:
    path = motion.ab_moves(d("step_px"), math.radians(d("move_direction_deg")), n_cycles=d("n_cycles"),
                           ramp_frames=d("ramp_frames"), dwell_frames=d("dwell_frames"),
                           smooth=d("smooth_ramp"))
    return _simulate(d, 640, 480, path, noise=_noise(d), probe=_probe(d), clutter=_clutter(d))


def _wander_family(d: Draws) -> Sequence:
    path = _wander(d, d("n_frames"))
    return _simulate(d, 512, 384, path, noise=_noise(d), probe=_probe(d), clutter=_clutter(d))


def _jumps(d: Draws) -> Sequence:
    r = d.ranges
    path, lengths, dwells = motion.jumps(d("n_frames"), d.rng, jump_px=(r["jump_px"].lo, r["jump_px"].hi),
                                         dwell_frames=(r["dwell_frames"].lo, r["dwell_frames"].hi),
                                         half_extent=(d("half_extent_x_px"), d("half_extent_y_px")))
    d.record("jump_px", [round(v, 2) for v in lengths])
    d.record("dwell_frames", dwells)
    return _simulate(d, 640, 480, path, noise=_noise(d), probe=_probe(d), clutter=_clutter(d))


def _low_dose(d: Draws) -> Sequence:
    noise = _noise(d, beam_current_pA=50.0).replace(dose_e_per_px=d("dose_e_per_px"))
    path = _wander(d, d("n_frames"))
    return _simulate(d, 512, 384, path, noise=noise, probe=_probe(d), clutter=_clutter(d))


def _gray_charging(d: Draws) -> Sequence:
    n = d("n_frames")
    noise = _noise(d, charging_amplitude=d("probe_charging")).replace(
        gain_jitter=d("gain_jitter"), offset_jitter_gray=255.0 * d("offset_jitter_of_full_scale"),
        charging_time_s=n * FRAME_PERIOD * d("charging_time_of_sequence"), charging_scales_rim=False)
    path = _wander(d, n)
    return _simulate(d, 512, 384, path, noise=noise, probe=_probe(d), clutter=_clutter(d))


def _clutter_family(d: Draws) -> Sequence:
    n = d("n_frames")
    path = _wander(d, n)
    width, height = 512, 384
    angle = math.radians(d("probe_angle_deg"))
    # the occluder crosses the shaft `behind` px behind the tip's mean position at t_cross
    behind = d("occluder_behind_px")
    half_path = d("occluder_half_path_px")
    t_cross = d("occluder_cross_frame") * FRAME_PERIOD
    axis = np.array([math.cos(angle), math.sin(angle)])
    perp = np.array([-axis[1], axis[0]])
    centre = np.array([width / 2, height / 2]) - behind * axis
    clutter = Clutter(n_static=d("n_static"), n_drifting=d("n_drifting"), drift_speed_px_s=d("drift_speed_px_s"),
                      occluder=True, occluder_radius_px=d("occluder_radius_px"),
                      occluder_path=(tuple(centre - half_path * perp), tuple(centre + half_path * perp)),
                      occluder_period_s=4.0 * t_cross, texture=d("texture"))

    def visible(sem, t, tip):
        occ = sem.occluder_position(t)
        return occ is None or math.hypot(tip[0] - occ[0], tip[1] - occ[1]) > clutter.occluder_radius_px + 2.0

    return _simulate(d, width, height, path, noise=_noise(d), probe=_probe(d), clutter=clutter,
                     visible=visible, angle_deg=math.degrees(angle))


def _thin(d: Draws) -> Sequence:
    n = d("n_frames")
    angle = d.record("probe_angle_deg", d("scan_axis_deg") + d("axis_offset_deg"))
    noise = _noise(d, beam_current_pA=50.0).replace(dose_e_per_px=d("dose_e_per_px"))
    probe = _probe(d)
    shaft = (math.cos(math.radians(angle)), math.sin(math.radians(angle)))
    path = _wander(d, n, along=shaft, along_fraction=d("along_shaft_fraction"))
    return _simulate(d, 512, 384, path, noise=noise, probe=probe, clutter=_clutter(d), angle_deg=angle)


def _shapes(d: Draws) -> Sequence:
    kind = d("shape")
    if kind == "blunt":
        shape = BluntProbe(width_nm=d("blunt_width_nm"), corner_radius_nm=d("blunt_corner_nm"))
    elif kind == "gripper":
        w = d("jaw_width_nm")
        shape = GripperJaws(jaw_length_nm=d("jaw_length_nm"), jaw_width_nm=w,
                            jaw_tip_width_nm=w * d("jaw_taper"), gap_nm=d("jaw_gap_nm"),
                            corner_radius_nm=d("jaw_corner_nm"))
    else:
        shape = AFMTip(cantilever_width_nm=d("cantilever_width_nm"), point_length_nm=d("point_length_nm"),
                       corner_radius_nm=d("afm_corner_nm"))
    path = _wander(d, d("n_frames"))
    return _simulate(d, 512, 384, path, noise=_noise(d), probe=_probe(d, shape=shape), clutter=_clutter(d))


def _substrates(d: Draws) -> Sequence:
    width, height = 512, 384
    kind = d("substrate")
    strength = 0.0 if kind == "flat" else d("texture_strength")
    sigma = 0.5  # the beam blur at these pixel sizes is ~0.52 px (semlab.sim.beam_blur_sigma_px)
    background = textured_substrate(width, height, d.rng, kind=kind, strength=strength, sigma_px=sigma,
                                    beta=d("fractal_beta"), grain_px=d("grain_px"))
    noise = _noise(d, line_jitter_px=d("scan_line_jitter_px"), drift_px_per_s=d("image_drift_px_per_s"))
    path = _wander(d, d("n_frames"))
    return _simulate(d, width, height, path, noise=noise, probe=_probe(d), clutter=Clutter.none(),
                     background=background)


def _semi_real(d: Draws) -> Sequence:
    from .semireal import semi_real_sequence

    return semi_real_sequence(d)


def _family_list():
    from .semireal import SEMI_REAL_RANGES

    ab = {"step_px": Uniform(200.0, 200.0), "move_direction_deg": Uniform(0.0, 360.0), "n_cycles": Int(5, 5),
          "ramp_frames": Int(2, 3), "dwell_frames": Int(2, 3), "smooth_ramp": Choice((True, False))}
    return [
        Family("still", "still probe: the paper's repeatability (report the spread, std_px)",
               _ranges(RIG, n_frames=Int(50, 50)), _still),
        Family("moves_200px", "the paper's A->B moves of 200 px, five times, ramped over 2-3 frames",
               _ranges(RIG, ab), _moves),
        Family("wander", "random smooth wander within a disc",
               _ranges(RIG, WANDER, n_frames=Int(50, 50)), _wander_family),
        Family("jumps", "fast jumps of 25-100 px between two frames, then a dwell (a feed-forward step)",
               _ranges(RIG, n_frames=Int(50, 50), jump_px=Uniform(25.0, 100.0), dwell_frames=Int(3, 8),
                       half_extent_x_px=Uniform(150.0, 180.0), half_extent_y_px=Uniform(100.0, 120.0)), _jumps),
        Family("low_dose", "a few electrons per pixel (fast scan), contrast lowered to keep the noise in range",
               _ranges(RIG, WANDER, drop=("beam_current_pA",), n_frames=Int(40, 40), dose_e_per_px=Uniform(3.0, 10.0),
                       contrast=Uniform(100.0, 130.0), black_level=Uniform(55.0, 70.0),
                       speed_px_per_frame=Uniform(0.3, 1.0)), _low_dose),
        Family("gray_charging", "per-frame gain jitter up to 15 %, offset up to 8 % of full scale, the probe "
               "(not the substrate, not the rim) charging 30-60 % brighter",
               _ranges(RIG, WANDER, drop=("charging_amplitude",), n_frames=Int(50, 50), gain_jitter=Uniform(0.08, 0.15),
                       offset_jitter_of_full_scale=Uniform(0.04, 0.08), probe_charging=Uniform(0.3, 0.6),
                       charging_time_of_sequence=Uniform(0.15, 0.4), contrast=Uniform(125.0, 145.0),
                       black_level=Uniform(30.0, 40.0), probe_yield=Uniform(0.45, 0.55),
                       speed_px_per_frame=Uniform(0.5, 2.0)), _gray_charging),
        Family("clutter", "100-200 static particles, 20-40 drifting ones, an occluder sliding over the shaft",
               _ranges(RIG, WANDER, n_frames=Int(50, 50), n_static=Int(100, 200), n_drifting=Int(20, 40),
                       drift_speed_px_s=Uniform(5.0, 20.0), occluder_radius_px=Uniform(15.0, 30.0),
                       occluder_behind_px=Uniform(30.0, 60.0), occluder_half_path_px=Uniform(60.0, 120.0),
                       occluder_cross_frame=Uniform(15.0, 35.0), speed_px_per_frame=Uniform(0.3, 1.5)),
               _clutter_family),
        Family("thin_low_dose", "a thin needle within 4 degrees of a scan axis at low dose, moving mostly along "
               "its shaft", _ranges(RIG, WANDER, drop=("beam_current_pA", "probe_angle_deg"), n_frames=Int(40, 40),
                                    half_angle_deg=Uniform(1.5, 3.5),
                                    tip_diameter_nm=Uniform(60.0, 120.0), scan_axis_deg=Choice((0.0, 90.0, 180.0, 270.0)),
                                    axis_offset_deg=Uniform(-4.0, 4.0), dose_e_per_px=Uniform(5.0, 15.0),
                                    contrast=Uniform(110.0, 140.0), black_level=Uniform(50.0, 65.0),
                                    along_shaft_fraction=Uniform(0.8, 0.95), speed_px_per_frame=Uniform(0.5, 1.5)),
               _thin),
        Family("shapes", "other probe shapes: a blunt flat-ended tip, gripper jaws, an AFM-like tip",
               _ranges(RIG, WANDER, n_frames=Int(40, 40), shape=Choice(("blunt", "gripper", "afm")),
                       blunt_width_nm=Uniform(400.0, 900.0), blunt_corner_nm=Uniform(30.0, 120.0),
                       jaw_length_nm=Uniform(1500.0, 3500.0), jaw_width_nm=Uniform(400.0, 900.0),
                       jaw_taper=Uniform(0.5, 0.9), jaw_gap_nm=Uniform(300.0, 1200.0), jaw_corner_nm=Uniform(20.0, 80.0),
                       cantilever_width_nm=Uniform(1500.0, 3000.0), point_length_nm=Uniform(800.0, 2500.0),
                       afm_corner_nm=Uniform(20.0, 100.0), speed_px_per_frame=Uniform(0.5, 2.0)), _shapes),
        Family("substrates", "substrates from flat to strongly textured (fractal or grains), scan-line jitter "
               "and slow image drift",
               _ranges(RIG, WANDER, drop=("n_static", "texture", "line_jitter_px", "drift_px_per_s"),
                       n_frames=Int(50, 50), substrate=Choice(("flat", "fractal", "grains")),
                       texture_strength=Uniform(0.02, 0.12), fractal_beta=Uniform(2.0, 3.5), grain_px=Uniform(6.0, 25.0),
                       scan_line_jitter_px=Uniform(0.1, 0.5), image_drift_px_per_s=Uniform(0.5, 3.0),
                       speed_px_per_frame=Uniform(0.3, 1.5)), _substrates, ablations=("occluder", *NOISE_ABLATIONS)),
        Family("semi_real", "the real FIB/SEM needle of data/real-sem cut out and moved by exact sub-pixel "
               "Fourier shifts over real backgrounds from other frames, shot noise at several doses",
               SEMI_REAL_RANGES, _semi_real, ablations=()),
    ]


#: name -> :class:`Family`, in the order tables list them.
FAMILIES: dict[str, Family] = {f.name: f for f in _family_list()}
FAMILY_NAMES = tuple(FAMILIES)


def check_ablations(names, without) -> tuple[str, ...]:
    """``without`` as a tuple, checked against :data:`ABLATIONS` and the own list of each family in
    ``names`` (a name or an iterable of names).

    Raises
    ------
    ValueError
        An unknown part, or one the family cannot take out (the substrate of ``substrates`` is not
        drawn through the simulator's clutter, nothing of ``semi_real`` through the simulator).
    """
    without = (without,) if isinstance(without, str) else tuple(without)
    unknown = sorted(set(without) - set(ABLATIONS))
    if unknown:
        raise ValueError(f"without: unknown part(s) {unknown}; valid: {', '.join(ABLATIONS)}")
    for name in (names,) if isinstance(names, str) else names:
        refused = sorted(set(without) - set(FAMILIES[name].ablations))
        if refused:
            raise ValueError(f"family {name!r} cannot take out {refused}: its scenes do not draw them through the "
                             f"simulator (it can take out: {', '.join(FAMILIES[name].ablations) or 'nothing'})")
    return without


def make_family_sequence(name: str, seed: int, *, noise_free: bool = False, without=()) -> Sequence:
    """The sequence of family ``name`` for ``seed`` (deterministic).

    ``noise_free=True`` (for tests of the ground truth) renders the same probe along the same path
    with no noise, clutter or texture: a flat background, so that the frames show the probe alone.
    ``without`` takes parts of the scene out (:data:`ABLATIONS`: ``"texture"``, the substrate's
    texture, whose amplitude becomes :data:`ABLATED_TEXTURE`; ``"occluder"``; and parts of the noise,
    :data:`NOISE_ABLATIONS`), every other draw kept: the same probe, path, particles and noise draws.

    Returns
    -------
    semlab.sim.Sequence
        ``frames``, ``truth`` (``frame, t, x, y, visible``), ``roi``, ``crb`` (RMS over sampled
        frames of the single-frame bound ``(sigma_x, sigma_y)`` px inside the ROI moved with the
        probe), ``meta`` (``family, seed, split, params`` -- the values drawn -- ``crb_frames``,
        frame size, pixel size, dose).

    Raises
    ------
    ValueError
        Unknown family, a seed that is not a non-negative integer, or a part in ``without`` that
        is unknown or that the family cannot take out (:func:`check_ablations`).
    """
    if name not in FAMILIES:
        raise ValueError(f"unknown family {name!r}; valid: {', '.join(FAMILY_NAMES)}")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    without = check_ablations(name, without)
    d = Draws(family_rng(name, seed), FAMILIES[name].ranges)
    d.noise_free = bool(noise_free)
    d.without = frozenset(without)
    seq = FAMILIES[name].build(d)
    seq.meta.update(family=name, seed=seed, split=split_of(seed), n_frames=len(seq.frames), params=d.params,
                    derived=sorted(d.derived), without=sorted(d.without))
    return seq
