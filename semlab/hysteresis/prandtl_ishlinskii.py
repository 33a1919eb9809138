"""The Prandtl-Ishlinskii hysteresis model: play operators and the analytic inverse.

:func:`play_operator` is the elementary hysteron; :class:`PIHysteresis` the weighted sum of plays
with an input shaping and the inverse of Krejci & Kuhnen (2001), the more accurate model the paper
recommends.
"""

from __future__ import annotations

import math

import numpy as np

from .model import EXTRAPOLATION_SLOPE_FACTOR, HysteresisModel, HysteresisState


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
