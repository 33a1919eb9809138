"""The :class:`Tracker`: frame 0's template and set-up; every later frame goes through its
:class:`~semlab.tracking.stepper.Stepper`."""

from __future__ import annotations

import inspect

import cv2
import numpy as np

from ..roi import as_gray_float, check_roi, roi_centre
from ..subpixel import NoiseModel, estimate_noise
from ..template import ContourTemplate, identify_contour_template
from .attached import MAX_OUTLINE_NOISE, clear_band, without_attached
from .band import MIN_BAND_PIXELS, background_texture, band_widths, edge_blur, registration_band
from .frames import GrayScale, as_frame
from .ic import ICMethod
from .method import Method, Motion, Setup
from .options import DEFAULT_METHOD, KEYWORD_GROUP, TrackerOptions
from .paper import ContourMethod, HBMethod, SSDMethod
from .result import TrackResult
from .stepper import Stepper
from .trust import Judge

__all__ = ["METHOD_CLASSES", "Tracker"]

#: One object per algorithm, chosen once (at construction) by the method's name.
METHOD_CLASSES: dict[str, type[Method]] = {"ic": ICMethod, "contour": ContourMethod, "ssd": SSDMethod,
                                           "hb": HBMethod}
#: The smallest ROI (px a side) that holds a contour template and its band.
MIN_ROI_PX = 16
#: The contour must enclose a contrast of at least this many standard deviations of the noise of the
#: smoothed ROI it was found in (a 3σ separation of the object's and the background's levels: below,
#: Otsu's threshold splits noise).
MIN_CONTRAST_NOISE = 3.0
#: A frame must exceed the ROI by this many px (each dimension) to be searched.
FRAME_OVER_ROI_PX = 4
#: What a method may raise on a frame it cannot handle: the frame is lost, never the run.
FRAME_ERRORS = (cv2.error, np.linalg.LinAlgError, ValueError, FloatingPointError, IndexError)


class Tracker:
    """Track the probe tip from frame to frame (paper, Fig. 4).

    Parameters
    ----------
    method : {"ic", "contour", "ssd", "hb"}
        See :mod:`semlab.tracking`; ``"ic"`` is the default because it measured best
        (``benchmarks/bench_tracking.py``).
    search_size : int
        Side of the square search window around the predicted position (paper: 300 px).
    coarse_factor : int
        ``"ic"``: downsampling of the coarse search.
    sigma, threshold, morph_kernel, morph_iterations, bright_object, choose
        Contour template identification (:func:`semlab.template.identify_contour_template`);
        ``choose=None`` (the default) takes the contour at the ROI's centre for ``"ic"`` and the
        paper's largest contour for the others.
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
        background's texture is at least :data:`~semlab.tracking.band.NARROW_BAND_TEXTURE` times
        the noise, and both sides reach across a blurred edge (3 σ of frame 0's edge blur, at most
        5 px: :attr:`edge_sigma`; see :meth:`band_widths`).
    static_background : bool
        ``"ic"``: once the object has moved :data:`~semlab.tracking.layer.GATE_PX` from where it
        started, the background beside it is learned in frame coordinates from the well-registered
        frames, its texture taken off each frame where the template is background, and the template's
        background flattened for the band model (:mod:`semlab.tracking.layer`): a static texture no
        longer matches itself where the template was taken. Only where frame 0's background texture
        is at least :data:`~semlab.tracking.layer.MIN_TEXTURE` times the noise (and under
        :data:`~semlab.tracking.band.FLAT_BACKGROUND_TEXTURE`, where the template is flattened from frame
        0 on); a still probe's template keeps its background (there it is information). False: off.
    inner_px : int
        ``"ic"``: on the object's side the band reaches this deep (its pixels move with the
        object and fix its gray level).
    background_tile : int
        ``"ic"``: the band's background pixels are grouped in tiles of this many px, each with
        its own gray level in the full-resolution fit (the substrate where the object moved to
        is brighter or darker at that scale); 0: one background level.
    photometric : bool
        ``"ic"``: estimate gain and offset per frame.
    photometry : {"regression", "regions", "instrument"}
        ``"ic"``: gain and offset by regression on the template, corrected for the template's
        noise (errors in variables), or from the mean levels of object and background pixels,
        or by the smoothed template as the gain's instrument.
    whiten : bool
        ``"ic"``: undo the scan line's noise correlation (:func:`semlab.subpixel.whiten_lines`).
    noise_weights : bool
        ``"ic"``: weight pixels by their inverse shot-noise variance.
    jacobian_sigma, jacobian_sigma_first : float
        ``"ic"``: Gaussian smoothing (px) of the template before its gradients (the Jacobian) are
        taken, growing with the template's noise from the first (an averaged template) to the
        second (a noisy one-frame template); 0 uses the raw template's gradients.
    normal_sigma : float
        ``"ic"``: the Jacobian keeps only the gradient component along the edge normal, taken
        from the template smoothed by this many px (0: keep the whole gradient).
    jacobian_denoise : float or None
        ``"ic"``: once the template averages :data:`~semlab.tracking.band.DENOISE_FROM_FRAMES`
        frames, its gradients (the Jacobian, eq. 5's ``M₀``) are taken after non-local-means
        denoising (scikit-image ``denoise_nl_means``, 7×7 patches, 13×13 search, filter strength
        this many times the template's noise standard deviation, which shrinks as the template is
        averaged). None or 0: off. The template's noise enters every estimate through its
        gradients; not denoised before it averages a few frames, at low dose too noisy for the
        patches' similarity to mean anything (measured over many scenes by
        ``benchmarks/bench_tracking_seeds.py --param jacobian_denoise=None``).
    coarse_sigma : float
        ``"ic"``: Gaussian smoothing (px) of template and image in the first registration stage
        of every frame (0: single stage at full resolution).
    max_iterations : int
        Gauss–Newton iterations per frame (``"ic"``, ``"hb"``).
    huber : float or None
        ``"ic"``: Huber threshold in robust standard deviations (None: plain least squares).
    misfit_p_value : float or None
        ``"ic"``: a 4-px tile of the band whose residuals are this improbable under the noise
        (their χ²'s p-value) and more than a fifth of the object's contrast is not explained by the
        template — a particle over the apex, an occluder's rim, debris in the band, each inside
        Huber's linear range pixel by pixel — and the frame is fitted again without it, worst tile
        first, at most three (:mod:`semlab.tracking.trimming`). None: off.
    template_frames : int
        ``"ic"`` averages the template over this many well-registered frames (1: frame 0 only),
        each no noisier than twice frame 0's noise variance (a dose drop leaves the template frame 0's).
    consistency_cut : float or None
        ``"ic"``: when the averaged template is built, band pixels whose mean over the
        registered frames taken near the start differs by more than this many standard errors
        from their mean over the frames taken after the object moved are static background, not
        object, and get no weight (None: keep all).
    reidentify : bool
        ``"ic"``: once the template is averaged (``template_frames``), identify the contour
        template again on the averaged template, at frame 0's threshold, take the band from it
        and register the stored frames, frame 0 included, once more. Off by default: it helps the
        scenes where frame 0's contour is poor and hurts the typical one
        (``benchmarks/bench_tracking_seeds.py --param reidentify=True``).
    min_score : float or None
        Absolute score below which a frame counts as lost (default per method).
    min_relative_score : float
        ``"ic"``: a frame also counts as lost when its score falls below this fraction of the
        typical score of the first frames (low-dose images have low correlations even when
        right).
    max_sigma : float or None
        ``"ic"``: an answer whose frame allows no better than this many px (the fits' part of
        ``sigma_x`` or ``sigma_y``, :mod:`semlab.tracking.uncertainty`; the median of the last
        frames' where that is worse, :class:`~semlab.tracking.uncertainty.RecentPrecision`) is reported ``ok=False``
        ("too uncertain"; the tracker follows it all the same). The default,
        :data:`~semlab.tracking.uncertainty.SIGMA_LIMIT_PX`, keeps frames more than 1 px off below
        0.5 %; None never flags.
    max_influence : float or None
        ``"ic"``: an answer that one quadrant of the band moves by more than this many px
        (significantly: it disagrees with the rest beyond the noise) is reported ``ok=False``
        ("inconsistent": a part of the template does not move with the object, or clutter covers
        it; :mod:`semlab.tracking.consistency`); the tracker follows it all the same. None never
        flags.
    min_resolved_contrast : float or None
        ``"ic"``: every answer is reported ``ok=False`` ("unresolved"; the tracker follows it all the
        same) when frame 0's object stands less than this many standard deviations of the smoothed
        noise above its background (:attr:`contrast_noise`;
        :data:`~semlab.tracking.uncertainty.MIN_RESOLVED_CONTRAST`): there the noise shapes the outline
        as much as the object, and a thin shaft's registration slides along it unseen by its
        precision. None never flags.
    min_track_score : float or None
        ``"ic"``: every answer is reported ``ok=False`` ("unexplained"; the tracker follows it all the
        same) while the track's first frames (up to ten) match its template at a median score under
        this (:data:`~semlab.tracking.uncertainty.MIN_TRACK_SCORE`): the template then accounts for
        too little of what the frames show for the fits' precision to vouch for an answer (a real
        needle over a real background at a low dose, biased by a pixel while its precision says a few
        tenths). None never flags.
    max_textured_drop : float or None
        ``"ic"``, over a strongly textured substrate only (frame 0's background flattened for the band
        model): an answer whose match scores more than this under the track's first frames' median is
        reported ``ok=False`` ("slid"; the tracker follows it all the same): the registration has slid
        along the shaft onto grains that stay where they are
        (:data:`~semlab.tracking.uncertainty.MAX_TEXTURED_SCORE_DROP`). None never flags.

    An unknown keyword raises TypeError with the list of the allowed ones; the options, checked
    and grouped by concern, are :attr:`options` (:class:`~semlab.tracking.options.TrackerOptions`).

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

    #: See :func:`semlab.tracking.band.background_texture`.
    background_texture = staticmethod(background_texture)

    def __init__(self, method: str = DEFAULT_METHOD, **options):
        self.options = TrackerOptions.from_keywords(method, **options)
        self.method = method
        #: The background's texture over the noise (standard deviations), measured by init().
        self.texture = None
        #: Frame 0's object/background contrast over the noise of the smoothed ROI it was found in (standard
        #: deviations), measured by init(); below ``min_resolved_contrast`` every answer is flagged.
        self.contrast_noise = None
        #: The edge's blur (px) along frame 0's contour, measured by init() (:func:`~semlab.tracking.band.edge_blur`).
        self.edge_sigma = 0.0
        self.roi = None
        self.algorithm: Method | None = None
        self.stepper: Stepper | None = None
        #: The particles cut off frame 0's contour region (ROI-sized bool mask; None: none cut), set by init()
        #: (:mod:`semlab.tracking.attached`).
        self.attached = None

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
        frame, image, roi, patch = self._frame0(frame, roi)
        x0, y0, w, h = roi
        # The frame's own gray levels (uint8 as they are), so a manual threshold means the same
        # here as in identify_contour_template and the TemplateExplorer.
        raw = GrayScale.as_8bit(np.asarray(frame)[y0:y0 + h, x0:x0 + w])
        contour = identify_contour_template(raw, **self.options.template.as_kwargs())
        # How identify_contour_template mapped frame 0's gray levels onto 0-255 (uint8 as they are).
        to_8bit = (0.0, 1.0) if raw.dtype == np.uint8 else (
            float(patch.min()), 255.0 / max(float(patch.max() - patch.min()), 1e-12))
        noise = self._measure(patch, contour, roi)
        widths = self.band_widths()
        contour, attached = self._cut_attached(contour, raw)
        band = _checked_band(clear_band(registration_band(contour, widths), attached, contour.region), roi)
        if not (self.options.photometry.whiten or self.options.photometry.noise_weights):
            noise = NoiseModel()
        algorithm = METHOD_CLASSES[self.method](self.options)
        algorithm.start(Setup(image, roi, patch, contour, band, widths, noise, to_8bit, self.texture, self.edge_sigma,
                              attached))
        self.algorithm, self.noise, self.roi, self.attached = algorithm, noise, roi, attached
        # Frame 0 is the origin of every displacement: its position is the ROI's centre by definition.
        centre0 = roi_centre(roi)
        #: Every later frame's states (:mod:`semlab.tracking.stepper`), its answers judged by
        #: :mod:`semlab.tracking.trust`.
        self.stepper = Stepper(algorithm, Judge(self.options.loss, self.contrast_noise, algorithm), roi,
                               self.options.search.search_size, self.options.loss.max_poor_jump, centre0)
        return TrackResult(float(centre0[0]), float(centre0[1]), 1.0, True, sigma_x=0.0, sigma_y=0.0)

    def _frame0(self, frame, roi):
        """``(frame, image, roi, patch)``: frame 0 on the tracker's gray scale (:attr:`scale`, set here),
        as float, the checked ROI and its patch.

        Raises
        ------
        TypeError, ValueError
            Bad frame, ROI not wholly inside it or too small, or a constant ROI.
        """
        as_gray_float(frame)  # a clear error for a bad frame 0, before anything is scaled
        self.scale = GrayScale.of(frame)
        frame = self.scale.apply(np.asarray(frame))
        image = as_gray_float(frame)
        roi = check_roi(roi, image.shape, min_size=MIN_ROI_PX)
        x0, y0, w, h = roi
        patch = image[y0:y0 + h, x0:x0 + w].copy()
        if float(patch.max() - patch.min()) <= 0:
            raise ValueError(f"the ROI {roi} is constant: nothing to track")
        return frame, image, roi, patch

    def _measure(self, patch, contour: ContourTemplate, roi) -> NoiseModel:
        """Frame 0's noise (returned), and :attr:`contrast_noise`, :attr:`texture` and :attr:`edge_sigma`
        (set); raises ValueError when the contour is not resolved from the noise at all (:func:`_check_contrast`)."""
        noise = estimate_noise(patch)
        contrast, smoothed_sd = _check_contrast(patch, contour, noise, roi, self.options.template.sigma)
        self.contrast_noise = contrast / smoothed_sd if smoothed_sd > 0 else float("inf")
        self.texture = background_texture(patch, contour.region, noise)
        self.edge_sigma = edge_blur(patch, contour, contrast)
        return noise

    def _cut_attached(self, contour: ContourTemplate, raw) -> tuple[ContourTemplate, np.ndarray | None]:
        """Frame 0's ``contour`` without the substrate Otsu's level joined to it and, where its outline is
        resolved above the noise, the particles touching it (:func:`~semlab.tracking.attached.without_attached`),
        and the pixels cut (None: none, or a method that does not cut)."""
        if not (METHOD_CLASSES[self.method].cuts_attached and self.options.band.cut_attached):
            return contour, None
        template = self.options.template
        return without_attached(contour, raw, choose=template.choose,
                                outline_resolved=self.contrast_noise * MAX_OUTLINE_NOISE >= 1.0,
                                bright_object=template.bright_object, morph_kernel=template.morph_kernel,
                                morph_iterations=template.morph_iterations)

    def band_widths(self) -> tuple[int, int]:
        """How far (px) the registration band reaches from the contour: ``(background, object)``
        (:func:`semlab.tracking.band.band_widths`)."""
        return band_widths(self.options.band, self.method, self.texture, self.edge_sigma)

    # ------------------------------------------------------------------ the options as attributes
    def __getattr__(self, name: str):
        """Every option reads as an attribute, as before the groups (``t.search_size``; ``t.canny``
        and ``t.template_params``: the keywords of the Canny and the template identification)."""
        options = self.__dict__.get("options")
        if options is not None:
            if name in KEYWORD_GROUP:
                return getattr(getattr(options, KEYWORD_GROUP[name]), name)
            if name == "canny":
                return options.contour.canny_kwargs()
            if name == "template_params":
                return options.template.as_kwargs()
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __setattr__(self, name: str, value):
        if name in KEYWORD_GROUP or name in ("canny", "template_params"):
            # A changed attribute that the tracker no longer reads would be a silent error.
            raise AttributeError(f"the Tracker's options are fixed at construction: make a new Tracker({name}=...)")
        super().__setattr__(name, value)

    # ------------------------------------------------------------------ what the method holds
    @property
    def contour(self) -> ContourTemplate:
        """The contour template (re-identified on the averaged template with ``reidentify``)."""
        return self.algorithm.contour

    @property
    def band(self) -> np.ndarray:
        """The registration band around :attr:`contour` (ROI coordinates)."""
        return self.algorithm.band

    @property
    def template(self) -> np.ndarray:
        """The template the method matches (``"ic"``: averaged over the first frames)."""
        return self.algorithm.template

    @property
    def centre0(self) -> np.ndarray:
        """Frame 0's answer, the ROI's centre (px)."""
        return self.stepper.centre0

    @property
    def motion(self) -> Motion:
        """The target's motion state (:class:`~semlab.tracking.method.Motion`)."""
        return self.stepper.motion

    @property
    def shift(self) -> np.ndarray:
        """The template's last shift against the ROI (:attr:`motion`)."""
        return self.motion.shift

    @property
    def velocity(self) -> np.ndarray:
        """The last frame-to-frame shift (:attr:`motion`)."""
        return self.motion.velocity

    @property
    def origin(self) -> np.ndarray:
        """Where the template sits in frame 0: positions are ``centre0 + shift − origin``."""
        return self.algorithm.origin

    @property
    def lost(self) -> bool:
        """Whether the last frame was lost."""
        return self.motion.lost

    @property
    def n_lost(self) -> int:
        """Frames lost since :meth:`init`."""
        return self.motion.n_lost

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
            arr = self.scale.apply(as_frame(frame))
        except (TypeError, ValueError) as err:
            return self.stepper.lose(f"unusable frame: {err}")
        if arr.shape[0] < self.roi[3] + FRAME_OVER_ROI_PX or arr.shape[1] < self.roi[2] + FRAME_OVER_ROI_PX:
            return self.stepper.lose(f"frame {arr.shape} is smaller than the ROI")
        try:
            return self.stepper.step(arr)
        except FRAME_ERRORS as err:
            return self.stepper.lose(f"{err}")


# The contract's keywords, defaults and annotations, as inspect.signature and typing.get_type_hints
# of Tracker.__init__ show them (the options themselves arrive as **options).
Tracker.__init__.__signature__ = TrackerOptions.signature(
    inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD))
Tracker.__init__.__annotations__ = {name: p.annotation for name, p in Tracker.__init__.__signature__.parameters.items()
                                    if p.annotation is not inspect.Parameter.empty}


def smoothed_noise_sd(noise: NoiseModel, level: float, sigma_px: float) -> float:
    """Standard deviation (gray levels) of the noise at ``level`` after the template identification's
    Gaussian smoothing of ``sigma_px`` (:func:`semlab.template.identify_contour_template`): the
    smoothing averages the white noise down, less along the scan line, whose noise is correlated
    (AR(1), ``noise.rho``)."""
    sd = float(np.sqrt(noise.variance(level)))
    if sigma_px <= 0:
        return sd
    kernel = cv2.getGaussianKernel(2 * int(np.ceil(4 * sigma_px)) + 1, sigma_px).ravel()
    lags = np.abs(np.subtract.outer(np.arange(kernel.size), np.arange(kernel.size)))
    along_line = float(kernel @ (noise.rho ** lags) @ kernel)
    across = float(kernel @ kernel)
    return sd * float(np.sqrt(along_line * across))


def _checked_band(band, roi) -> np.ndarray:
    """``band``, or a clear error when it holds fewer than :data:`~semlab.tracking.band.MIN_BAND_PIXELS`."""
    if band.sum() < MIN_BAND_PIXELS:
        raise ValueError(f"the contour template in ROI {roi} leaves {int(band.sum())} band pixels away from "
                         f"the ROI border, fewer than {MIN_BAND_PIXELS}: enlarge the ROI or move it onto the tip")
    return band


def _check_contrast(patch, contour: ContourTemplate, noise: NoiseModel, roi,
                    sigma_px: float) -> tuple[float, float]:
    """``(contrast, sd)``: the contour's object/background contrast and the noise of the smoothed image
    in which it was found (``(0, inf)`` when the region is empty or the whole ROI).

    Raises
    ------
    ValueError
        The contrast is below :data:`MIN_CONTRAST_NOISE` noise standard deviations: noise, not a probe.
    """
    region = contour.region
    if not (region.any() and not region.all()):
        return 0.0, float("inf")
    contrast = abs(float(patch[region].mean() - patch[~region].mean()))
    sd = smoothed_noise_sd(noise, float(patch.mean()), sigma_px)
    if contrast < MIN_CONTRAST_NOISE * sd:
        raise ValueError(f"no object in the ROI {roi}: the contour encloses a contrast of {contrast:.3g} gray levels, "
                         f"less than {MIN_CONTRAST_NOISE:g} times the noise of the smoothed ROI ({sd:.3g}); "
                         "this is noise, not a probe")
    return contrast, sd
