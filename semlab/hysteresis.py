"""Piezo hysteresis: models and their inverses, fitted to a characterisation by visual tracking.

The paper (Ru et al., "Visual Servo Control Incorporating a Feed-Forward Controller", Fig. 8)
characterises one piezo axis by applying voltages incrementally from U0 to Un and back while the visual
tracker records the probe displacement, fits the ascending and descending major branches Pn(u), Dn(u)
with fourth-order polynomials, describes curves that start at a reversal inside the loop with eq. 11,
and inverts the model by Newton-Raphson to obtain the feed-forward command.

This module provides the models; the experiment that measures them (the voltage path of Fig. 8b and
:func:`semlab.experiments.characterise_hysteresis`) drives a rig and lives in :mod:`semlab.experiments`,
the creep law in :mod:`semlab.creep` (their old import paths from here keep working):

* :class:`PolynomialHysteresis` -- Pn, Dn, eq. 11, its mirror for reversals on the ascending branch,
  reversal-point memory (wiping-out) and the Newton-Raphson inverse;
* :class:`PIHysteresis` -- a Prandtl-Ishlinskii model (play operators, weights by bounded/non-negative
  least squares) with the analytic inverse of Krejci & Kuhnen (2001), the paper's recommendation for a
  more accurate model;
* :func:`fit_hysteresis` -- fits either model to a characterisation.

Both models share one interface: ``forward`` (commit voltages, return displacements), ``displacement``
(peek), ``inverse`` (voltage that produces a desired displacement from the current memory state),
``reset``, ``state``, ``check_axis``, ``u_range`` and ``displacement_range``.

The characterised range ``u_range`` limits what the model *knows*, not where the axis may go: beyond it
the models extrapolate linearly (:attr:`HysteresisModel.extrapolation_slopes`, deliberately steeper than
anything measured, so that a feed-forward move beyond the range stops short rather than overshoots) and
remember an excursion out there like any other history (the curve back from it starts at it). The axis
limits are the servo's business (:mod:`semlab.control`).

Displacements are in image pixels along the measured image direction of the axis; the sign is chosen
so that rising voltage increases the displacement.

Displacements are in image pixels along the measured image direction of the axis; the sign is chosen
so that rising voltage increases the displacement.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .protocols import as_finite

__all__ = [
    "BRANCHES",
    "HysteresisModel",
    "HysteresisState",
    "PIHysteresis",
    "PolynomialHysteresis",
    "axis_identity",
    "fit_hysteresis",
    "inner_loop_displacement",
    "play_operator",
]

#: Branch labels used in a characterisation DataFrame.
BRANCHES = ("ascending", "descending", "inner_ascending", "inner_descending")

#: Beyond the characterised range the models extrapolate linearly with this many times the steepest
#: slope of their major loop. A piezo's gain keeps growing with the voltage (the simulated Preisach
#: axis characterised over 0-50 V of 0-100 V: 1.07x its steepest in-range slope 10 V beyond, 1.5x at
#: 100 V), and a model that is too steep only makes the feed-forward stop short, which the feedback
#: finishes, while one that is too shallow makes it overshoot.
EXTRAPOLATION_SLOPE_FACTOR = 1.25

# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------


def axis_identity(axis) -> str:
    """A string that identifies an actuator axis, used to refuse a model fitted on another axis.

    The axis' ``name`` (or ``id``/``label``) attribute is used when it has one; otherwise the Python
    object identity, which is only valid within one session.
    """
    if isinstance(axis, str):
        return axis
    for attr in ("name", "id", "label"):
        value = getattr(axis, attr, None)
        if value is not None and not callable(value):
            return str(value)
    return f"{type(axis).__name__}@{id(axis):x}"


def play_operator(u, r: float, z0: float | None = None) -> np.ndarray:
    """Output of the play (backlash) operator of threshold ``r`` for an input sequence.

    ``z_k = max(u_k - r, min(u_k + r, z_{k-1}))``, the elementary hysteron of the Prandtl-Ishlinskii
    model.

    Parameters
    ----------
    u : (N,) array_like
        Input sequence.
    r : float
        Threshold (half the backlash width), ``r >= 0``.
    z0 : float, optional
        Initial state; default ``u[0]`` clipped into ``[u0 - r, u0 + r]`` (i.e. ``u[0]``).

    Returns
    -------
    (N,) ndarray
    """
    u = np.asarray(u, dtype=float)
    if r < 0:
        raise ValueError(f"play operator threshold r={r} must be >= 0")
    out = np.empty_like(u)
    z = u[0] if z0 is None else float(z0)
    for k, uk in enumerate(u):
        z = max(uk - r, min(uk + r, z))
        out[k] = z
    return out


# ---------------------------------------------------------------------------------------------
# the models
# ---------------------------------------------------------------------------------------------


@dataclass
class HysteresisState:
    """Memory of a hysteresis model.

    Attributes
    ----------
    u : float
        Last committed voltage.
    y : float
        Displacement there (px).
    rising : bool
        Direction of the last voltage change.
    reversals : list of (float, float)
        Remembered reversal points ``(u, y)`` inside the range, oldest first (polynomial model); they
        alternate maxima and minima and are wiped out when the voltage passes them (closure of a loop).
    plays : ndarray or None
        Play-operator states (Prandtl-Ishlinskii model).
    """

    u: float
    y: float
    rising: bool = True
    reversals: list = field(default_factory=list)
    plays: np.ndarray | None = None


class HysteresisModel:
    """Common interface of the hysteresis models (see the module docstring).

    Attributes
    ----------
    kind : str
        ``"polynomial"`` or ``"pi"``.
    axis : str
        Identity of the axis the model was fitted on (see :func:`axis_identity`).
    direction : (float, float)
        Unit vector of the image direction in which rising voltage moves the probe.
    u_range : (float, float)
        ``(U0, Un)`` of the characterisation: what the model knows. Outside it the model extrapolates
        linearly (:attr:`extrapolation_slopes`); a voltage is only refused when it is not finite.
    extrapolation_slopes : (float, float)
        px/V below ``U0`` and above ``Un`` after a long monotonic run: :data:`EXTRAPOLATION_SLOPE_FACTOR`
        times the model's steepest slope at that end (see each model).
    """

    kind = "base"

    def __init__(self, u_range, *, axis="unknown", direction=(1.0, 0.0), meta=None):
        u0, un = (as_finite(v, "model range bound") for v in u_range)
        if not u0 < un:
            raise ValueError(f"model voltage range {u_range} is empty")
        self.u_range = (u0, un)
        self.axis = axis_identity(axis)
        d = np.asarray(direction, dtype=float)
        if d.shape != (2,) or not np.all(np.isfinite(d)) or np.hypot(*d) == 0:
            raise ValueError(f"direction {direction!r} must be a non-zero 2-vector")
        self.direction = tuple(d / np.hypot(*d))
        self.meta = dict(meta or {})
        self.extrapolation_slopes = self._extrapolation_slopes()
        self.state = None
        self.reset()

    # -- interface to be provided by subclasses -------------------------------------------------
    def _major(self, u: float, rising: bool) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def _advance(self, state: HysteresisState, u: float) -> HysteresisState:  # pragma: no cover
        """The state after a monotonic move from ``state`` to any voltage ``u``."""
        raise NotImplementedError

    def _inverse(self, state: HysteresisState, target: float) -> float:  # pragma: no cover - abstract
        """The voltage whose monotonic move from ``state`` reaches ``target`` (any finite value)."""
        raise NotImplementedError

    # -- shared behaviour -----------------------------------------------------------------------
    @property
    def displacement_range(self) -> tuple[float, float]:
        """Displacements at U0 and Un (px): the range the characterisation covered."""
        return (self._major(self.u_range[0], True), self._major(self.u_range[1], True))

    @property
    def gain(self) -> float:
        """Mean slope of the loop, px per volt (the 'linear fit' of the paper)."""
        lo, hi = self.displacement_range
        return (hi - lo) / (self.u_range[1] - self.u_range[0])

    def steepest_slope(self, n: int = 201) -> float:
        """The steepest slope (px/V) of the two major branches over the characterised range."""
        grid = np.linspace(*self.u_range, int(n))
        slopes = [np.max(np.diff([self._major(u, rising) for u in grid]) / np.diff(grid))
                  for rising in (True, False)]
        return float(max(max(slopes), self.gain))

    def _extrapolation_slopes(self) -> tuple[float, float]:
        slope = EXTRAPOLATION_SLOPE_FACTOR * self.steepest_slope()
        return (slope, slope)

    def reset(self, u: float | None = None, branch: str = "ascending") -> HysteresisState:
        """Forget all reversals and put the model on a major branch.

        Parameters
        ----------
        u : float, optional
            Voltage; default ``U0`` (the state after a descent to U0, as after a characterisation).
            Outside the range the model sits on its extrapolation.
        branch : {"ascending", "descending"}
            Major branch the actuator is on (how ``u`` was approached).
        """
        if branch not in ("ascending", "descending"):
            raise ValueError(f"branch must be 'ascending' or 'descending', got {branch!r}")
        u = self.u_range[0] if u is None else self._check_u(u)
        self.state = self._major_state(u, branch == "ascending")
        return self.state

    def _major_state(self, u: float, rising: bool) -> HysteresisState:
        return HysteresisState(u=u, y=self._major(u, rising), rising=rising)

    def _check_u(self, u) -> float:
        return as_finite(u, "voltage")

    def forward(self, voltages) -> np.ndarray | float:
        """Commit voltage(s) in order and return the displacement(s) they produce (px).

        The memory (reversal points / play states) is updated, so a model used as the shadow of an
        axis must see every command sent to that axis. Voltages outside ``u_range`` are extrapolated,
        and the memory keeps their reversals too (an excursion beyond the range is remembered).
        """
        scalar = np.ndim(voltages) == 0
        out = []
        for u in np.atleast_1d(np.asarray(voltages, dtype=float)):
            self.state = self._advance(self.state, self._check_u(u))
            out.append(self.state.y)
        return out[0] if scalar else np.asarray(out)

    def displacement(self, u: float) -> float:
        """Displacement a move from the current state to ``u`` would produce, without committing it."""
        return self._advance(copy.deepcopy(self.state), self._check_u(u)).y

    def inverse(self, target: float) -> float:
        """Voltage that brings the displacement to ``target`` from the current state (not committed).

        Inside the characterised range the model's own inverse (eq. 11 by Newton-Raphson, or the
        analytic inverse PI operator); beyond it the extrapolation. Every finite target has an answer:
        whether the axis can apply it is for the caller to check against the axis limits.

        Raises
        ------
        ValueError
            If the target is not finite.
        """
        y_t = as_finite(target, "target displacement")
        lo_y, hi_y = self.displacement_range
        if abs(y_t - self.state.y) <= 1e-12 * max(1.0, hi_y - lo_y):  # rounding
            return self.state.u
        return self._inverse(self.state, y_t)

    def predict(self, voltages, *, reset: bool | tuple = True) -> np.ndarray:
        """Displacements for a voltage sequence, on a copy of the model (the model is untouched).

        Parameters
        ----------
        voltages : (N,) array_like
        reset : bool or (float, str)
            ``True`` starts from the reset state (U0 after a descent), ``False`` from the current state,
            a tuple ``(u, branch)`` from that major-branch state.
        """
        m = self.copy()
        if reset is True:
            m.reset()
        elif reset:
            m.reset(*reset)
        return np.atleast_1d(m.forward(np.atleast_1d(voltages)))

    def replay(self, characterisation: pd.DataFrame) -> np.ndarray:
        """Predicted displacement for each row of a characterisation (starting from U0 after a descent)."""
        return self.predict(characterisation["u"].to_numpy(float), reset=True)

    def copy(self) -> HysteresisModel:
        """A deep copy (its own memory)."""
        return copy.deepcopy(self)

    def check_axis(self, axis) -> None:
        """Raise ValueError if ``axis`` is not the axis this model was fitted on."""
        ident = axis_identity(axis)
        if ident != self.axis:
            raise ValueError(
                f"this {self.kind} hysteresis model was fitted on axis {self.axis!r}, not on {ident!r}; "
                "characterise this axis and fit a model for it"
            )

    def __repr__(self) -> str:
        lo, hi = self.displacement_range
        return (
            f"<{type(self).__name__} axis={self.axis!r} u={self.u_range[0]:.4g}..{self.u_range[1]:.4g} V "
            f"displacement={lo:.4g}..{hi:.4g} px direction=({self.direction[0]:.3f}, {self.direction[1]:.3f})>"
        )


def inner_loop_displacement(u, origin, end, ascending_branch, descending_branch, u_range, *, derivative=False):
    """Displacement on a curve that starts at a reversal point, the paper's eq. 11 generalised.

    For a reversal at ``origin = (u1, y1)`` on the descending branch with the voltage then rising, the
    paper gives (eq. 11)

    .. math:: P_1(u) = k\\,P_n\\big(U_n + (u - U_n)/m\\big) + D_n(u_1) - k\\,P_n(U_0),

    :math:`k = (D_n(U_n) - D_n(u_1)) / (D_n(U_n) - D_n(U_0))`. As printed, :math:`m = (U_n - u_1)/(U_n - U_0)`
    multiplies :math:`(u - U_n)`, which does not give :math:`P_1(u_1) = D_n(u_1)`; the dashed curve of
    Fig. 8b starts at the reversal point, so the argument must map :math:`[u_1, U_n]` onto
    :math:`[U_0, U_n]`, i.e. divide by that :math:`m` (equivalently multiply by its reciprocal). That is
    the form implemented. The curve is the ascending major branch scaled into the box between the
    reversal point and the point where the loop closes (``end``, here :math:`(U_n, D_n(U_n))`).

    The same construction with the descending branch gives the mirror case the paper only names
    (voltage falling after a reversal on the ascending branch), and with ``end`` an older reversal point
    it gives nested (higher-order) loops.

    Parameters
    ----------
    u : float or ndarray
        Voltage(s) between ``origin[0]`` and ``end[0]``.
    origin, end : (float, float)
        ``(u, y)`` of the reversal point and of the closure point.
    ascending_branch, descending_branch : callable
        :math:`P_n(u)` and :math:`D_n(u)` (vectorised); with ``derivative=True`` they must accept a
        ``deriv`` keyword returning the derivative.
    u_range : (float, float)
        ``(U0, Un)``.
    derivative : bool
        Also return :math:`dy/du`.

    Returns
    -------
    y or (y, dy_du)
    """
    U0, Un = u_range
    (u1, y1), (u2, y2) = origin, end
    u = np.asarray(u, dtype=float)
    if u2 > u1:  # rising voltage: scaled ascending branch
        scale = (Un - U0) / (u2 - u1)
        s = U0 + (u - u1) * scale
        p0, pn = ascending_branch(U0), ascending_branch(Un)
        y = y1 + (y2 - y1) * (ascending_branch(s) - p0) / (pn - p0)
        if derivative:
            dy = (y2 - y1) * ascending_branch(s, deriv=1) * scale / (pn - p0)
    elif u2 < u1:  # falling voltage: scaled descending branch
        scale = (Un - U0) / (u1 - u2)
        s = Un - (u1 - u) * scale
        d0, dn = descending_branch(U0), descending_branch(Un)
        y = y1 + (y2 - y1) * (dn - descending_branch(s)) / (dn - d0)
        if derivative:
            dy = (y1 - y2) * descending_branch(s, deriv=1) * scale / (dn - d0)
    else:
        y = np.full_like(u, y1)
        dy = np.zeros_like(u)
    if y.ndim == 0:
        y = float(y)
        if derivative:
            dy = float(dy)
    return (y, dy) if derivative else y


def _newton_bisect(f, lo: float, hi: float, target: float, *, xtol: float, maxiter: int = 60) -> float:
    """Solve ``f(x)[0] = target`` for x in [lo, hi] with f increasing: Newton-Raphson steps, kept
    inside the bracket (bisection when a step leaves it or the slope vanishes)."""
    flo, fhi = f(lo)[0] - target, f(hi)[0] - target
    if flo >= 0:
        return lo
    if fhi <= 0:
        return hi
    x = lo + (hi - lo) * (-flo) / (fhi - flo)  # secant start
    for _ in range(maxiter):
        y, dy = f(x)
        g = y - target
        if g > 0:
            hi = x
        else:
            lo = x
        if abs(g) < 1e-12 or hi - lo < xtol:
            return x
        x_new = x - g / dy if dy > 0 else None
        if x_new is None or not lo < x_new < hi:
            x_new = 0.5 * (lo + hi)
        if abs(x_new - x) < xtol:
            return x_new
        x = x_new
    return x


class PolynomialHysteresis(HysteresisModel):
    """The paper's model: 4th-order major branches, eq. 11 inner curves, reversal memory, NR inverse.

    Parameters
    ----------
    ascending_coef, descending_coef : array_like
        Polynomial coefficients (lowest order first) of :math:`P_n` and :math:`D_n` in the normalised
        voltage ``s = (u - U0) / (Un - U0)``.
    u_range : (float, float)
        ``(U0, Un)``.
    axis, direction, meta
        See :class:`HysteresisModel`.

    Notes
    -----
    Memory follows the wiping-out rule: every reversal is pushed on a stack; a curve starting at the
    newest reversal point heads for the previous one (or the end of the major loop), and passing it
    closes that inner loop, whose two points are forgotten; passing an end of the major loop wipes out
    all memory. The inverse solves the monotonic path from the current state by Newton-Raphson on the
    (analytic) derivative of the active curve.

    Beyond the characterised range both major branches continue as one straight line
    (:attr:`extrapolation_slopes`, :data:`EXTRAPOLATION_SLOPE_FACTOR` times the loop's steepest slope),
    and a reversal out there is remembered like any other: the curve back from an excursion to
    ``u_p > Un`` is the descending branch scaled into the box from ``(u_p, y_p)`` to ``(U0, Pn(U0))``
    (eq. 11 generalised), so it starts as flat as the descending branch does at ``Un``.
    """

    kind = "polynomial"

    def __init__(self, ascending_coef, descending_coef, u_range, **kw):
        self._P = np.polynomial.Polynomial(np.asarray(ascending_coef, dtype=float))
        self._D = np.polynomial.Polynomial(np.asarray(descending_coef, dtype=float))
        self._dP, self._dD = self._P.deriv(), self._D.deriv()
        self._u0, self._un = float(u_range[0]), float(u_range[1])
        super().__init__(u_range, **kw)
        p0, pn = self._P(0.0), self._P(1.0)
        if not pn > p0:
            raise ValueError("ascending branch does not rise over the range: not a usable hysteresis model")

    # major branches in volts ------------------------------------------------------------------
    def ascending(self, u, deriv: int = 0):
        """:math:`P_n(u)` (or its derivative in px/V)."""
        s = (np.asarray(u, dtype=float) - self._u0) / (self._un - self._u0)
        return self._P(s) if not deriv else self._dP(s) / (self._un - self._u0)

    def descending(self, u, deriv: int = 0):
        """:math:`D_n(u)` (or its derivative in px/V)."""
        s = (np.asarray(u, dtype=float) - self._u0) / (self._un - self._u0)
        return self._D(s) if not deriv else self._dD(s) / (self._un - self._u0)

    def _major(self, u, rising, derivative=False):
        """The major branch, continued by the straight line beyond the range (both branches meet at
        the ends, so the line is the same for both)."""
        U0, Un = self.u_range
        if U0 <= u <= Un:
            y = float(self.ascending(u) if rising else self.descending(u))
            dy = float(self.ascending(u, deriv=1) if rising else self.descending(u, deriv=1))
        else:
            end, slope = (Un, self.extrapolation_slopes[1]) if u > Un else (U0, self.extrapolation_slopes[0])
            y, dy = float(self.ascending(end)) + slope * (u - end), slope
        return (y, dy) if derivative else y

    def _ends(self):
        U0, Un = self.u_range
        return (U0, float(self.ascending(U0))), (Un, float(self.ascending(Un)))

    def _curve(self, reversals, rising):
        """(origin, end) of the active curve for a direction, given the reversal stack."""
        low, high = self._ends()
        if not reversals:
            return (low, high) if rising else (high, low)
        origin = reversals[-1]
        if len(reversals) >= 2:
            end = reversals[-2]
        else:
            end = high if rising else low
        return origin, end

    def _eval(self, origin, end, u, derivative=False):
        low, high = self._ends()
        if (origin, end) in ((low, high), (high, low)):  # a major branch (continued beyond the range)
            return self._major(u, end == high, derivative=derivative)
        return inner_loop_displacement(
            u, origin, end, self.ascending, self.descending, self.u_range, derivative=derivative
        )

    def _active(self, state, rising, goes_past):
        """The reversal stack for a move in direction ``rising`` from ``state``, with the inner loops
        the move closes (``goes_past(point)``) forgotten; also the voltage the active curve starts from."""
        stack = list(state.reversals)
        if rising != state.rising:
            # a reversal is remembered, inside the range or beyond (at an end of the major loop with
            # nothing else remembered it is harmless: the curve from it is the major branch)
            stack.append((state.u, state.y))
        start = (state.u, state.y)
        while len(stack) >= 2 and goes_past(stack[-2]):
            start = stack[-2]
            del stack[-2:]  # wiping-out: passing the closure point forgets the inner loop
        return stack, start

    def _advance(self, state, u):
        U0, Un = self.u_range
        if abs(u - state.u) <= 1e-12 * (Un - U0):  # below the model's resolution: no move, no reversal
            return state
        rising = u > state.u
        stack, _ = self._active(state, rising, lambda p: (u >= p[0]) if rising else (u <= p[0]))
        origin, end = self._curve(stack, rising)
        tol = 1e-12 * (Un - U0)
        if len(stack) <= 1 and ((u >= end[0] - tol) if rising else (u <= end[0] + tol)):
            # past the end of the major loop (or of the curve heading there): all memory wiped out
            return HysteresisState(u=u, y=self._major(u, rising), rising=rising, reversals=[])
        return HysteresisState(u=u, y=float(self._eval(origin, end, u)), rising=rising, reversals=stack)

    def _inverse(self, st, y_t: float) -> float:
        """The voltage whose monotonic move from ``st`` reaches ``y_t``: the path is followed curve by
        curve (closing inner loops on the way) and the curve that contains the target is solved by
        Newton-Raphson (the paper's inverse); past the major loop's end, the straight line."""
        rising = y_t > st.y
        U0, Un = self.u_range
        stack, (u_from, y_from) = self._active(st, rising, lambda p: (y_t >= p[1]) if rising else (y_t <= p[1]))
        origin, end = self._curve(stack, rising)
        if len(stack) <= 1 and ((y_t >= end[1]) if rising else (y_t <= end[1])):
            edge, slope = (Un, self.extrapolation_slopes[1]) if rising else (U0, self.extrapolation_slopes[0])
            if not stack and ((u_from > Un) if rising else (u_from < U0)):
                return u_from + (y_t - y_from) / slope  # the move starts out on the line already
            return edge + (y_t - float(self.ascending(edge))) / slope

        def f(x):
            return self._eval(origin, end, x, derivative=True)

        xtol = 1e-10 * (Un - U0)
        if rising:
            return _newton_bisect(f, u_from, end[0], y_t, xtol=xtol)
        return _newton_bisect(f, end[0], u_from, y_t, xtol=xtol)


#: Round-off (in the shaped input's unit range) of the PI inverse operator's sums.
SHAPED_ROUND_OFF = 1e-12


class PIHysteresis(HysteresisModel):
    """Prandtl-Ishlinskii model with an analytic inverse.

    .. math:: y = \\sum_{i=0}^{n-1} w_i\\, F_{r_i}[v] + c, \\qquad v = \\varphi(s),\\; s = (u-U_0)/(U_n-U_0)

    with play operators :math:`F_{r_i}` (:func:`play_operator`), thresholds
    :math:`r_i = i/(2n)` (the range of ``v`` is [0, 1]), non-negative weights (``w_0 > 0``), and an
    optional monotonic input shaping :math:`\\varphi(s) = s + a\\,s(1-s)` (``|a| < 1``) that lets the
    otherwise point-symmetric PI loop lean like a real piezo loop; :math:`\\varphi` has a closed-form
    inverse, so the whole inverse stays analytic. Beyond the characterised range :math:`\\varphi` goes on
    as a straight line (:data:`EXTRAPOLATION_SLOPE_FACTOR` times its slope at that end) and the plays
    simply follow it: an excursion beyond the range is remembered like any other history.

    The inverse PI operator (Krejci & Kuhnen 2001) has thresholds
    :math:`r'_i = \\sum_{j\\le i} w_j (r_i - r_j)`, weights :math:`w'_0 = 1/w_0`,
    :math:`w'_i = -w_i / (W_i W_{i-1})` with :math:`W_i = \\sum_{j \\le i} w_j`, and states
    :math:`z'_i = W_i z_i + \\sum_{j>i} w_j z_j` computed from the forward states, so feed-forward
    is exact for the model whatever the memory.

    References
    ----------
    Krejci, P. & Kuhnen, K. (2001). Inverse control of systems with hysteresis and creep.
    IEE Proc. Control Theory Appl. 148, 185-192.
    Rakotondrabe, M. (2012). Classical Prandtl-Ishlinskii modeling and inverse multiplicative structure
    to compensate hysteresis in piezoactuators. ACC 2012.
    """

    kind = "pi"

    def __init__(self, weights, offset, u_range, *, shape: float = 0.0, **kw):
        w = np.asarray(weights, dtype=float)
        if w.ndim != 1 or w.size < 1 or not np.all(np.isfinite(w)):
            raise ValueError("PI weights must be a non-empty finite 1-D array")
        if w[0] <= 0 or np.any(w < 0):
            raise ValueError("PI weights must be non-negative with w[0] > 0 (otherwise no inverse exists)")
        if not -1.0 < shape < 1.0:
            raise ValueError(f"input shaping a={shape} must satisfy |a| < 1 to stay monotonic")
        self.weights = w
        self.thresholds = np.arange(w.size) / (2.0 * w.size)
        self.offset = float(offset)
        self.shape = float(shape)
        W = np.cumsum(w)
        self.inv_thresholds = np.array([np.sum(w[: i + 1] * (self.thresholds[i] - self.thresholds[: i + 1]))
                                        for i in range(w.size)])
        self.inv_weights = np.concatenate([[1.0 / w[0]], -w[1:] / (W[1:] * W[:-1])])
        self._W = W
        super().__init__(u_range, **kw)

    # input shaping -------------------------------------------------------------------------------
    def _v(self, u):
        """The shaped input; beyond [0, 1] a straight line :data:`EXTRAPOLATION_SLOPE_FACTOR` times as
        steep as the shaping at that end, so the plays (and the memory) run on beyond the range."""
        s = (np.asarray(u, dtype=float) - self.u_range[0]) / (self.u_range[1] - self.u_range[0])
        a, k = self.shape, EXTRAPOLATION_SLOPE_FACTOR
        inside = np.clip(s, 0.0, 1.0)
        v = inside + a * inside * (1.0 - inside)
        return v + np.where(s > 1.0, k * (1.0 - a) * (s - 1.0), 0.0) + np.where(s < 0.0, k * (1.0 + a) * s, 0.0)

    def _u(self, v):
        a, k = self.shape, EXTRAPOLATION_SLOPE_FACTOR
        v = float(v)
        # The inverse operator's sums round: a v within round-off of an end is that end, not a
        # step (by 1e-14 V) beyond the characterised range.
        if v > 1.0 + SHAPED_ROUND_OFF:
            s = 1.0 + (v - 1.0) / (k * (1.0 - a))
        elif v < -SHAPED_ROUND_OFF:
            s = v / (k * (1.0 + a))
        else:
            # the root in [0, 1] of a s^2 - (1 + a) s + v = 0, in the form without cancellation
            s = 2.0 * v / ((1.0 + a) + math.sqrt(max((1.0 + a) ** 2 - 4.0 * a * v, 0.0)))
            s = min(max(s, 0.0), 1.0)
        return self.u_range[0] + s * (self.u_range[1] - self.u_range[0])

    def _extrapolation_slopes(self) -> tuple[float, float]:
        # a long monotonic run beyond an end moves every play: sum(w) times the line's slope in v
        span = self.u_range[1] - self.u_range[0]
        k, a, total = EXTRAPOLATION_SLOPE_FACTOR, self.shape, float(np.sum(self.weights))
        return (k * total * (1.0 + a) / span, k * total * (1.0 - a) / span)

    # states ------------------------------------------------------------------------------------
    def _output(self, z):
        return float(self.weights @ z + self.offset)

    def _major_state(self, u, rising):
        v = float(self._v(u))
        r = self.thresholds
        # after a descent to U0 every play sits at r; rising to v lifts it to max(v - r, r); after a
        # rise to Un every play sits at 1 - r; falling to v lowers it to min(v + r, 1 - r)
        z = np.maximum(v - r, r) if rising else np.minimum(v + r, 1.0 - r)
        return HysteresisState(u=u, y=self._output(z), rising=rising, plays=z)

    def _major(self, u, rising):
        return self._major_state(u, rising).y

    def _advance(self, state, u):
        v = float(self._v(u))
        r = self.thresholds
        z = np.maximum(v - r, np.minimum(v + r, state.plays))
        rising = state.rising if u == state.u else u > state.u
        return HysteresisState(u=u, y=self._output(z), rising=rising, plays=z)

    def design_matrix(self, voltages, *, start_rising: bool = False) -> np.ndarray:
        """Play outputs ``(N, n)`` for a voltage path starting at U0 (after a descent by default)."""
        v = self._v(np.asarray(voltages, dtype=float))
        r = self.thresholds
        z = self._major_state(self.u_range[0], start_rising).plays.copy()
        out = np.empty((v.size, r.size))
        for k, vk in enumerate(v):
            z = np.maximum(vk - r, np.minimum(vk + r, z))
            out[k] = z
        return out

    def _inverse(self, state, target: float) -> float:
        """Analytic inverse: one step of the inverse PI operator from the states matching the
        forward states of ``state``, then the inverse input shaping."""
        y_t = target - self.offset
        z, w, W = state.plays, self.weights, self._W
        tail = np.concatenate([np.cumsum((w * z)[::-1])[::-1][1:], [0.0]])  # sum_{j>i} w_j z_j
        zi = W * z + tail
        ri = self.inv_thresholds
        zi = np.maximum(y_t - ri, np.minimum(y_t + ri, zi))
        v = float(self.inv_weights @ zi)
        return self._u(v)


# ---------------------------------------------------------------------------------------------
# fitting
# ---------------------------------------------------------------------------------------------


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


# What drives a rig (and plans its voltages) moved to semlab.experiments, the creep law to
# semlab.creep; their old import paths keep working.
_MOVED = {"characterise_hysteresis": "experiments", "characterise_creep": "experiments",
          "characterisation_voltages": "experiments", "label_branches": "experiments",
          "DEFAULT_INNER_TURNS": "experiments", "CreepModel": "creep", "fit_creep": "creep"}


def __getattr__(name: str):
    if name in _MOVED:
        import importlib

        return getattr(importlib.import_module(f"{__package__}.{_MOVED[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
