"""Whether the parts of the band agree on the answer: a frame one part of the band pulls is not trusted.

A registration's covariance (:mod:`semlab.tracking.uncertainty`) says how well the frame's noise
lets the band fix the shift, assuming the template explains the frame. Where it does not — a
static substrate that the template took for part of the object, clutter over one side of the
probe, a particle that touched its edge in frame 0 — the band's parts disagree: one part, left to
itself, would put the object elsewhere than the rest. So at the answer the band is split into
quadrants (at its centroid, along its principal axes) and, for each, the answer is recomputed
without it, one linearised Gauss–Newton step (eq. 2 with the Jacobian ``M₀`` of eqs. 4-5, the
quadrant's rows removed). When leaving one quadrant out moves the answer by more than
:data:`MAX_INFLUENCE_PX` and that move is significant under the noise (its χ² against the two
estimates' covariances exceeds :data:`INFLUENCE_CHI2`), the frame is reported ``ok=False``
("inconsistent"). Both conditions matter: a quadrant that only sees straight edges (the shaft)
may disagree along them by a pixel while its own covariance says so (large move, small χ²), and
a very precise frame may disagree significantly by a few hundredths of a pixel (small move,
large χ²); neither is a reason to distrust the answer.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["INFLUENCE_CHI2", "MAX_INFLUENCE_PX", "Influence", "band_quadrants", "inconsistent", "quadrant_influence"]

#: Leaving one quadrant of the band out may move the answer by at most this (px). Chosen on the
#: evaluation corpus's development seeds (``semlab.evaluation.DEV_SEEDS``): 0.5 px takes the frames
#: more than 1 px off that say ``ok`` from 5.5 to 1.8 % of the cluttered family's and from 4.2 to
#: 1.0 % of the substrates', and flags none of the still probe's and the shapes' frames.
MAX_INFLUENCE_PX = 0.5
#: ... and only when that move is significant: χ² (2 degrees of freedom) of the quadrant's own
#: estimate against the rest's above this (a false alarm about once in 20 000 quadrants under the
#: noise alone, P(χ²₂ > 20) = e⁻¹⁰).
INFLUENCE_CHI2 = 20.0
#: Fewest band pixels a quadrant needs to be judged on its own.
MIN_QUADRANT_PIXELS = 10


class Influence(NamedTuple):
    """The largest move of the answer (px) when one quadrant of the band is left out, and the χ²
    of that quadrant's own estimate against the rest's (2 degrees of freedom)."""

    shift_px: float
    chi2: float


def band_quadrants(points) -> np.ndarray:
    """Labels 0-3 of the band's points: their side of the centroid along each principal axis.

    Parameters
    ----------
    points : (K, 2) array_like
        The band's pixel coordinates.

    Returns
    -------
    (K,) ndarray of int
    """
    pts = np.asarray(points, np.float64)
    centred = pts - pts.mean(axis=0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    along, across = centred @ axes[:, 1], centred @ axes[:, 0]
    return (2 * (along > 0) + (across > 0)).astype(np.intp)


def quadrant_influence(jacobian, residual, weights, noise_variance: float, labels) -> Influence | None:
    """How far the answer moves when each quadrant is left out, at a converged registration.

    At the answer the estimating equation ``Σ w J r = 0`` holds over the whole band (``J = g ∇T``,
    the rows of ``M₀``). Without quadrant ``q`` one Gauss–Newton step gives the rest's estimate
    ``δ_rest = N_rest⁻¹ b_rest`` (``N = Σ w J Jᵀ``, ``b = Σ w J r`` over the rest), and the
    quadrant's own ``δ_q = N_q⁻¹ b_q``; their difference has covariance ``s² (N_q⁻¹ + N_rest⁻¹)``.

    Parameters
    ----------
    jacobian : (K, 2) array_like
        ``g ∇T`` at the band's pixels: the gain times the template's gradients (the fit's Jacobian).
    residual, weights : (K,) array_like
        The fit's last residuals and its weights (noise prior × robust weights).
    noise_variance : float
        ``s²``, the residuals' variance (the fit's own estimate).
    labels : (K,) array_like of int
        :func:`band_quadrants`.

    Returns
    -------
    Influence or None
        None when the whole band's normal matrix is singular or no quadrant can be judged.
    """
    jac = np.asarray(jacobian, np.float64)
    w = np.asarray(weights, np.float64)
    r = np.asarray(residual, np.float64)
    labels = np.asarray(labels, np.intp)
    n_groups = int(labels.max()) + 1 if labels.size else 0
    jx, jy = jac[:, 0], jac[:, 1]
    wx, wy = w * jx, w * jy

    def per_group(values):
        return np.bincount(labels, weights=values, minlength=n_groups)

    # Each quadrant's normal matrix [[a, b], [b, c]] and right-hand side (u, v), one pass each.
    a, b, c = per_group(wx * jx), per_group(wx * jy), per_group(wy * jy)
    u, v = per_group(wx * r), per_group(wy * r)
    counts = np.bincount(labels, minlength=n_groups)
    total = (float(a.sum()), float(b.sum()), float(c.sum()))
    whole = _inverse(*total)
    if whole is None:
        return None
    tu, tv = float(u.sum()), float(v.sum())
    joint = _apply(whole, tu, tv)
    largest, chi2 = None, 0.0
    # (2×2 algebra on Python floats: a LAPACK call per quadrant costs more than the sums.)
    for q in np.nonzero(counts >= MIN_QUADRANT_PIXELS)[0].tolist():
        own = (float(a[q]), float(b[q]), float(c[q]))
        inv_q = _inverse(*own)
        inv_rest = _inverse(total[0] - own[0], total[1] - own[1], total[2] - own[2])
        if inv_q is None or inv_rest is None:
            continue
        rest = _apply(inv_rest, tu - float(u[q]), tv - float(v[q]))
        mine = _apply(inv_q, float(u[q]), float(v[q]))
        dx, dy = mine[0] - rest[0], mine[1] - rest[1]
        spread = _inverse(*(noise_variance * (p + s) for p, s in zip(inv_q, inv_rest)))
        if spread is None:
            continue
        significance = dx * (spread[0] * dx + spread[1] * dy) + dy * (spread[1] * dx + spread[2] * dy)
        move = math.hypot(rest[0] - joint[0], rest[1] - joint[1])
        if math.isfinite(move) and (largest is None or move > largest):
            largest, chi2 = move, significance
    return None if largest is None else Influence(largest, chi2)


def _inverse(a: float, b: float, c: float):
    """``(a', b', c')`` of the inverse of the symmetric ``[[a, b], [b, c]]``, or None unless positive definite."""
    det = a * c - b * b
    if not (det > 0 and a > 0 and math.isfinite(det)):
        return None
    return c / det, -b / det, a / det


def _apply(inverse, u: float, v: float):
    """The symmetric 2×2 ``inverse`` times ``(u, v)``."""
    ia, ib, ic = inverse
    return ia * u + ib * v, ib * u + ic * v


def inconsistent(influence: Influence | None, max_shift_px: float = MAX_INFLUENCE_PX,
                 min_chi2: float = INFLUENCE_CHI2) -> bool:
    """Whether one quadrant moves the answer by more than ``max_shift_px``, significantly."""
    return influence is not None and influence.shift_px > max_shift_px and influence.chi2 > min_chi2
