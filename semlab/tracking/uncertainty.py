"""How far off a frame's answer may be: its standard uncertainty, and when it is too large to trust.

A position is ``ROI centre + shift − origin`` (:class:`~semlab.tracking.Tracker`): the frame's
registration and frame 0's (the origin) both carry noise, so the position's covariance is the sum
of the two fits' covariances (:meth:`~semlab.tracking.registration.FitResult.covariance`: the
Fisher information of the band under the noise measured in the frame's own residuals). What the
fits cannot see — the static background beside the object pulling the estimate, appearance that
changes in a way no gain and offset describe — is a model error (:func:`model_error`): a floor,
growing with the fit's change of gain since frame 0 and with how much worse its match score is than
a clean scene's, its constants fitted on the evaluation corpus's development seeds
(``semlab.evaluation.DEV_SEEDS``) so that 95 % ellipses hold 90-98 % of the frames; the whole is
scaled by a calibration factor (1). Against a template of one or two frames the fits' part is
reported larger (:func:`young_template_inflation`): such a template's own noise and background are in
every answer.

A frame whose own data allow no better than :data:`SIGMA_LIMIT_PX` is not trusted: the tracker
follows it (its motion state moves on) but reports ``ok=False``, so that nothing downstream (the
servo) acts on a number that may be a pixel off; nor is a frame that claims much better than the
frames before it (:class:`RecentPrecision`). What a frame's precision cannot see — a part of the
band that disagrees with the rest — is judged by :mod:`semlab.tracking.consistency`. Nor is an
answer that jumped away from the prediction to a match poorer than the track's typical one
(:func:`ambiguous_jump`): another minimum of the cost, which may be the object or something that looks
partly like it. Over a strongly textured substrate, nor is an answer whose match fell well under the
track's first frames' (:func:`slid_on_texture`): the registration has slid onto grains that stay where
they are.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np

from ..subpixel import median
from .consistency import Influence

__all__ = [
    "AMBIGUOUS_JUMP_PX",
    "CALIBRATION",
    "CLUSTER_TILE_PX",
    "INTEGER_VARIANCE_PX2",
    "MAX_TEXTURED_SCORE_DROP",
    "MIN_RECENT_FRAMES",
    "MIN_RESOLVED_CONTRAST",
    "MIN_TRACK_SCORE",
    "MODEL_ERROR_PER_GAIN_PX",
    "MODEL_ERROR_PER_MISFIT_PX",
    "MODEL_ERROR_PX",
    "RECENT_FRAMES",
    "SIGMA_LIMIT_PX",
    "TYPICAL_MATCH_SCORE",
    "UNVOUCHED_JUMP_PX",
    "YOUNG_TEMPLATE_FRAMES",
    "YOUNG_TEMPLATE_INFLATION",
    "RecentPrecision",
    "Uncertainty",
    "ambiguous_jump",
    "ambiguous_jump_limit",
    "band_tiles",
    "clustered_covariance",
    "least_squares_covariance",
    "model_error",
    "position_sigma",
    "slid_on_texture",
    "too_uncertain",
    "unexplained",
    "unresolved",
    "young_template_inflation",
]

#: A frame is not trusted above this standard uncertainty (px, either axis). A silent error is an
#: ok frame more than 1 px off; for a calibrated Gaussian error of standard deviation σ per axis,
#: P(|e| > 1 px) = 2Φ(−1/σ), at most 0.5 % (the corpus's target) when 1/σ ≥ 2.81, σ ≤ 0.356 px.
SIGMA_LIMIT_PX = 0.35
#: The factor that makes the reported σ hold what it claims, on the corpus's development seeds
#: (``semlab evaluate --split dev``): with the fits' covariances alone, 94.5 % of a still probe's
#: frames and 92 % of the 200-px moves' lie inside their 95 % ellipses, so 1.
CALIBRATION = 1.0
#: What the fits cannot see once the object has moved (px, each axis), at least: the static
#: background beside it biases the answer by about a tenth of a pixel on the corpus's moving families
#: (development seeds). The appearance terms below add to it in quadrature.
MODEL_ERROR_PX = 0.08
#: ... plus this much (px) per unit of relative gain change since frame 0 (``|g − 1|``): a probe
#: that brightens by charging does so without its rim and the substrate beside it, which no one
#: gain describes (the corpus's probe-only charging: gains 0.2-0.4 off, biases 0.2-0.3 px).
MODEL_ERROR_PER_GAIN_PX = 1.0
#: ... plus this much (px) per unit of match score below :data:`TYPICAL_MATCH_SCORE`: a template
#: that explains the frame less well than a clean scene's (texture it does not share, the
#: semi-real needle: scores about 0.7, biases about 0.3 px).
MODEL_ERROR_PER_MISFIT_PX = 2.0
#: A clean scene's match score: the median on the development seeds of the families without
#: appearance change is 0.94-0.95.
TYPICAL_MATCH_SCORE = 0.95
#: The model error (:func:`model_error`) reaches its full size once the object has moved this far
#: (px) from where frame 0 saw it (it grows from 0, the origin, over about the edge's width).
MODEL_ERROR_REACH_PX = 1.0
#: While the template averages fewer than this many frames (frame 0 alone, then frames 0-1: the
#: averaged template is refreshed at 2, 4, 8, ... frames) ...
YOUNG_TEMPLATE_FRAMES = 4
#: ... the fit's standard uncertainty is reported this many times larger (:func:`young_template_inflation`).
#: Such a template's gradients carry its own noise, which the fit counts as information (a wedge at
#: noise 16 against frame 0: 0.14 px said, 0.29 px scattered), and its static background pulls the
#: small displacements of the first frames. On the development seeds the 95 % ellipses of frames 1-3
#: held 0.73-0.87 of the ok frames of the still, moving, jump, wander and substrate families (0.91-0.99
#: later); with this factor 0.77-0.95, every other frame unchanged.
YOUNG_TEMPLATE_INFLATION = 1.5
#: A frame's precision is judged against the median of this many recent frames' (:class:`RecentPrecision`):
#: enough that one odd frame does not set it, few enough to follow a change of dose or contrast within a
#: second at 13 Hz.
RECENT_FRAMES = 5
#: ... once this many are known (a median of fewer is one frame's say).
MIN_RECENT_FRAMES = 3


#: Frame 0's object is resolved when its contrast stands at least this many standard deviations of the
#: smoothed noise above its background (twice the 3 σ below which :meth:`~semlab.tracking.Tracker.init`
#: refuses the ROI as noise): a 3 σ margin on each side of Otsu's threshold. Below it, at low dose, the
#: noise bumps a thin shaft's outline as much as its tip does, and the registration slides along the
#: shaft by pixels while the fit's Fisher information claims a few tenths (:func:`unresolved`). On the
#: evaluation corpus's development seeds no ok frame within 1 px comes from such a scene; on its spare
#: seeds (200-259) they hold 18 frames more than 1 px off reported ok, and 6 within it.
MIN_RESOLVED_CONTRAST = 6.0
#: A track is explained by its template when its first frames match it at a median score (weighted
#: normalised correlation at the band, :class:`~semlab.tracking.registration.FitResult`) of at least
#: this: a score of 0.6 says the template accounts for a third of the frames' variance at the band
#: (0.6² = 0.36), the rest is noise or what the template does not share (:func:`unexplained`). On
#: the evaluation corpus's development and spare seeds (100-119, 200-299) the semi-real needle's
#: tracks under it held 212 of its 220 ok frames more than 1 px off (biased by a pixel while the
#: fits' precision said 0.2-0.3 px), and 1055 within it; every simulated family's track stays
#: above 0.77 but the low-dose ones (0.22-0.70, nearly every frame flagged already); the real
#: needle of ``contact_brightness_seq`` at 0.78-0.84.
MIN_TRACK_SCORE = 0.6
#: Over a strongly textured substrate (frame 0's background at least
#: :data:`~semlab.tracking.band.FLAT_BACKGROUND_TEXTURE` times the noise, which the band model
#: flattens), an answer whose match scores more than this under the track's first frames' median is
#: not trusted (:func:`slid_on_texture`). There grains as bright as the probe lie along a thin tip's
#: flanks, some of them inside Otsu's region, and stay where they are while the probe moves: the
#: registration can slide along the shaft onto them, pixels off while its precision says a few tenths,
#: and the match then falls as the probe's edges leave the template's. On the evaluation corpus's
#: development and spare seeds (100-119, 200-299) the 25 such scenes held 124 ok frames more than 1 px
#: off in 1155 (three tracks slid by 2-18 px), and a drop of 0.06 takes about half of them for a few
#: good frames (0.04: more of them for five times as many good ones). Over the other scenes a falling
#: match is an occluder the robust weights handle or a change of charge the gain follows; judged the
#: same way there, it takes 12 of 72 such frames for 1070 good ones.
MAX_TEXTURED_SCORE_DROP = 0.06
#: An answer farther than this (px) from both the constant-velocity prediction and the last position is
#: another minimum of the cost than the one the track was in: a followed object sits within a pixel of
#: its prediction, and a change of speed the registration follows from there moves it at most this far
#: (:data:`~semlab.tracking.ic.STEADY_MAX_MOVE_PX`), or as far as the track expected it to move in
#: the frame when its last prediction held (an object may stop or double its speed: the real needle of
#: ``contact_brightness_seq`` slows from 10 px a frame to 5 as it bends at contact; after a jump the
#: speed is no motion to extrapolate). There the match's score must vouch for it
#: (:func:`ambiguous_jump`): with the tip hidden under a passing occluder the whole-frame search finds
#: the shaft tens of px along its axis, as well matched as the hidden tip's frames around it and far
#: below the track's typical match.
AMBIGUOUS_JUMP_PX = 3.0
#: Before the track has a typical score (frame 1 is always searched, and the coarse search's answer
#: stood instead of the registration's, which records no score), an answer farther than this (px) from the
#: prediction is ambiguous whatever its score: from frame 0's position a still or slowly moving object is
#: within a pixel (:data:`~semlab.tracking.ic.STEADY_PX`) and the registration converges from there, so
#: a search answer that differs by more is another minimum, and no registered frame's score can vouch for
#: it. On the corpus's development and spare seeds such frame-1 answers were more than 1 px off the truth
#: in 12 of 13 ok frames (1.1-7.3 px, at low dose and on the semi-real needle; the thirteenth, 0.75 px
#: from frame 0, was right).
UNVOUCHED_JUMP_PX = 1.0


#: The clustered covariance (:func:`clustered_covariance`) groups the band's pixels in tiles of this
#: many px: a template's misfit (texture the template does not share, an edge profile that changed) is
#: correlated over about an edge's width (the beam's blur and the template's smoothing, 2-4 px), so
#: tiles this size hold one correlated patch each, and a band holds a hundred of them or more.
CLUSTER_TILE_PX = 4


#: Variance (px²) of rounding to the nearest pixel: a uniform error over one pixel, 1/12.
INTEGER_VARIANCE_PX2 = 1.0 / 12.0


def least_squares_covariance(jacobian, residual) -> np.ndarray:
    """Covariance (px², 2×2) of a least-squares shift: ``s² (JᵀJ)⁻¹``, ``s²`` the residuals' variance.

    Parameters
    ----------
    jacobian : (K, 2) array_like
        The derivative of the model at each pixel with respect to the shift.
    residual : (K,) array_like
        The residuals at the answer.

    Returns
    -------
    (2, 2) ndarray
        Infinite when the system is singular or has no degrees of freedom left.
    """
    j = np.asarray(jacobian, float)
    r = np.asarray(residual, float)
    dof = r.size - j.shape[1]
    if dof <= 0:
        return np.full((2, 2), np.inf)
    try:
        inverse = np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        return np.full((2, 2), np.inf)
    return float(r @ r) / dof * inverse


def band_tiles(points, tile: int = CLUSTER_TILE_PX) -> np.ndarray:
    """Labels ``0 .. G−1`` of the ``tile``-px square each of the band's ``points`` (x, y) lies in."""
    pts = np.asarray(points, np.float64)
    cells = np.floor(pts / tile).astype(np.int64)
    _, labels = np.unique(cells[:, 1] * (cells[:, 0].max() + 1) + cells[:, 0], return_inverse=True)
    return labels.ravel()


def clustered_covariance(jacobian, residual, weights, clusters) -> np.ndarray:
    """Cluster-robust ("sandwich") covariance (px², 2×2) of a weighted least-squares shift.

    ``N⁻¹ V N⁻¹`` with ``N = Σ w J Jᵀ`` and ``V = G/(G−1) Σ_g (s_g − s̄)(s_g − s̄)ᵀ``, ``s_g = Σ_{i∈g}
    w_i J_i r_i`` the score of cluster ``g`` (Liang & Zeger 1986). Where the residuals are
    independent noise it agrees with ``s² N⁻¹`` (eq. 9's covariance); where the template's misfit is
    correlated over a few px — and so pulls the answer much more than independent noise of the
    same size — it says so, along the direction the misfit pulls.

    Parameters
    ----------
    jacobian : (K, 2) array_like
        The derivative of the model at each pixel with respect to the shift.
    residual, weights : (K,) array_like
        The residuals at the answer and the weights of the fit (noise prior × robust weights).
    clusters : (K,) array_like of int
        Labels ``0 .. G−1`` (:func:`band_tiles`).

    Returns
    -------
    (2, 2) ndarray
        Infinite when the system is singular or there are fewer than 3 clusters.
    """
    j = np.asarray(jacobian, np.float64)
    w = np.asarray(weights, np.float64)
    labels = np.asarray(clusters, np.intp)
    n_clusters = int(labels.max()) + 1 if labels.size else 0
    if n_clusters < 3:
        return np.full((2, 2), np.inf)
    wj = j * w[:, None]
    try:
        inverse = np.linalg.inv(wj.T @ j)
    except np.linalg.LinAlgError:
        return np.full((2, 2), np.inf)
    scores = wj * np.asarray(residual, np.float64)[:, None]
    per_cluster = np.stack([np.bincount(labels, weights=scores[:, k], minlength=n_clusters) for k in range(2)], axis=1)
    per_cluster -= per_cluster.mean(axis=0)
    middle = per_cluster.T @ per_cluster * (n_clusters / (n_clusters - 1))
    return inverse @ middle @ inverse


class Uncertainty(NamedTuple):
    """An answer's standard uncertainty: ``sigma`` ``(x, y)`` px, what it reports (the fits and the
    model error), and ``precision``, what the frame's own data allow (the fits alone), by which it
    is judged too uncertain to trust (:func:`too_uncertain`), no better than the recent frames'
    (:class:`RecentPrecision`): a frame is flagged for what its data cannot tell, not for the bias
    the corpus measured on average."""

    sigma: tuple[float, float]
    precision: tuple[float, float]
    #: How far one part of the band pulls the answer (:mod:`semlab.tracking.consistency`), or None.
    influence: Influence | None = None


class RecentPrecision:
    """A frame's precision judged against the recent frames': no better than their median.

    Where a track's frames allow about :data:`SIGMA_LIMIT_PX` (a thin needle at low dose), the frame
    whose own precision dips under the limit has more often registered onto something sharper than
    the probe — noise blobs frame 0's contour took in — than seen the probe better: on the
    corpus's thin low-dose needle (development seed 114) all five frames reported ok were 7-25 px off.
    So a frame is credited with ``max(own, median of the last RECENT_FRAMES, its own included)``
    per axis once :data:`MIN_RECENT_FRAMES` are known; a sharp track (every frame well under the
    limit) is unaffected.
    """

    def __init__(self) -> None:
        self.recent: deque[tuple[float, float]] = deque(maxlen=RECENT_FRAMES)

    def judged(self, precision: tuple[float, float]) -> tuple[float, float]:
        """``precision`` (px, x and y), no better than the recent frames' median; records it when
        finite (a frame with no precision neither counts nor is changed)."""
        own = (float(precision[0]), float(precision[1]))
        if not all(math.isfinite(p) for p in own):
            return own
        self.recent.append(own)
        if len(self.recent) < MIN_RECENT_FRAMES:
            return own
        recent = np.asarray(self.recent)
        return max(own[0], median(recent[:, 0])), max(own[1], median(recent[:, 1]))


def young_template_inflation(n_averaged: int) -> float:
    """How much larger than the fit's own (eq. 9's) the reported standard uncertainty of a frame
    registered against a template of ``n_averaged`` frames is: :data:`YOUNG_TEMPLATE_INFLATION` while
    fewer than :data:`YOUNG_TEMPLATE_FRAMES`, else 1. The precision a frame is judged by (the flags)
    is not inflated: the factor says how far off the answer may be, not that the frame saw less.
    """
    return YOUNG_TEMPLATE_INFLATION if n_averaged < YOUNG_TEMPLATE_FRAMES else 1.0


def model_error(displacement_px: float, gain: float = 1.0, score: float = TYPICAL_MATCH_SCORE) -> float:
    """The model error (px, each axis) of an answer ``displacement_px`` from frame 0's position.

    ``sqrt(M² + (k_g |g − 1|)² + (k_s max(0, S − score))²)`` (:data:`MODEL_ERROR_PX`,
    :data:`MODEL_ERROR_PER_GAIN_PX`, :data:`MODEL_ERROR_PER_MISFIT_PX`, :data:`TYPICAL_MATCH_SCORE`),
    growing from 0 at frame 0's position (the origin) to its full size at
    :data:`MODEL_ERROR_REACH_PX`. The three constants are fitted on the corpus's development seeds so
    that the 95 % ellipses hold 90-98 % of the ok frames in as many families as one rule allows.

    Parameters
    ----------
    displacement_px : float
        How far the answer is from frame 0's (px); not finite: the full model error.
    gain : float
        The fit's gain against the template (eq. 2's photometric model; 1 where nothing changed).
    score : float
        The fit's match score (0-1).
    """
    d = float(displacement_px)
    reach = 1.0 if not math.isfinite(d) else min(1.0, abs(d) / MODEL_ERROR_REACH_PX)
    g = float(gain) if math.isfinite(gain) else 1.0
    misfit = max(0.0, TYPICAL_MATCH_SCORE - float(score)) if math.isfinite(score) else 0.0
    full = math.sqrt(MODEL_ERROR_PX ** 2 + (MODEL_ERROR_PER_GAIN_PX * (g - 1.0)) ** 2
                     + (MODEL_ERROR_PER_MISFIT_PX * misfit) ** 2)
    return full * reach


def position_sigma(frame_cov, origin_cov=None, *, model_sd: float = 0.0,
                   calibration: float = CALIBRATION) -> tuple[float, float]:
    """``(sigma_x, sigma_y)`` px of a position ``shift − origin``.

    Parameters
    ----------
    frame_cov : (2, 2) array_like
        Covariance of the frame's shift (px²).
    origin_cov : (2, 2) array_like or None
        Covariance of the origin (frame 0's shift against the same template); None: exact.
    model_sd : float
        Standard deviation (px) of what the fits cannot see, added on both axes.
    calibration : float
        Scale of the result.

    Returns
    -------
    (float, float)
        ``inf`` where a covariance is not finite.
    """
    # The two variances on Python floats (the same float64 sums as the matrices', a frame's worth of
    # numpy calls fewer).
    frame = np.asarray(frame_cov, float)
    var = [float(frame[0, 0]), float(frame[1, 1])]
    if origin_cov is not None:
        origin = np.asarray(origin_cov, float)
        var = [var[0] + float(origin[0, 0]), var[1] + float(origin[1, 1])]
    model_var = model_sd * model_sd
    var = [v + model_var for v in var]
    if not all(math.isfinite(v) and v >= 0 for v in var):
        return math.inf, math.inf
    return calibration * math.sqrt(var[0]), calibration * math.sqrt(var[1])


def unresolved(contrast_noise: float, limit: float = MIN_RESOLVED_CONTRAST) -> bool:
    """Whether frame 0's object stands less than ``limit`` noise standard deviations above its
    background (``contrast_noise``: its contrast over the smoothed noise, infinite for a noiseless
    frame; not a number counts as unresolved)."""
    return not contrast_noise >= limit


def unexplained(track_score: float | None, limit: float = MIN_TRACK_SCORE) -> bool:
    """Whether a track's median match score so far, ``track_score`` (None: none yet, nothing to judge
    by), is under ``limit`` (or not a number): its template does not explain the frames well enough
    for the fits' precision to vouch for an answer."""
    return track_score is not None and not track_score >= limit


def ambiguous_jump(jump_px: float, score: float, typical_score: float | None,
                   limit_px: float = AMBIGUOUS_JUMP_PX) -> bool:
    """Whether an answer ``jump_px`` off the track (from both its prediction and its last position) is
    another minimum of the cost that its match does not vouch for: farther than ``limit_px``, with a
    ``score`` under the track's ``typical_score``; or, with no typical score yet (None: frame 1 found
    by the coarse search), farther than ``UNVOUCHED_JUMP_PX`` (or ``limit_px`` if smaller) whatever
    its score."""
    if jump_px <= ambiguous_jump_limit(typical_score, limit_px):
        return False
    return typical_score is None or not score >= typical_score


def ambiguous_jump_limit(typical_score: float | None, limit_px: float = AMBIGUOUS_JUMP_PX) -> float:
    """How far (px) an answer may jump before :func:`ambiguous_jump` judges it: ``limit_px`` once the
    track has a typical score, at most :data:`UNVOUCHED_JUMP_PX` before."""
    return limit_px if typical_score is not None else min(limit_px, UNVOUCHED_JUMP_PX)


def too_uncertain(sigma: tuple[float, float], limit: float = SIGMA_LIMIT_PX) -> bool:
    """Whether either axis's uncertainty exceeds ``limit`` (or is not a number)."""
    return not all(math.isfinite(s) and s <= limit for s in sigma)


def slid_on_texture(score: float, track_score: float | None, limit: float = MAX_TEXTURED_SCORE_DROP) -> bool:
    """Whether a match of ``score`` lies more than ``limit`` under the track's first frames'
    median ``track_score`` (None: no track score yet, never), judged only over a strongly textured
    substrate (see :data:`MAX_TEXTURED_SCORE_DROP`)."""
    return track_score is not None and score < track_score - limit
