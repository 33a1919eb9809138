"""Piezo creep: the logarithmic law, superposed over the commanded steps, and its fit to a hold.

Measured on a rig by :func:`semlab.experiments.characterise_creep`; the visual servo's feed-forward
subtracts the creep it predicts (:class:`semlab.control.VisualServo`).
"""

from __future__ import annotations

import math

import numpy as np

from .protocols import as_finite

__all__ = ["CreepModel", "fit_creep"]


class CreepModel:
    """Logarithmic piezo creep, superposed over the displacement steps the controller commanded.

    .. math:: c(t) = \\gamma \\sum_j \\Delta y_j \\log_{10}\\big(1 + (t - t_j)/t_0\\big)

    the usual creep law of piezo actuators (e.g. Jung & Gweon 2000): after a step of
    :math:`\\Delta y_j` at :math:`t_j` the actuator keeps moving by :math:`\\gamma` of the step per decade
    of time. The feed-forward subtracts the predicted growth so that the PID does not have to chase it.

    Parameters
    ----------
    gamma : float
        Creep per decade as a fraction of the step (>= 0).
    t0 : float
        Time constant in s (> 0).
    memory : int
        Number of recent steps kept (older ones are frozen at their value).
    """

    def __init__(self, gamma: float, t0: float = 0.1, memory: int = 64):
        gamma, t0 = as_finite(gamma, "creep gamma"), as_finite(t0, "creep t0")
        if gamma < 0 or t0 <= 0 or int(memory) < 1:
            raise ValueError("creep model needs gamma >= 0, t0 > 0 and memory >= 1")
        self.gamma, self.t0, self.memory = gamma, t0, int(memory)
        self.reset()

    def reset(self) -> None:
        """Forget every step."""
        self._events: list[list[float]] = []
        self._frozen = 0.0

    def record(self, t: float, dy: float) -> None:
        """A displacement step ``dy`` (px, as the hysteresis model predicts it) commanded at ``t`` (s)."""
        if dy == 0.0:
            return
        if self._events and self._events[-1][0] == t:
            self._events[-1][1] += dy
            return
        self._events.append([float(t), float(dy)])
        if len(self._events) > self.memory:
            t_old, d_old = self._events.pop(0)
            self._frozen += d_old * self.gamma * math.log10(1.0 + max(t - t_old, 0.0) / self.t0)

    def predict(self, t: float, extra=None) -> float:
        """Creep displacement (px) at time ``t``; ``extra=(t_j, dy_j)`` adds one more (trial) step."""
        c = self._frozen
        events = self._events if extra is None else [*self._events, list(extra)]
        for tj, dj in events:
            if t > tj:
                c += dj * self.gamma * math.log10(1.0 + (t - tj) / self.t0)
        return c

    def __repr__(self) -> str:
        return f"<CreepModel gamma={self.gamma:.4g}/decade t0={self.t0:.3g} s>"


def fit_creep(t, displacement, step_px, *, t0_grid=None) -> CreepModel:
    """Fit the logarithmic creep law to a hold after one step.

    Parameters
    ----------
    t : (N,) array_like
        Seconds since the step was commanded (> 0), e.g. ``(k - 0.5) * frame_period`` for frame ``k``
        after the command (the probe is imaged mid-frame).
    displacement : (N,) array_like
        Measured displacement (px) during the hold; NaN entries are ignored.
    step_px : float
        Size of the step (px).
    t0_grid : array_like, optional
        Candidate time constants (s). Default: 0.1 s only, the reference time of the usual law
        (Jung & Gweon 2000, ``y(t) = y(0.1 s) [1 + gamma log10(t / 0.1 s)]``): a hold of a few seconds
        measured with ~0.1 px noise cannot separate ``gamma`` and ``t0``.

    Returns
    -------
    CreepModel
        ``gamma`` by least squares for each ``t0`` (with a free offset), the best ``t0``.

    References
    ----------
    Jung, H. & Gweon, D.-G. (2000). Creep characteristics of piezoelectric actuators.
    Rev. Sci. Instrum. 71, 1896-1900.
    """
    t = np.asarray(t, float)
    y = np.asarray(displacement, float)
    step = as_finite(step_px, "step_px")
    good = np.isfinite(t) & np.isfinite(y) & (t > 0)
    if good.sum() < 4 or step == 0:
        raise ValueError("a creep fit needs a non-zero step and at least 4 valid samples after it")
    t, y = t[good], y[good]
    grid = np.array([0.1]) if t0_grid is None else np.atleast_1d(np.asarray(t0_grid, float))
    best = None
    for t0 in grid:
        x = step * np.log10(1.0 + t / t0)
        A = np.column_stack([np.ones_like(x), x])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        cost = float(np.sum((A @ coef - y) ** 2))
        if best is None or cost < best[0]:
            best = (cost, float(t0), float(coef[1]))
    return CreepModel(max(best[2], 0.0), best[1])
