"""Misfit tiles: the parts of the band the template does not explain are dropped and the frame refitted.

Huber's loss (:func:`semlab.gauss_newton.gauss_newton_translation`) bounds what one pixel can do, not
what a few dozen neighbouring ones can: a particle over the apex, the rim of an occluder across the
shaft, debris drifting through the band each bring a patch of pixels that are all off by a few noise
standard deviations, each inside Huber's linear range, and together they pull the answer along the
direction the band constrains least (along the shaft). Under the noise model the weighted squared
residuals of a small tile of the band (:func:`semlab.tracking.uncertainty.band_tiles`) are χ² with
as many degrees of freedom as the tile has pixels, on the scale of the band's typical tile (the
median: robust to the misfit tiles themselves and to a misfit the whole band shares); a tile whose
χ² is improbable (p-value below ``p_value``) and whose misfit is a sizeable fraction of the object's
contrast is not explained by the template at this answer, and the fit is repeated without it (eq. 2
over the remaining pixels). The worst tile goes first, so that the tiles a pulled answer
makes misfit around the culprit recover once it is gone; at most :data:`MAX_DROPPED_TILES` tiles and
:data:`MAX_DROPPED_FRACTION` of the band go, so that a frame the template does not explain at all is
left to the flags (its sigma, :mod:`semlab.tracking.consistency`) instead of being trimmed into
agreement. The refit's covariance counts only the pixels kept: dropping a tile costs precision, and
the reported sigma says so.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from scipy.special import chdtrc

from ..subpixel import median

__all__ = ["MAX_DROPPED_FRACTION", "MAX_DROPPED_TILES", "MIN_MISFIT_CONTRAST", "MISFIT_P_VALUE", "TileSums",
           "tile_p_values", "tile_rms", "tile_sums", "trim_misfit_tiles", "typical_tile_variance"]

#: A tile whose residuals' χ² has a p-value below this is a misfit (with ~100 tiles in a band, a
#: frame of pure noise loses a tile about once in 100 frames). On a moving probe many frames lose one
#: tile or two, mostly where the background next to the edge is not the template's; each costs only
#: that tile's precision. Chosen on the evaluation corpus's development seeds (``DEV_SEEDS`` and
#: seeds 200-239, which are in no split): 1e-3 trims more for the same result, 1e-6 misses
#: particles.
MISFIT_P_VALUE = 1e-4
#: At most this many tiles are dropped per fit: a particle or an occluder's rim covers one to three.
MAX_DROPPED_TILES = 3
#: ... and never more than this fraction of the band's pixels.
MAX_DROPPED_FRACTION = 0.25
#: Tiles with at least this many pixels set the typical scale.
MIN_TILE_PIXELS = 8
#: A misfit tile's RMS residual also exceeds this fraction of the object's contrast (both whitened):
#: where the noise is low the template's own shape error at a sharp apex (interpolation, blur) is
#: improbable under the noise too, at 2-13 % of the contrast on a clean wedge (noise 2-8 gray
#: levels), while the tiles a particle, an occluder or the background spoils are 34 % and more
#: on the corpus's development seeds.
MIN_MISFIT_CONTRAST = 0.2


class TileSums(NamedTuple):
    """Per tile of the band: its live pixels (``prior > 0``), and their residuals' squares summed plain and
    weighted by the prior (inverse noise variance)."""

    dof: np.ndarray
    squares: np.ndarray
    weighted: np.ndarray


def tile_sums(residual, prior, labels) -> TileSums:
    """:class:`TileSums` of the residuals at the band's pixels (``labels``: each pixel's tile, ``0 .. n-1``)."""
    prior = np.asarray(prior, float)
    live = prior > 0
    n = int(labels.max()) + 1
    squares = np.where(live, np.asarray(residual, float) ** 2, 0.0)
    return TileSums(np.bincount(labels, weights=live.astype(float), minlength=n),
                    np.bincount(labels, weights=squares, minlength=n),
                    np.bincount(labels, weights=squares * prior, minlength=n))


def tile_rms(sums: TileSums) -> np.ndarray:
    """Per tile, the RMS of the residuals at its live pixels (0 for a tile without any)."""
    return np.sqrt(sums.squares / np.maximum(sums.dof, 1))


def typical_tile_variance(sums: TileSums) -> float:
    """The median over the band's tiles of their mean weighted squared residual: the scale a tile is
    judged against (robust to the few misfit tiles, and to a misfit the whole band shares)."""
    full = sums.dof >= MIN_TILE_PIXELS
    return median(sums.weighted[full] / sums.dof[full]) if full.any() else float("nan")


def tile_p_values(sums: TileSums, noise_variance: float, only=None) -> np.ndarray:
    """Per tile, the probability under the noise of a χ² as large as its residuals'.

    Parameters
    ----------
    sums : TileSums
        The residuals' sums per tile (:func:`tile_sums`).
    noise_variance : float
        The residuals' variance at prior 1 (:func:`typical_tile_variance`).
    only : (n,) ndarray of bool, optional
        The tiles to judge (the others get 1): the χ² tail is the costly part.

    Returns
    -------
    (n,) ndarray
        ``P(χ²_k > Σ prior·r² / noise_variance)`` with ``k`` the tile's live pixels; 1 for a tile
        without any.
    """
    dof = sums.dof
    judged = dof > 0 if only is None else (dof > 0) & only
    p = np.ones(len(dof))
    p[judged] = chdtrc(dof[judged], sums.weighted[judged] / noise_variance)  # the χ² survival function, as a ufunc
    return p


def trim_misfit_tiles(fit, refit: Callable, labels, prior, p_value: float = MISFIT_P_VALUE, floor: float = 0.0):
    """Drop the band's misfit tiles one at a time, worst first, refitting after each.

    Parameters
    ----------
    fit : FitResult
        The frame's registration over the whole band (its ``residual`` at every band pixel).
    refit : callable
        ``refit(keep, fit) -> FitResult``: the registration again, from ``fit``'s answer, over the
        band pixels ``keep`` only (the others weigh 0; ``residual`` still at every band pixel).
    labels : (K,) ndarray of int
        The band pixels' tiles.
    prior : (K,) ndarray or None
        The band's inverse noise variances (relative); None: equal.
    p_value : float
        :data:`MISFIT_P_VALUE`.
    floor : float
        A misfit tile's RMS residual exceeds this too (e.g. :data:`MIN_MISFIT_CONTRAST` times the
        object's contrast).

    Returns
    -------
    (FitResult, (K,) ndarray of bool or None)
        The last converged fit and the band pixels it kept (None: nothing was dropped).
    """
    prior = np.ones(len(labels)) if prior is None else np.asarray(prior, float)
    keep = None
    for _ in range(MAX_DROPPED_TILES):
        if not fit.converged or fit.residual is None or len(fit.residual) != len(labels):
            break
        sums = tile_sums(fit.residual, prior if keep is None else prior * keep, labels)
        # The floor first: where no tile passes it, the χ² is not needed.
        above = tile_rms(sums) > floor
        if not above.any():
            break
        variance = typical_tile_variance(sums)
        if not np.isfinite(variance) or variance <= 0:
            break
        p = tile_p_values(sums, variance, only=above)
        worst = int(np.argmin(p))
        if p[worst] >= p_value:
            break
        candidate = (labels != worst) if keep is None else keep & (labels != worst)
        if 1.0 - candidate.mean() > MAX_DROPPED_FRACTION:
            break
        try:
            trimmed = refit(candidate, fit)
        except (ValueError, np.linalg.LinAlgError):
            break
        if not trimmed.converged:
            break
        fit, keep = trimmed, candidate
    return fit, keep
