"""The ``"ic"`` method's template through its life: what the per-frame steps of
:class:`~semlab.tracking.ic.ICMethod` register against.

Built once from frame 0 — the band model (:mod:`semlab.tracking.band`), the coarse template of the
search — and rebuilt as it changes: averaged over the first registered frames, with frame 0
re-registered against each new template as the origin of every displacement
(:mod:`semlab.tracking.averaging`); seen with its background flattened once the static background
acts (:mod:`semlab.tracking.layer`); and cut where a piece of it does not move with the object
(:mod:`semlab.tracking.pieces`). A registration against it, the misfit tiles trimmed
(:mod:`semlab.tracking.trimming`), is :meth:`TemplateLifecycle._register` / :meth:`~TemplateLifecycle._trim`.
"""

from __future__ import annotations

import numpy as np

from ..template import identify_contour_template
from .averaging import TemplateAverager, consistency_weights, store_frame
from .band import (
    MIN_BAND_PIXELS,
    build_band_model,
    flattened_background,
    region_contrast,
    registration_band,
)
from .consistency import band_quadrants
from .layer import GATE_PX, MIN_TEXTURE, BackgroundLayer, far_from_region, far_px, object_support
from .method import Method, Setup
from .pieces import LoosePieces
from .registration import FitResult, FrameCrops, Start, register
from .search import coarse_mask, coarse_template
from .trimming import MIN_MISFIT_CONTRAST, trim_misfit_tiles
from .uncertainty import band_tiles

__all__ = ["TemplateLifecycle"]


class TemplateLifecycle(Method):
    """The template, its band model and coarse template, the static background, the averaging and the
    loose pieces of a :class:`~semlab.tracking.ic.ICMethod` (its per-frame steps are there)."""

    def start_template(self, setup: Setup, *, flatten: bool, pieces: LoosePieces) -> None:
        """The template's state on frame 0 (after :meth:`Method.start`): its band model built, the static
        background started, the averaging begun with frame 0. ``flatten``: the template's background is
        flattened for the band model (:func:`~semlab.tracking.band.flattened_background`); ``pieces``: what
        the frames judge (:mod:`semlab.tracking.pieces`)."""
        self.noise, self.widths, self.to_8bit = setup.noise, setup.widths, setup.to_8bit
        self.flatten = flatten
        self.rho = setup.noise.rho if self.options.photometry.whiten else 0.0
        self._start_layer(setup)
        self.n_averaged = 1
        #: Covariance (px²) of the origin, frame 0's shift against the current template (0 while
        #: frame 0 is the template).
        self.origin_cov = np.zeros((2, 2))
        self.consistency = None
        #: The pieces frame 0's cut left, judged by the frames (:meth:`_cut_pulling`).
        self.pieces = pieces
        self._coarse_mask = None
        #: The last accepted fit, when tiles were trimmed from it, and the band model it used.
        self._trimmed = (None, None)
        #: The crops of the frame being registered (cleared for each frame: :meth:`_new_frame`).
        self._crops = FrameCrops()
        self._build()
        if self.layer is not None:
            self.layer.add(setup.image, np.zeros(2), 1.0, 0.0, self.rho, self.far)
        self.averager = None
        if self.options.averaging.template_frames > 1:
            first = store_frame(setup.image, self.roi, np.zeros(2), 1.0, 0.0)
            if first is not None:
                self.averager = TemplateAverager(first, self.options.averaging.template_frames, self.roi, self.rho)

    def _start_layer(self, setup: Setup) -> None:
        """The static background (:mod:`semlab.tracking.layer`), learned while the object has not moved
        and acting once it has (:attr:`layer_on`). None: ``static_background`` off, a background with
        little texture (under :data:`~semlab.tracking.layer.MIN_TEXTURE`), or a strongly textured
        substrate, whose template is flattened from frame 0 on: there the layer's texture, learned from a
        few frames of grains 1.5-2.2× the noise, took the probe more than 1 px off on more frames that
        said ok than it saved (the substrates family's spare seeds)."""
        self.layer, self.layer_on = None, False
        self.far_px = far_px(setup.edge_sigma)
        if self.options.band.static_background and MIN_TEXTURE <= setup.texture and not self.flatten:
            level = float(np.mean(setup.patch[~setup.contour.region])) if not setup.contour.region.all() else 0.0
            noise_var = float(np.asarray(setup.noise.variance(level)))
            self.layer = BackgroundLayer(setup.image.shape, setup.roi, setup.texture ** 2 * noise_var, noise_var)

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

    def _new_frame(self) -> None:
        """A new frame is registered: the last one's crops are forgotten."""
        self._crops.clear()

    def _register(self, arr, start: Start, **kw) -> FitResult:
        return register(arr, self.model, start, self.roi, self.options, crops=self._crops, **kw)

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
                            at=at, robust_start=False, crops=self._crops)

        trimmed, keep = trim_misfit_tiles(fit, refit, self.tiles, self.model.weights, p_value,
                                          floor=MIN_MISFIT_CONTRAST * abs(fit.gain) * self.contrast)
        return trimmed, next((model for kept, model in models if kept is keep), None)


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
                            self.roi, self.options, robust_start=False, crops=self._crops)

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
