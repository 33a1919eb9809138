"""The tracker users call: :class:`Tracker` and :func:`track` (Ru et al. 2012, Fig. 4).

Methods
-------
``"ic"`` (the default of :class:`Tracker`)
    Beyond the paper, and measured best (``benchmarks/bench_tracking.py``): inverse-compositional
    Gauss–Newton (eq. 2 with the paper's offline matrix ``M₀`` of eqs. 4-5 as its Jacobian) on the
    contour band — the pixels within ``band_px`` of the contour template, where nearly all the
    positional information is — started from the constant-velocity prediction and, when that
    fails, from a coarse masked normalised-correlation search at quarter resolution (the whole
    image after a loss), through a coarse-to-fine smoothed stage; exact Keys bicubic
    interpolation; gain and offset from the object and background levels (gray-level
    fluctuation, charging); Huber weights (occlusion, clutter); the image whitened along the scan
    line and weighted by the shot-noise variance (both estimated from the first frame); a
    Jacobian smoothed in proportion to the template's noise; and a template averaged over the
    first registered frames with frame 0 re-registered against it as the origin (a one-frame
    template doubles the variance of every estimate). When Gauss–Newton fails both from the
    prediction and from the coarse search (an edge's contrast vanishing at contact with a
    sample, a brightness jump), a masked normalised correlation of the object's neighbourhood
    over the whole search window — blind to gain and offset — re-acquires it if its peak stands
    out, and Gauss–Newton restarts from there.
``"contour"`` (the default of :func:`track`, as the contract fixes it)
    The paper's method: in a 300×300 window around the last position, Gaussian smoothing and
    adaptive-threshold Canny (eq. 10), the contour-template match (score from the template's
    contour pixels only), then one step of the gradient sub-pixel method (eq. 9) on the contour
    band.
``"ssd"``
    The conventional baseline the paper improves on: full-template SSD (eq. 2) at integer
    positions (``subpixel=True`` adds one step of eq. 9 on the whole template).
``"hb"``
    The paper's parametric SSD tracker (eqs. 2-5, Hager & Belhumeur 1998): integer SSD, then the
    increment ``Δμ = −(M₀ᵀM₀)⁻¹M₀ᵀ[I(f(R; μ), tₙ) − I(R, t₀)]`` with the offline matrix ``M₀``
    iterated to convergence on the whole template.

A lost target (occlusion, the probe leaving the window, contact, an unusable frame) never
raises: the row says ``ok=False`` with NaN position and a low score, and the next frame is
searched over the whole image to re-acquire it. Several targets (the rig's four probes) are
tracked in one pass over the frames by giving :func:`track` a list of ROIs (one independent
:class:`Tracker` per ROI, a ``target`` column in the result).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd
from skimage.restoration import denoise_nl_means

from .edges import canny_edges
from .matching import contour_match, offline_matrix, parabola_peak, ssd_match
from .roi import as_gray_float, check_roi, clip_window, roi_centre
from .subpixel import (
    NoiseModel,
    _keys_taps,
    estimate_noise,
    five_point_gradients,
    gauss_newton_setup,
    gauss_newton_translation,
    gradient_subpixel_shift,
    sample_shifted_filtered,
    weighted_ncc,
    whiten_lines,
)
from .template import ContourTemplate, identify_contour_template, to_uint8

__all__ = ["DEFAULT_METHOD", "METHODS", "TrackResult", "Tracker", "track"]

METHODS = ("ic", "contour", "ssd", "hb")
#: The method :class:`Tracker` uses unless told otherwise: the best measured combination.
DEFAULT_METHOD = "ic"
#: Half-width (px) of the contour band unless told otherwise.
DEFAULT_BAND_PX = 3
#: Background texture over noise (standard deviations) from which the "ic" band reaches only
#: 2 px into the background (:meth:`Tracker.band_widths`). Frame 0 of seeds 0-5 of the
#: simulator measures 0.48-0.64 (standard dose), 0.00-0.23 (low dose: the same substrate under
#: more noise); a flat background with white noise 0.00-0.25 (the noise model's estimate is a
#: few % low).
NARROW_BAND_TEXTURE = 0.4
#: The "ic" Jacobian is denoised (``jacobian_denoise``) once the template averages this many frames.
DENOISE_FROM_FRAMES = 4
#: Fewest band pixels a template may have: translation, gain, offset and the background tiles'
#: levels are fitted to them (on a synthetic tip, a 16x16 ROI leaves 16 and was read 3.5 px off
#: with a normal score; an 18x18 one leaves 36 and is sometimes lost, but flagged; 20x20, 63: fine).
MIN_BAND_PIXELS = 30
#: Step (px) below which each smoothed level of the "ic" first stage stops (widest first).
STAGE1_TOLERANCE = (0.1, 0.05, 0.02)


@dataclass(frozen=True)
class TrackResult:
    """One frame's answer: where the ROI's centre point has moved to.

    Attributes
    ----------
    x, y : float
        Position in px (pixel centres at integer coordinates); NaN when ``ok`` is False.
    score : float
        Match quality, 1 = perfect (``"ic"``, ``"ssd"``, ``"hb"``: normalised correlation with
        the template; ``"contour"``: fraction of contour pixels on an edge); 0 when lost.
    ok : bool
        False when the target is lost or the frame is unusable.
    reason : str
        Why ``ok`` is False ('' otherwise).
    """

    x: float
    y: float
    score: float
    ok: bool
    reason: str = ""


def _as_frame(frame) -> np.ndarray:
    """Validate dtype and dimensions without copying (the hot path converts only crops)."""
    arr = np.asarray(frame)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"frame must hold real gray levels (uint8, uint16 or float), got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise ValueError(f"frame must be a 2-D gray image, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError("frame is empty")
    return arr


def _crop(arr, x0, y0, x1, y1) -> np.ndarray:
    """float32 copy of ``arr[y0:y1, x0:x1]``; ValueError if it holds NaN/inf."""
    out = np.asarray(arr[y0:y1, x0:x1], np.float32)
    if np.issubdtype(arr.dtype, np.floating) and not np.isfinite(out).all():
        raise ValueError("NaN or infinite pixels where the target is searched")
    return out


class Tracker:
    """Track the probe tip from frame to frame (paper, Fig. 4).

    Parameters
    ----------
    method : {"ic", "contour", "ssd", "hb"}
        See the module docstring; ``"ic"`` is the default because it measured best.
    search_size : int
        Side of the square search window around the predicted position (paper: 300 px).
    sigma, threshold, morph_kernel, morph_iterations, bright_object
        Contour template identification (:func:`semlab.template.identify_contour_template`).
    canny_sigma, canny_low, canny_high
        Edge detection of ``"contour"`` (:func:`semlab.edges.canny_edges`; thresholds adaptive by
        eq. 10 unless both are given).
    contour_tolerance : int
        ``"contour"``: an edge within this many px of a contour pixel counts as a hit.
    subpixel : bool or None
        Refine the integer match of ``"contour"``/``"ssd"`` by one step of eq. 9 (default: True
        for ``"contour"``, False for ``"ssd"``, whose conventional form is integer-only).
    band_px : int or None
        Half-width of the band around the contour used for sub-pixel registration. None (the
        default): 3 px, except that ``"ic"`` reaches only 2 px into the background when the
        background's texture is at least :data:`NARROW_BAND_TEXTURE` times the noise (see
        :meth:`band_widths`).
    huber : float or None
        ``"ic"``: Huber threshold in robust standard deviations (None: plain least squares).
    whiten : bool
        ``"ic"``: undo the scan line's noise correlation (:func:`semlab.subpixel.whiten_lines`).
    noise_weights : bool
        ``"ic"``: weight pixels by their inverse shot-noise variance.
    photometric : bool
        ``"ic"``: estimate gain and offset per frame.
    template_frames : int
        ``"ic"`` averages the template over this many well-registered frames (1: frame 0 only).
    coarse_factor : int
        ``"ic"``: downsampling of the coarse search.
    max_iterations : int
        Gauss–Newton iterations per frame (``"ic"``, ``"hb"``).
    min_score : float or None
        Absolute score below which a frame counts as lost (default per method).
    min_relative_score : float
        ``"ic"``: a frame also counts as lost when its score falls below this fraction of the
        typical score of the first frames (low-dose images have low correlations even when
        right).
    coarse_sigma : float
        ``"ic"``: Gaussian smoothing (px) of template and image in the first registration stage
        of every frame (0: single stage at full resolution).
    jacobian_sigma : float
        ``"ic"``: Gaussian smoothing (px) of the template before its gradients (the Jacobian)
        are taken; 0 uses the raw template's gradients.
    normal_sigma : float
        ``"ic"``: the Jacobian keeps only the gradient component along the edge normal, taken
        from the template smoothed by this many px (0: keep the whole gradient).
    inner_px : int
        ``"ic"``: on the object's side the band reaches this deep (its pixels move with the
        object and fix its gray level).
    photometry : {"regression", "regions", "instrument"}
        ``"ic"``: gain and offset by regression on the template, corrected for the template's
        noise (errors in variables), or from the mean levels of object and background pixels.
    consistency_cut : float or None
        ``"ic"``: when the averaged template is built, band pixels whose mean over the
        registered frames taken near the start differs by more than this many standard errors
        from their mean over the frames taken after the object moved are static background, not
        object, and get no weight (None: keep all).
    background_tile : int
        ``"ic"``: the band's background pixels are grouped in tiles of this many px, each with
        its own gray level in the full-resolution fit (the substrate where the object moved to
        is brighter or darker at that scale); 0: one background level.
    jacobian_denoise : float or None
        ``"ic"``: once the template averages :data:`DENOISE_FROM_FRAMES` frames, its gradients
        (the Jacobian, eq. 5's ``M₀``) are taken after non-local-means denoising (scikit-image
        ``denoise_nl_means``, 7×7 patches, 13×13 search, filter strength this many times the
        template's noise standard deviation, which shrinks as the template is averaged). None
        or 0: off. The template's noise enters every estimate through its gradients. Measured
        on the simulator, seeds 0-17, against ``jacobian_denoise=None``: median RMSE / bound
        1.92 -> 1.70 (200-px moves), 2.79 -> 2.43 (low dose), 2.42 -> 1.88 (gray-level
        fluctuation), 2.18 -> 1.97 (clutter); a still probe's spread 1.29 -> 1.28; worst
        low-dose loss rate 46 % -> 9 %; a still probe at low dose 2.28 -> 2.32 (12 seeds).
        Denoising from the first template on did 1-3 % better on the standard-dose moving
        sequences but 2.28 -> 2.67 on the still probe at low dose; 5×5 patches doubled the
        low-dose error on 2 of 6 seeds; 3×3 were worse everywhere.
    reidentify : bool
        ``"ic"``: once the template is averaged (``template_frames``), identify the contour
        template again on the averaged template, at frame 0's threshold, take the band from it
        and register the stored frames, frame 0 included, once more (:meth:`_reidentify`).
        Off by default: on the simulator's moving sequences, seeds 0-17, it lowers the geometric
        mean of RMSE / bound by 1-9 % and the worst scenes' by up to 30 % (frame 0's contour
        poor: a particle at the apex, a thin probe), but raises the median by up to 8 % (low
        dose 2.43 -> 2.58, clutter 1.97 -> 2.13) and, next to a static particle beside a thin
        shaft, leaves a 0.17-px bias that frame 0's band does not.

    Examples
    --------
    >>> import numpy as np
    >>> from semlab.tracking import Tracker
    >>> yy, xx = np.mgrid[:240, :320]
    >>> def frame(dx):
    ...     return np.where((xx - 150 - dx) ** 2 + (yy - 120) ** 2 < 30 ** 2, 200.0, 60.0).astype(np.float32)
    >>> t = Tracker()
    >>> _ = t.init(frame(0), (100, 70, 100, 100))
    >>> r = t.update(frame(3))
    >>> r.ok, round(r.x - 149.5)
    (True, 3)
    """

    def __init__(self, method: str = DEFAULT_METHOD, *, search_size: int = 300, sigma: float = 2.0,
                 threshold: float | None = None, morph_kernel: int = 3, morph_iterations: int = 1,
                 bright_object: bool = True, canny_sigma: float = 2.0, canny_low: float | None = None,
                 canny_high: float | None = None, contour_tolerance: int = 0, subpixel: bool | None = None,
                 band_px: int | None = None, huber: float | None = 2.0, whiten: bool = True, noise_weights: bool = True,
                 photometric: bool = True, template_frames: int = 20, coarse_factor: int = 4,
                 max_iterations: int = 20, min_score: float | None = None, min_relative_score: float = 0.5,
                 coarse_sigma: float = 1.0, jacobian_sigma: float = 0.7, jacobian_sigma_first: float = 2.0,
                 normal_sigma: float = 0.0, photometry: str = "regions", inner_px: int = 0,
                 consistency_cut: float | None = 6.0, background_tile: int = 8,
                 jacobian_denoise: float | None = 0.8, reidentify: bool = False):
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
        if int(search_size) != search_size or search_size < 16:
            raise ValueError(f"search_size must be an integer of at least 16 px, got {search_size!r}")
        if band_px is not None and (int(band_px) != band_px or band_px < 1):
            raise ValueError(f"band_px must be a positive integer or None, got {band_px!r}")
        if int(coarse_factor) != coarse_factor or coarse_factor < 1:
            raise ValueError(f"coarse_factor must be a positive integer, got {coarse_factor!r}")
        if huber is not None and not huber > 0:
            raise ValueError(f"huber must be > 0 or None, got {huber!r}")
        if int(max_iterations) != max_iterations or max_iterations < 1:
            raise ValueError(f"max_iterations must be a positive integer, got {max_iterations!r}")
        if not 0 <= min_relative_score < 1:
            raise ValueError(f"min_relative_score must lie in [0, 1), got {min_relative_score!r}")
        self.method = method
        self.search_size = int(search_size)
        self.template_params = {"sigma": sigma, "threshold": threshold, "morph_kernel": morph_kernel,
                                "morph_iterations": morph_iterations, "bright_object": bright_object}
        self.canny = {"sigma": canny_sigma, "low": canny_low, "high": canny_high}
        self.contour_tolerance = int(contour_tolerance)
        self.subpixel = (method == "contour") if subpixel is None else bool(subpixel)
        self.band_px = None if band_px is None else int(band_px)
        self.huber = huber
        self.whiten = bool(whiten)
        self.noise_weights = bool(noise_weights)
        self.photometric = bool(photometric)
        self.template_frames = max(int(template_frames), 1)
        self.coarse_factor = int(coarse_factor)
        self.max_iterations = int(max_iterations)
        self.coarse_sigma = float(coarse_sigma)
        self.jacobian_sigma = float(jacobian_sigma)
        self.normal_sigma = float(normal_sigma)
        if photometry not in ("regression", "regions", "instrument"):
            raise ValueError(f"photometry must be 'regression', 'regions' or 'instrument', got {photometry!r}")
        self.photometry = photometry
        self.inner_px = int(inner_px)
        self.jacobian_sigma_first = float(jacobian_sigma_first)
        if consistency_cut is not None and not consistency_cut > 0:
            raise ValueError(f"consistency_cut must be > 0 or None, got {consistency_cut!r}")
        self.consistency_cut = consistency_cut
        if int(background_tile) != background_tile or background_tile < 0:
            raise ValueError(f"background_tile must be a non-negative integer, got {background_tile!r}")
        self.background_tile = int(background_tile)
        if jacobian_denoise is not None and not jacobian_denoise >= 0:
            raise ValueError(f"jacobian_denoise must be >= 0 or None, got {jacobian_denoise!r}")
        self.jacobian_denoise = jacobian_denoise
        self.reidentify = bool(reidentify)
        #: The background's texture over the noise (standard deviations), measured by init().
        self.texture = None
        default_min = {"ic": 0.1, "contour": 0.3, "ssd": 0.3, "hb": 0.3}[method]
        self.min_score = default_min if min_score is None else float(min_score)
        self.min_relative_score = float(min_relative_score)
        self.roi = None

    # ------------------------------------------------------------------ set-up
    def init(self, frame, roi) -> TrackResult:
        """Take the template from ``frame`` inside ``roi = (x, y, w, h)`` (paper, Fig. 2).

        Returns
        -------
        TrackResult
            The ROI's centre point, ``ok=True``.

        Raises
        ------
        TypeError, ValueError
            Bad frame (dtype, dimensions, NaN/inf, empty), ROI not wholly inside the frame or too
            small, a constant ROI, or no usable contour in the ROI.
        """
        image = as_gray_float(frame)
        roi = check_roi(roi, image.shape, min_size=16)
        x0, y0, w, h = roi
        patch = image[y0:y0 + h, x0:x0 + w].copy()
        if float(patch.max() - patch.min()) <= 0:
            raise ValueError(f"the ROI {roi} is constant: nothing to track")
        # The frame's own gray levels (uint8 as they are), so a manual threshold means the same
        # here as in identify_contour_template and the TemplateExplorer.
        raw = np.asarray(frame)[y0:y0 + h, x0:x0 + w]
        contour = identify_contour_template(raw, **self.template_params)
        # How identify_contour_template mapped frame 0's gray levels onto 0-255 (uint8 as they are).
        self._to_8bit = (0.0, 1.0) if raw.dtype == np.uint8 else (
            float(patch.min()), 255.0 / max(float(patch.max() - patch.min()), 1e-12))
        self.noise = estimate_noise(patch)
        region = contour.region
        if region.any() and not region.all():
            contrast = abs(float(patch[region].mean() - patch[~region].mean()))
            sigma = float(np.sqrt(self.noise.variance(float(patch.mean()))))
            if contrast < 2.0 * sigma:
                raise ValueError(f"no object in the ROI {roi}: the contour encloses a contrast of {contrast:.3g} "
                                 f"gray levels, less than twice the noise ({sigma:.3g}); this is noise, not a probe")
        self.texture = self.background_texture(patch, region, self.noise)
        band = self._registration_band(contour)
        if band.sum() < MIN_BAND_PIXELS:
            raise ValueError(f"the contour template in ROI {roi} leaves {int(band.sum())} band pixels away from "
                             f"the ROI border, fewer than {MIN_BAND_PIXELS}: enlarge the ROI or move it onto the tip")
        self.roi = roi
        self.contour: ContourTemplate = contour
        self.band = band
        self._contour_core = self._core(contour)
        if not (self.whiten or self.noise_weights):
            self.noise = NoiseModel()
        self.template = patch
        self.origin = np.zeros(2)
        self._n_averaged = 1
        self._consistency = None
        self._stack = None
        self._sum = None
        self.centre0 = np.array(roi_centre(roi))
        self.shift = np.zeros(2)
        self.velocity = np.zeros(2)
        self.gain, self.offset = 1.0, 0.0
        self.lost = False
        self._scores: list[float] = []
        self._score_median = (0, float("nan"))
        self._last_prediction_error = np.inf
        self.n_lost = 0
        self._small_mask = None
        self._prepare_template()
        self._contour_offset = (0, 0)
        if self.method == "contour":
            # The contour (an Otsu boundary) and the Canny edges it is matched against need not
            # coincide: the integer match in frame 0 itself is the reference that later integer
            # matches are compared with, so that such an offset cancels in the displacement;
            # eq. 9 then refines from the corrected integer position.
            ix, iy = self._contour_integer(image, np.zeros(2))
            self._contour_offset = (ix - x0, iy - y0)
            self.shift = np.zeros(2)
        if self.method == "ic" and self.template_frames > 1:
            m = 16
            ax0, ay0 = x0 - m, y0 - m
            if ax0 >= 0 and ay0 >= 0 and x0 + w + m <= image.shape[1] and y0 + h + m <= image.shape[0]:
                area = image[ay0:y0 + h + m, ax0:x0 + w + m].copy()
                rho = self.noise.rho if self.whiten else 0.0
                self._stack = [[area, (ax0, ay0), np.zeros(2), 1.0, 0.0 * (1 - rho)]]
        return TrackResult(float(self.centre0[0]), float(self.centre0[1]), 1.0, True)

    def band_widths(self) -> tuple[int, int]:
        """How far (px) the registration band reaches from the contour: ``(background, object)``.

        The band's background pixels do not move with the object: where it moves to, another
        patch of substrate lies beside it, and a textured background pulls the estimate towards
        where the template was taken. Each pixel of the band also carries information, which is
        what the estimate lacks when the noise dominates. So with ``band_px=None`` the ``"ic"``
        band reaches 2 px into the background when the background's texture is at least
        :data:`NARROW_BAND_TEXTURE` times the noise (:attr:`texture`; bias-limited), 3 px
        otherwise (a flat background, or low dose: variance-limited), and 3 px into the object
        either way. On the simulator (textured substrate, texture/noise 0.48-0.64), with the
        plain Jacobian, the narrower band lowered the moving sequences' median RMSE over seeds
        0-5 by 2-14 % (seeds 6-11: -2 to 7 %); with the NL-means Jacobian (the default), seeds
        0-17, against ``band_px=3``: clutter median 2.03 -> 1.97 x the bound (geometric mean
        2.45 -> 2.35), 200-px moves and gray-level fluctuation within ±4 % (gray 1.80 -> 1.88),
        a still probe's spread 1.23 -> 1.27 (geometric mean). An explicit ``band_px`` is used on
        both sides (``inner_px`` deepens the object's side).
        """
        if self.band_px is not None or self.method != "ic":
            width = DEFAULT_BAND_PX if self.band_px is None else self.band_px
            return width, max(width, self.inner_px if self.method == "ic" else 0)
        if self.texture is None:
            raise RuntimeError("band_widths() with band_px=None needs init(): the background's texture is measured there")
        outside = 2 if self.texture >= NARROW_BAND_TEXTURE else DEFAULT_BAND_PX
        return outside, max(DEFAULT_BAND_PX, self.inner_px)

    def _registration_band(self, contour: ContourTemplate) -> np.ndarray:
        """The band of :meth:`band_widths` around ``contour``, away from the ROI border."""
        outside, inside = self.band_widths()
        band = self._band(contour.mask, outside)
        if inside > outside:
            # The object's inside moves with it: a deeper band on that side pins its gray level
            # (the photometric nuisance) without taking in background that stays behind.
            band |= self._band(contour.mask, inside) & contour.region
        return band

    @classmethod
    def _core(cls, contour: ContourTemplate) -> np.ndarray:
        """The contour's pixels 2 px inside the ROI ("contour" matching), or all if fewer than 5."""
        core = contour.mask & cls._inner(contour.mask.shape, 2)
        return core if core.sum() >= 5 else contour.mask

    @staticmethod
    def background_texture(patch, region, noise: NoiseModel, min_distance: float = 4.0) -> float:
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
        ys, xs = np.nonzero((distance >= min_distance) & Tracker._inner(region.shape, 3))
        if len(xs) < 50:
            return 0.0
        values = np.asarray(patch, np.float64)[ys, xs]
        x, y = xs.astype(np.float64), ys.astype(np.float64)
        surface = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
        coef, *_ = np.linalg.lstsq(surface, values, rcond=None)
        residual = values - surface @ coef
        # Robust spread: object pixels that the region (an Otsu mask) left out are outliers.
        spread = 1.4826 * float(np.median(np.abs(residual - np.median(residual))))
        noise_var = float(np.mean(noise.variance(values)))
        excess = spread * spread - noise_var
        return float(np.sqrt(max(excess, 0.0) / max(noise_var, 1e-12)))

    @staticmethod
    def _inner(shape, margin):
        h, w = shape
        inner = np.zeros(shape, bool)
        inner[margin:h - margin, margin:w - margin] = True
        return inner

    @classmethod
    def _band(cls, mask, half_width):
        """Pixels within ``half_width`` of the contour, away from the ROI border (whose contour
        segments are where the object leaves the ROI, not edges of it)."""
        k = 2 * half_width + 1
        band = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
        return band & cls._inner(mask.shape, half_width + 3)

    def _prepare_template(self):
        """Everything the per-frame work needs from the template, computed once (offline)."""
        ys, xs = np.nonzero(self.band)
        self._points = np.stack([xs, ys], axis=1).astype(np.float64)  # ROI coordinates
        self._bbox = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
        self._t_values = self.template[ys, xs].astype(np.float64)
        if self.method == "ic":
            rho = self.noise.rho if self.whiten else 0.0
            # Only the band's neighbourhood is filtered (the widest kernel's reach around it):
            # at the band the values are those of the whole template's filtering, 4x cheaper.
            reach = int(np.ceil(4.0 * max(4.0 * self.coarse_sigma, self.coarse_sigma + 1.5,
                                          self.jacobian_sigma_first, self.normal_sigma, 1.0))) + 3
            th, tw_ = self.template.shape
            bx0, by0, bx1, by1 = self._bbox
            sx0, sy0 = max(bx0 - reach, 0), max(by0 - reach, 0)
            sx1, sy1 = min(bx1 + reach, tw_), min(by1 + reach, th)
            template = np.ascontiguousarray(self.template[sy0:sy1, sx0:sx1])
            # Whitened whole, then cut: the same first column.
            tw = np.ascontiguousarray(whiten_lines(self.template, rho)[sy0:sy1, sx0:sx1])
            yb, xb = ys - sy0, xs - sx0
            # Gradients by eq. 8's 5-point mask of the lightly smoothed template: a noisy Jacobian
            # inflates the variance along the weakly constrained direction (along the shaft, only
            # the apex tells x); the curvature then comes from the image (see _fit).
            # A noisy template needs a smoother Jacobian; an averaged or clean one a sharper one:
            # the smoothing grows with the template's noise relative to its contrast.
            inside = self.contour.region[ys, xs]
            contrast = abs(float(self._t_values[inside].mean() - self._t_values[~inside].mean())) if (
                inside.any() and not inside.all()) else 1.0
            noise = float(np.sqrt(np.mean(self.noise.variance(self._t_values)) / self._n_averaged))
            sigma_j = float(np.clip(5.0 * noise / max(contrast, 1e-6), self.jacobian_sigma,
                                    self.jacobian_sigma_first))
            self._sigma_j = sigma_j
            tj = tw
            if self.jacobian_denoise and self._n_averaged >= DENOISE_FROM_FRAMES:
                # The Jacobian from the template denoised by non-local means: its noise (and
                # the averaged template's leftover) enters every estimate through the gradients.
                # (Not on the first templates: averaged over fewer frames, at low dose they are
                # too noisy for the patches' similarity to mean anything.)
                noise_sd = float(np.sqrt((1.0 - rho ** 2) * np.mean(self.noise.variance(self._t_values))
                                         / self._n_averaged))
                tj = denoise_nl_means(tw.astype(np.float64), h=self.jacobian_denoise * noise_sd, sigma=noise_sd,
                                      patch_size=7, patch_distance=6, fast_mode=True).astype(np.float32)
            gx, gy = five_point_gradients(cv2.GaussianBlur(tj, (0, 0), sigma_j) if sigma_j > 0 else tj)
            if self.normal_sigma > 0:
                # Keep only the gradient's component along the edge normal, whose direction
                # comes from the heavily smoothed template: noise across the normal would leak
                # into x along a near-horizontal shaft, whose only x information is its apex.
                nx, ny = five_point_gradients(cv2.GaussianBlur(template, (0, 0), self.normal_sigma))
                norm = np.hypot(nx, ny) + 1e-12
                nx, ny = nx / norm, ny / norm
                along = gx * nx + gy * ny
                gx, gy = along * nx, along * ny
            self._tw_values = tw[yb, xb].astype(np.float64)
            self._gx, self._gy = gx[yb, xb].astype(np.float64), gy[yb, xb].astype(np.float64)
            # The same, smoothed: the first, robust stage of every frame's registration.
            tws = cv2.GaussianBlur(tw, (0, 0), self.coarse_sigma) if self.coarse_sigma > 0 else tw
            sgx, sgy = five_point_gradients(tws)
            self._tws_values = tws[yb, xb].astype(np.float64)
            self._sgx, self._sgy = sgx[yb, xb].astype(np.float64), sgy[yb, xb].astype(np.float64)
            self._inside = self.contour.region[ys, xs]
            self._sector = self._background_sectors(xs, ys, self._inside)
            # Noise variance of the (whitened, averaged) template at the band pixels.
            self._t_var = (1.0 - rho ** 2) * self.noise.variance(self._t_values) / self._n_averaged
            self._stage1_sigmas = (4.0 * self.coarse_sigma, 2.0 * self.coarse_sigma, self.coarse_sigma)
            stage1 = {}
            for k, sigma in enumerate(self._stage1_sigmas if self.coarse_sigma > 0 else ()):
                if sigma == self.coarse_sigma:
                    ts, s_gx, s_gy = tws, sgx, sgy  # the finest level is the smoothed template above
                else:
                    ts = cv2.GaussianBlur(tw, (0, 0), sigma)
                    s_gx, s_gy = five_point_gradients(ts)
                stage1[f"_s{k}_values"] = ts[yb, xb].astype(np.float64)
                stage1[f"_s{k}_gx"], stage1[f"_s{k}_gy"] = s_gx[yb, xb].astype(np.float64), s_gy[yb, xb].astype(np.float64)
            # The instrument for the gain: the template smoothed (its own noise mostly averaged out).
            iv = self.photometry == "instrument"
            self._instrument = cv2.GaussianBlur(tw, (0, 0), 1.5)[yb, xb].astype(np.float64) if iv else None
            if self.noise_weights:
                level = cv2.GaussianBlur(template, (0, 0), 1.0)[yb, xb]
                var = self.noise.variance(level)
                self._base_weights = var.min() / var
            else:
                self._base_weights = None
            self._arrays = {k: getattr(self, k) for k in (
                "_inside", "_tws_values", "_sgx", "_sgy", "_tw_values", "_gx", "_gy", "_t_var",
                "_instrument", "_t_values", "_sector")}
            self._arrays.update(stage1)
            self._apply_weights()
            self._setups = self._gn_setups(self._arrays)
            f = self.coarse_factor
            h, w = self.template.shape
            hc, wc = h - h % f, w - w % f
            self._small = cv2.resize(self.template[:hc, :wc], (wc // f, hc // f), interpolation=cv2.INTER_AREA)
            # The coarse search sees the object and its immediate surroundings only, so that static
            # background in the ROI does not pull the match back when the probe moves.
            # (Made once per contour: frame 0's, then the averaged template's.)
            if self._small_mask is None:
                k = 8 * f + 1
                region = cv2.dilate((self.contour.region | self.band).astype(np.uint8),
                                    cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
                self._small_mask = cv2.resize(region[:hc, :wc].astype(np.float32), (wc // f, hc // f),
                                              interpolation=cv2.INTER_AREA) > 0.5
            mask = self._small_mask
            if mask.sum() >= 4 and np.ptp(self._small[mask]) > 0:
                # Outside the object's neighbourhood the template is flat (its mean there), so
                # it adds nothing to the correlation's numerator: a mask at the price of none.
                self._small = np.where(mask, self._small, float(self._small[mask].mean())).astype(np.float32)
        elif self.method == "hb":
            h, w = self.template.shape
            inner = self._inner((h, w), 3)
            self._hb_mask = inner
            # M₀ from the lightly smoothed template: with the raw one, its noise inflates M₀ᵀM₀ and
            # every increment falls short (eq. 5 then needs dozens of iterations).
            self._m0 = offline_matrix(cv2.GaussianBlur(self.template, (0, 0), 1.0), inner)
            yy, xx = np.nonzero(inner)
            self._hb_points = np.stack([xx, yy], axis=1).astype(np.float64)
            self._hb_values = self.template[yy, xx].astype(np.float64)

    # ------------------------------------------------------------------ per frame
    def update(self, frame) -> TrackResult:
        """Locate the target in the next frame.

        Never raises for a bad frame or a lost target: the result then has ``ok=False``, NaN
        position, score 0 and a ``reason``.

        Raises
        ------
        RuntimeError
            If :meth:`init` was not called first.
        """
        if self.roi is None:
            raise RuntimeError("call init(frame, roi) before update(frame)")
        try:
            arr = _as_frame(frame)
        except (TypeError, ValueError) as err:
            return self._lost(f"unusable frame: {err}")
        if arr.shape[0] < self.roi[3] + 4 or arr.shape[1] < self.roi[2] + 4:
            return self._lost(f"frame {arr.shape} is smaller than the ROI")
        update = {"ic": self._update_ic, "contour": self._update_contour, "ssd": self._update_ssd,
                  "hb": self._update_hb}[self.method]
        try:
            return update(arr)
        except (cv2.error, np.linalg.LinAlgError, ValueError, FloatingPointError, IndexError) as err:
            return self._lost(f"{err}")

    def _lost(self, reason: str) -> TrackResult:
        self._last_prediction_error = np.inf
        self.lost = True
        self.n_lost += 1
        self.velocity[:] = 0.0
        return TrackResult(float("nan"), float("nan"), 0.0, False, reason)

    def _accept(self, shift, score) -> TrackResult:
        shift = np.asarray(shift, float)
        self.velocity = shift - self.shift if not self.lost else np.zeros(2)
        self.shift = shift
        self.lost = False
        x, y = self.centre0 + shift - self.origin
        return TrackResult(float(x), float(y), float(score), True)

    def _window(self, shape, shift):
        """Search window (x0, y0, w, h) centred on the template at ``shift``; the whole image when lost."""
        if self.lost:
            return 0, 0, shape[1], shape[0]
        _x0, _y0, w, h = self.roi
        size = max(self.search_size, w + 2, h + 2)
        cx, cy = roi_centre(self.roi)
        return clip_window(cx + shift[0], cy + shift[1], size, size, shape)

    def _band_inside(self, shift, shape, margin=2, fraction=1.0) -> bool:
        """Whether at least ``fraction`` of the band lies ``margin`` px inside the image at ``shift``."""
        x0, y0 = self.roi[:2]
        bx0, by0, bx1, by1 = self._bbox
        if (bx0 + x0 + shift[0] >= margin and by0 + y0 + shift[1] >= margin
                and bx1 - 1 + x0 + shift[0] <= shape[1] - 1 - margin and by1 - 1 + y0 + shift[1] <= shape[0] - 1 - margin):
            return True  # the band's bounding box is inside
        px = self._points[:, 0] + x0 + shift[0]
        py = self._points[:, 1] + y0 + shift[1]
        inside = (px >= margin) & (py >= margin) & (px <= shape[1] - 1 - margin) & (py <= shape[0] - 1 - margin)
        return bool(inside.mean() >= fraction)

    # ---- "ic"
    def _coarse(self, arr, predicted):
        """Coarse template position by masked normalised correlation at 1/coarse_factor scale."""
        wx, wy, ww, wh = self._window(arr.shape, predicted)
        f = self.coarse_factor
        window = _crop(arr, wx, wy, wx + ww - ww % f, wy + wh - wh % f)
        if float(window.max() - window.min()) <= 0:
            raise ValueError("the search window is constant")
        small = window if f == 1 else cv2.resize(window, (ww // f, wh // f), interpolation=cv2.INTER_AREA)
        if small.shape[0] < self._small.shape[0] or small.shape[1] < self._small.shape[1]:
            raise ValueError("the search window is smaller than the template")
        scores = cv2.matchTemplate(small, self._small, cv2.TM_CCOEFF_NORMED)
        scores = np.nan_to_num(scores, nan=-1.0, posinf=-1.0, neginf=-1.0)
        _, _, _, (ix, iy) = cv2.minMaxLoc(scores)
        px, py = parabola_peak(scores, ix, iy)
        # Block-averaging by f maps both images alike: an offset k in the small image is f·k.
        return np.array([wx + f * px - self.roi[0], wy + f * py - self.roi[1]])

    def _gn_setups(self, arrays):
        """The per-template constants of every Gauss–Newton stage (:func:`gauss_newton_setup`)."""
        common = {"weights": arrays["_weights"], "photometric": self.photometric}
        try:
            setups = {"fine": gauss_newton_setup(arrays["_tw_values"], arrays["_gx"], arrays["_gy"], **common,
                                                 regions=arrays["_inside"] if self.photometry == "regions" else None)}
            for k in range(len(self._stage1_sigmas) if self.coarse_sigma > 0 else 0):
                setups[k] = gauss_newton_setup(arrays[f"_s{k}_values"], arrays[f"_s{k}_gx"], arrays[f"_s{k}_gy"],
                                               **common, regions=arrays["_inside"])
        except ValueError:
            return {}  # a template without two levels: every fit says why
        return setups

    def _band_crop(self, arr, shift, margin, at):
        """The whitened crop of ``arr`` around the band at ``shift`` (``margin`` px each side).

        Returns the float32 crop, its whitened version, the band points in crop coordinates at
        zero shift, the per-point arrays (band pixels that have left the image dropped), the
        crop's integer shift and the Gauss–Newton set-ups for those points.
        """
        x0, y0 = self.roi[0] - at[0], self.roi[1] - at[1]
        bx0, by0, bx1, by1 = self._bbox
        sx, sy = round(shift[0]), round(shift[1])
        cx0, cy0 = max(x0 + bx0 + sx - margin, 0), max(y0 + by0 + sy - margin, 0)
        cx1 = min(x0 + bx1 + sx + margin, arr.shape[1])
        cy1 = min(y0 + by1 + sy + margin, arr.shape[0])
        if cx1 - cx0 < 8 or cy1 - cy0 < 8:
            raise ValueError("the target is outside the image")
        crop = _crop(arr, cx0, cy0, cx1, cy1)
        rho = self.noise.rho if self.whiten else 0.0
        cw = whiten_lines(crop, rho)
        pts = self._points + (x0 - cx0, y0 - cy0)
        arrays, setups = self._arrays, self._setups
        # Band pixels that have left the image (the object near its border) drop out; the band's
        # bounding box tells whether any has.
        lo_x, lo_y = bx0 + x0 - cx0 + shift[0], by0 + y0 - cy0 + shift[1]
        hi_x, hi_y = bx1 - 1 + x0 - cx0 + shift[0], by1 - 1 + y0 - cy0 + shift[1]
        if not (lo_x >= 3 and lo_y >= 3 and hi_x <= cw.shape[1] - 4 and hi_y <= cw.shape[0] - 4):
            px0, py0 = pts[:, 0] + shift[0], pts[:, 1] + shift[1]
            valid = (px0 >= 3) & (py0 >= 3) & (px0 <= cw.shape[1] - 4) & (py0 <= cw.shape[0] - 4)
            if not valid.all():
                if valid.mean() < 0.5 or valid.sum() < 10:
                    raise ValueError("the target has left the image")
                pts = pts[valid]
                arrays = {k: (v[valid] if isinstance(v, np.ndarray) else v) for k, v in arrays.items()}
                setups = {}
        return crop, cw, pts, arrays, np.array([sx, sy], float), setups

    def _fit(self, arr, shift0, gain0, offset0, margin=12, at=(0, 0), robust_start=True, max_move=None,
             give_up=False):
        """Gauss–Newton on the contour band of the whitened crop around ``shift0``.

        ``arr`` is the frame, or a part of it whose pixel [0, 0] is the frame's pixel ``at``.
        ``give_up``: the start is only a prediction, and the fast path is taken: a smoothed level
        stops, unconverged, when the band would leave the crop (``margin − 3`` px: beyond, it
        would sample the crop's replicated border), the whole fit as soon as the widest level
        does so (the coarse search's job), the smoothed levels stop early and the last one is
        left out once the template is averaged, and the full-resolution stage runs in a crop
        centred on its start. Without it (a start from the coarse search, the last resort)
        the smoothed stage runs in full, as it always did. The full-resolution stage stops,
        unconverged, after ``margin − 3`` or ``max_move`` px.
        """
        careful = robust_start and not give_up
        reach = margin - 3
        crop, cw, pts, arrays, centre, setups = self._band_crop(arr, shift0, margin, at)
        two_level = self.photometry == "regions"
        common = {"weights": arrays["_weights"], "huber": self.huber, "photometric": self.photometric,
                  "regions": arrays["_inside"] if two_level else None}
        iv = self.photometry == "instrument"
        # An averaged template (lightly smoothed Jacobian): the iterations shrink geometrically and
        # may stop one early (early_stop). A young, noisy one takes its curvature from the image,
        # and its iterations, which do not shrink so regularly, run to the tolerance.
        mature = self._sigma_j <= 1.0
        if self.coarse_sigma > 0 and robust_start:
            # Stage 1, coarse to fine, both images smoothed alike (σ = 4, 2, 1 × coarse_sigma): a
            # wide basin and a smooth cost, so a start several px off (a bad prediction, a coarse
            # peak slid along a straight edge) or a noisy one-frame template still converges.
            # With an averaged template the full-resolution stage takes over from σ = 2 × coarse_sigma
            # (its basin reaches that far); a young, noisy one needs the last smoothed level too.
            levels = self._stage1_sigmas[:2] if (mature and not careful) else self._stage1_sigmas
            for k, sigma in enumerate(levels):
                smooth = cv2.GaussianBlur(cw, (0, 0), sigma)
                values, sgx, sgy = (arrays[f"_s{k}_values"], arrays[f"_s{k}_gx"], arrays[f"_s{k}_gy"])
                room = np.inf if careful else reach - float(np.max(np.abs(np.asarray(shift0, float) - centre)))
                # The smoothed levels only have to bring the next one into its basin.
                tolerance = 0.02 if careful else STAGE1_TOLERANCE[min(k, len(STAGE1_TOLERANCE) - 1)]
                first = gauss_newton_translation(smooth, pts, values, sgx, sgy, shift0, gain0=gain0, offset0=offset0,
                                                 max_iterations=self.max_iterations, tolerance=tolerance,
                                                 weights=arrays["_weights"], huber=self.huber,
                                                 photometric=self.photometric, regions=arrays["_inside"],
                                                 max_move=room, setup=setups.get(k), early_stop=mature and not careful)
                if first.converged and abs(first.gain) > 0.05:
                    shift0, gain0, offset0 = first.shift, first.gain, first.offset
                elif give_up and k == 0 and np.max(np.abs(first.shift - shift0)) > room:
                    # The widest basin leaves the crop: the prediction is farther off than the
                    # crop reaches, a job for the coarse search.
                    return first, 0.0
            if not careful and np.any(np.round(shift0) != centre):
                # Stage 2 in a crop centred on its start (the same pixels, whitened alike).
                crop, cw, pts, arrays, centre, setups = self._band_crop(arr, shift0, margin, at)
            # (the crop, hence the band pixels still inside it, may have changed in stage 1)
            common = {"weights": arrays["_weights"], "huber": self.huber, "photometric": self.photometric,
                      "regions": arrays["_inside"] if two_level else None}
        # Stage 2, full resolution: the efficient estimate. A strongly smoothed Jacobian (young
        # template) takes its curvature from the image; a light one is close enough to exact.
        curvature = None if mature else five_point_gradients(cw)
        limit = reach if max_move is None else min(reach, max_move)
        fit = gauss_newton_translation(cw, pts, arrays["_tw_values"], arrays["_gx"], arrays["_gy"], shift0,
                                       gain0=gain0, offset0=offset0, max_iterations=self.max_iterations,
                                       curvature=curvature,
                                       template_variance=None if (two_level or iv) else arrays["_t_var"],
                                       instrument=arrays["_instrument"] if iv else None,
                                       max_move=limit, setup=setups.get("fine"),
                                       early_stop=mature and not careful, sectors=arrays["_sector"], **common)
        moved = float(np.max(np.abs(fit.shift - np.asarray(shift0, float)))) if np.all(np.isfinite(fit.shift)) else np.inf
        if moved > limit:
            fit.converged = False
        plain = cv2.remap(crop, (pts[:, 0] + fit.shift[0]).astype(np.float32).reshape(1, -1),
                          (pts[:, 1] + fit.shift[1]).astype(np.float32).reshape(1, -1), cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REPLICATE).reshape(-1) if np.isfinite(moved) else None
        score = weighted_ncc(plain, arrays["_t_values"], fit.weights) if plain is not None else 0.0
        return fit, score

    def _background_sectors(self, xs, ys, inside):
        """Background band pixels grouped in ``background_tile``-px tiles, each with its own level.

        The background next to the object is not part of it: where the object moves to, the
        substrate around it is another one, brighter or darker at the scale of a few px (texture,
        shading). Fitted with the template's background, such a local change of level biases the
        edge by a fraction of its width; each tile's own level absorbs it. Object pixels (and all
        pixels when the option is off, ``background_tile=0``) get -1: no local level.
        """
        if self.background_tile <= 0:
            return None
        tile = self.background_tile
        key = (ys // tile) * (self.band.shape[1] // tile + 1) + xs // tile
        _, labels = np.unique(key[~inside], return_inverse=True)
        sector = np.full(len(xs), -1, np.intp)
        sector[~inside] = labels
        return sector

    def _threshold(self) -> float:
        if self._scores:
            return max(self.min_score, self.min_relative_score * self._median_score())
        return self.min_score

    def _median_score(self) -> float:
        """Median of the first frames' scores (cached: the list only grows, to 10)."""
        if self._score_median[0] != len(self._scores):
            self._score_median = (len(self._scores), float(np.median(self._scores)))
        return self._score_median[1]

    def _update_ic(self, arr) -> TrackResult:
        predicted = self.shift + self.velocity
        fit, score, good = None, 0.0, False
        typical = 0.9 * self._median_score() if self._scores else 1.0
        if not self.lost:
            # The constant-velocity prediction first: while tracking it is within a fraction of
            # a pixel (then the smoothed first stage is skipped) or a few px (a change of speed).
            steady = self._last_prediction_error < 1.0
            # A steady fit that has to move more than a few px is a change of speed: the
            # smoothed stage is the tool then, not 20 crawling full-resolution iterations.
            fit, score = self._fit(arr, predicted, self.gain, self.offset, robust_start=not steady,
                                   max_move=3.0 if steady else None, give_up=True)
            if steady and not fit.converged:
                fit, score = self._fit(arr, predicted, self.gain, self.offset, give_up=True)
            good = fit.converged and score >= max(self._threshold(), typical)
        if not good:
            # A jump, a poor match or a lost target: the coarse search over the window (the
            # whole image when lost), and keep the better match, the one nearer the prediction
            # when about as good.
            coarse = self._coarse(arr, predicted)
            fit2, score2 = self._fit(arr, coarse, self.gain, self.offset)
            if fit is None or (fit2.converged and (not fit.converged or score2 > score + 0.05 or (
                    score2 >= score - 0.05
                    and np.hypot(*(fit2.shift - predicted)) < np.hypot(*(fit.shift - predicted))))):
                fit, score = fit2, score2
        if not self.lost and (not fit.converged or score < self._threshold()):
            # The appearance changed (an edge's contrast vanished at contact, a brightness
            # jump): the contrast-invariant correlation of the object over the whole window.
            found = self._reacquire(arr, predicted)
            if found is not None:
                return found
        if not fit.converged:
            return self._lost(f"no convergence (score {score:.2f})")
        if score < self._threshold():
            return self._lost(f"no match (score {score:.2f} < {self._threshold():.2f})")
        if not self._band_inside(fit.shift, arr.shape, fraction=0.5):
            return self._lost("the target has left the image")
        self.gain, self.offset = fit.gain, fit.offset
        if len(self._scores) < 10:
            self._scores.append(score)
        self._last_prediction_error = float(np.hypot(*(fit.shift - predicted)))
        # The answer is the shift against the template that measured it, with that template's
        # origin; a template refreshed from this frame brings its own origin, and the state
        # moves into its coordinates (the position, shift − origin, stays).
        result = self._accept(fit.shift, score)
        if self._stack is not None and fit.inliers > 0.8 and score >= 0.8 * np.median(self._scores):
            origin = self.origin.copy()
            self._average_into_template(arr, fit)
            self.shift = self.shift + (self.origin - origin)
        return result

    def _reacquire(self, arr, predicted, sigma=1.5, min_ncc=0.6, min_margin=0.05):
        """Fallback when Gauss–Newton fails: where in the search window the object looks most alike.

        The object and its immediate surroundings (its region dilated by 4 px, so static
        background in the ROI counts little) are matched by masked normalised correlation of
        the smoothed images — blind to gain and offset (a brightness jump) and degrading
        gracefully when one edge loses its contrast (contact with a sample) — over the whole
        search window, at half resolution and then at full resolution around the peak. The
        best match over the window, not the one nearest the prediction: near the prediction a
        probe that jumped along its own shaft leaves shaft behind, which correlates well too.
        The peak must stand out from the best match more than a few px away (``min_margin``),
        or the answer is ambiguous and the frame stays lost. Gauss–Newton restarted there
        refines it when it converges nearby; otherwise the correlation peak is the answer.

        Returns
        -------
        TrackResult or None
            The accepted result, or None (nothing found well enough).
        """
        x0, y0, w, h = self.roi
        wx, wy, ww, wh = self._window(arr.shape, predicted)
        if ww < w + 4 or wh < h + 4:
            return None
        window = cv2.GaussianBlur(_crop(arr, wx, wy, wx + ww, wy + wh), (0, 0), sigma)
        tmpl = cv2.GaussianBlur(self.template, (0, 0), sigma)
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
        mask = cv2.dilate(self.contour.region.astype(np.uint8), kernel) > 0
        mask &= self._inner(mask.shape, 2)
        if mask.sum() < 10 or mask.all() or np.ptp(tmpl[mask]) <= 0:
            return None
        # Half resolution over the window (a quarter of the work), full resolution near its peak.
        half = cv2.resize(window, (ww // 2, wh // 2), interpolation=cv2.INTER_AREA)
        th, tw_ = h // 2, w // 2
        tmpl_half = cv2.resize(tmpl[:2 * th, :2 * tw_], (tw_, th), interpolation=cv2.INTER_AREA)
        mask_half = cv2.resize(mask[:2 * th, :2 * tw_].astype(np.float32), (tw_, th), interpolation=cv2.INTER_AREA)
        coarse = cv2.matchTemplate(half, tmpl_half, cv2.TM_CCOEFF_NORMED, mask=(mask_half > 0.5).astype(np.float32))
        coarse = np.nan_to_num(coarse, nan=-1.0, posinf=-1.0, neginf=-1.0)
        _, peak, _, (cx, cy) = cv2.minMaxLoc(coarse)
        # The runner-up: the best other local maximum more than 8 px away (a ridge through the
        # peak, e.g. along an edge, is the same peak's shoulder, not a rival).
        yy, xx = np.ogrid[:coarse.shape[0], :coarse.shape[1]]
        local_max = coarse >= cv2.dilate(coarse, np.ones((5, 5), np.uint8))
        rivals = local_max & ((np.abs(xx - cx) > 4) | (np.abs(yy - cy) > 4))
        runner_up = float(coarse[rivals].max()) if rivals.any() else -1.0
        if peak < min_ncc or peak - runner_up < min_margin:
            return None
        r = 3
        fx0, fy0 = max(2 * cx - r, 0), max(2 * cy - r, 0)
        fx1, fy1 = min(2 * cx + r + w, ww), min(2 * cy + r + h, wh)
        fine = cv2.matchTemplate(window[fy0:fy1, fx0:fx1], tmpl, cv2.TM_CCOEFF_NORMED, mask=mask.astype(np.float32))
        fine = np.nan_to_num(fine, nan=-1.0, posinf=-1.0, neginf=-1.0)
        _, peak, _, (ix, iy) = cv2.minMaxLoc(fine)
        if peak < min_ncc or not (0 < ix < fine.shape[1] - 1 and 0 < iy < fine.shape[0] - 1):
            return None
        px, py = parabola_peak(fine, ix, iy)
        shift = np.array([wx + fx0 + px - x0, wy + fy0 + py - y0])
        # Gain and offset of the match (whitened units: a constant c whitens to (1 − ρ)·c).
        a = window[fy0 + iy:fy0 + iy + h, fx0 + ix:fx0 + ix + w][mask].astype(np.float64)
        b = tmpl[mask].astype(np.float64)
        gain = float(np.cov(a, b)[0, 1] / np.var(b, ddof=1))
        rho = self.noise.rho if self.whiten else 0.0
        offset = (1.0 - rho) * float(a.mean() - gain * b.mean())
        try:
            fit, score = self._fit(arr, shift, gain, offset)
        except (ValueError, np.linalg.LinAlgError):
            fit, score = None, 0.0
        self._last_prediction_error = np.inf
        if (fit is not None and fit.converged and score >= self._threshold()
                and np.hypot(*(fit.shift - shift)) <= 1.5):
            self.gain, self.offset = fit.gain, fit.offset
            return self._accept(fit.shift, score)
        self.gain, self.offset = gain, offset
        return self._accept(shift, float(peak))

    def _average_into_template(self, arr, fit):
        """Running mean of the registered, photometrically normalised ROI (a less noisy template).

        The ROI's surroundings are kept for the first ``template_frames`` frames; at the end all
        of them are registered again against the averaged template and averaged anew, so that the
        early registrations against a noisy template do not blur the final one. Frame 0 is
        registered against every new template: it defines the origin, which so carries frame 0's
        noise once instead of the one-frame template's noise in every position.
        """
        x0, y0, w, h = self.roi
        m = 16
        sx, sy = round(fit.shift[0]), round(fit.shift[1])
        ax0, ay0 = x0 + sx - m, y0 + sy - m
        if ax0 < 0 or ay0 < 0 or ax0 + w + 2 * m > arr.shape[1] or ay0 + h + 2 * m > arr.shape[0]:
            return
        area = _crop(arr, ax0, ay0, ax0 + w + 2 * m, ay0 + h + 2 * m)
        self._stack.append([area, (ax0, ay0), fit.shift.copy(), fit.gain, fit.offset])
        n = len(self._stack)
        self._n_averaged = n
        if n >= self.template_frames:
            self._rebuild_template(passes=2 if self.reidentify else 1)
            self._stack = None
        else:
            patch = self._registered_patch(area, (ax0, ay0), fit.shift, fit.gain, fit.offset)
            self._sum = (self._sum if self._sum is not None else self.template.astype(np.float64)) + patch
            if n & (n - 1):
                return  # the template is refreshed when the count doubles (2, 4, 8, ...): cheaper
            self.template = (self._sum / n).astype(np.float32)
            self._prepare_template()
            area0, at0, shift0, gain0, offset0 = self._stack[0]
            ref, _ = self._fit(area0, shift0, gain0, offset0, at=at0, robust_start=False)
            if ref.converged:
                self._stack[0][2:] = [ref.shift.copy(), ref.gain, ref.offset]
                self.origin = ref.shift.copy()

    def _registered_patch(self, area, at, shift, gain, offset):
        """The ROI-sized patch of ``area`` at ``shift``, in the template's gray levels."""
        x0, y0, w, h = self.roi
        # The same exact Keys interpolation as the registration: another kernel (OpenCV's
        # a = −0.75, positions rounded to 1/32 px) would shift sharp edges by a few hundredths
        # of a pixel at every averaging step, and the template would drift.
        px, py = x0 + shift[0] - at[0], y0 + shift[1] - at[1]
        ix, iy = int(np.floor(px)), int(np.floor(py))
        wx, wy = _keys_taps(px - ix), _keys_taps(py - iy)
        filtered = cv2.sepFilter2D(np.asarray(area, np.float32), -1, wx.reshape(1, 4), wy.reshape(4, 1),
                                   anchor=(1, 1), borderType=cv2.BORDER_REPLICATE)
        patch = filtered[iy:iy + h, ix:ix + w]
        if patch.shape != (h, w):
            raise ValueError("the registered patch leaves the stored area")
        rho = self.noise.rho if self.whiten else 0.0
        # Gain and offset were estimated on whitened images: a constant c whitens to (1 − ρ)·c.
        return (patch - offset / (1.0 - rho)) / gain

    def _rebuild_template(self, passes=1):
        for pass_no in range(passes):
            patches = []
            for item in self._stack:
                area, at, shift, gain, offset = item
                ref, _ = self._fit(area, shift, gain, offset, at=at, robust_start=False)
                if ref.converged:
                    item[2:] = [ref.shift.copy(), ref.gain, ref.offset]
                patches.append(self._registered_patch(area, at, item[2], item[3], item[4]))
            patches = np.stack(patches)
            self.template = patches.mean(axis=0).astype(np.float32)
            if self.reidentify and pass_no == 0 and passes > 1:
                # The next pass registers every stored frame against the new band, frame 0 (the
                # origin) included.
                self._reidentify()
            self._consistency = (self._consistency_weights(patches, [item[2] for item in self._stack],
                                                           self.consistency_cut)
                                 if self.consistency_cut is not None else None)
            self._prepare_template()
        # The origin: where frame 0 (the first item) sits against the new template.
        self.origin = np.asarray(self._stack[0][2], float).copy()

    def _reidentify(self):
        """The contour template and the band identified again, on the averaged template.

        Frame 0's contour follows frame 0's noise: the band built around it holds the pixels
        that noise pushed over the threshold, so frame 0's residuals on it are not centred and
        its own registration — the origin of every displacement — is pulled (measured on the
        simulator's gray-level sequence, seeds 0-5, in x: frame 0 registered 0.03-0.27 px off
        its noise-free render, mean 0.12 px; -0.02-0.11 px, mean 0.05 px, with this). The averaged
        template's contour, at frame 0's threshold (the user's choice, or Otsu's of frame 0), has
        lost that noise. Kept as it was when no usable contour comes out.
        """
        lo, scale = self._to_8bit
        template8 = np.clip(np.rint((self.template - lo) * scale), 0, 255).astype(np.uint8)
        params = dict(self.template_params, threshold=self.contour.threshold)
        try:
            contour = identify_contour_template(template8, **params)
        except ValueError:
            return
        band = self._registration_band(contour)
        if band.sum() < MIN_BAND_PIXELS or not (contour.region.any() and not contour.region.all()):
            return
        self.contour, self.band = contour, band
        self._contour_core = self._core(contour)
        self._small_mask = None  # the coarse search's mask follows the new region

    def _consistency_weights(self, patches, shifts, cut):
        """Band pixels that do not move with the object get no weight.

        Registered on the object, the stacked frames agree wherever the pixels belong to it, up to
        noise, wherever the object was. A static background feature next to it (a particle beside
        the shaft) is there in the frames taken with the object where it started and gone in those
        taken after it moved. So each band pixel's mean over the frames within 1 px of the start
        is compared with its mean over the frames more than 3 px away (Welch's t); where the
        difference exceeds ``cut`` standard errors, the pixel (and its neighbours: a feature is a
        few px across) is background: kept in the template, it would pull the object back to
        where the template was taken. Only background pixels at least 1 px from the contour can be
        flagged: the object and its contour, above all its apex (without which the fit slides
        along the shaft), always stay. Without frames in both groups (the object stood still)
        nothing is flagged.
        """
        moved = np.hypot(*(np.asarray(shifts, float) - np.asarray(shifts[0], float)).T)
        near, far = moved < 1.0, moved > 3.0
        if near.sum() < 3 or far.sum() < 3:
            return None
        ys, xs = np.nonzero(self.band)
        values = patches[:, ys, xs].astype(np.float64)
        a, b = values[near], values[far]
        se = np.sqrt(a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b))
        t = np.abs(a.mean(axis=0) - b.mean(axis=0)) / np.maximum(se, 1e-9)
        distance = cv2.distanceTransform((~self.contour.mask).astype(np.uint8), cv2.DIST_L2, 3)
        eligible = ~self.contour.region & (distance >= 1.0)
        flagged = np.zeros(self.band.shape, np.uint8)
        flagged[ys[t > cut], xs[t > cut]] = 1
        flagged = cv2.dilate(flagged, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
        keep = (flagged[ys, xs] == 0) | ~eligible[ys, xs]
        if keep.mean() < 0.5:
            return None  # more than half inconsistent: no object model to trust, keep all
        return keep.astype(np.float64)

    def _apply_weights(self):
        """The band's weights: inverse noise variance, times the consistency mask."""
        weights = self._base_weights
        if self._consistency is not None:
            weights = self._consistency if weights is None else weights * self._consistency
        self._weights = weights
        self._arrays["_weights"] = weights

    # ---- "contour", "ssd", "hb"
    def _contour_integer(self, arr, shift):
        """Integer top-left of the contour template's best match (paper: adaptive Canny, eq. 10,
        then the score from the contour pixels only), and its score."""
        wx, wy, ww, wh = self._window(arr.shape, shift)
        window = _crop(arr, wx, wy, wx + ww, wy + wh)
        if float(window.max() - window.min()) <= 0:
            raise ValueError("constant search window")
        edges = canny_edges(to_uint8(window), **self.canny)
        x0, y0 = self.roi[:2]
        prefer = (x0 + self._contour_offset[0] + shift[0] - wx, y0 + self._contour_offset[1] + shift[1] - wy)
        ix, iy, score, _ = contour_match(edges, self._contour_core, tolerance_px=self.contour_tolerance,
                                         prefer=prefer)
        self._contour_score = score
        return wx + ix, wy + iy

    def _update_contour(self, arr) -> TrackResult:
        left, top = self._contour_integer(arr, self.shift)
        dx, dy = self._contour_offset
        return self._finish_integer(arr, left - dx, top - dy, self._contour_score, mask=self.band)

    def _update_ssd(self, arr) -> TrackResult:
        wx, wy, ww, wh = self._window(arr.shape, self.shift)
        window = _crop(arr, wx, wy, wx + ww, wy + wh)
        ix, iy, _ = ssd_match(window, self.template)
        _x0, _y0, w, h = self.roi
        patch = window[iy:iy + h, ix:ix + w]
        score = weighted_ncc(patch.ravel(), self.template.ravel())
        return self._finish_integer(arr, wx + ix, wy + iy, score, mask=None)

    def _finish_integer(self, arr, left, top, score, mask) -> TrackResult:
        """Integer match with top-left (left, top), optionally refined by the paper's eq. 9."""
        if score < self.min_score:
            return self._lost(f"no match (score {score:.2f} < {self.min_score:.2f})")
        x0, y0, w, h = self.roi
        dx = dy = 0.0
        if self.subpixel:
            patch = _crop(arr, left, top, left + w, top + h)
            dx, dy = gradient_subpixel_shift(self.template, patch, mask=mask)
            if not (np.isfinite(dx) and np.isfinite(dy)):
                dx = dy = 0.0
            # One linearised step is only trusted within a pixel.
            dx, dy = float(np.clip(dx, -1.0, 1.0)), float(np.clip(dy, -1.0, 1.0))
        return self._accept((left - x0 + dx, top - y0 + dy), score)

    def _update_hb(self, arr) -> TrackResult:
        wx, wy, ww, wh = self._window(arr.shape, self.shift)
        window = _crop(arr, wx, wy, wx + ww, wy + wh)
        ix, iy, _ = ssd_match(window, self.template)
        x0, y0, _w, _h = self.roi
        start = np.array([wx + ix - x0, wy + iy - y0], float)
        p = start.copy()
        m0 = self._m0
        solve = np.linalg.inv(m0.T @ m0) @ m0.T  # (M₀ᵀM₀)⁻¹M₀ᵀ: offline, once per template
        pts = self._hb_points + (x0 - wx, y0 - wy)
        converged = False
        warped = self._hb_values
        for _ in range(self.max_iterations):
            warped = sample_shifted_filtered(window, pts, p)  # I(f(R; μ), tₙ), eq. 3
            # Eq. 5: I(f(R; μ + Δμ), tₙ) ≈ I(f(R; μ), tₙ) + M₀Δμ, with the template's gradients
            # standing in for the image's, so that M₀ is constant; μ ← μ + Δμ.
            delta = -solve @ (warped - self._hb_values)
            p += delta
            if float(np.hypot(*delta)) < 2e-3:
                converged = True
                break
            if np.max(np.abs(p - start)) > 3:
                break
        score = weighted_ncc(warped, self._hb_values)
        if not converged:
            return self._lost(f"no convergence (score {score:.2f})")
        if score < self.min_score:
            return self._lost(f"no match (score {score:.2f} < {self.min_score:.2f})")
        return self._accept(p, score)


def _iter_frames(frames):
    if isinstance(frames, np.ndarray):
        if frames.ndim == 2:
            raise ValueError("frames is a single 2-D image; pass a sequence of frames or a 3-D array")
        if frames.ndim != 3:
            raise ValueError(f"a frame array must be 3-D (N, H, W), got shape {frames.shape}")
        return iter(frames), len(frames)
    if isinstance(frames, (str, bytes)):
        raise TypeError("frames must be arrays, not a path; read them with semlab.io.read_frames")
    try:
        n = len(frames)
    except TypeError:
        n = None
    try:
        return iter(frames), n
    except TypeError:
        raise TypeError(f"frames must be an iterable of 2-D arrays or a 3-D array, got {type(frames).__name__}") from None


def _is_roi_list(roi) -> bool:
    try:
        first = roi[0]
    except (TypeError, IndexError, KeyError):
        return False
    return not np.isscalar(first)


def track(frames, roi, *, method: str = "contour", progress: bool | None = None, **params) -> pd.DataFrame:
    """Track the ROI's centre point through a sequence of frames.

    Parameters
    ----------
    frames : iterable of (H, W) array_like, or (N, H, W) ndarray
        uint8, uint16 or float gray frames.
    roi : (x, y, w, h), or a list of them
        ROI in frame 0 (top-left pixel and size). A list tracks several targets (e.g. the four
        probes) in one pass over the frames, one :class:`Tracker` each, and adds a ``target``
        column (the index in the list).
    method : {"contour", "ic", "ssd", "hb"}
        ``"contour"`` (default) is the paper's method, ``"ssd"`` the conventional baseline and
        ``"ic"`` semlab's best (the default of :class:`Tracker`); see the module docstring.
    progress : bool or None
        tqdm progress bar; ``None`` shows it for sequences longer than 50 frames.
    **params
        Passed to :class:`Tracker`.

    Returns
    -------
    pandas.DataFrame
        One row per frame (and target): ``frame, x, y, score, ok``. ``x, y`` is where the ROI's
        centre point has moved to, px; NaN with ``ok=False`` where the target was lost.

    Raises
    ------
    TypeError, ValueError
        Bad first frame or ROI (from :meth:`Tracker.init`), no frames, or bad parameters; later
        bad frames only flag their rows.

    Examples
    --------
    >>> import numpy as np
    >>> yy, xx = np.mgrid[:240, :320]
    >>> frames = [np.where((xx - 150 - k) ** 2 + (yy - 120) ** 2 < 30 ** 2, 200, 60).astype(np.uint8)
    ...           for k in range(3)]
    >>> df = track(frames, (100, 70, 100, 100), method="ic")
    >>> df["x"].round(1).tolist(), bool(df["ok"].all())
    ([149.5, 150.5, 151.5], True)
    """
    rois = list(roi) if _is_roi_list(roi) else None
    iterator, n = _iter_frames(frames)
    try:
        first = next(iterator)
    except StopIteration:
        raise ValueError("frames is empty") from None
    trackers = [Tracker(method, **params) for _ in (rois or [roi])]
    rows = []
    for k, (t, r) in enumerate(zip(trackers, rois or [roi])):
        res = t.init(first, r)
        rows.append((0, k, res.x, res.y, res.score, res.ok))
    show = (n is not None and n > 50) if progress is None else bool(progress)
    if show:
        from tqdm.auto import tqdm

        iterator = tqdm(iterator, total=None if n is None else n - 1, desc=f"tracking ({method})")
    for i, frame in enumerate(iterator, start=1):
        for k, t in enumerate(trackers):
            res = t.update(frame)
            rows.append((i, k, res.x, res.y, res.score, res.ok))
    df = pd.DataFrame(rows, columns=["frame", "target", "x", "y", "score", "ok"])
    df["ok"] = df["ok"].astype(bool)
    if rois is None:
        return df.drop(columns="target")
    return df.sort_values(["frame", "target"], kind="stable").reset_index(drop=True)
