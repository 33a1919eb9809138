"""The paper's hysteresis model: 4th-order major branches, the inner-loop curves of eq. 11, the inverse.

:func:`inner_loop_displacement` is eq. 11 (generalised to the mirror case and to nested loops),
:func:`_newton_bisect` the bracketed Newton-Raphson root finder of the inverse, and
:class:`PolynomialHysteresis` the model with its reversal-point memory.
"""

from __future__ import annotations

import numpy as np

from .model import HysteresisModel, HysteresisState


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
