"""Piezo ground truth: Preisach hysteresis, creep, lag and DAC quantisation; the alternative family
(Prandtl-Ishlinskii plays with a static output nonlinearity, Kelvin-Voigt creep)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semlab.sim import (
    DAC,
    ExponentialCreep,
    LogCreep,
    PiezoParameters,
    PrandtlIshlinskiiHysteresis,
    PreisachHysteresis,
)
from semlab.sim.manipulator import AXES
from semlab.sim.piezo import PiezoAxis
from semlab.sim.rig import alternative_hysteresis, default_hysteresis

V = np.linspace(0.0, 1.0, 501)


def _major_loop(h):
    h.reset()
    up = h.branch(V)
    down = h.branch(V[::-1])[::-1]
    return up, down


@pytest.mark.parametrize("family", [default_hysteresis, alternative_hysteresis], ids=["preisach", "pi"])
@pytest.mark.parametrize("m", range(4))
@pytest.mark.parametrize("axis", AXES)
def test_major_loop_width_is_10_to_15_percent(m, axis, family):
    h = family(m, axis)
    up, down = _major_loop(h)
    assert up[0] == pytest.approx(0.0) and up[-1] == pytest.approx(1.0)
    assert down[0] == pytest.approx(0.0) and down[-1] == pytest.approx(1.0)
    width = np.max(down - up) / (up[-1] - up[0])
    assert 0.10 <= width <= 0.15
    assert np.all(np.diff(up) > 0) and np.all(np.diff(down) > 0)  # monotone branches


def test_loop_is_asymmetric_so_not_prandtl_ishlinskii():
    # a (symmetric) PI loop satisfies down(v) = 1 - up(1 - v); the ground truth must not
    up, down = _major_loop(PreisachHysteresis())
    asym = np.max(np.abs(down - (1 - up[::-1])))
    assert asym > 0.02


def test_minor_loops_close_and_lie_inside_the_major_loop():
    h = PreisachHysteresis()
    up, down = _major_loop(h)
    h.reset()
    h.update(0.8)
    y_a = h.update(0.3)  # reversal at 0.3 on the way down from 0.8
    path_up = np.linspace(0.3, 0.7, 41)
    inner_up = h.branch(path_up)
    inner_down = h.branch(path_up[::-1])
    y_back = h.output()
    # return-point memory: going back to 0.3 closes the minor loop exactly
    assert y_back == pytest.approx(y_a, abs=1e-12)
    # and the minor loop is inside the major loop
    lo = np.interp(path_up, V, up)
    hi = np.interp(path_up, V, down)
    assert np.all(inner_up >= lo - 1e-9) and np.all(inner_up <= hi + 1e-9)
    assert np.all(inner_down[::-1] >= lo - 1e-9) and np.all(inner_down[::-1] <= hi + 1e-9)
    # a larger excursion wipes the minor loop out: back on the major ascending branch
    h.update(0.95)
    h.update(0.2)
    h.update(0.0)
    assert h.memory == (0.0,)
    assert h.update(0.5) == pytest.approx(np.interp(0.5, V, up), abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30))
def test_any_history_stays_inside_the_major_loop(path):
    h = PreisachHysteresis()
    lo, hi = PreisachHysteresis(), PreisachHysteresis()
    for v in path:
        y = h.update(v)
        lo.reset()
        hi.reset()
        hi.update(1.0)
        assert lo.update(v) - 1e-12 <= y <= hi.update(v) + 1e-12
        # the memory stack alternates and shrinks towards the current input
        mem = h.memory
        assert mem[0] == 0.0 and len(mem) <= 2 * len(path) + 1


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 0.999), st.floats(1e-9, 1e-3), st.booleans())
def test_output_is_continuous_for_tiny_steps(v, dv, down_first):
    h = PreisachHysteresis()
    h.update(1.0 if down_first else 0.0)
    y0 = h.update(v)
    y1 = h.update(min(v + dv, 1.0))
    # the slope of the loop is bounded (< 3 per unit input for the default weights)
    assert abs(y1 - y0) <= 3.0 * dv + 1e-12


def test_creep_grows_linearly_in_log_time():
    p = PiezoParameters(lag_s=0.0, creep_per_decade=0.015, creep_t0_s=0.1)
    ax = PiezoAxis(50_000.0, 0.0, 100.0, params=p)
    ax.set_target(50.0, 0.0)
    t = np.logspace(0, 3, 13)  # 1 s .. 1000 s
    x = np.array([ax.position_nm(ti) for ti in t])
    step = x[0] - ax.creep.value(1.0)  # the hysteresis part of the step
    slope, _ = np.polyfit(np.log10(t), x, 1)
    # x = step (1 + gamma log10(1 + t / t0)): slope gamma * step per decade for t >> t0
    assert slope == pytest.approx(0.015 * step, rel=0.03)
    resid = x - np.polyval(np.polyfit(np.log10(t), x, 1), np.log10(t))
    assert np.max(np.abs(resid)) < 0.01 * 0.015 * step * 3


def test_creep_superposes_per_step_and_memory_is_bounded():
    c = LogCreep(gamma=0.02, t0=0.1, memory=4)
    c.add_step(0.0, 100.0)
    c.add_step(1.0, -100.0)
    # a step and its undo: creep decays back towards zero as log((t + t0) / (t - 1 + t0))
    expect = 100 * 0.02 * (math.log10(1 + 10 / 0.1) - math.log10(1 + 9 / 0.1))
    assert c.value(10.0) == pytest.approx(expect)
    for k in range(10):
        c.add_step(2.0 + k, 1.0)
    assert len(c._events) == 4


def test_first_order_lag():
    p = PiezoParameters(lag_s=0.004, creep_per_decade=0.0, hysteresis=False)
    ax = PiezoAxis(10_000.0, 0.0, 100.0, params=p)
    ax.set_target(40.0, 1.0)
    for dt in (0.001, 0.004, 0.01, 0.0385):
        assert ax.position_nm(1.0 + dt) == pytest.approx(4000.0 * (1 - math.exp(-dt / 0.004)), rel=1e-9)


@pytest.mark.parametrize("bits", [12, 16])
def test_dac_step_is_range_over_2_to_the_bits(bits):
    dac = DAC(bits, 0.0, 100.0)
    assert dac.lsb == pytest.approx(100.0 / 2**bits)
    v = np.linspace(0.0, 100.0, 1001)
    q = np.array([dac.quantise(x) for x in v])
    assert np.max(np.abs(q - v)[v < 100 - dac.lsb]) <= dac.lsb / 2 + 1e-12
    # a sweep finer than the LSB sees every code: the steps are exactly one LSB
    fine = np.arange(40.0, 40.0 + 50 * dac.lsb, dac.lsb / 7)
    steps = np.diff(np.unique([dac.quantise(x) for x in fine]))
    np.testing.assert_allclose(steps, dac.lsb, rtol=1e-9)
    assert dac.quantise(100.0) == pytest.approx(100.0 - dac.lsb)


def test_bad_piezo_parameters_raise():
    with pytest.raises(ValueError):
        PreisachHysteresis(lambdas=(-1.0,), weights=(1.0,))
    with pytest.raises(ValueError):
        PreisachHysteresis().update(1.5)
    with pytest.raises(ValueError):
        PiezoParameters(lag_s=-1.0)
    with pytest.raises(ValueError):
        DAC(0, 0.0, 1.0)


# the alternative family


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
