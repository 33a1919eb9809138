"""fit_hysteresis against independent solutions: the polynomial fit is the equality-constrained least
squares of the paper's P_n, D_n (solved here through its KKT system), the PI fit recovers the
parameters of a PI world exactly, the fitted-branch monotonicity rule refuses what it says it refuses.

The range does not start at 0 V on purpose: the fits normalise s = (u - U0) / (Un - U0), and a fit
that forgot U0 would pass every test on a 0-based range.
"""

from __future__ import annotations

import numpy as np
import pytest

from semlab.experiments import characterisation_voltages
from semlab.hysteresis import PIHysteresis, PolynomialHysteresis, fit_hysteresis

U0, UN = -20.0, 40.0
SPAN = UN - U0
# a closed, asymmetric loop in s: P(0) = D(0) = 0, P(1) = D(1) = 90, both rising
P_COEF = [0.0, 55.0, 45.0, -15.0, 5.0]
D_COEF = [0.0, 125.0, -45.0, 15.0, -5.0]
# exact data in the model family: a least-squares fit reproduces it up to rounding (the scaled
# Vandermonde matrices of order <= 4 on [0, 1] have condition numbers ~1e3, times eps ~1e-16)
EXACT_ATOL = 1e-8


def characterisation(displacement_of, *, n_steps=20, attrs=True):
    """A characterisation plan on [U0, Un] with the displacement of a model (or function) of u."""
    plan = characterisation_voltages(U0, UN, n_steps)
    u = plan["u"].to_numpy()
    y = displacement_of.predict(u) if hasattr(displacement_of, "predict") else displacement_of(u)
    char = plan.assign(displacement=y, ok=True)
    if attrs:
        char.attrs.update(axis="m0.x", direction=(1.0, 0.0), u_min=U0, u_max=UN)
    return char


def constrained_lstsq(char, order):
    """The paper's fit by another route: minimise |A c - b|^2 over both branches' coefficients subject
    to P(U0) = D(U0), P(Un) = D(Un), through the KKT system (not the fit's null-space method)."""
    n = order + 1
    keep = char["ok"].to_numpy(bool) & np.isfinite(char["displacement"].to_numpy(float))
    rows = []
    for k, label in enumerate(("ascending", "descending")):
        sel = keep & (char["branch"].to_numpy() == label)
        s = (char["u"].to_numpy(float)[sel] - U0) / SPAN
        block = np.zeros((s.size, 2 * n))
        block[:, k * n:(k + 1) * n] = s[:, None] ** np.arange(n)
        rows.append((block, char["displacement"].to_numpy(float)[sel]))
    A = np.vstack([r[0] for r in rows])
    b = np.concatenate([r[1] for r in rows])
    C = np.zeros((2, 2 * n))
    C[0, 0], C[0, n] = 1.0, -1.0  # s = 0: only the constant terms
    C[1, :n], C[1, n:] = 1.0, -1.0  # s = 1: the sums of the coefficients
    kkt = np.block([[2 * A.T @ A, C.T], [C, np.zeros((2, 2))]])
    sol = np.linalg.solve(kkt, np.concatenate([2 * A.T @ b, np.zeros(2)]))
    return sol[:n], sol[n:2 * n]


def test_exact_polynomial_loop_on_a_range_that_does_not_start_at_zero():
    truth = PolynomialHysteresis(P_COEF, D_COEF, (U0, UN), axis="m0.x")
    m = fit_hysteresis(characterisation(truth))
    us = np.linspace(U0, UN, 13)
    np.testing.assert_allclose(m.ascending(us), truth.ascending(us), atol=EXACT_ATOL)
    np.testing.assert_allclose(m.descending(us), truth.descending(us), atol=EXACT_ATOL)
    assert m.u_range == (U0, UN)
    assert m.gain == pytest.approx(90.0 / SPAN, rel=1e-12)  # (P(1) - P(0)) / (Un - U0)


@pytest.mark.parametrize("order", [2, 3, 4])
def test_polynomial_fit_is_the_constrained_least_squares(order):
    """On noisy data from a piezo outside the family, with lost and NaN rows: the fit is the unique
    minimiser, so it matches the KKT solution up to rounding (tolerance: cond(KKT) ~1e6 on these
    normal equations times eps, on displacements of ~100 px -> 1e-7 px)."""
    rng = np.random.default_rng(3)

    def piezo(u):
        s = (u - U0) / SPAN
        return 90.0 * s + 8.0 * np.sin(3.0 * s) * s * (1 - s) + rng.normal(0.0, 0.3, u.size)

    char = characterisation(piezo)
    lost = np.arange(3, len(char), 9)
    char.loc[lost, "ok"] = False
    char.loc[lost, "displacement"] = 1e4  # garbage where the tracker had lost the probe
    char.loc[[5, 30], "displacement"] = np.nan  # not flagged, but not a number either
    m = fit_hysteresis(char, order=order)
    p, d = constrained_lstsq(char, order)
    s = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(m.ascending(U0 + s * SPAN), np.polynomial.polynomial.polyval(s, p), atol=1e-7)
    np.testing.assert_allclose(m.descending(U0 + s * SPAN), np.polynomial.polynomial.polyval(s, d), atol=1e-7)
    # the residual figures are over the valid rows only (the fitted model replayed over the path)
    res = char["displacement"].to_numpy(float) - m.predict(char["u"].to_numpy(float), reset=True)
    good = char["ok"].to_numpy(bool) & np.isfinite(res)
    assert m.meta["rms_residual_px"] == pytest.approx(np.sqrt(np.mean(res[good] ** 2)), rel=1e-9)
    inner = good & char["branch"].str.startswith("inner").to_numpy()
    assert m.meta["rms_residual_inner_px"] == pytest.approx(np.sqrt(np.mean(res[inner] ** 2)), rel=1e-9)
    assert m.meta["n_points"] == int((good & ~char["branch"].str.startswith("inner").to_numpy()).sum())


def dip(k, g=600.0):
    """P(s) = g (s - 2k s^2 + 4k/3 s^3): slope g (1 - 4k s(1-s)) per unit s, least at s = 1/2 (u = 10 V):
    g (1 - k) / SPAN px/V, against the loop's mean slope (gain) g (1 - 2k/3) / SPAN px/V."""
    return [0.0, g, -2.0 * k * g, 4.0 * k * g / 3.0]


def min_slope_over_gain(k):
    return (1.0 - k) / (1.0 - 2.0 * k / 3.0)


@pytest.mark.parametrize("branch", ["ascending", "descending"])
def test_a_fitted_branch_falling_by_more_than_5_percent_of_the_gain_is_refused(branch):
    # k = 1.1: the branch falls at 0.375 x the gain near u = 10 V (beyond the 5 % allowance: refused)
    assert min_slope_over_gain(1.1) == pytest.approx(-0.375)
    coef = dip(1.1)
    line = [0.0, float(np.sum(coef))]  # a straight branch that closes the loop at both ends
    asc, desc = (coef, line) if branch == "ascending" else (line, coef)
    truth = PolynomialHysteresis(asc, desc, (U0, UN), axis="m0.x")
    with pytest.raises(ValueError, match=rf"fitted {branch} branch falls near u=10 V \(slope -1 px/V\)"):
        fit_hysteresis(characterisation(truth))


def test_a_fitted_branch_falling_within_5_percent_of_the_gain_is_kept():
    # k = 1.01: falls at 0.031 x the gain (3.3 px/V), i.e. -0.1 px/V: within the allowance, kept as fitted
    assert min_slope_over_gain(1.01) == pytest.approx(-0.0306, abs=1e-4)
    truth = PolynomialHysteresis(dip(1.01), dip(1.01), (U0, UN), axis="m0.x")
    m = fit_hysteresis(characterisation(truth))
    us = np.linspace(U0, UN, 13)
    np.testing.assert_allclose(m.ascending(us), truth.ascending(us), atol=EXACT_ATOL)
    assert m.ascending(10.0, deriv=1) == pytest.approx(-0.1, abs=1e-9)


# ---------------------------------------------------------------------------------------------
# Prandtl-Ishlinskii
# ---------------------------------------------------------------------------------------------

# weights with zeros inside (allowed: w >= 0) and w0 > 0 (required for the inverse)
PI_WEIGHTS = np.array([40.0, 10.0, 0.0, 25.0, 5.0, 0.0, 15.0, 8.0, 3.0, 6.0])
PI_OFFSET = -7.5
# exact data: lsq_linear stops when the cost changes by < 1e-10 relative; near a quadratic minimum the
# parameters are then within ~sqrt(1e-10) = 1e-5 of their scale (sum(w) = 112 px): 1e-3 px
PI_ATOL = 1e-3


@pytest.mark.parametrize("shape", [0.0, 0.4, -0.3])
def test_pi_fit_recovers_the_weights_offset_of_a_pi_world(shape):
    truth = PIHysteresis(PI_WEIGHTS, PI_OFFSET, (U0, UN), shape=shape, axis="m0.x")
    truth.reset(U0, "descending")
    m = fit_hysteresis(characterisation(truth), kind="pi", n_operators=PI_WEIGHTS.size, shape=shape)
    np.testing.assert_allclose(m.weights, PI_WEIGHTS, atol=PI_ATOL)
    assert m.offset == pytest.approx(PI_OFFSET, abs=PI_ATOL)
    assert m.shape == shape and m.u_range == (U0, UN)
    assert m.meta["rms_residual_px"] < PI_ATOL


def test_pi_fit_finds_the_input_shaping_when_not_given():
    """shape=None: a bounded 1-D search (xatol 1e-3) over a, so a is found to ~1e-3 and the loop is
    reproduced to the error of that a: dy/da <= sum(w) * max s(1-s) = 112 px * 1/4 per unit a."""
    truth = PIHysteresis(PI_WEIGHTS, PI_OFFSET, (U0, UN), shape=0.4, axis="m0.x")
    char = characterisation(truth)
    m = fit_hysteresis(char, kind="pi", n_operators=PI_WEIGHTS.size)
    assert m.shape == pytest.approx(0.4, abs=2e-3)
    u = char["u"].to_numpy()
    np.testing.assert_allclose(m.predict(u), truth.predict(u), atol=112.0 * 0.25 * 2e-3)


def test_pi_fit_keeps_a_as_zero_when_shaping_does_not_help():
    """A loop with no lean (a = 0) is fitted with a = 0 exactly: the search's best is kept only if it
    is no worse than a = 0."""
    truth = PIHysteresis(PI_WEIGHTS, PI_OFFSET, (U0, UN), shape=0.0, axis="m0.x")
    m = fit_hysteresis(characterisation(truth), kind="pi", n_operators=PI_WEIGHTS.size)
    assert abs(m.shape) < 2e-3
    np.testing.assert_allclose(m.weights, PI_WEIGHTS, atol=112.0 * 2e-3)


def test_pi_with_one_operator_is_a_straight_line():
    # one play with threshold 0 is the identity: y = w0 v + c, a line through the (unshaped) input
    char = characterisation(lambda u: 3.0 * (u - U0) + 2.0)
    m = fit_hysteresis(char, kind="pi", n_operators=1, shape=0.0)
    assert m.weights == pytest.approx([3.0 * SPAN], rel=1e-9)
    assert m.offset == pytest.approx(2.0, abs=1e-6)


def test_pi_bad_operator_counts_and_too_few_points():
    char = characterisation(lambda u: 3.0 * (u - U0))
    with pytest.raises(ValueError, match="n_operators must be >= 1"):
        fit_hysteresis(char, kind="pi", n_operators=0)
    # n operators and an offset need n + 2 valid rows (one more than the unknowns): keep 5 rows of each
    # major branch (the least a 4th-order check of the branches accepts), 10 in all
    few = char.copy()
    few.attrs = dict(char.attrs)
    keep = np.concatenate([few.index[few["branch"] == b][:5] for b in ("ascending", "descending")])
    few["ok"] = few.index.isin(keep)
    with pytest.raises(ValueError, match=r"too few valid points \(10\) for a PI model with 9 operators"):
        fit_hysteresis(few, kind="pi", n_operators=9, shape=0.0)
    assert fit_hysteresis(few, kind="pi", n_operators=8, shape=0.0).kind == "pi"


@pytest.mark.parametrize("kind", ["polynomial", "pi", "linear"])
def test_without_an_ok_column_every_row_counts(kind):
    """``ok`` is optional: a characterisation without it is fitted as if every row were valid."""
    rng = np.random.default_rng(5)
    char = characterisation(lambda u: 1.5 * (u - U0) + 0.002 * (u - U0) ** 2 + rng.normal(0, 0.2, u.size))
    bare = char.drop(columns="ok")
    bare.attrs = dict(char.attrs)
    kw = {"shape": 0.0} if kind == "pi" else {}
    with_ok, without = fit_hysteresis(char, kind=kind, **kw), fit_hysteresis(bare, kind=kind, **kw)
    u = char["u"].to_numpy()
    np.testing.assert_allclose(without.predict(u), with_ok.predict(u), atol=1e-9)
    assert without.meta["rms_residual_px"] == pytest.approx(with_ok.meta["rms_residual_px"], rel=1e-9)


def test_a_branch_swept_the_wrong_way_is_refused_at_its_row():
    char = characterisation(lambda u: 1.5 * (u - U0))
    for label, verb in (("ascending", "falls"), ("descending", "rises")):
        bad = char.copy()
        bad.attrs = dict(char.attrs)
        i, j = bad.index[bad["branch"] == label][[6, 7]]
        bad.loc[[i, j], "u"] = bad.loc[[j, i], "u"].to_numpy()  # one step backwards at row j
        with pytest.raises(ValueError, match=rf"the voltage on the '{label}' branch {verb} at row {j};"):
            fit_hysteresis(bad)


def test_the_range_is_the_characterisation_s_attrs_else_its_voltages():
    char = characterisation(lambda u: 1.5 * (u - U0))
    wide = char.copy()
    wide.attrs = dict(char.attrs, u_min=U0 - 5.0, u_max=UN + 5.0)  # U0, Un as the experiment declared them
    assert fit_hysteresis(wide).u_range == (U0 - 5.0, UN + 5.0)
    bare = char.copy()
    bare.attrs = {}
    m = fit_hysteresis(bare)
    assert m.u_range == (U0, UN) and m.axis == "unknown" and m.direction == (1.0, 0.0)


def test_voltages_that_are_not_numbers_are_refused_and_an_object_column_is_read():
    char = characterisation(lambda u: 1.5 * (u - U0))
    nan = char.copy()
    nan.attrs = dict(char.attrs)
    nan.loc[nan.index[3], "u"] = np.nan
    with pytest.raises(ValueError, match="characterisation has non-finite voltages"):
        fit_hysteresis(nan)
    as_objects = char.astype({"u": object, "displacement": object, "ok": object})  # e.g. built from Python values
    as_objects.attrs = dict(char.attrs)
    u = char["u"].to_numpy()
    np.testing.assert_allclose(fit_hysteresis(as_objects).predict(u), fit_hysteresis(char).predict(u), atol=1e-9)


def test_the_linear_kind_is_the_least_squares_line_through_both_branches():
    rng = np.random.default_rng(8)
    char = characterisation(lambda u: 1.5 * (u - U0) + 0.01 * (u - U0) ** 2 + rng.normal(0, 0.3, u.size))
    m = fit_hysteresis(char, kind="linear")
    major = char[char["branch"].isin(["ascending", "descending"])]
    slope, icept = np.polyfit(major["u"], major["displacement"], 1)
    us = np.linspace(U0, UN, 7)
    np.testing.assert_allclose(m.ascending(us), slope * us + icept, atol=1e-8)
    np.testing.assert_allclose(m.descending(us), slope * us + icept, atol=1e-8)


def test_the_residual_is_of_the_path_from_its_start_whatever_state_it_ended_in():
    """A characterisation cut short at an inner turning point leaves the model's memory mid-loop; the
    residual figure still replays the path from U0 (as the characterisation ran)."""
    truth = PolynomialHysteresis(P_COEF, D_COEF, (U0, UN), axis="m0.x")
    full = characterisation(truth)
    turns = np.flatnonzero(np.diff(np.sign(np.diff(full["u"].to_numpy()))) != 0) + 1
    cut = full.iloc[: turns[-1] + 1].copy()  # ends on the last turning point, mid-range
    cut.attrs = dict(full.attrs)
    cut["displacement"] += np.where(np.arange(len(cut)) % 2, 0.1, -0.1)  # a known +-0.1 px misfit
    m = fit_hysteresis(cut)
    res = cut["displacement"].to_numpy() - m.predict(cut["u"].to_numpy(), reset=True)
    assert m.meta["rms_residual_px"] == pytest.approx(np.sqrt(np.mean(res**2)), rel=1e-9)
    assert U0 < m.state.u < UN  # the memory is where the path ended


def test_messages_of_the_refusals():
    char = characterisation(lambda u: 1.5 * (u - U0))
    flat = char.copy()
    flat.attrs = dict(char.attrs, u_min=10.0, u_max=10.0)
    with pytest.raises(ValueError, match="characterisation spans no voltage range"):
        fit_hysteresis(flat)
    backwards = char.assign(displacement=-char["displacement"])
    backwards.attrs = dict(char.attrs)
    with pytest.raises(ValueError, match="non-monotonic characterisation: the displacement does not follow the "
                                         r"voltage \(range 90 px, correlation -1.00\)"):
        fit_hysteresis(backwards)
    few = char.copy()
    few.attrs = dict(char.attrs)
    few["ok"] = ~few.index.isin(few.index[few["branch"] == "descending"][4:])
    with pytest.raises(ValueError, match="the descending branch has 4 valid distinct voltage"):
        fit_hysteresis(few)
