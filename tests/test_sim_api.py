"""The simulator's public API as the team brief specifies it (fast smoke + contract checks)."""

import numpy as np
import pandas as pd
import pytest

from semlab.protocols import Axis, Microscope
from semlab.sim import (
    Clutter,
    ProbeGeometry,
    SEMNoise,
    SimulatedRig,
    SimulatedSEM,
    make_sequence,
    pixel_size_from_magnification,
    translation_crb,
)


def test_pixel_size_matches_paper():
    assert pixel_size_from_magnification(3000) == pytest.approx(66.0)
    assert pixel_size_from_magnification(30000) == pytest.approx(6.6)
    with pytest.raises(ValueError):
        pixel_size_from_magnification(-5)


def test_sem_render_and_acquire_shapes():
    sem = SimulatedSEM(width=320, height=240, seed=1)
    tips = np.array([[100.0, 120.0]])
    clean = sem.render_clean(tips)
    assert clean.shape == (240, 320) and clean.dtype == np.float64
    # render_clean = brightness + contrast * yield with a yield >= 0: nothing darker than the black level
    assert clean.min() >= sem.noise.brightness
    assert sem.time == pytest.approx(0.5 * sem.frame_period)  # the next frame's mid-time
    frame = sem.acquire(tips)
    assert frame.shape == (240, 320) and frame.dtype == np.uint8
    assert sem.frame_index == 1 and sem.time == pytest.approx(1.5 * sem.frame_period)


def test_acquire_with_every_effect_off_is_the_rounded_clean_render():
    # SEMNoise.off(): acquire returns render_clean up to the 8-bit rounding (the acquired frame is
    # rendered in float32, so a level within float32 rounding of .5 may round the other way: 1 LSB)
    sem = SimulatedSEM(width=320, height=240, seed=1, noise=SEMNoise.off())
    tips = np.array([[100.0, 120.0]])
    clean = sem.render_clean(tips)
    frame = sem.acquire(tips).astype(float)
    diff = np.abs(frame - np.clip(np.rint(clean), 0, 255))
    assert diff.max() <= 1.0 and diff.mean() < 1e-3


def test_rig_implements_protocols_and_truth():
    rig = SimulatedRig(seed=0)
    assert isinstance(rig.microscope, Microscope)
    ax = rig.axis(0, "x")
    assert isinstance(ax, Axis)
    assert ax.limits == (0.0, 100.0)
    assert rig.truth.empty  # nothing scanned yet
    frame = rig.microscope.grab()
    assert frame.shape == (480, 640)
    t = rig.truth
    assert list(t.columns) == ["frame", "t", "probe", "x", "y", "visible"]
    assert len(t) == 4 and t["visible"].all() and list(t["probe"]) == [0, 1, 2, 3]
    # the truth is sampled at the frame's mid-time (13 Hz: 1/26 s) at the rig's base positions,
    # moved only by the slow drift (0.05 px/s: < 0.01 px by then)
    assert rig.microscope.frame_period == pytest.approx(1 / 13)
    np.testing.assert_allclose(t["t"], 0.5 / 13)
    np.testing.assert_allclose(t[["x", "y"]].to_numpy(), np.asarray(rig.base_positions, float), atol=0.05)
    rig.microscope.grab()
    assert list(rig.truth["frame"]) == [1] * 4 and rig.truth["t"].iloc[0] == pytest.approx(1.5 / 13)
    assert rig.macro(0, "x").limits == (0.0, 12e6)
    assert rig.macro(0, "y").limits == (0.0, 10e6)


@pytest.mark.parametrize("kind", ["static", "moves_200px", "low_dose", "gray_fluctuation",
                                  "clutter_occluder"])
def test_make_sequence_contract(kind):
    seq = make_sequence(kind, n_frames=4, seed=3, width=320, height=240, n_manipulators=1,
                        base_positions=[(120.0, 120.0)])
    assert seq.frames.shape == (4, 240, 320) and seq.frames.dtype == np.uint8
    assert isinstance(seq.truth, pd.DataFrame)
    assert {"frame", "x", "y"} <= set(seq.truth.columns) and len(seq.truth) == 4
    assert list(seq.truth["frame"]) == [0, 1, 2, 3]
    x, y, w, h = seq.roi
    assert (w, h) == (200, 200) and 0 <= x <= 320 - w and 0 <= y <= 240 - h
    # the ROI is centred on probe 0's tip in frame 0, to the rounding of its corner (0.5 px)
    tip = seq.truth[["x", "y"]].to_numpy()[0]
    assert np.all(np.abs(np.array([x, y]) + (w - 1) / 2 - tip) <= 0.5)
    # the bound is translation_crb of frame 0 (checked against an efficient estimator in
    # tests/test_sim_noise.py); here: positive and finite on both axes
    assert all(np.isfinite(s) and s > 0 for s in seq.crb)
    assert seq.meta["kind"] == kind and seq.meta["pixel_size_nm"] == 66.0
    # the probe moves in every kind but "static" (tests/test_sim_rig.py checks the sweep)
    assert seq.meta["motion"] == {"static": "still", "moves_200px": "steps"}.get(kind, "sweep")
    assert len(seq.commands) == 4 and seq.commands["u"].iloc[0] == 0.0


def test_low_dose_raises_the_bound_by_at_most_the_square_root_of_the_dose_ratio():
    # Shot-noise variance scales as 1/dose at a fixed contrast; the read noise, line offsets and
    # jitter do not. So the bound grows when the dose drops, but by at most sqrt(dose ratio).
    kw = {"n_frames": 2, "seed": 3, "width": 320, "height": 240, "n_manipulators": 1,
          "base_positions": [(120.0, 120.0)]}
    full, low = make_sequence("static", **kw), make_sequence("low_dose", motion="still", **kw)
    ratio = np.array(low.crb) / np.array(full.crb)
    limit = np.sqrt(full.meta["dose_e_per_px"] / low.meta["dose_e_per_px"])
    assert np.all(ratio > 1.0) and np.all(ratio <= limit * (1 + 1e-6))


def test_crb_follows_the_noise_and_bad_roi_raises():
    tips = np.array([[150.0, 250.0]])
    roi = (50, 150, 200, 200)
    # read noise only (white, no shot noise, no line effects): F = J^T J / s^2 with s^2 the read
    # variance plus the 8-bit quantisation (1/12 LSB^2) -- the bound in closed form from the
    # render's own finite-difference Jacobian
    white = SEMNoise.off().replace(read_noise_gray=4.0)
    sem = SimulatedSEM(seed=0, noise=white)
    sx, sy = translation_crb(sem, tips, roi)
    h = 1e-2
    t = sem.time

    def render(dx, dy):
        return sem.render_clean(tips + (dx, dy), t=t)[150:350, 50:250]

    jx = (render(h, 0) - render(-h, 0)) / (2 * h)
    jy = (render(0, h) - render(0, -h)) / (2 * h)
    var = 4.0 ** 2 + 1 / 12
    cov = np.linalg.inv(np.array([[jx.ravel() @ jx.ravel(), jx.ravel() @ jy.ravel()],
                                  [jx.ravel() @ jy.ravel(), jy.ravel() @ jy.ravel()]]) / var)
    assert (sx, sy) == pytest.approx(tuple(np.sqrt(np.diag(cov))), rel=1e-6)
    # a sub-ROI has less information: the bound can only grow
    sx_small, sy_small = translation_crb(sem, tips, (100, 200, 100, 100))
    assert sx_small >= sx and sy_small >= sy
    with pytest.raises(ValueError, match="roi"):
        translation_crb(SimulatedSEM(seed=0), tips, (500, 400, 200, 200))


def test_dataclass_defaults_and_off():
    off = SEMNoise.off()
    assert off.shot_noise is False and off.read_noise_gray == 0.0 and off.line_correlation == 0.0
    assert ProbeGeometry().tip_diameter_nm == 200.0
    assert Clutter.none().n_static == 0
