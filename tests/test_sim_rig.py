"""The simulated rig: manipulators move the probes in the image, with exact ground truth."""

import math

import numpy as np
import pytest

from semlab.sim import Clutter, PiezoParameters, SEMNoise, SimulatedRig, make_sequence
from semlab.sim.manipulator import NANO_TRAVEL_NM

QUIET = {"noise": SEMNoise.off(), "clutter": Clutter.none()}


def _rig(**kw):
    for k, v in QUIET.items():
        kw.setdefault(k, v)
    kw.setdefault("n_manipulators", 2)
    return SimulatedRig(**kw)


def test_commands_take_effect_from_the_next_frame():
    rig = _rig(piezo=PiezoParameters(creep_per_decade=0.0, position_noise_nm=0.0))
    rig.microscope.grab()
    x0 = rig.truth.loc[0, "x"]
    frame_before = rig.microscope.grab()
    assert rig.truth.loc[0, "x"] == pytest.approx(x0, abs=1e-9)
    rig.axis(0, "x").apply(20.0)
    # nothing has moved yet: the truth is that of the last grabbed frame
    assert rig.truth.loc[0, "x"] == pytest.approx(x0, abs=1e-9)
    frame_after = rig.microscope.grab()
    assert rig.truth.loc[0, "x"] - x0 > 50
    assert rig.truth.loc[0, "frame"] == 2
    assert np.any(frame_after != frame_before)
    # the lag (2 ms) is over long before the mid-frame: the next frame is the same place
    x1 = rig.truth.loc[0, "x"]
    rig.microscope.grab()
    assert rig.truth.loc[0, "x"] == pytest.approx(x1, abs=1e-6)


def test_displacement_follows_view_rotation_and_pixel_size():
    rig = _rig(piezo=PiezoParameters(creep_per_decade=0.0, hysteresis=False, position_noise_nm=0.0))
    rig.microscope.grab()
    p0 = rig.truth.loc[0, ["x", "y"]].to_numpy(float)
    rig.axis(0, "x").apply(10.0)
    rig.microscope.grab()
    d = rig.truth.loc[0, ["x", "y"]].to_numpy(float) - p0
    volts = rig.axis(0, "x").command
    expect = volts / 100.0 * NANO_TRAVEL_NM["x"] / 66.0
    th = math.radians(rig.view_angles_deg[0])
    np.testing.assert_allclose(d, expect * np.array([math.cos(th), math.sin(th)]), atol=1e-9)
    # y axis: 10 um over 100 V, perpendicular in the image
    rig.axis(0, "y").apply(50.0)
    rig.microscope.grab()
    d2 = rig.truth.loc[0, ["x", "y"]].to_numpy(float) - p0 - d
    q = rig.axis(0, "y").command / 100.0 * NANO_TRAVEL_NM["y"] / 66.0
    # (the x step's 2 ms lag tail still contributes exp(-38.5 / 2) * 76 px ~ 3e-7 px)
    np.testing.assert_allclose(d2, q * np.array([-math.sin(th), math.cos(th)]), atol=1e-6)


def test_probe_0_has_room_to_move_300px_and_leaving_the_frame_is_not_an_error():
    rig = _rig()
    rig.microscope.grab()
    x0 = rig.truth.loc[0, "x"]
    ax = rig.axis(0, "x")
    ax.apply(65.0)  # the ascending branch is convex: 65 % of the voltage ~ 45 % of the travel
    rig.microscope.grab()
    t = rig.truth
    assert t.loc[0, "x"] - x0 > 300 and t.loc[0, "visible"]
    ax.apply(100.0)  # 50 um = 757 px: past the frame's right edge
    frame = rig.microscope.grab()
    t = rig.truth
    assert t.loc[0, "x"] > 640 and not t.loc[0, "visible"]
    assert frame.shape == (480, 640)


def test_dac_quantisation_of_commands():
    rig = _rig()
    x, y = rig.axis(0, "x"), rig.axis(0, "y")
    assert x.lsb_volts == pytest.approx(100.0 / 2**16)
    assert y.lsb_volts == pytest.approx(100.0 / 2**12)
    code_410 = 410 * y.lsb_volts
    y.apply(code_410 + 0.4 * y.lsb_volts)
    assert y.command == pytest.approx(code_410, abs=1e-12)
    y.apply(code_410 + 0.6 * y.lsb_volts)
    assert y.command == pytest.approx(code_410 + y.lsb_volts, abs=1e-12)
    y.apply(10.0)
    assert abs(y.command - 10.0) <= y.lsb_volts / 2


def test_macro_stepper_quantises_to_100nm_and_moves_the_probe():
    rig = _rig(piezo=PiezoParameters(creep_per_decade=0.0, position_noise_nm=0.0))
    rig.microscope.grab()
    p0 = rig.truth.loc[0, ["x", "y"]].to_numpy(float)
    mac = rig.macro(0, "x")
    target = mac.position_nm + 1234.0
    assert mac.move_to(target) == pytest.approx(mac.home_nm + 1200.0)
    rig.microscope.grab()
    d = rig.truth.loc[0, ["x", "y"]].to_numpy(float) - p0
    assert np.hypot(*d) == pytest.approx(1200.0 / 66.0, rel=1e-9)
    with pytest.raises(ValueError, match="travel"):
        mac.move_to(13e6)
    with pytest.raises(ValueError, match="finite"):
        mac.move_to(float("nan"))
    assert rig.macro(0, "y").limits == (0.0, 10e6)


def test_bad_axis_manipulator_and_commands_raise():
    rig = _rig()
    with pytest.raises(ValueError, match="manipulator"):
        rig.axis(2, "x")
    with pytest.raises(ValueError, match="manipulator"):
        rig.axis(-1, "x")
    with pytest.raises(ValueError, match="axis"):
        rig.axis(0, "w")
    with pytest.raises(ValueError, match="axis"):
        rig.macro(0, "theta")
    ax = rig.axis(0, "x")
    for bad in (float("nan"), float("inf"), -0.1, 100.1, "ten"):
        with pytest.raises(ValueError):
            ax.apply(bad)
    with pytest.raises(ValueError, match="n_manipulators"):
        SimulatedRig(n_manipulators=5)


def test_position_noise_is_in_the_truth():
    rig = _rig(piezo=PiezoParameters(creep_per_decade=0.0, position_noise_nm=3.3))
    xs = []
    for _ in range(200):
        rig.microscope.grab()
        xs.append(rig.truth.loc[0, ["x", "y"]].to_numpy(float))
    # x and y piezo noise of 3.3 nm each, rotated into the image, plus z's 5 deg projection
    sd = np.std(np.array(xs), axis=0) * 66.0
    assert np.hypot(*sd) == pytest.approx(3.3 * math.sqrt(2 + math.sin(math.radians(5)) ** 2),
                                          rel=0.15)


def test_truth_log_and_columns():
    rig = _rig(n_manipulators=4)
    for _ in range(3):
        rig.microscope.grab()
    log = rig.truth_log
    assert list(log.columns) == ["frame", "t", "probe", "x", "y", "visible"]
    assert len(log) == 12
    np.testing.assert_allclose(log["t"].unique(), (np.arange(3) + 0.5) / 13)


def test_moves_200px_sequence_reaches_b_and_returns():
    seq = make_sequence("moves_200px", seed=1, **QUIET)
    x = seq.truth["x"].to_numpy()
    assert len(seq) == 12 + 5 * 36
    d = x - x[0]
    # dwell at B: 200 px plus creep; back at A (0 V wipes the hysteresis memory out): 0
    # plus the creep left over, each bounded by gamma * 200 px * log10(1 + t / t0) with t
    # at most one cycle (36 frames) after the step
    creep_max = 0.015 * 200 * math.log10(1 + 36 / 13 / 0.1)
    at_b = d[12 + 6:12 + 18]
    assert np.all(np.abs(at_b - 200) < creep_max)
    assert np.all(np.abs(d[-12:]) < creep_max)
    np.testing.assert_allclose(seq.truth["frame"], np.arange(len(seq)))
    assert seq.meta["u_B"] > 0


def test_sequence_rois_and_errors():
    seq = make_sequence("static", n_frames=3, seed=0)
    x, y, w, h = seq.roi
    tx, ty = seq.truth.loc[0, ["x", "y"]]
    assert abs(x + (w - 1) / 2 - tx) <= 0.5 and abs(y + (h - 1) / 2 - ty) <= 0.5
    with pytest.raises(ValueError, match="kind"):
        make_sequence("wobble")
    with pytest.raises(ValueError, match="override"):
        make_sequence("static", n_frames=2, not_a_parameter=3)
    with pytest.raises(ValueError, match="n_frames"):
        make_sequence("static", n_frames=0)
    with pytest.raises(ValueError, match="roi_size"):
        make_sequence("static", n_frames=1, roi_size=500)
    with pytest.raises(ValueError, match="dose"):
        make_sequence("low_dose", n_frames=1, dose_e_per_px=-1.0)
    with pytest.raises(ValueError, match="off the"):
        make_sequence("static", n_frames=1, n_manipulators=1, base_positions=[(-30.0, 100.0)])


def test_same_seed_same_frames_different_seed_different_noise():
    a = make_sequence("static", n_frames=2, seed=4)
    b = make_sequence("static", n_frames=2, seed=4)
    c = make_sequence("static", n_frames=2, seed=5)
    np.testing.assert_array_equal(a.frames, b.frames)
    assert np.mean(a.frames != c.frames) > 0.5
    assert a.crb == b.crb


def test_occluder_passes_over_the_probe_shaft():
    # the probe still, so that one pixel stays on its shaft (the sweeping probe: next test)
    seq = make_sequence("clutter_occluder", n_frames=100, seed=0, n_manipulators=1,
                        noise=SEMNoise.off(), motion="still")
    x, y, w, h = seq.roi
    tx, ty = seq.truth.loc[0, ["x", "y"]]
    ang = math.radians(10.0)
    px, py = round(tx - 45 * math.cos(ang)), round(ty - 45 * math.sin(ang))
    vals = seq.frames[:, py, px].astype(float)
    # on the shaft the probe is bright; the occluder darkens it while passing
    assert vals.max() - vals.min() > 30
    assert x <= px < x + w and y <= py < y + h


# --------------------------------------------------------------- the probe sweep (moving probe)
def test_sweep_follows_the_voltage_from_rest():
    # low_dose with the default sweep, noise and clutter off (the piezo's 1 nm position noise
    # stays: 0.015 px): the truth follows the raised-cosine voltage on the x piezo.
    seq = make_sequence("low_dose", n_frames=100, seed=1, **QUIET)
    amp, period = 30.0, 80
    assert seq.meta["motion"] == "sweep"
    assert seq.meta["sweep_amplitude_px"] == amp and seq.meta["sweep_period_frames"] == period
    u = seq.commands["u"].to_numpy()
    k = np.arange(100)
    lsb = 100.0 / 2**16
    np.testing.assert_allclose(u, seq.meta["u_peak"] * (1 - np.cos(2 * np.pi * k / period)) / 2,
                               atol=lsb / 2 + 1e-12)
    assert u[0] == 0.0
    x = seq.truth["x"].to_numpy()
    d = x - x[0]
    # at rest in frame 0: the first step is u_peak (1 - cos(2 pi / 80)) / 2 = 0.15 % of u_peak
    assert abs(d[1]) < 0.1
    # at the top (frame 40, u = u_peak) the ascending branch gives 2 x amplitude exactly; creep
    # adds at most gamma * 60 px * log10(1 + t / t0) with t the 40 frames of the rise
    creep_max = 0.015 * 2 * amp * math.log10(1 + 40 / 13 / 0.1)
    assert 2 * amp - 0.1 < d[period // 2] < 2 * amp + creep_max
    assert d.max() < 2 * amp + creep_max
    # where the voltage moves, the probe moves the same way; never more than ~3 px per frame
    du, dx = np.diff(u), np.diff(x)
    big = np.abs(du) > 0.2 * np.abs(du).max()
    assert big.sum() > 40 and np.all(np.sign(dx[big]) == np.sign(du[big]))
    assert np.abs(dx).max() < 3.0
    # back at 0 V (frame 80) the hysteresis memory is wiped out: only creep is left
    creep_back = 0.015 * 2 * amp * math.log10(1 + 80 / 13 / 0.1)
    assert abs(d[period]) < creep_back
    # along the image's y only the 2 deg view rotation of the x axis: tan(2 deg) of the travel
    dy = seq.truth["y"].to_numpy() - seq.truth["y"].iloc[0]
    np.testing.assert_allclose(dy, d * math.tan(math.radians(2.0)), atol=0.05)


@pytest.mark.parametrize("kind", ["gray_fluctuation", "clutter_occluder"])
def test_sweep_amplitude_and_period_overrides(kind):
    seq = make_sequence(kind, n_frames=21, seed=2, n_manipulators=1, sweep_amplitude_px=10,
                        sweep_period_frames=40, noise=SEMNoise.off())
    d = seq.truth["x"].to_numpy() - seq.truth["x"].iloc[0]
    # frame 20 is the top of a 40-frame period: 2 x 10 px (+ creep)
    assert 19.9 < d[20] < 20.0 + 0.015 * 20 * math.log10(1 + 20 / 13 / 0.1)
    assert seq.meta["motion"] == "sweep" and seq.meta["sweep_period_frames"] == 40


def test_still_motion_is_the_old_still_probe():
    # the still variant of low_dose is the still scene at 10 pA: frame for frame the "static"
    # sequence with the beam current lowered, and the piezo never leaves 0 V
    still = make_sequence("low_dose", n_frames=4, seed=3, motion="still")
    ref = make_sequence("static", n_frames=4, seed=3, beam_current_pA=10.0)
    np.testing.assert_array_equal(still.frames, ref.frames)
    assert still.meta["motion"] == "still" and (still.commands["u"] == 0).all()
    assert make_sequence("static", n_frames=2, seed=3).meta["motion"] == "still"
    moving = make_sequence("low_dose", n_frames=4, seed=3)
    assert moving.crb == still.crb  # frame 0 is the same (the probe at rest at 0 V)
    np.testing.assert_array_equal(moving.frames[0], still.frames[0])


def test_sweep_is_deterministic_by_seed():
    a = make_sequence("clutter_occluder", n_frames=6, seed=4)
    b = make_sequence("clutter_occluder", n_frames=6, seed=4)
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.truth[["x", "y"]].to_numpy(), b.truth[["x", "y"]].to_numpy())
    np.testing.assert_array_equal(a.commands["u"], b.commands["u"])


@pytest.mark.parametrize("kind, kw, match", [
    ("low_dose", {"motion": "wobble"}, "motion"),
    ("low_dose", {"motion": 3}, "motion"),
    ("static", {"motion": "sweep"}, "static"),
    ("moves_200px", {"motion": "still"}, "moves_200px"),
    ("gray_fluctuation", {"motion": "still", "sweep_amplitude_px": 10}, "sweep"),
    ("static", {"sweep_period_frames": 50}, "sweep"),
    ("low_dose", {"sweep_amplitude_px": 0}, "sweep_amplitude_px"),
    ("low_dose", {"sweep_amplitude_px": -5}, "sweep_amplitude_px"),
    ("low_dose", {"sweep_amplitude_px": float("nan")}, "sweep_amplitude_px"),
    ("low_dose", {"sweep_amplitude_px": "big"}, "sweep_amplitude_px"),
    ("low_dose", {"sweep_period_frames": 1}, "sweep_period_frames"),
    ("low_dose", {"sweep_period_frames": float("inf")}, "sweep_period_frames"),
    ("clutter_occluder", {"sweep_amplitude_px": 400}, "travel"),  # 800 px > 757 px of travel
])
def test_bad_motion_raises(kind, kw, match):
    with pytest.raises(ValueError, match=match):
        make_sequence(kind, n_frames=2, seed=0, n_manipulators=1, **kw)


def test_occluder_crosses_the_sweeping_probe_45px_behind_its_tip():
    # With the default sweep the occluder's path is placed where the tip is planned to be when
    # it crosses (a quarter of its 15 s period in: frame 48, the probe near the top of its
    # travel): at that frame it darkens the shaft 45 px behind the tip, and never the tip.
    kw = {"n_frames": 50, "seed": 0, "n_manipulators": 1, "noise": SEMNoise.off()}
    seq = make_sequence("clutter_occluder", **kw)
    bare = make_sequence("clutter_occluder", occluder_radius_px=1e-3, **kw)  # same path, no disc
    diff = np.abs(seq.frames.astype(float) - bare.frames.astype(float))
    tips = seq.truth[["x", "y"]].to_numpy()
    assert tips[48, 0] - tips[0, 0] > 55
    ang = math.radians(10.0)  # probe 0 points along 10 deg
    x, y = tips[48]
    assert diff[48, round(y - 45 * math.sin(ang)), round(x - 45 * math.cos(ang))] > 30
    for k, (x, y) in enumerate(tips):
        iy, ix = round(y), round(x)
        assert diff[k, iy - 5:iy + 6, ix - 5:ix + 6].max() <= 2  # the blurred disc's far tail only
