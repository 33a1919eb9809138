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
that does not move with it is cut (:mod:`semlab.tracking.pieces`). That template's life is
:mod:`semlab.tracking.lifecycle`; this module holds the method's per-frame steps.
"""

from __future__ import annotations

import numpy as np

from .averaging import store_frame
from .band import FLAT_BACKGROUND_TEXTURE
from .consistency import quadrant_influence
from .lifecycle import TemplateLifecycle
from .method import Motion, Setup, Verdict
from .pieces import LoosePieces, loose_pieces
from .registration import FitResult, OffImage, Start
from .search import coarse_search, reacquire
from .uncertainty import (
    RecentPrecision,
    Uncertainty,
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


class ICMethod(TemplateLifecycle):
    """The ``"ic"`` method's per-frame steps (:class:`~semlab.tracking.method.Method`): its template
    through its life is :class:`~semlab.tracking.lifecycle.TemplateLifecycle`; here the photometric
    state, the first frames' scores, the verdicts and the uncertainty."""

    name = "ic"
    flags_uncertain = True
    widens_search = True
    cuts_attached = True

    def start(self, setup: Setup) -> None:
        super().start(setup)
        self.gain, self.offset = 1.0, 0.0
        self.scores: list[float] = []
        #: The recent frames' precisions, by which each frame's is judged.
        self.recent_precision = RecentPrecision()
        self._score_median = (0, float("nan"))
        #: The pieces frame 0's cut left, judged by the frames (:mod:`semlab.tracking.pieces`).
        pieces = LoosePieces(loose_pieces(setup.contour.region) if self.options.band.cut_attached else [],
                             setup.attached)
        # The template's background is flattened for the band model over a strongly textured substrate.
        self.start_template(setup, flatten=setup.texture >= FLAT_BACKGROUND_TEXTURE, pieces=pieces)

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
        self._new_frame()
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
                and fit.score >= AVERAGE_MIN_SCORE_FRACTION * self._median_score()):
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
