"""Registration: the band model fitted to a frame — shift, gain and offset from a start.

:func:`register` is the one fit every "ic" step uses (tracking from the prediction, from a
coarse-search candidate, after a re-acquisition, and the re-registration of stored frames when
the template is averaged): inverse-compositional Gauss–Newton (:func:`semlab.gauss_newton.
gauss_newton_translation`, eq. 2 with the paper's offline matrix ``M₀`` of eqs. 4-5 as its
Jacobian) on the band of a whitened crop around the start, first down the coarse-to-fine ladder
of the model's smoothed levels (a wide basin), then at full resolution (the efficient estimate).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..gauss_newton import GaussNewtonResult, gauss_newton_translation
from ..subpixel import five_point_gradients, weighted_ncc, whiten_lines
from .band import BandModel
from .frames import crop as crop_frame
from .options import TrackerOptions

__all__ = ["CROP_MARGIN_PX", "STAGE1_TOLERANCE", "BandCrop", "FitResult", "FrameCrops", "OffImage", "Start", "band_crop",
           "register"]


class OffImage(ValueError):
    """The band at the fit's start is off the image (:func:`band_crop`): nothing there to register."""


#: The crop around the band reaches this many px beyond it at the start.
CROP_MARGIN_PX = 12
#: Band pixels must stay this many px inside the crop (the bicubic stencil's reach plus one):
#: beyond, they would sample the crop's replicated border.
STENCIL_MARGIN_PX = 3
#: A crop narrower than this (px) holds no target.
MIN_CROP_PX = 8
#: A band whose pixels leave the image keeps at least this fraction of them, and this many.
MIN_BAND_FRACTION = 0.5
MIN_BAND_POINTS = 10
#: Step (px) below which each smoothed level stops, widest first, when the start is a prediction;
#: from a search's candidate (``careful``) every level runs to :data:`CAREFUL_TOLERANCE`.
STAGE1_TOLERANCE = (0.1, 0.05, 0.02)
CAREFUL_TOLERANCE = 0.02
#: A smoothed level's answer is taken only with a gain above this (else the image is not the object).
MIN_LEVEL_GAIN = 0.05
#: A template whose Jacobian is smoothed by at most this (px) counts as averaged ("mature"):
#: its iterations shrink geometrically (early stop), and the full-resolution basin reaches from
#: the second smoothed level.
MATURE_JACOBIAN_SIGMA = 1.0
#: Levels of the ladder a mature template uses from a prediction (the widest ones).
MATURE_LEVELS = 2
#: Parameters a fit estimates besides those of its normal matrix: the two region levels (gain
#: and offset) when they follow the object and background means instead.
FIT_NUISANCE_PARAMETERS = 2


@dataclass(frozen=True)
class Start:
    """Where a fit starts: the shift against the ROI, gain and offset (whitened units)."""

    shift: np.ndarray
    gain: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class FitResult:
    """One registration's answer, and what its uncertainty is made of.

    Attributes
    ----------
    shift : (2,) ndarray
        The template's shift against the ROI (frame coordinates).
    gain, offset : float
        Photometric parameters (whitened units).
    score : float
        Weighted normalised correlation of the frame (not whitened) at ``shift`` with the template
        at the band's pixels; 0 when the fit gave up.
    converged : bool
        False also when the fit moved farther than allowed.
    inliers : float
        Fraction of the band's pixels with full Huber weight.
    iterations : int
        Of the last Gauss–Newton stage.
    normal_matrix : ndarray or None
        The last stage's Gauss–Newton normal matrix (2×2 for the shift, or 4×4 with gain and
        offset): the shift's Fisher information up to the noise scale.
    weighted_ssr : float
        The last stage's weighted sum of squared residuals.
    n_pixels : int
        Band pixels in the last stage.
    weight_total : float
        Their robust weights' total.
    robust_ssr : float
        The residuals' squared influence (:class:`semlab.gauss_newton.GaussNewtonResult`).
    information : ndarray or None
        The shift's information (:class:`semlab.gauss_newton.GaussNewtonResult`).
    residual, weights : (K,) ndarray or None
        The last stage's residuals and robust weights at the band's pixels.
    """

    shift: np.ndarray
    gain: float
    offset: float
    score: float
    converged: bool
    inliers: float
    iterations: int
    normal_matrix: np.ndarray | None
    weighted_ssr: float
    n_pixels: int
    weight_total: float
    robust_ssr: float = float("nan")
    information: np.ndarray | None = None
    residual: np.ndarray | None = None
    weights: np.ndarray | None = None

    def covariance_scale(self) -> float:
        """``s²``, the residuals' variance as :meth:`covariance` takes it (inf when there is none)."""
        matrix = self.normal_matrix if self.information is None else self.information
        dof = self.weight_total - (0 if matrix is None else len(matrix)) - FIT_NUISANCE_PARAMETERS
        if matrix is None or not dof > 0 or not np.isfinite(self.robust_ssr):
            return float("inf")
        return float(self.robust_ssr / dof)

    def covariance(self) -> np.ndarray:
        """The shift's covariance (px², 2×2) from this fit alone: ``s² N⁻¹``.

        ``N`` is the last stage's normal matrix (the shift's Fisher information up to the noise
        scale, the robust weights included, gain and offset eliminated when they were fitted
        jointly) and ``s²`` the residuals' variance as Huber's M-estimator has it,
        ``Σ prior·w²·r² / (Σ w − p)``, measured on the frame: residuals that the model does not
        explain (charging, the template's own noise) inflate it, an outlier (clutter, an occluder)
        only by its bounded influence, and pixels the robust weights dropped carry no information.
        Infinite when the fit left nothing to judge it by.
        """
        inf = np.full((2, 2), np.inf)
        scale = self.covariance_scale()
        if not np.isfinite(scale):
            return inf
        matrix = self.normal_matrix if self.information is None else self.information
        symmetric = 0.5 * (matrix + matrix.T)
        try:
            inverse = np.linalg.inv(symmetric)[:2, :2]
        except np.linalg.LinAlgError:
            return inf
        if not (np.all(np.isfinite(inverse)) and inverse[0, 0] > 0 and inverse[1, 1] > 0):
            return inf
        return scale * inverse

    @classmethod
    def of(cls, fit: GaussNewtonResult, score: float, converged: bool | None = None) -> FitResult:
        return cls(shift=fit.shift, gain=fit.gain, offset=fit.offset, score=score,
                   converged=fit.converged if converged is None else converged, inliers=fit.inliers,
                   iterations=fit.iterations, normal_matrix=fit.normal_matrix, weighted_ssr=fit.weighted_ssr,
                   n_pixels=fit.n_pixels, weight_total=fit.weight_total, robust_ssr=fit.robust_ssr,
                   information=fit.information, residual=fit.residual, weights=fit.weights)


@dataclass(frozen=True)
class BandCrop:
    """The frame around the band at an integer shift: the float32 crop, its whitened version, the
    band's points in crop coordinates at zero shift, the model on the points still inside the
    image, and the crop's integer shift ``centre``."""

    image: np.ndarray
    whitened: np.ndarray
    points: np.ndarray
    model: BandModel
    centre: np.ndarray


class FrameCrops:
    """The crops of a frame around the band, plain and whitened, kept while that frame is registered.

    One frame is registered several times at nearly the same place (from the prediction, again without
    its misfit tiles, without a loose piece; a stored frame once per refreshed template): the crop and its
    whitening are the same each time. The owner calls :meth:`clear` before each new frame, so that a
    frame array the caller fills anew in place is never read from here.
    """

    def __init__(self) -> None:
        self._crops: dict = {}

    def clear(self) -> None:
        self._crops = {}

    def get(self, arr, box, rho: float) -> tuple[np.ndarray, np.ndarray]:
        """``(image, whitened)``: ``arr[y0:y1, x0:x1]`` as float32 (:func:`~semlab.tracking.frames.crop`) and
        :func:`~semlab.subpixel.whiten_lines` of it with ``rho``, for ``box`` ``(x0, y0, x1, y1)``. Read only."""
        key = (id(arr), box, rho)
        kept = self._crops.get(key)
        if kept is not None and kept[0] is arr:
            return kept[1], kept[2]
        image = crop_frame(arr, *box)
        whitened = whiten_lines(image, rho)
        self._crops[key] = (arr, image, whitened)
        return image, whitened


def band_crop(arr, model: BandModel, shift, roi, margin: int, at=(0, 0), crops: FrameCrops | None = None) -> BandCrop:
    """The crop of ``arr`` around the band at ``shift``, ``margin`` px each side.

    ``arr`` is the frame, or a part of it whose pixel [0, 0] is the frame's pixel ``at``; ``crops``: where
    this frame's crops are kept (None: made anew).

    Raises
    ------
    ValueError
        The target is outside the image, or too little of the band is left inside it.
    """
    x0, y0 = roi[0] - at[0], roi[1] - at[1]
    bx0, by0, bx1, by1 = model.bbox
    sx, sy = round(shift[0]), round(shift[1])
    cx0, cy0 = max(x0 + bx0 + sx - margin, 0), max(y0 + by0 + sy - margin, 0)
    cx1 = min(x0 + bx1 + sx + margin, arr.shape[1])
    cy1 = min(y0 + by1 + sy + margin, arr.shape[0])
    if cx1 - cx0 < MIN_CROP_PX or cy1 - cy0 < MIN_CROP_PX:
        raise OffImage("the target is outside the image")
    if crops is None:
        image = crop_frame(arr, cx0, cy0, cx1, cy1)
        whitened = whiten_lines(image, model.rho)
    else:
        image, whitened = crops.get(arr, (cx0, cy0, cx1, cy1), model.rho)
    pts = model.points + (x0 - cx0, y0 - cy0)
    # Band pixels that have left the image (the object near its border) drop out; the band's
    # bounding box tells whether any has.
    m, rows, cols = STENCIL_MARGIN_PX, whitened.shape[0], whitened.shape[1]
    lo_x, lo_y = bx0 + x0 - cx0 + shift[0], by0 + y0 - cy0 + shift[1]
    hi_x, hi_y = bx1 - 1 + x0 - cx0 + shift[0], by1 - 1 + y0 - cy0 + shift[1]
    if not (lo_x >= m and lo_y >= m and hi_x <= cols - 1 - m and hi_y <= rows - 1 - m):
        px0, py0 = pts[:, 0] + shift[0], pts[:, 1] + shift[1]
        valid = (px0 >= m) & (py0 >= m) & (px0 <= cols - 1 - m) & (py0 <= rows - 1 - m)
        if not valid.all():
            if valid.mean() < MIN_BAND_FRACTION or valid.sum() < MIN_BAND_POINTS:
                raise OffImage("the target has left the image")
            return BandCrop(image, whitened, pts[valid], model.subset(valid), np.array([sx, sy], float))
    return BandCrop(image, whitened, pts, model, np.array([sx, sy], float))


def _ladder(crop: BandCrop, start: Start, options: TrackerOptions, *, reach: int, careful: bool, give_up: bool,
            mature: bool):
    """Stage 1, coarse to fine, both images smoothed alike (σ = 4, 2, 1 × coarse_sigma).

    A wide basin and a smooth cost, so a start several px off (a bad prediction, a coarse peak slid
    along a straight edge) or a noisy one-frame template still converges. With an averaged template
    the full-resolution stage takes over from σ = 2 × coarse_sigma (its basin reaches that far); a
    young, noisy one needs the last smoothed level too. The smoothed levels only have to bring the
    next one into its basin. Returns the start of stage 2, or the widest level's fit when it leaves
    the crop (``give_up``: the prediction is farther off than the crop reaches, a job for the coarse
    search).
    """
    model, stages = crop.model, options.stages
    shift0, gain0, offset0 = start.shift, start.gain, start.offset
    levels = model.smoothed[:MATURE_LEVELS] if (mature and not careful) else model.smoothed
    for k, level in enumerate(levels):
        smooth = cv2.GaussianBlur(crop.whitened, (0, 0), level.sigma)
        room = np.inf if careful else reach - float(np.max(np.abs(np.asarray(shift0, float) - crop.centre)))
        tolerance = CAREFUL_TOLERANCE if careful else STAGE1_TOLERANCE[min(k, len(STAGE1_TOLERANCE) - 1)]
        first = gauss_newton_translation(smooth, crop.points, level.values, level.gx, level.gy, shift0, gain0=gain0,
                                         offset0=offset0, max_iterations=stages.max_iterations, tolerance=tolerance,
                                         weights=model.weights, huber=stages.huber,
                                         photometric=options.photometry.photometric, regions=model.inside,
                                         max_move=room, setup=level.setup, early_stop=mature and not careful)
        if first.converged and abs(first.gain) > MIN_LEVEL_GAIN:
            shift0, gain0, offset0 = first.shift, first.gain, first.offset
        elif give_up and k == 0 and np.max(np.abs(first.shift - shift0)) > room:
            return FitResult.of(first, 0.0)
    return Start(shift0, gain0, offset0)


def _full_resolution(crop: BandCrop, start: Start, options: TrackerOptions, *, limit: float, careful: bool,
                     mature: bool) -> FitResult:
    """Stage 2, full resolution: the efficient estimate, then its score.

    A strongly smoothed Jacobian (young template) takes its curvature from the image; a light one
    is close enough to exact. It stops, unconverged, after ``limit`` px.
    """
    model, mode = crop.model, options.photometry.photometry
    two_level, iv = mode == "regions", mode == "instrument"
    pts = crop.points
    fit = gauss_newton_translation(
        crop.whitened, pts, model.fine.values, model.fine.gx, model.fine.gy, start.shift, gain0=start.gain,
        offset0=start.offset, max_iterations=options.stages.max_iterations,
        curvature=None if mature else five_point_gradients(crop.whitened),
        template_variance=None if (two_level or iv) else model.template_variance,
        instrument=model.instrument if iv else None, max_move=limit, setup=model.fine.setup,
        early_stop=mature and not careful, sectors=model.sector, weights=model.weights,
        huber=options.stages.huber, photometric=options.photometry.photometric,
        regions=model.inside if two_level else None)
    shift0 = np.asarray(start.shift, float)
    moved = float(np.max(np.abs(fit.shift - shift0))) if np.all(np.isfinite(fit.shift)) else np.inf
    if not np.isfinite(moved):
        return FitResult.of(fit, 0.0, converged=False)
    # The score on the plain (not whitened) crop, as any template matcher would read it.
    plain = cv2.remap(crop.image, (pts[:, 0] + fit.shift[0]).astype(np.float32).reshape(1, -1),
                      (pts[:, 1] + fit.shift[1]).astype(np.float32).reshape(1, -1), cv2.INTER_CUBIC,
                      borderMode=cv2.BORDER_REPLICATE).reshape(-1)
    return FitResult.of(fit, weighted_ncc(plain, model.values, fit.weights),
                        converged=fit.converged and not moved > limit)


def register(arr, model: BandModel, start: Start, roi, options: TrackerOptions, *, margin: int = CROP_MARGIN_PX,
             at=(0, 0), robust_start: bool = True, max_move: float | None = None, give_up: bool = False,
             crops: FrameCrops | None = None) -> FitResult:
    """Fit shift, gain and offset of ``model`` to ``arr`` from ``start``.

    Parameters
    ----------
    arr : (H, W) ndarray
        The frame, or a part of it whose pixel [0, 0] is the frame's pixel ``at``.
    model : BandModel
        The template at the band's pixels (:func:`semlab.tracking.band.build_band_model`).
    start : Start
    roi : (x, y, w, h)
        The ROI of frame 0, whose top-left the shift is counted from.
    options : TrackerOptions
    margin : int
        The crop reaches this many px beyond the band at the start.
    robust_start : bool
        Run the smoothed ladder first (with ``coarse_sigma > 0``).
    max_move : float or None
        The full-resolution stage stops, unconverged, after this many px (and after
        ``margin − 3`` px in any case: beyond, the band would sample the crop's border).
    give_up : bool
        The start is only a prediction, and the fast path is taken: a smoothed level stops,
        unconverged, when the band would leave the crop, the whole fit as soon as the widest
        level does so (the coarse search's job), the smoothed levels stop early and the last one
        is left out once the template is averaged, and the full-resolution stage runs in a crop
        centred on its start. Without it (a start from a search, the last resort) the smoothed
        stage runs in full.
    crops : FrameCrops or None
        Where the crops of ``arr`` are kept while it is registered (None: made anew).

    Raises
    ------
    ValueError
        The target is outside the image (:class:`OffImage`, :func:`band_crop`), or the template has no usable
        levels (:func:`semlab.gauss_newton.gauss_newton_setup`).
    """
    careful = robust_start and not give_up
    reach = margin - STENCIL_MARGIN_PX
    crop = band_crop(arr, model, start.shift, roi, margin, at, crops)
    mature = model.jacobian_sigma <= MATURE_JACOBIAN_SIGMA
    if model.smoothed and robust_start:
        start = _ladder(crop, start, options, reach=reach, careful=careful, give_up=give_up, mature=mature)
        if isinstance(start, FitResult):
            return start
        if not careful and np.any(np.round(start.shift) != crop.centre):
            # Stage 2 in a crop centred on its start (the same pixels, whitened alike).
            crop = band_crop(arr, model, start.shift, roi, margin, at, crops)
    limit = reach if max_move is None else min(reach, max_move)
    return _full_resolution(crop, start, options, limit=limit, careful=careful, mature=mature)
