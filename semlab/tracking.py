"""The tracker users call: :class:`Tracker` and :func:`track` (Ru et al. 2012, Fig. 4).

Methods
-------
``"contour"``
    The paper's method: in a 300×300 window around the last position, adaptive-threshold Canny
    (eq. 10), contour-template match, then one step of the gradient sub-pixel method (eq. 9) on
    the contour band.
``"ssd"``
    The conventional baseline: full-template SSD (eq. 2) at integer positions, then eq. 9 on the
    whole template.
``"ic"`` (the default)
    Beyond the paper: a coarse normalised-correlation search at quarter resolution, then
    inverse-compositional Gauss–Newton on the contour band with bicubic interpolation, gain/offset
    invariance and Huber weights; the template is the average of the first registered frames
    (a one-frame template doubles the estimate's variance).

A lost target never raises: the row says ``ok=False`` with NaN position, and the next frame is
searched over the whole image to re-acquire it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from .edges import canny_edges
from .roi import as_gray_float, check_roi, clip_window, roi_centre
from .matching import contour_match, parabola_peak, ssd_match
from .subpixel import (
    five_point_gradients,
    gauss_newton_translation,
    gradient_subpixel_shift,
)
from .template import ContourTemplate, identify_contour_template, to_uint8

__all__ = ["METHODS", "TrackResult", "Tracker", "track"]

METHODS = ("ic", "contour", "ssd")


@dataclass(frozen=True)
class TrackResult:
    """One frame's answer: where the ROI's centre point has moved to.

    Attributes
    ----------
    x, y : float
        Position in px (pixel centres at integer coordinates); NaN when ``ok`` is False.
    score : float
        Match quality in [0, 1] (method-specific; see :class:`Tracker`).
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


class Tracker:
    """Track the probe tip from frame to frame.

    Parameters
    ----------
    method : {"ic", "contour", "ssd"}
        See the module docstring. ``"ic"`` is the default because it measured best (see
        ``benchmarks/bench_tracking.py``).
    search_size : int
        Side of the square search window around the last position (paper: 300 px).
    sigma, threshold, morph_kernel, morph_iterations
        Contour template identification (:func:`semlab.template.identify_contour_template`).
    canny_sigma, canny_low, canny_high
        Edge detection for ``"contour"`` (:func:`semlab.edges.canny_edges`; adaptive unless both
        thresholds are given).
    band_px : int
        Half-width of the band around the contour used for sub-pixel registration.
    huber : float or None
        Huber threshold (robust standard deviations) of ``"ic"``.
    template_frames : int
        ``"ic"`` averages the template over this many well-registered frames.
    min_score : float
        Below this score a frame counts as lost.
    coarse_factor : int
        Downsampling of ``"ic"``'s coarse search.
    """

    def __init__(self, method: str = "ic", *, search_size: int = 300, sigma: float = 2.0,
                 threshold: float | None = None, morph_kernel: int = 3, morph_iterations: int = 1,
                 canny_sigma: float = 1.0, canny_low: float | None = None, canny_high: float | None = None,
                 band_px: int = 3, huber: float | None = 2.0, template_frames: int = 20,
                 min_score: float | None = None, coarse_factor: int = 4):
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
        if search_size < 16:
            raise ValueError(f"search_size must be at least 16 px, got {search_size}")
        self.method = method
        self.search_size = int(search_size)
        self.template_params = {"sigma": sigma, "threshold": threshold, "morph_kernel": morph_kernel,
                                    "morph_iterations": morph_iterations}
        self.canny = {"sigma": canny_sigma, "low": canny_low, "high": canny_high}
        self.band_px = int(band_px)
        self.huber = huber
        self.template_frames = max(int(template_frames), 1)
        self.min_score = {"ic": 0.5, "contour": 0.3, "ssd": 0.5}[method] if min_score is None else float(min_score)
        self.coarse_factor = int(coarse_factor)
        self.roi = None

    # ------------------------------------------------------------------ set-up
    def init(self, frame, roi) -> TrackResult:
        """Take the template from ``frame`` inside ``roi = (x, y, w, h)``.

        Raises
        ------
        TypeError, ValueError
            Bad frame (dtype, dimensions, NaN), ROI not wholly inside the frame or too small,
            or no contour in the ROI.
        """
        image = as_gray_float(frame)
        self.roi = check_roi(roi, image.shape)
        x0, y0, w, h = self.roi
        patch = image[y0:y0 + h, x0:x0 + w]
        if float(patch.max() - patch.min()) <= 0:
            raise ValueError(f"the ROI {self.roi} is constant: nothing to track")
        self.contour: ContourTemplate = identify_contour_template(patch, **self.template_params)
        self.band = self._band(self.contour.mask, self.band_px)
        if self.band.sum() < 10:
            raise ValueError("the contour template leaves fewer than 10 pixels away from the ROI border")
        self.template = patch.copy()
        self._frame0 = image if (self.method == "ic" and self.template_frames > 1) else None
        self.origin = np.zeros(2)
        self._n_averaged = 1
        self._grid = np.mgrid[0:h, 0:w].astype(np.float32)
        self._prepare_template()
        self.centre0 = np.array(roi_centre(self.roi))
        self.shift = np.zeros(2)
        self.velocity = np.zeros(2)
        self.gain, self.offset = 1.0, 0.0
        self.lost = False
        return TrackResult(float(self.centre0[0]), float(self.centre0[1]), 1.0, True)

    @staticmethod
    def _band(mask, half_width):
        h, w = mask.shape
        k = 2 * half_width + 1
        band = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
        margin = half_width + 3
        inner = np.zeros_like(band)
        inner[margin:h - margin, margin:w - margin] = True
        return band & inner

    def _prepare_template(self):
        # Gradients of a lightly smoothed template: noise in the Jacobian only slows Gauss–Newton.
        gx, gy = five_point_gradients(cv2.GaussianBlur(self.template, (0, 0), 0.7))
        ys, xs = np.nonzero(self.band)
        x0, y0 = self.roi[:2]
        self._points = np.stack([xs + x0, ys + y0], axis=1)
        self._values = self.template[ys, xs]
        self._gx, self._gy = gx[ys, xs], gy[ys, xs]
        f = self.coarse_factor
        h, w = self.template.shape
        self._small = cv2.resize(self.template[:h - h % f, :w - w % f], None, fx=1 / f, fy=1 / f,
                                 interpolation=cv2.INTER_AREA)

    # ------------------------------------------------------------------ per frame
    def update(self, frame) -> TrackResult:
        """Locate the target in the next frame; never raises for bad frames or a lost target."""
        if self.roi is None:
            raise RuntimeError("call init(frame, roi) before update(frame)")
        try:
            image = as_gray_float(frame)
        except (TypeError, ValueError) as err:
            return self._lost(f"unusable frame: {err}")
        if float(image.max() - image.min()) <= 0:
            return self._lost("constant frame")
        if image.shape[0] < self.roi[3] or image.shape[1] < self.roi[2]:
            return self._lost(f"frame {image.shape} smaller than the ROI")
        try:
            result = {"ic": self._update_ic, "contour": self._update_contour, "ssd": self._update_ssd}[
                self.method](image)
        except (cv2.error, np.linalg.LinAlgError, ValueError, FloatingPointError) as err:
            return self._lost(f"matching failed: {err}")
        return result

    def _lost(self, reason: str) -> TrackResult:
        self.lost = True
        self.velocity[:] = 0.0
        return TrackResult(float("nan"), float("nan"), 0.0, False, reason)

    def _accept(self, shift, score) -> TrackResult:
        shift = np.asarray(shift, float)
        self.velocity = shift - self.shift if not self.lost else np.zeros(2)
        self.shift = shift
        self.lost = False
        x, y = self.centre0 + shift - self.origin
        return TrackResult(float(x), float(y), float(score), True)

    def _window(self, image, shift):
        """Search window (x0, y0, w, h) centred on the template at ``shift``; the whole image when lost."""
        if self.lost:
            return 0, 0, image.shape[1], image.shape[0]
        _x0, _y0, w, h = self.roi
        size = max(self.search_size, w + 2, h + 2)
        cx, cy = roi_centre(self.roi)
        return clip_window(cx + shift[0], cy + shift[1], size, size, image.shape)

    def _in_frame(self, shift, shape) -> bool:
        x0, y0, w, h = self.roi
        return (x0 + shift[0] >= 0 and y0 + shift[1] >= 0 and x0 + shift[0] + w <= shape[1]
                and y0 + shift[1] + h <= shape[0])

    def _update_ic(self, image) -> TrackResult:
        predicted = self.shift + self.velocity
        wx, wy, ww, wh = self._window(image, predicted)
        f = self.coarse_factor
        window = image[wy:wy + wh - wh % f, wx:wx + ww - ww % f]
        small = cv2.resize(window, None, fx=1 / f, fy=1 / f, interpolation=cv2.INTER_AREA)
        if small.shape[0] < self._small.shape[0] or small.shape[1] < self._small.shape[1]:
            return self._lost("search window smaller than the template")
        scores = cv2.matchTemplate(small, self._small, cv2.TM_CCOEFF_NORMED)
        _, _, _, (ix, iy) = cv2.minMaxLoc(scores)
        px, py = parabola_peak(scores, ix, iy)
        # Block-averaging by f maps both images alike: small offset px is image offset f * px.
        coarse = np.array([wx + f * px - self.roi[0], wy + f * py - self.roi[1]])
        fit = gauss_newton_translation(image, self._points, self._values, self._gx, self._gy, coarse,
                                       gain0=self.gain, offset0=self.offset, huber=self.huber)
        if not fit.converged or fit.score < self.min_score or not self._in_frame(fit.shift, image.shape):
            return self._lost(f"no match (score {fit.score:.2f})")
        self.gain, self.offset = fit.gain, fit.offset
        if self._frame0 is not None and fit.inliers > 0.9 and fit.score > 0.8:
            self._average_into_template(image, fit)
        return self._accept(fit.shift, fit.score)

    def _average_into_template(self, image, fit):
        """Running mean of the registered, photometrically normalised ROI (a less noisy template)."""
        x0, y0, _w, _h = self.roi
        ys, xs = self._grid
        mx = (xs + x0 + fit.shift[0]).astype(np.float32)
        my = (ys + y0 + fit.shift[1]).astype(np.float32)
        patch = cv2.remap(image, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        patch = (patch - fit.offset) / fit.gain
        n = self._n_averaged
        self.template = ((self.template * n + patch) / (n + 1)).astype(np.float32)
        self._n_averaged = n + 1
        self._prepare_template()
        # Frame 0 defines the origin: re-register it against the better template so that its
        # own noise does not offset every later position.
        ref = gauss_newton_translation(self._frame0, self._points, self._values, self._gx, self._gy,
                                       self.origin, huber=self.huber)
        if ref.converged:
            self.origin = ref.shift
        if self._n_averaged >= self.template_frames:
            self._frame0 = None

    def _update_contour(self, image) -> TrackResult:
        wx, wy, ww, wh = self._window(image, self.shift)
        window = image[wy:wy + wh, wx:wx + ww]
        edges = canny_edges(to_uint8(window), **self.canny)
        ix, iy, score, _ = contour_match(edges, self.contour.mask)
        return self._refine_eq9(image, wx + ix, wy + iy, score, mask=self.band)

    def _update_ssd(self, image) -> TrackResult:
        wx, wy, ww, wh = self._window(image, self.shift)
        window = image[wy:wy + wh, wx:wx + ww]
        ix, iy, _ = ssd_match(window, self.template)
        _x0, _y0, w, h = self.roi
        patch = image[wy + iy:wy + iy + h, wx + ix:wx + ix + w]
        score = float(cv2.matchTemplate(patch, self.template, cv2.TM_CCOEFF_NORMED)[0, 0])
        return self._refine_eq9(image, wx + ix, wy + iy, score, mask=None)

    def _refine_eq9(self, image, left, top, score, mask) -> TrackResult:
        """Integer match at top-left (left, top), refined by the paper's eq. 9."""
        if score < self.min_score:
            return self._lost(f"no match (score {score:.2f})")
        x0, y0, w, h = self.roi
        patch = image[top:top + h, left:left + w]
        dx, dy = gradient_subpixel_shift(self.template, patch, mask=mask)
        if not (np.isfinite(dx) and np.isfinite(dy)):
            dx = dy = 0.0
        # One linearised step is only trusted within half a pixel.
        dx, dy = float(np.clip(dx, -1.0, 1.0)), float(np.clip(dy, -1.0, 1.0))
        return self._accept((left - x0 + dx, top - y0 + dy), score)


def _iter_frames(frames):
    if isinstance(frames, np.ndarray):
        if frames.ndim == 2:
            raise ValueError("frames is a single 2-D image; pass a sequence of frames or a 3-D array")
        if frames.ndim != 3:
            raise ValueError(f"a frame array must be 3-D (N, H, W), got shape {frames.shape}")
        return iter(frames), len(frames)
    try:
        n = len(frames)
    except TypeError:
        n = None
    return iter(frames), n


def track(frames, roi, *, method: str = "ic", progress: bool | None = None, **params) -> pd.DataFrame:
    """Track the ROI's centre point through a sequence of frames.

    Parameters
    ----------
    frames : iterable of (H, W) array_like, or (N, H, W) ndarray
        uint8, uint16 or float gray frames.
    roi : (x, y, w, h), or a list of them
        ROI in frame 0 (top-left pixel and size). A list tracks several targets (e.g. the four
        probes) in one pass over the frames and adds a ``target`` column.
    method : {"ic", "contour", "ssd"}
        ``"contour"`` is the paper's method, ``"ssd"`` the conventional baseline, ``"ic"`` the
        default (see :class:`Tracker`).
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
        Bad first frame or ROI (from :meth:`Tracker.init`); later bad frames only flag rows.
    """
    rois = roi if (len(roi) > 0 and not np.isscalar(roi[0])) else None
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
    show = (n is not None and n > 50) if progress is None else progress
    if show:
        from tqdm.auto import tqdm

        iterator = tqdm(iterator, total=None if n is None else n - 1, desc=f"tracking ({method})")
    for i, frame in enumerate(iterator, start=1):
        for k, t in enumerate(trackers):
            res = t.update(frame)
            rows.append((i, k, res.x, res.y, res.score, res.ok))
    df = pd.DataFrame(rows, columns=["frame", "target", "x", "y", "score", "ok"])
    if rois is None:
        return df.drop(columns="target")
    return df[["frame", "target", "x", "y", "score", "ok"]]
