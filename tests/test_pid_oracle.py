"""semlab.control.PID against a control-theory oracle (python-control), and its anti-windup.

Without limits the PID is a linear time-invariant system with two inputs, the error ``e = r - m``
and the measurement ``m`` (the derivative acts on the filtered measurement only):

    I(z) = k_i z / (z - 1) E(z)                         (I_k = I_{k-1} + k_i e_k)
    M~(z) = (1 - α) z / (z - α) M(z)                    (m~_k = α m~_{k-1} + (1 - α) m_k)
    D(z) = -k_d (1 - z⁻¹) M~(z) = -k_d (1 - α)(z - 1)/(z - α) M(z)
    C(z) = [k_p + k_i z/(z - 1)] E(z) + D(z)

``PID.update`` starts its filter at the first measurement (m~_0 = m_0, no derivative kick), which is
the transfer function's zero initial state in deviations from m_0. Every update is a handful of
float operations, so the recursion and python-control's state-space simulation of the same
difference equations agree to rounding: the tolerance is 1e-9 of the signal's scale (60 steps of
an integrator accumulate ~1e-14 relative rounding per step).
"""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from semlab.control import PID

N = 60
T = np.arange(N, dtype=float)  # one sample per frame: dt = 1 frame
Z = ct.TransferFunction([1.0, 0.0], [1.0], dt=1)
# kp, ki, kd, alpha: the servo's default (I only), PI, PID with light, heavy and no filtering, PD
GAINS = [
    (0.0, 0.6, 0.0, 0.5),
    (0.4, 0.3, 0.0, 0.5),
    (1.2, 0.3, 0.8, 0.2),
    (0.5, 0.1, 2.0, 0.9),
    (0.3, 0.2, 1.5, 0.0),
    (2.0, 0.0, 0.5, 0.7),
]


def pid_transfer_functions(kp, ki, kd, alpha):
    """(C_e, D): the PID's transfer functions from the error and from the measurement."""
    c_e = kp + ki * Z / (Z - 1)
    d_m = -kd * (1 - alpha) * (Z - 1) / (Z - alpha)
    return c_e, d_m


def oracle(kp, ki, kd, alpha, setpoint, measurement):
    c_e, d_m = pid_transfer_functions(kp, ki, kd, alpha)
    m0 = measurement[0]
    from_error = ct.forced_response(c_e, T, setpoint - measurement).outputs
    from_measurement = ct.forced_response(d_m, T, measurement - m0).outputs
    return from_error + from_measurement


def run_pid(pid, setpoint, measurement):
    return np.array([pid.update(r, m) for r, m in zip(setpoint, measurement, strict=True)])


k = T
SIGNALS = {
    # name: (setpoint, measurement)
    "setpoint step": (np.where(k >= 5, 3.0, 0.0), np.zeros(N)),
    "setpoint ramp": (0.25 * k, np.full(N, 1.5)),
    "measurement step": (np.full(N, 2.0), np.where(k >= 7, 4.5, -1.0)),
    "measurement ramp": (np.full(N, 2.0), 3.0 - 0.2 * k),
    "both, sine on a ramp": (np.where(k >= 3, 10.0, 0.0), 0.1 * k + np.sin(0.4 * k)),
}


@pytest.mark.parametrize("gains", GAINS, ids=lambda g: "kp={} ki={} kd={} a={}".format(*g))
@pytest.mark.parametrize("signal", list(SIGNALS))
def test_pid_update_reproduces_its_transfer_function(gains, signal):
    kp, ki, kd, alpha = gains
    r, m = SIGNALS[signal]
    got = run_pid(PID(kp=kp, ki=ki, kd=kd, derivative_smoothing=alpha), r, m)
    want = oracle(kp, ki, kd, alpha, r, m)
    scale = max(1.0, float(np.max(np.abs(want))))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("gains", [(0.0, 0.6, 0.0, 0.5), (0.2, 0.3, 0.3, 0.5), (0.2, 0.5, 1.0, 0.8)])
def test_closed_loop_step_matches_the_oracle(gains):
    # The servo's loop: a plant of gain g with one frame of latency, m_k = g c_{k-1} (P(z) = g/z).
    # c = C_e (r - m) + D m and m = P c give c = C_e r / (1 + (C_e - D) P).
    kp, ki, kd, alpha = gains
    g = 0.9
    c_e, d_m = pid_transfer_functions(kp, ki, kd, alpha)
    plant = g / Z
    to_measurement = ct.minreal(plant * c_e / (1 + (c_e - d_m) * plant), verbose=False)
    slowest_pole = float(np.max(np.abs(to_measurement.poles())))
    assert slowest_pole < 0.8  # these gains give a stable loop: after 58 frames 0.8^58 < 1e-5
    r = np.where(T >= 2, 5.0, 0.0)
    want = ct.forced_response(to_measurement, T, r).outputs
    pid, c, got = PID(kp=kp, ki=ki, kd=kd, derivative_smoothing=alpha), 0.0, []
    for rk in r:
        m = g * c
        got.append(m)
        c = pid.update(rk, m)
    # minreal cancels the common pole/zero pairs numerically (tolerance ~1e-7 on the roots)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    # integral action: no steady-state error (the transient has decayed below 5 x 0.8^58 < 1e-4)
    assert got[-1] == pytest.approx(5.0, abs=1e-4)


def test_derivative_filter_weights_the_new_measurement_by_one_minus_alpha():
    # One measurement step of h after a still start: m~_1 = α m_0 + (1 - α)(m_0 + h), so the
    # derivative's first response is -k_d (1 - α) h and then decays by α per frame.
    alpha, h, kd = 0.8, 5.0, 2.0
    pid = PID(kp=0.0, ki=0.0, kd=kd, derivative_smoothing=alpha)
    outs = run_pid(pid, np.zeros(6), np.array([1.0, 1.0 + h, 1.0 + h, 1.0 + h, 1.0 + h, 1.0 + h]))
    expected = [0.0] + [-kd * (1 - alpha) * h * alpha ** j for j in range(5)]
    np.testing.assert_allclose(outs, expected, rtol=1e-12)


# ---------------------------------------------------------------------------------- anti-windup
def test_integral_stops_growing_at_the_output_limit_and_leaves_it_when_the_error_reverses():
    kp, ki, hi = 0.5, 0.4, 5.0
    pid = PID(kp=kp, ki=ki, output_limits=(-hi, hi))
    e = 4.0
    outs, integrals = [], []
    for _ in range(30):
        outs.append(pid.update(e, 0.0))
        integrals.append(pid.integral)
    # kp e = 2 < hi: the integral fills the remaining 3.0 (1.6 per frame: two frames) and then
    # stays at hi - kp e exactly; the output sits on the limit.
    np.testing.assert_allclose(outs[:2], [kp * e + ki * e, hi])
    np.testing.assert_allclose(integrals[1:], hi - kp * e, rtol=0, atol=1e-12)
    assert max(outs) == hi
    # The error reverses: the output leaves the limit in this very update, by exactly what the
    # linear law gives from the held integral (no wound-up reserve to unwind first).
    e_rev = -0.5
    out = pid.update(e_rev, 0.0)
    assert out == pytest.approx(kp * e_rev + (hi - kp * e) + ki * e_rev, abs=1e-12)
    assert out < hi - 1.0


def test_integral_does_not_wind_up_while_the_slew_limit_holds_the_output():
    ki, slew = 1.0, 0.5
    pid = PID(kp=0.0, ki=ki, slew_limit=slew)
    outs, integrals = [], []
    for _ in range(8):  # a large error: a free integrator would reach 8 x 10 = 80
        outs.append(pid.update(10.0, 0.0))
        integrals.append(pid.integral)
    np.testing.assert_allclose(outs, slew * np.arange(1, 9))
    # The integral never runs ahead of the output the slew limit lets through (I-only: output = I)
    assert max(integrals) <= outs[-1] + 1e-12
    # the error reverses: the output turns down in this very update, at the slew rate
    out = pid.update(-1.0, 0.0)
    assert out == pytest.approx(outs[-1] - slew)


def test_slew_limited_integral_never_moves_the_output_against_the_error():
    # Closed loop with a unit plant and one frame of latency (m_k = c_{k-1}) and an I-only PID
    # under a slew limit: while the error is positive the integrator can only push the output up,
    # so the output must rise monotonically to the setpoint (it never falls back while e > 0).
    for ki, slew in ((0.5, 1.0), (0.3, 0.5), (1.0, 2.0)):
        pid, m, outs = PID(kp=0.0, ki=ki, slew_limit=slew), 0.0, []
        for _ in range(80):
            c = pid.update(10.0, m)
            if 10.0 - m > 0 and outs:
                assert c >= outs[-1] - 1e-12, f"ki={ki} slew={slew}: output fell while the error was > 0"
            outs.append(c)
            m = c
        assert outs[-1] == pytest.approx(10.0, abs=1e-6)
        assert max(np.diff(outs)) <= slew + 1e-12


def test_back_calculation_from_downstream_limits():
    # An I-only PID whose output is cut downstream (axis limit) at 2.0: track() pulls the integral
    # back to what was applied, so it does not wind up while the limit holds ...
    pid = PID(kp=0.0, ki=1.0)
    for _ in range(10):
        pid.update(5.0, 0.0)
        pid.track(2.0)
        assert pid.integral == pytest.approx(2.0) and pid.output == 2.0
    # ... and the output leaves the limit as soon as the error reverses
    assert pid.update(-0.5, 0.0) == pytest.approx(1.5)
    # from below (a lower limit) symmetrically
    pid = PID(kp=0.0, ki=1.0)
    for _ in range(10):
        pid.update(-5.0, 0.0)
        pid.track(-2.0)
        assert pid.integral == pytest.approx(-2.0)
    assert pid.update(0.5, 0.0) == pytest.approx(-1.5)
    # an applied value the controller's own output already respects changes nothing
    pid = PID(kp=0.5, ki=0.2)
    out = pid.update(1.0, 0.0)
    before = pid.integral
    pid.track(out)
    assert pid.integral == before and pid.output == out


def test_back_calculation_accounts_for_the_proportional_and_derivative_terms():
    kp, ki, kd = 0.5, 0.3, 1.0
    pid = PID(kp=kp, ki=ki, kd=kd, derivative_smoothing=0.0)
    pid.update(0.0, 0.0)
    out = pid.update(4.0, 1.0)  # e = 3; no filtering: the derivative is -kd (1 - 0) = -1
    assert out == pytest.approx(kp * 3 + ki * 3 - kd * 1)
    pid.track(0.25)  # limited downstream: P + I + D must equal what was applied
    assert pid.integral == pytest.approx(0.25 - kp * 3 - (-1.0))
    pid2 = PID(kp=kp, ki=ki, kd=kd, derivative_smoothing=0.0)
    pid2.update(0.0, 0.0)
    pid2.update(-4.0, -1.0)
    pid2.track(-0.25)  # a lower limit (applied above the output)
    assert pid2.integral == pytest.approx(-0.25 - kp * -3 - 1.0)


def test_without_an_integrator_limits_leave_no_memory():
    # ki = 0: nothing can wind up, so saturating once must not change later outputs (a P-only
    # controller's output is clip(kp e), whatever came before).
    pid = PID(kp=10.0, ki=0.0, output_limits=(-1.0, 1.0))
    assert pid.update(1.0, 0.0) == 1.0
    assert pid.update(0.05, 0.0) == pytest.approx(0.5)
    pid.track(0.2)
    assert pid.update(0.05, 0.0) == pytest.approx(0.5)


def test_reset_is_bumpless_and_limits_are_checked():
    pid = PID(kp=0.0, ki=0.5)
    pid.reset(3.0)
    assert pid.integral == 3.0 and pid.output == 3.0
    assert pid.update(1.0, 1.0) == 3.0  # zero error: the output stays where reset put it
    pid.set_limits(-2.0, 2.0)
    assert pid.output_limits == (-2.0, 2.0)
    assert pid.update(1.0, 1.0) == 2.0
    with pytest.raises(ValueError, match="empty"):
        pid.set_limits(1.0, -1.0)
    pid.set_limits(1.0, 1.0)  # a single point is a valid (if useless) range
    for bad, msg in (({"kp": math.nan}, r"^PID gain kp=nan must be finite and >= 0$"),
                     ({"kd": -0.1}, r"^PID gain kd=-0\.1 must be finite and >= 0$"),
                     ({"ki": math.inf}, r"^PID gain ki=inf must be finite and >= 0$"),
                     ({"derivative_smoothing": 1.0}, r"^derivative_smoothing must be in \[0, 1\)$"),
                     ({"derivative_smoothing": -0.1}, r"^derivative_smoothing must be in \[0, 1\)$"),
                     ({"slew_limit": 0.0}, r"^slew_limit must be > 0$")):
        with pytest.raises(ValueError, match=msg):
            PID(**bad)
    PID(derivative_smoothing=0.0)  # the documented range [0, 1) includes 0


def test_back_calculation_keeps_the_output_equal_to_p_plus_i_plus_d():
    # With kp, kd > 0 the limits' back-calculation must subtract both other terms: the integral is
    # set so that P + I + D equals the output actually given (upper and lower limit, slew limit).
    kp, ki, kd = 0.5, 0.4, 2.0
    for limits, setpoint, meas in (((-1.0, 1.0), 5.0, (0.0, 0.5)), ((-1.0, 1.0), -5.0, (0.0, -0.5))):
        pid = PID(kp=kp, ki=ki, kd=kd, derivative_smoothing=0.0, output_limits=limits)
        pid.update(setpoint, meas[0])
        out = pid.update(setpoint, meas[1])
        p, d = kp * (setpoint - meas[1]), -kd * (meas[1] - meas[0])
        # the error keeps its sign: the output sits on that side's limit, and P + I + D equals it
        assert out == (limits[1] if setpoint > 0 else limits[0])
        assert pid.integral == pytest.approx(out - p - d, abs=1e-12)
    pid = PID(kp=kp, ki=ki, kd=kd, derivative_smoothing=0.0, slew_limit=0.25)
    pid.update(5.0, 0.0)
    out = pid.update(5.0, 0.5)
    assert out == pytest.approx(0.5)  # two slew-limited steps of 0.25
    assert pid.integral == pytest.approx(out - kp * 4.5 - (-kd * 0.5), abs=1e-12)


def test_tracking_right_after_a_reset_concerns_the_integral_alone():
    # no update yet: no proportional or derivative term, so the applied value is the integral
    pid = PID(kp=0.7, ki=0.5, kd=1.0)
    pid.reset(2.0)
    pid.track(1.25)
    assert pid.integral == 1.25 and pid.output == 1.25
    pid.reset(-2.0)
    pid.track(-1.0)
    assert pid.integral == -1.0
