"""The alternative piezo ground truth: Prandtl-Ishlinskii hysteresis with a static output nonlinearity,
Kelvin-Voigt creep, a 0-150 V amplifier and 16-bit DACs (``SimulatedRig(piezo_model="prandtl-ishlinskii")``)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semlab.sim import (
    ExponentialCreep,
    PiezoParameters,
    PrandtlIshlinskiiHysteresis,
    SEMNoise,
    SimulatedRig,
)
from semlab.sim.manipulator import AXES, NANO_TRAVEL_NM
from semlab.sim.rig import alternative_hysteresis

V = np.linspace(0.0, 1.0, 501)
ALT = "prandtl-ishlinskii"


def _major_loop(h):
    h.reset()
    up = h.branch(V)
    down = h.branch(V[::-1])[::-1]
    return up, down


@pytest.mark.parametrize("m", range(4))
@pytest.mark.parametrize("axis", AXES)
def test_major_loop_is_closed_monotone_and_10_to_15_percent_wide(m, axis):
    up, down = _major_loop(alternative_hysteresis(m, axis, seed=0))
    assert up[0] == pytest.approx(0.0) and up[-1] == pytest.approx(1.0)
    assert down[0] == pytest.approx(0.0, abs=1e-12) and down[-1] == pytest.approx(1.0)
    assert 0.10 <= np.max(down - up) <= 0.15  # as wide as a real piezo's (and the Preisach rig's)
    assert np.all(np.diff(up) > 0) and np.all(np.diff(down) > 0)


def test_the_output_nonlinearity_takes_the_loop_out_of_the_pi_family():
    # a PI operator's major loop is point-symmetric, down(v) = 1 - up(1 - v); g breaks the symmetry
    up, down = _major_loop(PrandtlIshlinskiiHysteresis(quadratic=0.0, cubic=0.0))
    assert np.max(np.abs(down - (1 - up[::-1]))) < 1e-12
    up, down = _major_loop(PrandtlIshlinskiiHysteresis())
    assert np.max(np.abs(down - (1 - up[::-1]))) > 0.05
    # and minor loops between the same input extremes are congruent in p (a PI property), not in y:
    # two histories, then the same cycle 0.6 -> 0.3 -> 0.6
    h = PrandtlIshlinskiiHysteresis()

    def minor(start):
        h.reset()
        h.update(start)
        h.update(0.6)
        h.update(0.3)
        ps, ys = [], []
        for v in np.linspace(0.3, 0.6, 31):
            h.update(v)
            ps.append(h.operator_output())
            ys.append(h.output())
        return np.array(ps), np.array(ys)

    p_a, y_a = minor(0.9)
    p_b, y_b = minor(0.45)
    np.testing.assert_allclose(p_a - p_a[0], p_b - p_b[0], atol=1e-12)
    assert np.max(np.abs((y_a - y_a[0]) - (y_b - y_b[0]))) > 1e-3


@settings(max_examples=40, deadline=None)
@given(path=st.lists(st.floats(0.0, 1.0, allow_nan=False), min_size=1, max_size=12),
       excursion=st.floats(0.0, 1.0, allow_nan=False))
def test_minor_loops_close_and_stay_inside_the_major_loop(path, excursion):
    h = PrandtlIshlinskiiHysteresis()
    y = h.branch(path)[-1]
    v0 = h.input
    # any history stays inside the major loop (its branches at the same input)
    ref = PrandtlIshlinskiiHysteresis()
    ascending = ref.update(v0)
    ref.update(1.0)
    descending = ref.update(v0)
    assert ascending - 1e-12 <= y <= descending + 1e-12
    # wiping-out: a minor loop v0 -> excursion -> v0 -> excursion closes where it started
    y_first = h.update(excursion)
    h.update(v0)
    assert h.update(excursion) == pytest.approx(y_first, abs=1e-12)


def test_exponential_creep_relaxes_by_its_time_constants_and_superposes():
    c, tau = (0.01, 0.02), (0.5, 5.0)
    creep = ExponentialCreep(c, tau)
    creep.add_step(1.0, 100.0)
    for t in (1.0, 1.5, 3.0, 20.0):
        expected = 100.0 * sum(ck * (1 - math.exp(-(t - 1.0) / tk)) for ck, tk in zip(c, tau))
        assert creep.value(t) == pytest.approx(expected, rel=1e-12)
    assert creep.value(1e4) == pytest.approx(3.0)  # saturates at sum(c) of the step, unlike the log law
    creep.add_step(2.0, -50.0)
    creep.add_step(1.5, 10.0)  # a step of an earlier time registered late (the lag's increments)
    t = 4.0
    expected = sum(d * sum(ck * (1 - math.exp(-(t - tj) / tk)) for ck, tk in zip(c, tau))
                   for tj, d in ((1.0, 100.0), (2.0, -50.0), (1.5, 10.0)))
    assert creep.value(t) == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError, match="before its last step"):
        creep.value(1.9)
    with pytest.raises(ValueError):
        ExponentialCreep((0.1,), (0.0,))


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
