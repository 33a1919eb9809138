"""``"ic"``: inverse-compositional Gauss–Newton on the contour band (semlab's method).

Beyond the paper, and measured best (``benchmarks/bench_tracking.py``): the band model
(:mod:`semlab.tracking.band`) registered (:mod:`semlab.tracking.registration`) from the
constant-velocity prediction; when that fails, from a coarse masked normalised-correlation
search (:mod:`semlab.tracking.search`) over the window (the whole image after a loss); when both
fail (an edge's contrast vanishing at contact with a sample, a brightness jump), the
re-acquisition by contrast-blind correlation. The template is averaged over the first
registered frames (:mod:`semlab.tracking.averaging`), frame 0 re-registered against it as the
origin. Once the object has moved, the static background beside it is learned in frame coordinates
and its texture taken off the frames, which are then registered against the template with its
background flattened (:mod:`semlab.tracking.layer`). While the template is young, a piece of the object
that does not move with it is cut (:mod:`semlab.tracking.pieces`).
"""

from __future__ import annotations

import numpy as np

from ..template import identify_contour_template
from .averaging import TemplateAverager, consistency_weights, store_frame
from .band import (
    FLAT_BACKGROUND_TEXTURE,
    MIN_BAND_PIXELS,
    build_band_model,
    flattened_background,
    region_contrast,
    registration_band,
)
from .consistency import band_quadrants, quadrant_influence
from .layer import GATE_PX, MIN_TEXTURE, BackgroundLayer, far_from_region, far_px, object_support
from .method import Method, Motion, Setup, Verdict
from .pieces import LoosePieces, loose_pieces
from .registration import FitResult, OffImage, Start, register
from .search import coarse_mask, coarse_search, coarse_template, reacquire
from .trimming import MIN_MISFIT_CONTRAST, trim_misfit_tiles
from .uncertainty import (
    RecentPrecision,
    Uncertainty,
    band_tiles,
    clustered_covariance,
    model_error,
    position_sigma,
    young_template_inflation,
)

__all__ = ["ICMethod"]

#: A prediction that was within this many px last frame is "steady": the smoothed stage is skipped,
#: and the static background's texture is taken off the frame (:mod:`semlab.tracking.layer`).
STEADY_PX = 1.0
#: A steady fit that has to move more than this (px) is a change of speed: the smoothed stage's job.
STEADY_MAX_MOVE_PX = 3.0
#: A fit from the prediction stands when its score reaches this fraction of the typical one.
TYPICAL_SCORE_FRACTION = 0.9
#: Two scores within this are about as good: the fit nearer the prediction wins.
SCORE_TIE = 0.05
#: The first frames' scores kept for the typical score (the loss threshold).
SCORES_KEPT = 10
#: A re-acquired candidate is refined by Gauss–Newton when the fit stays within this (px).
REFINED_WITHIN_PX = 1.5
#: The band must keep this fraction inside the image, this many px from its border.
BAND_INSIDE_FRACTION = 0.5
BAND_INSIDE_MARGIN_PX = 2
#: A frame enters the template average when this fraction of the band are inliers and its score
#: reaches this fraction of the first frames' median.
AVERAGE_MIN_INLIERS = 0.8
AVERAGE_MIN_SCORE_FRACTION = 0.8
#: ... and when its pixel noise variance is at most this many times frame 0's, in gray levels or in the
#: template's (:meth:`~semlab.tracking.averaging.TemplateAverager.as_noisy_as_the_first`). The frames of one
#: setting of the microscope agree to a few % (:func:`~semlab.subpixel.noise_variance`; gain jitter,
#: charging and passing clutter included). After a dose drop, noisier frames averaged in make the
#: template noisier than frame 0 alone, and the sigma then falls short of the error (a wedge at 20×
#: frame 0's noise: errors of 0.7 px sd along its axis reported at 0.38 px,
#: ``tests/test_track_dose.py``).
AVERAGE_MAX_NOISE_RATIO = 2.0


class ICMethod(Method):
    """The ``"ic"`` method's state: its template (averaged), band model, photometric state and
    the first frames' scores."""

    name = "ic"
    flags_uncertain = True
    widens_search = True
    cuts_attached = True

    def start(self, setup: Setup) -> None:
        super().start(setup)
        self.noise, self.widths, self.to_8bit = setup.noise, setup.widths, setup.to_8bit
        #: The template's background is flattened for the band model (:func:`~semlab.tracking.band.
        #: flattened_background`) over a strongly textured substrate.
        self.flatten = setup.texture >= FLAT_BACKGROUND_TEXTURE
        #: The static background (:mod:`semlab.tracking.layer`), learned while the object has not moved
        #: and acting once it has (:attr:`layer_on`). None: ``static_background`` off, a background with
        #: little texture (under :data:`~semlab.tracking.layer.MIN_TEXTURE`), or a strongly
        #: textured substrate, whose template is flattened from frame 0 on: there the layer's texture,
        #: learned from a few frames of grains 1.5-2.2× the noise, took the probe more than 1 px off on more
        #: frames that said ok than it saved (the substrates family's spare seeds).
        self.layer, self.layer_on = None, False
        self.far_px = far_px(setup.edge_sigma)
        if self.options.band.static_background and MIN_TEXTURE <= setup.texture and not self.flatten:
            level = float(np.mean(setup.patch[~setup.contour.region])) if not setup.contour.region.all() else 0.0
            noise_var = float(np.asarray(setup.noise.variance(level)))
            self.layer = BackgroundLayer(setup.image.shape, setup.roi, setup.texture ** 2 * noise_var, noise_var)
        self.rho = setup.noise.rho if self.options.photometry.whiten else 0.0
        self.n_averaged = 1
        #: Covariance (px²) of the origin, frame 0's shift against the current template (0 while
        #: frame 0 is the template).
        self.origin_cov = np.zeros((2, 2))
        self.consistency = None
        #: The pieces frame 0's cut left, judged by the frames (:meth:`_cut_pulling`, :mod:`semlab.tracking.pieces`).
        self.pieces = LoosePieces(loose_pieces(setup.contour.region) if self.options.band.cut_attached else [],
                                  setup.attached)
        self.gain, self.offset = 1.0, 0.0
        self.scores: list[float] = []
        #: The recent frames' precisions, by which each frame's is judged.
        self.recent_precision = RecentPrecision()
        self._score_median = (0, float("nan"))
        self._coarse_mask = None
        #: The last accepted fit, when tiles were trimmed from it, and the band model it used.
        self._trimmed = (None, None)
        self._build()
        if self.layer is not None:
            self.layer.add(setup.image, np.zeros(2), 1.0, 0.0, self.rho, self.far)
        self.averager = None
        if self.options.averaging.template_frames > 1:
            first = store_frame(setup.image, self.roi, np.zeros(2), 1.0, 0.0)
            if first is not None:
                self.averager = TemplateAverager(first, self.options.averaging.template_frames, self.roi, self.rho)

    def _build(self) -> None:
        """The band model and the coarse template of the current template (offline)."""
        if self.layer is not None:
            #: The object, its thin apex's blurred end included (:func:`~semlab.tracking.layer.object_support`),
            #: and the template's background away from it and its blurred edge (:func:`~semlab.tracking.layer.far_px`).
            self.support = object_support(self.template, self.contour.region, 2 * self.far_px)
            self.far = far_from_region(self.support, self.far_px)
        template = flattened_background(self.template, self.contour.region) if self.flatten else self.template
        #: The band model of the template, and (once the static background acts) of the template
        #: flattened beyond :attr:`far_px`, for the frames its texture is taken off
        #: (:meth:`prepare`): a frame and its model see the background alike.
        self.models = {False: self._band_model(template)}
        if self.layer_on:
            self.models[True] = self._flattened_model()
        self.model = self.models[False]
        factor = self.options.search.coarse_factor
        if self._coarse_mask is None:  # made once per contour: frame 0's, then the averaged template's
            self._coarse_mask = coarse_mask(self.contour.region, self.band, factor)
        self.coarse = coarse_template(self.template, self._coarse_mask, factor)
        self.quadrants = band_quadrants(self.model.points)
        self.tiles = band_tiles(self.model.points)
        self._use(self.model)

    def _flattened_template(self) -> np.ndarray:
        """The template with its background flattened beyond :attr:`far_px` (the static background's frames)."""
        return flattened_background(self.template, self.support, self.far_px, mean_of_flattened=True)

    def _band_model(self, template, reuse=None):
        return build_band_model(template, self.contour, self.band, self.noise, self.options,
                                n_averaged=self.n_averaged, consistency=self.consistency, reuse=reuse)

    def _flattened_model(self):
        """The band model of :meth:`_flattened_template`, reusing the template's own denoised Jacobian
        source away from the flattened pixels."""
        return self._band_model(self._flattened_template(), reuse=(self.models[False], self.far))

    def _use(self, model) -> None:
        """Register with ``model`` (one of :attr:`models`) and measure the fits against it."""
        self.model = model
        #: The object's contrast in the (whitened) template the fits' residuals are measured against.
        self.contrast = region_contrast(model.fine.values, model.inside, default=0.0)
        #: The band's template gradients (K, 2), the Jacobian up to the fit's gain.
        self.gradients = np.stack([model.fine.gx, model.fine.gy], axis=1)

    def _register(self, arr, start: Start, **kw) -> FitResult:
        return register(arr, self.model, start, self.roi, self.options, **kw)

    def _register_stored(self, stored) -> FitResult:
        """A stored frame (as it came: no texture taken off) registered against the flattened template once
        the static background acts (its texture is then noise about the answer, not a pull towards where the
        template was taken: :func:`~semlab.tracking.band.flattened_background`)."""
        model = self.models[self.layer_on]
        if self.model is not model:
            self._use(model)
        fit = self._register(stored.area, Start(stored.shift, stored.gain, stored.offset), at=stored.at,
                             robust_start=False)
        return self._trim(stored.area, fit, at=stored.at)[0]

    def _trim(self, arr, fit, at=(0, 0)):
        """``(fit, model)``: the fit refitted without the band's misfit tiles
        (:mod:`semlab.tracking.trimming`) and the band model it used (None: nothing trimmed)."""
        p_value = self.options.stages.misfit_p_value
        if p_value is None or not isinstance(fit, FitResult):
            return fit, None
        models = []  # (keep, model) of each refit

        def refit(keep, last):
            models.append((keep, self.model.reweighted(keep, self.options)))
            return register(arr, models[-1][1], Start(last.shift, last.gain, last.offset), self.roi, self.options,
                            at=at, robust_start=False)

        trimmed, keep = trim_misfit_tiles(fit, refit, self.tiles, self.model.weights, p_value,
                                          floor=MIN_MISFIT_CONTRAST * abs(fit.gain) * self.contrast)
        return trimmed, next((model for kept, model in models if kept is keep), None)

    # ---- the loss threshold
    def threshold(self) -> float:
        """Score below which a frame is lost: the absolute ``min_score`` or, once scores are known,
        ``min_relative_score`` of the first frames' median, whichever is higher."""
        loss = self.options.loss
        if self.scores:
            return max(loss.min_score, loss.min_relative_score * self._median_score())
        return loss.min_score

    def _median_score(self) -> float:
        """Median of the first frames' scores (cached: the list only grows, to 10)."""
        if self._score_median[0] != len(self.scores):
            self._score_median = (len(self.scores), float(np.median(self.scores)))
        return self._score_median[1]

    # ---- the states of a frame
    def predict(self, motion: Motion) -> np.ndarray:
        """The constant-velocity prediction."""
        return motion.shift + motion.velocity

    def prepare(self, arr, predicted, motion: Motion) -> np.ndarray:
        """The frame with the static background's texture taken off where the template, at the
        prediction, is background (:meth:`~semlab.tracking.layer.BackgroundLayer.detextured`), once the
        layer acts and while the prediction holds (a jump's frame is registered as it came)."""
        detexture = self.layer_on and motion.prediction_error < STEADY_PX
        model = self.models[detexture]
        if model is not self.model:
            self._use(model)
        return self.layer.detextured(arr, predicted, self.gain, self.far) if detexture else arr

    def follow(self, arr, predicted, motion: Motion) -> FitResult | None:
        """Registration from the prediction: while tracking it is within a fraction of a pixel
        (then the smoothed first stage is skipped) or a few px (a change of speed). None when the
        band there is off the image: a move that stopped at the border (the 200-px A→B moves) has
        its speed extrapolated past it, and the search from the prediction's window finds it."""
        steady = motion.prediction_error < STEADY_PX
        start = Start(predicted, self.gain, self.offset)
        # A steady fit that has to move more than a few px is a change of speed: the smoothed
        # stage is the tool then, not 20 crawling full-resolution iterations.
        try:
            fit = self._register(arr, start, robust_start=not steady,
                                 max_move=STEADY_MAX_MOVE_PX if steady else None, give_up=True)
            if steady and not fit.converged:
                fit = self._register(arr, start, give_up=True)
        except OffImage:
            return None
        return fit

    def typical_score(self) -> float | None:
        """A fraction of the first frames' median score (None before frame 1 is registered)."""
        return TYPICAL_SCORE_FRACTION * self._median_score() if self.scores else None

    def track_score(self) -> float | None:
        """The first frames' median score (None before frame 1 is registered)."""
        return self._median_score() if self.scores else None

    def good(self, fit) -> bool:
        typical = self.typical_score()
        # Before frame 1 has a score, no fit from the prediction is good enough to skip the search.
        bar = max(self.threshold(), 1.0 if typical is None else typical)
        return fit is not None and fit.converged and fit.score >= bar

    def search(self, arr, window, predicted, fit) -> FitResult:
        """A jump, a poor match or a lost target: the coarse search over the window, and the better
        match of the two, the one nearer the prediction when about as good."""
        found = self._register(arr, Start(coarse_search(arr, window, self.coarse, self.options.search.coarse_factor,
                                                        self.roi, self._coarse_mask), self.gain, self.offset))
        if fit is None or self.clearly_better(found, fit) or (found.converged and (not fit.converged or (
                found.score >= fit.score - SCORE_TIE
                and np.hypot(*(found.shift - predicted)) < np.hypot(*(fit.shift - predicted))))):
            return found
        return fit

    def acceptable(self, fit) -> bool:
        return fit.converged and fit.score >= self.threshold()

    def clearly_better(self, other, fit) -> bool:
        return other.converged and other.score > fit.score + SCORE_TIE

    def reacquire(self, arr, window, predicted) -> Verdict | None:
        """The appearance changed: the contrast-invariant correlation of the object over the whole
        window, refined by Gauss–Newton when that converges nearby."""
        found = reacquire(arr, window, self.template, self.contour.region, self.roi, self.rho)
        if found is None:
            return None
        try:
            fit = self._register(arr, Start(found.shift, found.gain, found.offset))
        except (ValueError, np.linalg.LinAlgError):
            fit = None
        matches = fit is not None and fit.score >= self.threshold()
        stays = fit is not None and np.hypot(*(fit.shift - found.shift)) <= REFINED_WITHIN_PX
        if matches and stays and fit.converged:
            self.gain, self.offset = fit.gain, fit.offset
            return Verdict.accept(fit.shift, fit.score, reacquired=True, found=fit)
        self.gain, self.offset = found.gain, found.offset
        # A registration that matches but drifts away is a cost without a clear minimum (a slide along
        # a shaft); one that does not match at all is a changed appearance (the real needle's
        # brightness at contact), where the contrast-invariant correlation is the better witness.
        return Verdict.accept(found.shift, found.score, reacquired=True, found=found,
                              drifted=matches and not stays)

    def verdict(self, arr, fit, predicted) -> Verdict:
        if not fit.converged:
            return Verdict.lose(f"no convergence (score {fit.score:.2f})")
        if fit.score < self.threshold():
            return Verdict.lose(f"no match (score {fit.score:.2f} < {self.threshold():.2f})")
        if not self.model.inside_image(self.roi, fit.shift, arr.shape, margin=BAND_INSIDE_MARGIN_PX,
                                       fraction=BAND_INSIDE_FRACTION):
            return Verdict.lose("the target has left the image")
        fit, model = self._trim(arr, fit)
        self._trimmed = (fit, model) if model is not None else (None, None)
        fit = self._cut_pulling(arr, fit)
        self.gain, self.offset = fit.gain, fit.offset
        if len(self.scores) < SCORES_KEPT:
            self.scores.append(fit.score)
        return Verdict.accept(fit.shift, fit.score, found=fit)

    @property
    def pieces_cut(self) -> np.ndarray | None:
        """The pieces the frames cut off the region (ROI-sized bool mask; None: none)."""
        return self.pieces.cut

    def _cut_pulling(self, arr, fit: FitResult) -> FitResult:
        """``fit``, or its refit once a piece that pulls it is cut off (:mod:`semlab.tracking.pieces`); judged
        while the template is averaged (the first frames)."""
        if not self.pieces.pending or self.averager is None:
            return fit

        def without(mask):
            return register(arr, self.model.reweighted(~mask, self.options), Start(fit.shift, fit.gain, fit.offset),
                            self.roi, self.options, robust_start=False)

        for index, rest in self.pieces.pulling_pieces(self.model.points, fit.shift, without):
            cut = self.pieces.cut_off(self.contour, index, self.widths, choose=self.options.template.choose or "central")
            if cut is None:
                continue
            self.contour, self.band = cut
            self._coarse_mask = None  # the coarse search's mask follows the new region
            self._build()
            self._trimmed = (None, None)
            refit = self._register(arr, Start(rest.shift, rest.gain, rest.offset), robust_start=False)
            return refit if refit.converged else rest
        return fit

    def sigma(self, verdict: Verdict) -> Uncertainty | None:
        """The frame's fit (or the re-acquired match's) and the origin's, and the model error once
        the object has moved (:mod:`semlab.tracking.uncertainty`), the fit's part larger against a
        young template (:func:`~semlab.tracking.uncertainty.young_template_inflation`); the
        precision no better than the recent frames' (:class:`~semlab.tracking.uncertainty.RecentPrecision`)."""
        found = verdict.found
        if found is None:
            return Uncertainty((np.inf, np.inf), (np.inf, np.inf))
        cov = found.covariance() if isinstance(found, FitResult) else found.covariance
        parts = self._band_residuals(found)
        cov = np.full((2, 2), np.inf) if cov is None else self._no_less_than_clustered(cov, parts)
        moved = float(np.hypot(*(np.asarray(verdict.shift, float) - self.origin)))
        reported = cov * young_template_inflation(self.n_averaged) ** 2
        return Uncertainty(position_sigma(reported, self.origin_cov,
                                          model_sd=model_error(moved, found.gain, found.score)),
                           self.recent_precision.judged(position_sigma(cov, self.origin_cov)),
                           self._influence(found, parts))

    def _band_residuals(self, fit):
        """``(jacobian, residual, weights)`` of a registration at the band's pixels, or None (a
        re-acquired match, a band cut by the image border); a trimmed fit's weights are 0 on the
        tiles it dropped."""
        model = self._trimmed[1] if fit is self._trimmed[0] else self.model
        if not isinstance(fit, FitResult) or fit.residual is None or len(fit.residual) != len(model.points):
            return None
        prior = 1.0 if model.weights is None else model.weights
        return fit.gain * self.gradients, fit.residual, prior * fit.weights

    def _no_less_than_clustered(self, cov, parts) -> np.ndarray:
        """The fit's covariance, each axis's variance raised to the clustered covariance's where
        that is larger (a misfit correlated over a few px: :func:`~semlab.tracking.uncertainty.
        clustered_covariance`); ``parts``: :meth:`_band_residuals`."""
        if parts is None:
            return cov
        clustered = clustered_covariance(*parts, self.tiles)
        if not np.all(np.isfinite(clustered)):
            return cov
        raised = np.array(cov, float)
        for k in range(2):
            raised[k, k] = max(raised[k, k], clustered[k, k])
        return raised

    def _influence(self, fit, parts):
        """How far one quadrant of the band pulls the registration's answer
        (:func:`~semlab.tracking.consistency.quadrant_influence`); None when it cannot be judged.
        ``parts``: :meth:`_band_residuals`."""
        variance = fit.covariance_scale() if parts is not None else np.inf
        if not np.isfinite(variance):
            return None
        return quadrant_influence(*parts, variance, self.quadrants)

    def after_accept(self, arr, verdict: Verdict) -> np.ndarray | None:
        """The frame enters the template average when it registered well and is no noisier than
        :data:`AVERAGE_MAX_NOISE_RATIO` times frame 0 (the dose has not dropped). The answer is the shift
        against the template that measured it, with that template's origin; a template refreshed
        from this frame brings its own origin, and the motion moves into its coordinates."""
        fit = verdict.found
        if not isinstance(fit, FitResult) or not (
                fit.inliers > AVERAGE_MIN_INLIERS and self.scores
                and fit.score >= AVERAGE_MIN_SCORE_FRACTION * np.median(self.scores)):
            return None
        self._learn_background(arr, fit)
        if self.averager is None:
            return None
        stored = store_frame(arr, self.roi, fit.shift, fit.gain, fit.offset)
        if stored is None or not self.averager.as_noisy_as_the_first(stored, AVERAGE_MAX_NOISE_RATIO):
            return None
        origin = self.origin.copy()
        self._average(stored)
        return self.origin - origin

    # ---- the static background
    def _learn_background(self, arr, fit: FitResult) -> None:
        """A well-registered frame's background enters the layer; the layer acts (and the band model
        sees the template's background flattened beyond :attr:`far_px`) once the object has moved
        :data:`~semlab.tracking.layer.GATE_PX` from the origin."""
        if self.layer is None:
            return
        self.layer.add(arr, fit.shift, fit.gain, fit.offset, self.rho, self.far)
        if not self.layer_on and np.hypot(*(fit.shift - self.origin)) > GATE_PX:
            self.layer_on = True
            self.models[True] = self._flattened_model()

    # ---- template averaging
    def _average(self, stored) -> None:
        """Running mean of the registered, photometrically normalised ROI (a less noisy template),
        ``stored`` (:func:`~semlab.tracking.averaging.store_frame`) added.

        Frame 0 is registered against every new template: it defines the origin, which so carries
        frame 0's noise once instead of the one-frame template's noise in every position.
        """
        mean = self.averager.add(stored, self.template)
        self.n_averaged = self.averager.count
        if self.averager.complete:
            self._rebuild()
            self.averager = None
            return
        if mean is None:
            return
        self.template = mean
        self._build()
        first = self.averager.frames[0]
        ref = self._register_stored(first)
        if ref.converged:
            first.shift, first.gain, first.offset = ref.shift.copy(), ref.gain, ref.offset
            self.origin = ref.shift.copy()
            self.origin_cov = ref.covariance()

    def _rebuild(self) -> None:
        """Every stored frame registered against the averaged template and averaged anew (twice with
        ``reidentify``: the second pass against the band of the re-identified contour)."""
        passes = 2 if self.options.averaging.reidentify else 1
        cut = self.options.averaging.consistency_cut
        for pass_no in range(passes):
            patches = self.averager.reregister(self._register_stored)
            self.template = patches.mean(axis=0).astype(np.float32)
            if pass_no == 0 and passes > 1:
                # The next pass registers every stored frame against the new band, frame 0 (the
                # origin) included.
                self._reidentify()
            self.consistency = (consistency_weights(patches, self.averager.shifts(), self.band, self.contour, cut)
                                if cut is not None else None)
            self._build()
        # The origin: where frame 0 (the first stored frame) sits against the new template.
        first = self.averager.frames[0]
        self.origin = np.asarray(first.shift, float).copy()
        self.origin_cov = self._register_stored(first).covariance()

    def _reidentify(self) -> None:
        """The contour template and the band identified again, on the averaged template.

        Frame 0's contour follows frame 0's noise: the band built around it holds the pixels that
        noise pushed over the threshold, so frame 0's residuals on it are not centred and its own
        registration — the origin of every displacement — is pulled. The averaged template's
        contour, at frame 0's threshold (the user's choice, or Otsu's of frame 0), has lost that
        noise (``reidentify``'s effect is measured by ``benchmarks/bench_tracking_seeds.py --param
        reidentify=True``). Kept as it was when no usable contour comes out.
        """
        lo, scale = self.to_8bit
        template8 = np.clip(np.rint((self.template - lo) * scale), 0, 255).astype(np.uint8)
        params = dict(self.options.template.as_kwargs(), threshold=self.contour.threshold)
        try:
            contour = identify_contour_template(template8, **params)
        except ValueError:
            return
        band = registration_band(contour, self.widths)
        if band.sum() < MIN_BAND_PIXELS or not (contour.region.any() and not contour.region.all()):
            return
        self.contour, self.band = contour, band
        self._coarse_mask = None  # the coarse search's mask follows the new region
        self.pieces.forget()  # the pieces' frames are over
