"""The alternative rig, ``SimulatedRig(piezo_model="prandtl-ishlinskii")``: a 0-150 V amplifier, 16-bit DACs,
its axes follow their Prandtl-Ishlinskii model and creep; and a skewed view (the hysteresis and creep physics
are tested in test_sim_piezo)."""

import math

import numpy as np
import pytest

from semlab.sim import (
    PiezoParameters,
    SEMNoise,
    SimulatedRig,
)
from semlab.sim.manipulator import AXES, NANO_TRAVEL_NM
from semlab.sim.rig import alternative_hysteresis

V = np.linspace(0.0, 1.0, 501)
ALT = "prandtl-ishlinskii"


def test_the_alternative_rig_has_0_150_v_16_bit_axes_and_follows_its_model():
    piezo = PiezoParameters(creep_per_decade=0.0, position_noise_nm=0.0)
    rig = SimulatedRig(n_manipulators=1, seed=4, piezo_model=ALT, piezo=piezo, z_view=(0.0, 0.0))
    for a in AXES:
        axis = rig.axis(0, a)
        assert axis.limits == (0.0, 150.0) and axis.bits == 16
        assert axis.lsb_volts == pytest.approx(150.0 / 2**16)
    rig.microscope.grab()
    p0 = rig.truth[["x", "y"]].to_numpy(float)[0]
    x = rig.axis(0, "x")
    h = alternative_hysteresis(0, "x", seed=4)
    th = math.radians(rig.view_angles_deg[0])
    d = np.array([math.cos(th), math.sin(th)])
    for u in (40.0, 120.0, 75.0, 90.0, 10.0):
        x.apply(u)
        rig.microscope.grab()  # the command acts from this frame (2 ms lag: settled by mid-frame)
        expected = h.update(x.command / 150.0) * NANO_TRAVEL_NM["x"] / rig.pixel_size_nm
        moved = (rig.truth[["x", "y"]].to_numpy(float)[0] - p0) @ d
        assert moved == pytest.approx(expected, abs=1e-3 * expected + 1e-6)


def test_the_alternative_rig_creeps_and_differs_from_the_default_rig():
    default = SimulatedRig(n_manipulators=1, seed=1)
    alt = SimulatedRig(n_manipulators=1, seed=1, piezo_model=ALT)
    tips = []
    for rig in (default, alt):
        rig.microscope.grab()
        p0 = rig.truth[["x", "y"]].to_numpy(float)[0]
        rig.axis(0, "x").apply(40.0)
        track = []
        for _ in range(40):
            rig.microscope.grab()
            track.append(rig.truth[["x", "y"]].to_numpy(float)[0, 0] - p0[0])
        tips.append(np.array(track))
    step_default, step_alt = tips
    # 40 V is 40 % of one amplifier's range and 27 % of the other's: the probes end far apart
    assert abs(step_default[-1] - step_alt[-1]) > 20.0
    # the alternative probe keeps creeping after the step (Kelvin-Voigt, 0.3 s and slower)
    assert step_alt[-1] - step_alt[0] > 0.005 * step_alt[0]
    with pytest.raises(ValueError, match="piezo_model"):
        SimulatedRig(piezo_model="preisch")


def test_a_skewed_view_moves_the_y_axis_off_the_perpendicular():
    piezo = PiezoParameters(creep_per_decade=0.0, hysteresis=False, position_noise_nm=0.0)
    rig = SimulatedRig(n_manipulators=2, seed=0, piezo=piezo, view_skew_deg=(12.0, -7.0), z_view=(0.0, 0.0),
                       noise=SEMNoise.off())  # no image drift
    assert rig.view_skew_deg == (12.0, -7.0)
    rig.microscope.grab()
    p0 = rig.truth[["x", "y"]].to_numpy(float)
    for m in range(2):
        rig.axis(m, "y").apply(60.0)
    rig.microscope.grab()
    moved = rig.truth[["x", "y"]].to_numpy(float) - p0
    for m, skew in enumerate((12.0, -7.0)):
        expect = rig.axis(m, "y").command / 100.0 * NANO_TRAVEL_NM["y"] / rig.pixel_size_nm
        ty = math.radians(rig.view_angles_deg[m] + 90.0 + skew)
        np.testing.assert_allclose(moved[m], expect * np.array([math.cos(ty), math.sin(ty)]), atol=1e-6)
    with pytest.raises(ValueError, match="view_skew_deg"):
        SimulatedRig(view_skew_deg=(1.0, 2.0))
