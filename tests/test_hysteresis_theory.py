"""semlab.hysteresis against closed forms: the play operator's recursion, the PI model as a weighted
sum of plays, the Krejci-Kuhnen inverse's parameters, the Newton-Raphson root finder's convergence
order, the logarithmic creep superposition, and the exact characterisation path.

(tests/test_hysteresis.py holds eq. 11, the inverses' round trips and the fits; this file adds
what those leave open.)
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from semlab.hysteresis import (
    CreepModel,
    PIHysteresis,
    PolynomialHysteresis,
    _newton_bisect,
    axis_identity,
    characterisation_voltages,
    fit_creep,
    label_branches,
    play_operator,
)

U0, UN = 0.0, 100.0
P_COEF = [0.0, 55.0, 45.0, -15.0, 5.0]
D_COEF = [0.0, 125.0, -45.0, 15.0, -5.0]


def poly_model(**kw):
    return PolynomialHysteresis(P_COEF, D_COEF, (U0, UN), axis="m0.x", **kw)


# ------------------------------------------------------------------------------- play operator
def play_reference(u, r, z):
    out = []
    for uk in u:
        z = max(uk - r, min(uk + r, z))
        out.append(z)
    return np.array(out)


def test_play_operator_is_the_backlash_recursion():
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(0, 1, 50))
    for r in (0.0, 0.3, 2.0):
        np.testing.assert_allclose(play_operator(u, r, z0=0.7), play_reference(u, r, 0.7))
        np.testing.assert_allclose(play_operator(u, r), play_reference(u, r, u[0]))  # default z0 = u[0]
    np.testing.assert_array_equal(play_operator([1, 2, 3], 0.0), [1.0, 2.0, 3.0])  # integers become floats
    assert play_operator([1, 2], 0.0).dtype == np.float64
    with pytest.raises(ValueError, match=r"^play operator threshold r=-0\.5 must be >= 0$"):
        play_operator(u, -0.5)


# ------------------------------------------------------------------------------- the path
def test_characterisation_path_is_exact():
    plan = characterisation_voltages(10.0, 50.0, 4, inner_loops=False)
    np.testing.assert_allclose(plan["u"], [10, 20, 30, 40, 50, 40, 30, 20, 10])
    assert list(plan["segment"]) == [0, 0, 0, 0, 0, 1, 1, 1, 1]
    assert list(plan["step"]) == list(range(9))
    assert list(plan["branch"]) == ["ascending"] * 5 + ["descending"] * 4
    custom = characterisation_voltages(0.0, 100.0, 4, inner_loops=[0.5, 0.25])
    np.testing.assert_allclose(custom["u"], [0, 25, 50, 75, 100, 75, 50, 25, 0, 25, 50, 25])
    assert list(custom["segment"][-3:]) == [2, 2, 3]
    assert list(custom["branch"][-3:]) == ["ascending", "ascending", "inner_descending"]
    # a turning point closer than one step still gets one increment
    tiny = characterisation_voltages(0.0, 100.0, 4, inner_loops=[0.05])
    np.testing.assert_allclose(tiny["u"].iloc[-1], 5.0)
    assert len(characterisation_voltages(0.0, 1.0, 2, inner_loops=None)) == 5
    with pytest.raises(ValueError, match=r"^u_min=5\.0 must be below u_max=5\.0$"):
        characterisation_voltages(5.0, 5.0)
    with pytest.raises(ValueError, match=r"^n_steps=1: at least 2 increments per branch are needed$"):
        characterisation_voltages(0.0, 1.0, 1)
    with pytest.raises(ValueError, match=r"^inner-loop turning points must be fractions in \[0, 1\]"):
        characterisation_voltages(0.0, 1.0, 4, inner_loops=[1.2])
    characterisation_voltages(0.0, 1.0, 2)  # two increments are enough


def test_label_branches_follows_the_wiping_out_rule():
    labels = label_branches([0, 40, 80, 60, 70, 90, 100, 50, 20, 35, 10, 0], 0.0, 100.0)
    assert labels == ["ascending", "ascending", "ascending", "inner_descending", "inner_ascending",
                      "ascending",  # passing 80 closed the 80-60 loop
                      "ascending", "descending", "descending", "inner_ascending",
                      "descending",  # passing 20 on the way down closed the 20-35 loop
                      "descending"]
    # repeated voltages keep the label; the ends of the range wipe out everything
    assert label_branches([50, 50, 30, 30, 0, 10], 0.0, 100.0) == [
        "ascending", "ascending", "inner_descending", "inner_descending", "descending", "ascending"]


# ------------------------------------------------------------------------------- the models' interface
def test_model_geometry_direction_and_range():
    m = PolynomialHysteresis(P_COEF, D_COEF, (10.0, 60.0), direction=(3.0, -4.0), axis="a")
    assert m.direction == pytest.approx((0.6, -0.8))
    assert m.displacement_range == (pytest.approx(0.0), pytest.approx(90.0))
    assert m.gain == pytest.approx(90.0 / 50.0)
    assert m.state.u == 10.0 and m.state.rising and m.state.reversals == []
    with pytest.raises(ValueError, match=r"^model voltage range \(5\.0, 5\.0\) is empty$"):
        PolynomialHysteresis(P_COEF, D_COEF, (5.0, 5.0))
    with pytest.raises(ValueError, match=r"^model range bound nan is not finite"):
        PolynomialHysteresis(P_COEF, D_COEF, (float("nan"), 1.0))
    for d in ((0.0, 0.0), (1.0, float("nan")), (1.0, 0.0, 0.0)):
        with pytest.raises(ValueError, match=r"must be a non-zero 2-vector$"):
            PolynomialHysteresis(P_COEF, D_COEF, (U0, UN), direction=d)
    with pytest.raises(ValueError, match=r"^ascending branch does not rise over the range"):
        PolynomialHysteresis([5.0, -1.0], D_COEF, (U0, UN))
    assert repr(m) == ("<PolynomialHysteresis axis='a' u=10..60 V displacement=0..90 px "
                       "direction=(0.600, -0.800)>")


def test_axis_identity():
    assert axis_identity("m1.y") == "m1.y"
    assert axis_identity(type("A", (), {"name": "stage x"})()) == "stage x"
    assert axis_identity(type("A", (), {"id": 7})()) == "7"
    assert axis_identity(type("A", (), {"label": "L", "name": None})()) == "L"
    method = type("A", (), {"name": lambda self: "no", "label": "yes"})()
    assert axis_identity(method) == "yes"  # a method called name is not a name
    anon = type("Anon", (), {})()
    assert axis_identity(anon) == f"Anon@{id(anon):x}"
    m = poly_model()
    m.check_axis("m0.x")
    with pytest.raises(ValueError, match=r"^this polynomial hysteresis model was fitted on axis 'm0\.x', not on 'm1\.x'"):
        m.check_axis("m1.x")


def test_voltages_and_targets_beyond_the_range_are_extrapolated_and_nan_is_refused():
    # the characterised range limits what the model knows, not where the axis may go (issue 16): beyond
    # it the branches continue as one line, 1.25 times the loop's steepest slope, continuous at the ends
    m = poly_model()
    slope = m.extrapolation_slopes[1]
    assert m.forward(UN + 1e-8) == pytest.approx(m.ascending(UN))
    assert m.forward(UN + 1e-3) == pytest.approx(m.ascending(UN) + 1e-3 * slope)
    assert m.state.u == UN + 1e-3
    m.reset()
    assert m.forward(U0 - 1e-3) == pytest.approx(-1e-3 * m.extrapolation_slopes[0])
    m.reset()
    hi = m.displacement_range[1]
    assert m.inverse(hi) == pytest.approx(UN)
    assert m.inverse(90.1) == pytest.approx(UN + (90.1 - hi) / slope)
    with pytest.raises(ValueError, match="target displacement"):
        m.inverse(float("nan"))
    with pytest.raises(ValueError, match="voltage"):
        m.forward(float("nan"))


def test_displacement_peeks_and_predict_copies():
    m = poly_model()
    m.forward([60.0, 30.0])
    state = (m.state.u, m.state.y, list(m.state.reversals))
    peek = m.displacement(45.0)
    assert (m.state.u, m.state.y, list(m.state.reversals)) == state  # not committed
    assert m.forward(45.0) == peek
    m.reset()
    m.forward([60.0, 30.0])
    cont = m.predict([45.0], reset=False)
    fresh = m.predict([45.0])  # from U0 after a descent: the major ascending branch
    from_desc = m.predict([45.0], reset=(100.0, "descending"))
    assert cont[0] == pytest.approx(peek) and fresh[0] == pytest.approx(m.ascending(45.0))
    assert from_desc[0] == pytest.approx(m.descending(45.0))
    assert (m.state.u, m.state.y) == state[:2]  # predict never touches the model
    c = m.copy()
    c.forward(90.0)
    assert m.state.u == 30.0 and c.state.u == 90.0
    assert isinstance(m.forward(np.float64(50.0)), float) and m.forward([50.0, 55.0]).shape == (2,)


def test_polynomial_branches_and_their_derivatives_in_volts():
    m = PolynomialHysteresis(P_COEF, D_COEF, (20.0, 70.0))
    u = np.array([20.0, 33.0, 70.0])
    s = (u - 20.0) / 50.0
    P, D = np.polynomial.Polynomial(P_COEF), np.polynomial.Polynomial(D_COEF)
    np.testing.assert_allclose(m.ascending(u), P(s))
    np.testing.assert_allclose(m.descending(u), D(s))
    np.testing.assert_allclose(m.ascending(u, deriv=1), P.deriv()(s) / 50.0)
    np.testing.assert_allclose(m.descending(u, deriv=1), D.deriv()(s) / 50.0)


def test_a_move_below_the_resolution_is_no_move():
    m = poly_model()
    m.forward([60.0, 40.0])
    before = m.state
    m.forward(40.0 + 1e-12)  # 1e-14 of the range: below the model's 1e-12 resolution
    assert m.state is before
    m.forward(40.0 + 1e-6)
    assert m.state.reversals == [(60.0, pytest.approx(m.ascending(60.0)))] + [(40.0, before.y)]


# ------------------------------------------------------------------------------- PI model
WEIGHTS = np.array([0.9, 0.3, 0.2, 0.0, 0.1])


def test_pi_forward_is_the_weighted_sum_of_plays_on_the_shaped_input():
    a, c = 0.3, -2.0
    m = PIHysteresis(WEIGHTS, c, (U0, UN), shape=a)
    r = np.arange(5) / 10.0  # r_i = i / (2n)
    np.testing.assert_allclose(m.thresholds, r)
    path = np.array([0.0, 30.0, 80.0, 50.0, 65.0, 10.0, 100.0, 40.0])
    s = path / 100.0
    v = s + a * s * (1 - s)
    want = sum(w * play_operator(v, ri, z0=ri) for w, ri in zip(WEIGHTS, r, strict=True)) + c
    np.testing.assert_allclose(m.predict(path), want, atol=1e-12)
    np.testing.assert_allclose(m.design_matrix(path) @ WEIGHTS + c, want, atol=1e-12)
    # after a rise to Un every play sits at 1 - r
    np.testing.assert_allclose(m.design_matrix([100.0, 60.0], start_rising=True)[1],
                               np.minimum(0.6 + a * 0.6 * 0.4 + r, 1 - r))
    assert m.displacement_range == (pytest.approx(WEIGHTS @ r + c), pytest.approx(WEIGHTS @ np.maximum(1 - r, r) + c))


def test_pi_inverse_parameters_are_krejci_kuhnen():
    m = PIHysteresis(WEIGHTS, 0.0, (U0, UN))
    r, w, W = m.thresholds, WEIGHTS, np.cumsum(WEIGHTS)
    np.testing.assert_allclose(m.inv_thresholds, [np.sum(w[: i + 1] * (r[i] - r[: i + 1])) for i in range(5)])
    np.testing.assert_allclose(m.inv_weights, [1 / w[0]] + [-w[i] / (W[i] * W[i - 1]) for i in range(1, 5)])


@pytest.mark.parametrize("a", [-0.6, 0.0, 0.45])
def test_pi_inverse_undoes_the_input_shaping_exactly(a):
    m = PIHysteresis(WEIGHTS, 1.5, (10.0, 60.0), shape=a)
    m.forward([50.0, 20.0, 35.0])
    for target in np.linspace(*m.displacement_range, 11):
        u = m.inverse(target)
        assert 10.0 <= u <= 60.0
        assert m.displacement(u) == pytest.approx(target, abs=1e-9)


def test_pi_model_refuses_parameters_without_an_inverse():
    for w, msg in (([], "non-empty"), ([[1.0]], "non-empty"), ([1.0, np.nan], "finite"),
                   ([0.0, 1.0], r"w\[0\] > 0"), ([1.0, -0.1], "non-negative")):
        with pytest.raises(ValueError, match=msg):
            PIHysteresis(w, 0.0, (U0, UN))
    for a in (1.0, -1.0):
        with pytest.raises(ValueError, match=r"^input shaping a=.* must satisfy \|a\| < 1"):
            PIHysteresis([1.0], 0.0, (U0, UN), shape=a)


# ------------------------------------------------------------------------------- Newton-Raphson
def test_newton_bisect_converges_quadratically_and_keeps_to_the_bracket():
    calls = []

    def f(x):  # increasing, f'(0) = 0 (a flat point: Newton's step is undefined there)
        calls.append(x)
        return x ** 3 + x * abs(x), 3 * x * x + 2 * abs(x)

    for target in (-5.0, 0.3, 7.0):
        calls.clear()
        x = _newton_bisect(f, -3.0, 3.0, target, xtol=1e-12)
        assert abs(f(x)[0] - target) < 1e-9
        # Newton from a secant start: a handful of evaluations, where bisection would need
        # log2(6 / 1e-12) ≈ 43
        assert len(calls) <= 12, len(calls)
        assert all(-3.0 <= c <= 3.0 for c in calls)
    # targets at or beyond the bracket's ends return the end itself (f(lo) >= target, f(hi) <= target)
    assert _newton_bisect(f, -1.0, 2.0, f(-1.0)[0], xtol=1e-12) == -1.0
    assert _newton_bisect(f, -1.0, 2.0, f(2.0)[0], xtol=1e-12) == 2.0
    assert _newton_bisect(f, -1.0, 2.0, -50.0, xtol=1e-12) == -1.0
    assert _newton_bisect(f, -1.0, 2.0, 50.0, xtol=1e-12) == 2.0
    # a zero slope at the iterate falls back to bisection and still converges
    x = _newton_bisect(lambda x: (x ** 3, 0.0 * x), -1.0, 2.0, 0.125, xtol=1e-12)
    assert x == pytest.approx(0.5, abs=1e-9)


def test_polynomial_inverse_reaches_1e_10_of_the_range():
    m = poly_model()
    m.forward([70.0, 20.0, 55.0])
    for target in np.linspace(1.0, 89.0, 9):
        u = m.inverse(target)
        assert m.displacement(u) == pytest.approx(target, abs=1e-8)  # xtol = 1e-10 of the range
    assert m.inverse(m.state.y) == m.state.u  # the current displacement: no move


# ------------------------------------------------------------------------------- creep
def test_creep_superposes_steps_and_freezes_the_oldest():
    g, t0 = 0.02, 0.1
    c = CreepModel(g, t0=t0, memory=2)

    def law(dt):
        return g * math.log10(1 + dt / t0)

    c.record(0.0, 10.0)
    c.record(0.0, 5.0)  # same time: one step of 15
    c.record(0.5, 0.0)  # no step: nothing recorded
    assert c.predict(1.0) == pytest.approx(15 * law(1.0))
    assert c.predict(0.0) == 0.0  # at the step's own time: nothing yet (t > t_j)
    c.record(1.0, -4.0)
    c.record(2.0, 3.0)  # a third step with memory 2: the first is frozen at its value at t = 2
    frozen = 15 * law(2.0)
    assert c.predict(3.0) == pytest.approx(frozen - 4 * law(2.0) + 3 * law(1.0))
    assert c.predict(3.0, extra=(2.5, 1.0)) == pytest.approx(frozen - 4 * law(2.0) + 3 * law(1.0) + law(0.5))
    assert c.predict(3.0) == pytest.approx(frozen - 4 * law(2.0) + 3 * law(1.0))  # extra is not kept
    c.reset()
    assert c.predict(10.0) == 0.0
    assert repr(CreepModel(0.015, 0.1)) == "<CreepModel gamma=0.015/decade t0=0.1 s>"
    for bad in ({"gamma": -0.1}, {"gamma": 0.1, "t0": 0.0}, {"gamma": 0.1, "memory": 0}):
        with pytest.raises(ValueError, match=r"^creep model needs gamma >= 0, t0 > 0 and memory >= 1$"):
            CreepModel(**bad)


def test_fit_creep_is_least_squares_with_a_free_offset():
    t = (np.arange(1, 31) - 0.5) / 13
    y = 50.0 + 40.0 * 0.012 * np.log10(1 + t / 0.2)  # noise-free, t0 = 0.2
    fit = fit_creep(t, y, 40.0, t0_grid=[0.1, 0.2, 0.4])
    assert fit.t0 == 0.2 and fit.gamma == pytest.approx(0.012, rel=1e-9)
    default = fit_creep(t, y, 40.0)
    assert default.t0 == 0.1  # only the reference time by default
    # NaNs and non-positive times are ignored; a creep against the step is clipped at gamma = 0
    y_nan = y.copy()
    y_nan[::3] = np.nan
    assert fit_creep(np.r_[-1.0, 0.0, t], np.r_[0.0, 0.0, y_nan], 40.0, t0_grid=[0.2]).gamma == pytest.approx(0.012)
    assert fit_creep(t, -y, 40.0).gamma == 0.0
    with pytest.raises(ValueError, match=r"^a creep fit needs a non-zero step and at least 4 valid samples"):
        fit_creep(t, y, 0.0)
    with pytest.raises(ValueError, match="at least 4 valid samples"):
        fit_creep(t[:4], np.r_[y[:3], np.nan], 40.0)
