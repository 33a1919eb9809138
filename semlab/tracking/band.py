"""The registration band and the template model built on it (offline, once per template).

The band is the set of template pixels within a few px of the contour template (paper, Fig. 1c):
nearly all the positional information of a probe is at its edges. :func:`band_widths` says how
far it reaches on each side, :func:`registration_band` draws it, and :class:`BandModel` holds
everything the per-frame registration needs from the template at the band's pixels, computed
once: the whitened template and its gradients (the Jacobian, the paper's offline matrix ``M₀``
of eqs. 4-5) at full resolution and at each smoothed level, the noise weights, the object/
background split, the background tiles and the Gauss–Newton constants.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np
from skimage.restoration import denoise_nl_means

from ..gauss_newton import gauss_newton_setup
from ..subpixel import (
    FIVE_POINT_KERNEL,
    MAD_TO_SD,
    NoiseModel,
    five_point_gradients,
    whiten_lines,
)
from ..template import ContourTemplate
from .options import BandOptions, TrackerOptions
from .uncertainty import band_tiles

__all__ = [
    "DEFAULT_BAND_PX",
    "DENOISE_FROM_FRAMES",
    "EDGE_BAND_SIGMAS",
    "FLAT_BACKGROUND_TEXTURE",
    "MAX_EDGE_BAND_PX",
    "MIN_BAND_PIXELS",
    "NARROW_BAND_TEXTURE",
    "BandModel",
    "Level",
    "background_sectors",
    "background_texture",
    "band_widths",
    "build_band_model",
    "contour_band",
    "contour_core",
    "edge_blur",
    "far_from_region",
    "flattened_background",
    "inner_mask",
    "region_contrast",
    "registration_band",
]

#: Half-width (px) of the contour band unless told otherwise.
DEFAULT_BAND_PX = 3
#: How far (px) the "ic" band reaches into a textured background (:func:`band_widths`).
NARROW_BAND_PX = 2
#: Background texture over noise (standard deviations) from which the "ic" band reaches only
#: :data:`NARROW_BAND_PX` into the background (:func:`band_widths`): between what frame 0 of the
#: simulator's textured substrate measures (about half the noise and more, at standard dose) and a
#: flat background (a quarter of it at most, the noise model's estimate being a few % low).
NARROW_BAND_TEXTURE = 0.4
#: The "ic" band reaches this many standard deviations of the edge's blur (:func:`edge_blur`) to
#: each side of the contour, where that is farther than the widths above: a blurred edge (a real
#: needle's, 1-2 px) carries its position over its whole transition, which a 2-3 px band cuts off
#: (3 σ: 99.7 % of an erf edge's slope; the simulator's edges, σ ≈ 0.5 px, keep the widths above).
EDGE_BAND_SIGMAS = 3.0
#: ... but no farther than this (px): a wider band takes in the static surroundings beside the edge
#: (a lamella the needle touches: at 6-7 px its quadrant pulls the real needle's contact frame of
#: ``contact_brightness_seq`` 2 px off and the frame is flagged inconsistent; at 5 px it is not).
MAX_EDGE_BAND_PX = 5
#: :func:`edge_blur` smooths frame 0 by this many px before reading the edge's slope (noise would
#: otherwise make the slope steeper: the blur is then underestimated, never over).
EDGE_SMOOTHING_PX = 1.0
#: The slope is read at the contour pixels this far (px) inside the ROI, within this many px
#: across the edge (a 5×5 neighbourhood: the contour is the Otsu level, not the steepest point).
EDGE_BORDER_PX = 8
EDGE_SEARCH_PX = 2
#: The "ic" Jacobian is denoised (``jacobian_denoise``) once the template averages this many frames:
#: averaged over fewer, a low-dose template is too noisy for NL-means' patch similarity to mean anything.
DENOISE_FROM_FRAMES = 4
#: Fewest band pixels a template may have: translation, gain, offset and the background tiles'
#: levels are fitted to them (a synthetic tip in a 16×16 ROI leaves 16, read 3.5 px off with a
#: normal score; 36 in an 18×18 one are sometimes lost, but flagged; 63 in a 20×20 one: fine).
MIN_BAND_PIXELS = 30
#: The band keeps this many px more than its half-width from the ROI border: there the contour
#: segments are where the object leaves the ROI, not edges of it.
BORDER_MARGIN_PX = 3
#: Over a background whose texture is at least this many times the noise (:func:`background_texture`, on
#: frame 0), the "ic" band model sees the template's background flattened (:func:`flattened_background`):
#: the strongly textured substrates of the corpus reach 1.5-2.2, every other family's scenes stay under 1.4.
FLAT_BACKGROUND_TEXTURE = 1.5
#: ... beyond this many px from the object's region, to its local mean over a Gaussian of this σ (px).
FLAT_FROM_PX = 1.0
FLAT_SIGMA_PX = 4.0
#: "contour" matching uses the contour pixels this far inside the ROI, unless fewer than
#: :data:`MIN_CORE_PIXELS` remain.
CORE_MARGIN_PX = 2
MIN_CORE_PIXELS = 5
#: Background texture: pixels at least this far (px) from the object, this far from the ROI
#: border, and at least this many of them.
TEXTURE_DISTANCE_PX = 4.0
TEXTURE_BORDER_PX = 3
MIN_TEXTURE_PIXELS = 50
#: The Jacobian's smoothing (px) is this many times the template's noise over its contrast,
#: clipped to ``[jacobian_sigma, jacobian_sigma_first]``: a noisy template needs a smoother one.
JACOBIAN_SIGMA_PER_NOISE = 5.0
#: NL-means on the template before the Jacobian: 7×7 patches in a 13×13 search (5×5 doubled the
#: low-dose error on some seeds, 3×3 was worse everywhere: ``benchmarks/bench_tracking_seeds.py``).
NL_MEANS_PATCH = 7
NL_MEANS_DISTANCE = 6
#: NL-means' value at a pixel reads the template this far (px) around it: the search distance plus
#: the half patch. The 5-point derivative reads this far (px) along its axis.
NL_MEANS_REACH_PX = NL_MEANS_PATCH // 2 + NL_MEANS_DISTANCE
FIVE_POINT_REACH_PX = len(FIVE_POINT_KERNEL) // 2
#: ``photometry="instrument"``: the gain's instrument is the template smoothed by this many px.
INSTRUMENT_SIGMA = 1.5
#: The noise weights take the gray level from the template smoothed by this many px.
NOISE_LEVEL_SIGMA = 1.0
#: The smoothed registration levels, in units of ``coarse_sigma``, widest first.
LADDER = (4.0, 2.0, 1.0)
#: Only the band's neighbourhood is filtered: this many Gaussian σ of the widest kernel, plus the
#: 5-point derivative's reach and a margin, around it.
FILTER_REACH_SIGMAS = 4.0
FILTER_REACH_EXTRA_PX = 3


def inner_mask(shape, margin) -> np.ndarray:
    """True everywhere but a ``margin``-px border."""
    h, w = shape
    inner = np.zeros(shape, bool)
    inner[margin:h - margin, margin:w - margin] = True
    return inner


def contour_band(mask, half_width) -> np.ndarray:
    """Pixels within ``half_width`` of the contour ``mask``, away from the ROI border (whose
    contour segments are where the object leaves the ROI, not edges of it)."""
    k = 2 * half_width + 1
    band = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
    return band & inner_mask(mask.shape, half_width + BORDER_MARGIN_PX)


def contour_core(contour: ContourTemplate) -> np.ndarray:
    """The contour's pixels 2 px inside the ROI ("contour" matching), or all if fewer than 5."""
    core = contour.mask & inner_mask(contour.mask.shape, CORE_MARGIN_PX)
    return core if core.sum() >= MIN_CORE_PIXELS else contour.mask


def band_widths(options: BandOptions, method: str, texture: float | None,
                edge_sigma: float = 0.0) -> tuple[int, int]:
    """How far (px) the registration band reaches from the contour: ``(background, object)``.

    The band's background pixels do not move with the object: where it moves to, another patch of
    substrate lies beside it, and a textured background pulls the estimate towards where the
    template was taken. Each pixel of the band also carries information, which is what the
    estimate lacks when the noise dominates. So with ``band_px=None`` the ``"ic"`` band reaches
    :data:`NARROW_BAND_PX` into the background when its ``texture`` is at least
    :data:`NARROW_BAND_TEXTURE` times the noise (bias-limited), :data:`DEFAULT_BAND_PX` otherwise
    (a flat background, or low dose: variance-limited), and 3 px into the object either way; the
    trade is measured over many scenes by ``benchmarks/bench_tracking_seeds.py --param band_px=3``.
    Both sides reach at least :data:`EDGE_BAND_SIGMAS` times ``edge_sigma``, the edge's blur
    (:func:`edge_blur`), up to :data:`MAX_EDGE_BAND_PX`: a band narrower than the edge's transition
    loses the slope that tells where the edge is. An explicit ``band_px`` is used on both sides
    (``inner_px`` deepens the object's side).

    Raises
    ------
    RuntimeError
        ``band_px=None`` for ``"ic"`` and no ``texture`` yet (it is measured on the first frame).
    """
    if options.band_px is not None or method != "ic":
        width = DEFAULT_BAND_PX if options.band_px is None else options.band_px
        return width, max(width, options.inner_px if method == "ic" else 0)
    if texture is None:
        raise RuntimeError("band_widths() with band_px=None needs init(): the background's texture is measured there")
    outside = NARROW_BAND_PX if texture >= NARROW_BAND_TEXTURE else DEFAULT_BAND_PX
    inside = max(DEFAULT_BAND_PX, options.inner_px)
    reach = 0
    if math.isfinite(edge_sigma) and edge_sigma > 0:
        reach = min(math.ceil(EDGE_BAND_SIGMAS * edge_sigma), MAX_EDGE_BAND_PX)
    return max(outside, reach), max(inside, reach)


def edge_blur(patch, contour: ContourTemplate, contrast: float | None = None) -> float:
    """The edge's blur (px, the σ of a Gaussian-blurred step) along the contour of ``patch``.

    An erf edge of contrast ``C`` blurred by ``σ`` and smoothed by ``s`` rises with a steepest
    slope of ``C / (√(2π) √(σ² + s²))``: the median over the contour pixels (those
    :data:`EDGE_BORDER_PX` inside the ROI) of the steepest slope within :data:`EDGE_SEARCH_PX`,
    on ``patch`` smoothed by :data:`EDGE_SMOOTHING_PX`, gives ``σ``, with ``C`` the object/background
    contrast of the contour's region (``contrast``, when the caller has measured it already). Noise
    and a bright rim steepen the slope, so they can only make the blur look smaller. 0 when there is
    no contour to read.
    """
    region, mask = contour.region, contour.mask
    if not (region.any() and not region.all()):
        return 0.0
    img = np.asarray(patch, np.float32)
    if contrast is None:
        contrast = region_contrast(img, region, default=0.0)
    smoothed = cv2.GaussianBlur(img, (0, 0), EDGE_SMOOTHING_PX)
    gx, gy = five_point_gradients(smoothed)
    side = 2 * EDGE_SEARCH_PX + 1
    steepest = cv2.dilate(np.hypot(gx, gy), np.ones((side, side), np.uint8))
    read = mask & inner_mask(mask.shape, EDGE_BORDER_PX)
    if not read.any():
        return 0.0
    slope = float(np.median(steepest[read]))
    if not slope > 0:
        return 0.0
    seen = contrast / (math.sqrt(2.0 * math.pi) * slope)
    return math.sqrt(max(seen * seen - EDGE_SMOOTHING_PX ** 2, 0.0))


def registration_band(contour: ContourTemplate, widths: tuple[int, int]) -> np.ndarray:
    """The band of :func:`band_widths` ``(background, object)`` around ``contour``."""
    outside, inside = widths
    band = contour_band(contour.mask, outside)
    if inside > outside:
        # The object's inside moves with it: a deeper band on that side pins its gray level
        # (the photometric nuisance) without taking in background that stays behind.
        band |= contour_band(contour.mask, inside) & contour.region
    return band


def far_from_region(region, distance: float) -> np.ndarray:
    """Bool mask of the pixels at least ``distance`` px from ``region`` (True where background)."""
    background = (~np.asarray(region, bool)).astype(np.uint8)
    return cv2.distanceTransform(background, cv2.DIST_L2, 3) >= distance


def flattened_background(template, region, from_px: float = FLAT_FROM_PX, *, mean_of_flattened: bool = False) -> np.ndarray:
    """``template`` with its background ``from_px`` or more from ``region`` replaced by its local mean.

    The band's background pixels do not move with the object: in every later frame another patch of
    the substrate lies beside it. A textured background kept in the template pulls each registration
    towards where the template was taken (a static texture matches itself there), by a pixel or more
    along a thin tip's shaft, where only the apex tells the position. Its local mean (the background
    alone, smoothed by a normalised Gaussian of :data:`FLAT_SIGMA_PX`) keeps the edge's step and the
    background's level, and no texture to match: what the texture does to a frame becomes noise
    about the answer instead of a pull towards the start.

    Parameters
    ----------
    template : (h, w) array_like
    region : (h, w) array_like of bool
        The object.
    from_px : float
        Distance (px) from ``region`` where the flattening starts (:data:`FLAT_FROM_PX`).
    mean_of_flattened : bool
        The local mean of the flattened pixels alone (the static background layer's flattening,
        :mod:`semlab.tracking.layer`, from a few px: there the blurred edge's tail, nearer, would give a
        flat background a slope towards the object), or of all the background (the textured substrates'
        flattening from 1 px, as measured).

    Returns
    -------
    (h, w) ndarray of float32
    """
    img = np.asarray(template, np.float32)
    region = np.asarray(region, bool)
    far = far_from_region(region, from_px)
    weight = (far if mean_of_flattened else ~region).astype(np.float32)
    mean = cv2.GaussianBlur(img * weight, (0, 0), FLAT_SIGMA_PX) / np.maximum(
        cv2.GaussianBlur(weight, (0, 0), FLAT_SIGMA_PX), 1e-6)
    out = img.copy()
    out[far] = mean[far]
    return out


def background_texture(patch, region, noise: NoiseModel, min_distance: float = TEXTURE_DISTANCE_PX) -> float:
    """Standard deviation of the background's texture over that of the noise.

    The background pixels at least ``min_distance`` px from the object (``~region``) minus
    a quadratic surface fitted to them (shading) vary by noise and texture; the noise
    model's variance at their gray levels is taken off the residual's robust variance
    (1.4826 × MAD, squared). 0 for a flat background, or when fewer than 50 such pixels
    remain.

    Returns
    -------
    float
        ``sqrt(max(robust var(residual) − mean noise variance, 0) / mean noise variance)``.
    """
    region = np.asarray(region, bool)
    distance = cv2.distanceTransform((~region).astype(np.uint8), cv2.DIST_L2, 5)
    ys, xs = np.nonzero((distance >= min_distance) & inner_mask(region.shape, TEXTURE_BORDER_PX))
    if len(xs) < MIN_TEXTURE_PIXELS:
        return 0.0
    values = np.asarray(patch, np.float64)[ys, xs]
    x, y = xs.astype(np.float64), ys.astype(np.float64)
    surface = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    coef, *_ = np.linalg.lstsq(surface, values, rcond=None)
    residual = values - surface @ coef
    # Robust spread: object pixels that the region (an Otsu mask) left out are outliers.
    spread = MAD_TO_SD * float(np.median(np.abs(residual - np.median(residual))))
    noise_var = float(np.mean(noise.variance(values)))
    excess = spread * spread - noise_var
    return float(np.sqrt(max(excess, 0.0) / max(noise_var, 1e-12)))


def background_sectors(xs, ys, inside, tile: int) -> np.ndarray | None:
    """Background band pixels grouped in ``tile``-px tiles, each with its own level.

    The background next to the object is not part of it: where the object moves to, the
    substrate around it is another one, brighter or darker at the scale of a few px (texture,
    shading). Fitted with the template's background, such a local change of level biases the
    edge by a fraction of its width; each tile's own level absorbs it. Object pixels get -1: no
    local level. None when the option is off (``tile=0``).
    """
    if tile <= 0:
        return None
    sector = np.full(len(xs), -1, np.intp)
    outside = ~np.asarray(inside, bool)
    if outside.any():
        sector[outside] = band_tiles(np.stack([xs[outside], ys[outside]], axis=1), tile)
    return sector


@dataclass(frozen=True)
class Level:
    """One registration level: the whitened template, smoothed by ``sigma`` (0: the Jacobian's
    own smoothing at full resolution), and its gradients at the band's pixels."""

    sigma: float
    values: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    setup: dict | None = None  # gauss_newton_setup of these with the band's weights (None: per call)

    def subset(self, keep) -> Level:
        return Level(self.sigma, self.values[keep], self.gx[keep], self.gy[keep], None)


@dataclass(frozen=True)
class BandModel:
    """What the per-frame registration needs from one template, at the band's pixels.

    Attributes
    ----------
    points : (K, 2) ndarray
        The band's pixels ``(x, y)`` in ROI coordinates.
    bbox : (x0, y0, x1, y1)
        The whole band's bounding box (also after :meth:`subset`).
    values : (K,) ndarray
        The template's gray levels (not whitened: the score's reference).
    inside : (K,) ndarray of bool
        Object (True) or background pixel.
    sector : (K,) ndarray of int or None
        :func:`background_sectors`.
    weights : (K,) ndarray or None
        Inverse noise variance (relative), times the consistency mask; None: equal.
    template_variance : (K,) ndarray
        Noise variance of the whitened, averaged template.
    instrument : (K,) ndarray or None
        ``photometry="instrument"``: the smoothed template.
    fine : Level
        Full resolution (the efficient estimate).
    smoothed : tuple of Level
        The coarse-to-fine ladder, widest first (empty with ``coarse_sigma=0``).
    jacobian_sigma : float
        The smoothing of ``fine``'s Jacobian: at most 1 px, the template counts as averaged (mature).
    rho : float
        The scan line's correlation the template was whitened with (0: not whitened).
    n_averaged : int
        Frames the template averages.
    denoised : (h, w) ndarray or None
        The whitened template around the band, denoised for the Jacobian (``jacobian_denoise``; None:
        not denoised), which a model of the same template flattened can reuse (:func:`build_band_model`).
    """

    points: np.ndarray
    bbox: tuple[int, int, int, int]
    values: np.ndarray
    inside: np.ndarray
    sector: np.ndarray | None
    weights: np.ndarray | None
    template_variance: np.ndarray
    instrument: np.ndarray | None
    fine: Level
    smoothed: tuple[Level, ...]
    jacobian_sigma: float
    rho: float
    n_averaged: int
    denoised: np.ndarray | None = None

    def inside_image(self, roi, shift, shape, *, margin: int = 2, fraction: float = 1.0) -> bool:
        """Whether at least ``fraction`` of the band lies ``margin`` px inside an image of ``shape``
        when the template is at ``shift`` against ``roi``."""
        x0, y0 = roi[:2]
        bx0, by0, bx1, by1 = self.bbox
        if (bx0 + x0 + shift[0] >= margin and by0 + y0 + shift[1] >= margin
                and bx1 - 1 + x0 + shift[0] <= shape[1] - 1 - margin and by1 - 1 + y0 + shift[1] <= shape[0] - 1 - margin):
            return True  # the band's bounding box is inside
        px = self.points[:, 0] + x0 + shift[0]
        py = self.points[:, 1] + y0 + shift[1]
        inside = (px >= margin) & (py >= margin) & (px <= shape[1] - 1 - margin) & (py <= shape[0] - 1 - margin)
        return bool(inside.mean() >= fraction)

    def subset(self, keep) -> BandModel:
        """The same model on the band pixels ``keep`` only (those still inside the image); the
        Gauss–Newton constants are then rebuilt per call."""
        def cut(v):
            return None if v is None else v[keep]

        return dataclasses.replace(
            self, points=self.points[keep], values=self.values[keep], inside=self.inside[keep],
            sector=cut(self.sector), weights=cut(self.weights), template_variance=self.template_variance[keep],
            instrument=cut(self.instrument), fine=self.fine.subset(keep),
            smoothed=tuple(level.subset(keep) for level in self.smoothed))

    def reweighted(self, keep, options: TrackerOptions) -> BandModel:
        """The same band with the pixels outside ``keep`` weighing 0 (:mod:`semlab.tracking.trimming`).

        Only the full-resolution level is set up again: a refit starts at the answer.
        """
        weights = np.asarray(keep, np.float64) if self.weights is None else self.weights * keep
        # (What does not depend on the weights is taken from the band's own set-up.)
        fine, _ = _setups(dataclasses.replace(self.fine, setup=None), [], weights, self.inside, options,
                          like=self.fine.setup)
        return dataclasses.replace(self, weights=weights, fine=fine,
                                   smoothed=tuple(dataclasses.replace(level, setup=None) for level in self.smoothed))


def region_contrast(values, inside, default: float) -> float:
    """``|mean(object) − mean(background)|`` of the band's ``values``; ``default`` when one side is empty."""
    if not (inside.any() and not inside.all()):
        return default
    return abs(float(values[inside].mean() - values[~inside].mean()))


def _jacobian_sigma(values, inside, noise: NoiseModel, n_averaged: int, options: TrackerOptions) -> float:
    """The Jacobian's smoothing: grows with the template's noise relative to its contrast."""
    contrast = region_contrast(values, inside, default=1.0)
    noise_sd = float(np.sqrt(np.mean(noise.variance(values)) / n_averaged))
    jac = options.jacobian
    return float(np.clip(JACOBIAN_SIGMA_PER_NOISE * noise_sd / max(contrast, 1e-6), jac.jacobian_sigma,
                         jac.jacobian_sigma_first))


def _jacobian(template, whitened, values, noise, rho, n_averaged, sigma_j, options: TrackerOptions, used,
              reuse=None):
    """``(gx, gy, denoised)``: the template's gradients (eq. 8's 5-point mask) that serve as the Jacobian,
    on the crop, and the denoised crop they were taken from (None: not denoised).

    From the lightly smoothed template: a noisy Jacobian inflates the variance along the weakly
    constrained direction (along the shaft, only the apex tells x); the curvature then comes from
    the image (see :func:`semlab.tracking.registration.register`). ``used`` ``(x0, y0, x1, y1)``:
    the crop's box that holds the band, where the gradients are read (elsewhere they are not
    those of the whole template). ``reuse`` ``(denoised, flat)``: the denoised crop of the same template
    before its background ``flat`` (a crop-sized mask) was flattened: the flattened pixels, a smooth local
    mean already, are taken as they are and the rest from ``denoised`` (NL-means' cost once, not twice).
    """
    jac = options.jacobian
    source, denoised = whitened, None
    if jac.jacobian_denoise and n_averaged >= DENOISE_FROM_FRAMES and reuse is not None and reuse[0] is not None:
        denoised = source = np.where(reuse[1], whitened, reuse[0]).astype(np.float32)
    elif jac.jacobian_denoise and n_averaged >= DENOISE_FROM_FRAMES:
        # The Jacobian from the template denoised by non-local means: its noise (and the averaged
        # template's leftover) enters every estimate through the gradients.
        noise_sd = float(np.sqrt((1.0 - rho ** 2) * np.mean(noise.variance(values)) / n_averaged))
        reach = FIVE_POINT_REACH_PX + (_gaussian_reach(sigma_j) if sigma_j > 0 else 0)
        denoised = source = _denoised_around(whitened, _grown(used, reach, whitened.shape),
                                             jac.jacobian_denoise * noise_sd, noise_sd)
    gx, gy = five_point_gradients(cv2.GaussianBlur(source, (0, 0), sigma_j) if sigma_j > 0 else source)
    if jac.normal_sigma > 0:
        # Keep only the gradient's component along the edge normal, whose direction comes from the
        # heavily smoothed template: noise across the normal would leak into x along a
        # near-horizontal shaft, whose only x information is its apex.
        nx, ny = five_point_gradients(cv2.GaussianBlur(template, (0, 0), jac.normal_sigma))
        norm = np.hypot(nx, ny) + 1e-12
        nx, ny = nx / norm, ny / norm
        along = gx * nx + gy * ny
        gx, gy = along * nx, along * ny
    return gx, gy, denoised


def _gaussian_reach(sigma: float) -> int:
    """How far (px) OpenCV's ``GaussianBlur(img, (0, 0), sigma)`` of a float image reads around a
    pixel: its kernel spans ``round(8σ + 1) | 1`` taps; one px more for the rounding."""
    return math.ceil(4.0 * sigma) + 1


def _grown(box, by: int, shape) -> tuple[int, int, int, int]:
    """``box`` ``(x0, y0, x1, y1)`` grown by ``by`` px on each side, within an image of ``shape``."""
    x0, y0, x1, y1 = box
    return max(x0 - by, 0), max(y0 - by, 0), min(x1 + by, shape[1]), min(y1 + by, shape[0])


def _denoised_around(whitened, box, h: float, sigma: float) -> np.ndarray:
    """``whitened`` with its ``box`` ``(x0, y0, x1, y1)`` denoised by non-local means as in the whole.

    Only the box and :data:`NL_MEANS_REACH_PX` around it are filtered (NL-means' cost grows with
    the area): inside the box each value is the whole image's, up to the last bits of the
    filter's running sums; outside it the pixels are left as they were.
    """
    x0, y0, x1, y1 = _grown(box, NL_MEANS_REACH_PX, whitened.shape)
    bx0, by0, bx1, by1 = box
    part = denoise_nl_means(whitened[y0:y1, x0:x1].astype(np.float64), h=h, sigma=sigma, patch_size=NL_MEANS_PATCH,
                            patch_distance=NL_MEANS_DISTANCE, fast_mode=True).astype(np.float32)
    out = whitened.copy()
    out[by0:by1, bx0:bx1] = part[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0]
    return out


def _smoothed_levels(whitened, finest, at, coarse_sigma: float) -> list[tuple[float, np.ndarray, tuple]]:
    """``(sigma, values, (gx, gy))`` of the ladder's levels at the pixels ``at`` (widest first)."""
    levels = []
    for factor in (LADDER if coarse_sigma > 0 else ()):
        sigma = factor * coarse_sigma
        if sigma == coarse_sigma:
            smooth, grads = finest  # the finest level is the smoothed template the caller made
        else:
            smooth = cv2.GaussianBlur(whitened, (0, 0), sigma)
            grads = five_point_gradients(smooth)
        levels.append((sigma, smooth[at].astype(np.float64), tuple(g[at].astype(np.float64) for g in grads)))
    return levels


def _setups(fine: Level, smoothed: list[Level], weights, inside, options: TrackerOptions, like: dict | None = None):
    """The levels with their Gauss–Newton constants; without any when one fails (a template
    without two levels: every fit then says why). ``like``: a set-up of ``fine`` with other weights
    (:func:`~semlab.gauss_newton.gauss_newton_setup`)."""
    common = {"weights": weights, "photometric": options.photometry.photometric}
    try:
        regions = inside if options.photometry.photometry == "regions" else None
        fine_setup = gauss_newton_setup(fine.values, fine.gx, fine.gy, **common, regions=regions, like=like)
        setups = [gauss_newton_setup(level.values, level.gx, level.gy, **common, regions=inside)
                  for level in smoothed]
    except ValueError:
        return fine, tuple(smoothed)
    return (dataclasses.replace(fine, setup=fine_setup),
            tuple(dataclasses.replace(level, setup=setup) for level, setup in zip(smoothed, setups)))


def build_band_model(template, contour: ContourTemplate, band, noise: NoiseModel, options: TrackerOptions, *,
                     n_averaged: int = 1, consistency=None, reuse=None) -> BandModel:
    """Everything the per-frame registration needs from ``template``, computed once (offline).

    Parameters
    ----------
    template : (h, w) ndarray of float32
        The (averaged) ROI patch.
    contour : ContourTemplate
        Its contour template (region: the object).
    band : (h, w) ndarray of bool
        :func:`registration_band`.
    noise : NoiseModel
        The frames' noise (line correlation used when ``whiten``).
    options : TrackerOptions
    n_averaged : int
        Frames the template averages (its noise variance is a frame's over this).
    consistency : (K,) ndarray or None
        Per-band-pixel weights from the template averaging (0: static background).
    reuse : (BandModel, (h, w) ndarray of bool) or None
        ``template`` is that model's template with the masked pixels' background flattened
        (:func:`flattened_background`): its denoised Jacobian source is reused there.
    """
    ys, xs = np.nonzero(band)
    points = np.stack([xs, ys], axis=1).astype(np.float64)  # ROI coordinates
    bbox = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
    values = template[ys, xs].astype(np.float64)
    rho = noise.rho if options.photometry.whiten else 0.0
    coarse_sigma = options.stages.coarse_sigma
    jac = options.jacobian
    # Only the band's neighbourhood is filtered (the widest kernel's reach around it): at the band
    # the values are those of the whole template's filtering, 4x cheaper.
    reach = int(np.ceil(FILTER_REACH_SIGMAS * max(LADDER[0] * coarse_sigma, coarse_sigma + INSTRUMENT_SIGMA,
                                                  jac.jacobian_sigma_first, jac.normal_sigma,
                                                  NOISE_LEVEL_SIGMA))) + FILTER_REACH_EXTRA_PX
    bx0, by0, bx1, by1 = bbox
    sx0, sy0, sx1, sy1 = _grown(bbox, reach, template.shape)
    near = np.ascontiguousarray(template[sy0:sy1, sx0:sx1])
    # Whitened whole, then cut: the same first column.
    whitened = np.ascontiguousarray(whiten_lines(template, rho)[sy0:sy1, sx0:sx1])
    at = (ys - sy0, xs - sx0)
    inside = contour.region[ys, xs]
    sigma_j = _jacobian_sigma(values, inside, noise, n_averaged, options)
    gx, gy, denoised = _jacobian(near, whitened, values, noise, rho, n_averaged, sigma_j, options,
                                 used=(bx0 - sx0, by0 - sy0, bx1 - sx0, by1 - sy0),
                                 reuse=None if reuse is None else (reuse[0].denoised, reuse[1][sy0:sy1, sx0:sx1]))
    fine = Level(0.0, whitened[at].astype(np.float64), gx[at].astype(np.float64), gy[at].astype(np.float64))
    # The same, smoothed: the first, robust stage of every frame's registration.
    smooth = cv2.GaussianBlur(whitened, (0, 0), coarse_sigma) if coarse_sigma > 0 else whitened
    ladder = [Level(sigma, v, g[0], g[1]) for sigma, v, g in _smoothed_levels(
        whitened, (smooth, five_point_gradients(smooth)), at, coarse_sigma)]
    # The instrument for the gain: the template smoothed (its own noise mostly averaged out).
    instrument = cv2.GaussianBlur(whitened, (0, 0), INSTRUMENT_SIGMA)[at].astype(np.float64) if (
        options.photometry.photometry == "instrument") else None
    weights = None
    if options.photometry.noise_weights:
        variance = noise.variance(cv2.GaussianBlur(near, (0, 0), NOISE_LEVEL_SIGMA)[at])
        weights = variance.min() / variance
    if consistency is not None:
        weights = consistency if weights is None else weights * consistency
    fine, smoothed = _setups(fine, ladder, weights, inside, options)
    return BandModel(
        points=points, bbox=bbox, values=values, inside=inside,
        sector=background_sectors(xs, ys, inside, options.band.background_tile),
        weights=weights,
        # Noise variance of the (whitened, averaged) template at the band pixels.
        template_variance=(1.0 - rho ** 2) * noise.variance(values) / n_averaged,
        instrument=instrument, fine=fine, smoothed=smoothed, jacobian_sigma=sigma_j, rho=rho,
        n_averaged=n_averaged, denoised=denoised)
