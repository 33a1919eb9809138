"""Fitting a hysteresis model to a characterisation (the paper's Fig. 8b).

:func:`fit_hysteresis` validates the characterisation and fits the polynomial model (the paper's
4th-order branches), the Prandtl-Ishlinskii model or a straight line; the private helpers check the
table and solve the least-squares problems.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .model import BRANCHES, HysteresisModel
from .polynomial import PolynomialHysteresis
from .prandtl_ishlinskii import PIHysteresis


def _validated_characterisation(char) -> pd.DataFrame:
    if not isinstance(char, pd.DataFrame):
        raise TypeError(f"characterisation must be a pandas DataFrame, got {type(char).__name__}")
    missing = {"u", "displacement", "branch"} - set(char.columns)
    if missing:
        raise ValueError(f"characterisation lacks column(s) {sorted(missing)}")
    if len(char) == 0:
        raise ValueError("characterisation is empty: no voltages were recorded")
    bad = set(char["branch"].unique()) - set(BRANCHES)
    if bad:
        raise ValueError(f"unknown branch label(s) {sorted(bad)}; expected {BRANCHES}")
    u = char["u"].to_numpy(float)
    if not np.all(np.isfinite(u)):
        raise ValueError("characterisation has non-finite voltages")
    return char


def _branch_runs(char: pd.DataFrame, label: str):
    """Contiguous runs of one major-branch label (each run must be monotonic in u)."""
    lab = char["branch"].to_numpy()
    idx = np.flatnonzero(lab == label)
    if idx.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    return np.split(idx, cuts)


def _check_monotonic(char, label, rising):
    u = char["u"].to_numpy(float)
    for run in _branch_runs(char, label):
        du = np.diff(u[run])
        if du.size and (np.any(du < 0) if rising else np.any(du > 0)):
            k = run[1:][(du < 0) if rising else (du > 0)][0]
            raise ValueError(
                f"non-monotonic characterisation: the voltage on the '{label}' branch "
                f"{'falls' if rising else 'rises'} at row {k}; each branch must be swept one way"
            )


def _major_points(char, label):
    ok = char["ok"].to_numpy(bool) if "ok" in char else np.ones(len(char), bool)
    disp = char["displacement"].to_numpy(float)
    sel = (char["branch"].to_numpy() == label) & ok & np.isfinite(disp)
    return char["u"].to_numpy(float)[sel], disp[sel]


def fit_hysteresis(characterisation: pd.DataFrame, kind: str = "polynomial", *, order: int = 4,
                   n_operators: int = 10, shape: float | None = None) -> HysteresisModel:
    """Fit a hysteresis model to a characterisation (paper, Fig. 8b).

    Parameters
    ----------
    characterisation : DataFrame
        From :func:`~semlab.experiments.characterise_hysteresis` (columns ``u, displacement, branch`` and optionally ``ok``;
        ``attrs`` ``axis``, ``direction``, ``u_min``, ``u_max``). Rows with ``ok=False`` are excluded.
    kind : {"polynomial", "pi", "linear"}
        ``"polynomial"``: the paper's 4th-order :math:`P_n, D_n` fitted to the major branches (with the
        two branches forced to meet at U0 and Un so the loop is closed) and eq. 11 for inner curves.
        ``"pi"``: Prandtl-Ishlinskii, fitted to every valid row (inner loops included).
        ``"linear"``: one straight line through both branches (the paper's coarse "linear fit"; it
        ignores the hysteresis, a baseline for feed-forward errors).
    order : int
        Polynomial order (the paper: 4).
    n_operators : int
        Number of play operators of the PI model.
    shape : float, optional
        PI input shaping coefficient; default: chosen by least squares over ``(-0.9, 0.9)``.

    Returns
    -------
    HysteresisModel
        With its memory replayed over the characterisation, i.e. matching the axis' state at the end of
        the characterisation.

    Raises
    ------
    TypeError, ValueError
        Not a DataFrame; empty; unknown branch labels; a branch swept both ways (non-monotonic);
        too few valid points for the fit; a probe that did not move or moved against the voltage.

    Examples
    --------
    >>> from semlab.sim import SimulatedRig
    >>> rig = SimulatedRig()
    >>> char = characterise_hysteresis(rig.microscope, rig.axis(0, "x"), (50, 150, 200, 200),
    ...                                u_min=0.0, u_max=50.0)          # doctest: +SKIP
    >>> model = fit_hysteresis(char, kind="pi")                         # doctest: +SKIP
    >>> u = model.inverse(model.state.y + 100.0)   # feed-forward for a 100-px move  # doctest: +SKIP
    """
    char = _validated_characterisation(characterisation)
    if kind not in ("polynomial", "pi", "linear"):
        raise ValueError(f"kind must be 'polynomial', 'pi' or 'linear', got {kind!r}")
    _check_monotonic(char, "ascending", True)
    _check_monotonic(char, "descending", False)
    attrs = dict(char.attrs)
    u_all = char["u"].to_numpy(float)
    u0 = float(attrs.get("u_min", u_all.min()))
    un = float(attrs.get("u_max", u_all.max()))
    if not un > u0:
        raise ValueError("characterisation spans no voltage range")
    order = int(order)
    ua, ya = _major_points(char, "ascending")
    ud, yd = _major_points(char, "descending")
    need = order + 1
    for name, uu in (("ascending", ua), ("descending", ud)):
        n_distinct = np.unique(uu).size
        if n_distinct < need:
            raise ValueError(
                f"too few points for a {order}th-order fit: the {name} branch has {n_distinct} valid "
                f"distinct voltage(s), at least {need} are needed"
            )
    y_all = np.concatenate([ya, yd])
    u_cat = np.concatenate([ua, ud])
    spread = np.ptp(y_all)
    corr = np.corrcoef(u_cat, y_all)[0, 1] if spread > 0 else 0.0
    if not corr >= 0.5:
        raise ValueError(
            "non-monotonic characterisation: the displacement does not follow the voltage "
            f"(range {spread:.3g} px, correlation {corr:.2f}); "
            "was the probe tracked, and did it move?"
        )
    kw = {"axis": attrs.get("axis", "unknown"), "direction": attrs.get("direction", (1.0, 0.0)),
          "meta": {"n_points": int(y_all.size)}}
    if kind == "polynomial":
        model = _fit_polynomial(ua, ya, ud, yd, (u0, un), order, kw)
    elif kind == "linear":  # one straight line through both branches: no hysteresis at all
        coef = np.polynomial.polynomial.polyfit((u_cat - u0) / (un - u0), y_all, 1)
        model = PolynomialHysteresis(coef, coef, (u0, un), **kw)
        model.kind = "linear"
    else:
        model = _fit_pi(char, (u0, un), n_operators, shape, kw)
    # replay the characterisation so that the memory matches the axis now
    model.reset()
    model.forward(np.clip(u_all, u0, un))
    fitted = model.predict(u_all, reset=True)
    ok = char["ok"].to_numpy(bool) if "ok" in char else np.ones(len(char), bool)
    res = char["displacement"].to_numpy(float) - fitted
    good = ok & np.isfinite(res)
    lab = char["branch"].to_numpy()
    model.meta["rms_residual_px"] = float(np.sqrt(np.mean(res[good] ** 2)))
    inner = good & np.char.startswith(lab.astype(str), "inner")
    model.meta["rms_residual_inner_px"] = float(np.sqrt(np.mean(res[inner] ** 2))) if inner.any() else float("nan")
    return model


def _fit_polynomial(ua, ya, ud, yd, u_range, order, kw):
    U0, Un = u_range
    sa, sd = (ua - U0) / (Un - U0), (ud - U0) / (Un - U0)
    n = order + 1
    Va = np.vander(sa, n, increasing=True)
    Vd = np.vander(sd, n, increasing=True)
    A = np.zeros((Va.shape[0] + Vd.shape[0], 2 * n))
    A[: Va.shape[0], :n] = Va
    A[Va.shape[0]:, n:] = Vd
    b = np.concatenate([ya, yd])
    # the loop is closed: Pn(U0) = Dn(U0), Pn(Un) = Dn(Un)  (null-space method)
    C = np.zeros((2, 2 * n))
    C[0, 0], C[0, n] = 1.0, -1.0
    C[1, :n], C[1, n:] = 1.0, -1.0
    _, _, vt = np.linalg.svd(C)
    N = vt[2:].T
    z, *_ = np.linalg.lstsq(A @ N, b, rcond=None)
    coef = N @ z
    model = PolynomialHysteresis(coef[:n], coef[n:], u_range, **kw)
    grid = np.linspace(U0, Un, 401)
    slope = model.gain
    for name, fn in (("ascending", model.ascending), ("descending", model.descending)):
        d = fn(grid, deriv=1)
        if d.min() < -0.05 * abs(slope):
            raise ValueError(
                f"non-monotonic characterisation: the fitted {name} branch falls near "
                f"u={grid[np.argmin(d)]:.4g} V (slope {d.min():.3g} px/V); check the tracking"
            )
    return model


def _fit_pi(char, u_range, n_operators, shape, kw):
    n_operators = int(n_operators)
    if n_operators < 1:
        raise ValueError("n_operators must be >= 1")
    u = np.clip(char["u"].to_numpy(float), *u_range)
    y = char["displacement"].to_numpy(float)
    ok = (char["ok"].to_numpy(bool) if "ok" in char else np.ones(len(char), bool)) & np.isfinite(y)
    if ok.sum() < n_operators + 2:
        raise ValueError(f"too few valid points ({int(ok.sum())}) for a PI model with {n_operators} operators")
    from scipy.optimize import lsq_linear, minimize_scalar

    def solve(a):
        proto = PIHysteresis(np.ones(n_operators), 0.0, u_range, shape=a, **kw)
        Z = proto.design_matrix(u)[ok]
        A = np.column_stack([Z, np.ones(Z.shape[0])])
        scale = max(np.ptp(y[ok]), 1e-12)
        lb = np.r_[1e-6 * scale, np.zeros(n_operators - 1), -np.inf]
        res = lsq_linear(A, y[ok], bounds=(lb, np.full(n_operators + 1, np.inf)))
        return res.cost, res.x

    if shape is None:
        best = minimize_scalar(lambda a: solve(a)[0], bounds=(-0.9, 0.9), method="bounded",
                               options={"xatol": 1e-3})
        shape = float(best.x) if solve(best.x)[0] <= solve(0.0)[0] else 0.0
    _, x = solve(float(shape))
    return PIHysteresis(x[:n_operators], x[n_operators], u_range, shape=float(shape), **kw)
