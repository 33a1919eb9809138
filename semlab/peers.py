"""The tools people would use instead, each used as its documentation shows.

Every peer has the :class:`semlab.Tracker` interface (``init(frame, roi)``, ``update(frame)`` →
:class:`semlab.tracking.TrackResult`) so that benchmarks and notebooks run them through the same
loop on the same frames:

- :class:`MatchTemplatePeer`: OpenCV ``matchTemplate`` (``TM_CCOEFF_NORMED`` or ``TM_SQDIFF``) in a
  300×300 window, with a 3-point parabola through the peak;
- :class:`ECCPeer`: OpenCV ``findTransformECC`` with ``MOTION_TRANSLATION``;
- :class:`PhaseCorrelationPeer`: scikit-image ``phase_cross_correlation`` with ``upsample_factor=100``.
"""

from __future__ import annotations

import cv2
import numpy as np
from skimage.registration import phase_cross_correlation

from .matching import parabola_peak
from .roi import as_gray_float, check_roi, clip_window, roi_centre
from .tracking import Tracker, TrackResult

__all__ = ["TRACKERS", "ECCPeer", "MatchTemplatePeer", "PhaseCorrelationPeer", "make_tracker"]


class _Peer:
    """Shared bookkeeping: template from the ROI, position as the ROI centre plus a shift."""

    name = "peer"

    def __init__(self, search_size: int = 300):
        self.search_size = int(search_size)

    def init(self, frame, roi) -> TrackResult:
        image = as_gray_float(frame)
        self.roi = check_roi(roi, image.shape)
        x, y, w, h = self.roi
        self.template = image[y:y + h, x:x + w].copy()
        self.centre0 = np.array(roi_centre(self.roi))
        self.shift = np.zeros(2)
        return TrackResult(*self.centre0, 1.0, True)

    def update(self, frame) -> TrackResult:
        try:
            image = as_gray_float(frame)
            shift, score = self._locate(image)
        except (cv2.error, ValueError, TypeError, np.linalg.LinAlgError) as err:
            return TrackResult(float("nan"), float("nan"), 0.0, False, f"{self.name} failed: {err}")
        if not np.all(np.isfinite(shift)):
            return TrackResult(float("nan"), float("nan"), 0.0, False, f"{self.name}: no estimate")
        self.shift = np.asarray(shift, float)
        x, y = self.centre0 + self.shift
        return TrackResult(float(x), float(y), float(score), True)

    def _window(self, image):
        cx, cy = self.centre0 + self.shift
        size = max(self.search_size, self.roi[2] + 2, self.roi[3] + 2)
        return clip_window(cx, cy, size, size, image.shape)


class MatchTemplatePeer(_Peer):
    """OpenCV template matching with a 3-point parabola sub-pixel peak.

    Parameters
    ----------
    mode : {"TM_CCOEFF_NORMED", "TM_SQDIFF"}
    search_size : int
    """

    def __init__(self, mode: str = "TM_CCOEFF_NORMED", search_size: int = 300):
        super().__init__(search_size)
        if mode not in ("TM_CCOEFF_NORMED", "TM_SQDIFF"):
            raise ValueError(f"mode must be TM_CCOEFF_NORMED or TM_SQDIFF, got {mode!r}")
        self.mode = mode
        self.name = f"opencv {mode}"

    def _locate(self, image):
        wx, wy, ww, wh = self._window(image)
        scores = cv2.matchTemplate(image[wy:wy + wh, wx:wx + ww], self.template, getattr(cv2, self.mode))
        if self.mode == "TM_SQDIFF":
            scores = -scores
        _, best, _, (ix, iy) = cv2.minMaxLoc(scores)
        px, py = parabola_peak(scores, ix, iy)
        score = best if self.mode == "TM_CCOEFF_NORMED" else 1.0
        return np.array([wx + px - self.roi[0], wy + py - self.roi[1]]), score


class ECCPeer(_Peer):
    """OpenCV ``findTransformECC`` (Evangelidis & Psarakis 2008), translation only.

    The warp starts from the last estimate; the template is the first frame's ROI.
    """

    name = "opencv findTransformECC"

    def __init__(self, search_size: int = 300, iterations: int = 100, eps: float = 1e-5, gauss_filt_size: int = 5):
        super().__init__(search_size)
        self.criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, eps)
        self.gauss_filt_size = gauss_filt_size

    def _locate(self, image):
        wx, wy, ww, wh = self._window(image)
        window = image[wy:wy + wh, wx:wx + ww]
        warp = np.eye(2, 3, dtype=np.float32)
        warp[0, 2] = self.roi[0] + self.shift[0] - wx
        warp[1, 2] = self.roi[1] + self.shift[1] - wy
        cc, warp = cv2.findTransformECC(self.template, window, warp, cv2.MOTION_TRANSLATION, self.criteria,
                                        None, self.gauss_filt_size)
        return np.array([warp[0, 2] + wx - self.roi[0], warp[1, 2] + wy - self.roi[1]]), cc


class PhaseCorrelationPeer(_Peer):
    """scikit-image ``phase_cross_correlation`` with 100× upsampling (Guizar-Sicairos et al. 2008).

    The moving image is the ROI-sized patch at the last integer position.
    """

    name = "skimage phase_cross_correlation"

    def __init__(self, search_size: int = 300, upsample_factor: int = 100):
        super().__init__(search_size)
        self.upsample_factor = int(upsample_factor)

    def _locate(self, image):
        x, y, w, h = self.roi
        ix, iy = np.round(self.shift).astype(int)
        ix = int(np.clip(x + ix, 0, image.shape[1] - w)) - x
        iy = int(np.clip(y + iy, 0, image.shape[0] - h)) - y
        moving = image[y + iy:y + iy + h, x + ix:x + ix + w]
        shift, error, _ = phase_cross_correlation(self.template, moving, upsample_factor=self.upsample_factor)
        # ``shift`` (rows, cols) registers moving onto the reference: the object moved by -shift.
        return np.array([ix - shift[1], iy - shift[0]]), 1.0 - float(error)


#: Name → factory of every tracker the benchmarks compare, semlab's first.
TRACKERS = {
    "semlab ic (default)": lambda: Tracker("ic"),
    "paper contour": lambda: Tracker("contour"),
    "paper ssd baseline": lambda: Tracker("ssd"),
    "opencv TM_CCOEFF_NORMED": lambda: MatchTemplatePeer("TM_CCOEFF_NORMED"),
    "opencv TM_SQDIFF": lambda: MatchTemplatePeer("TM_SQDIFF"),
    "opencv ECC": lambda: ECCPeer(),
    "skimage phase corr.": lambda: PhaseCorrelationPeer(),
}


def make_tracker(name: str):
    """A fresh tracker by its :data:`TRACKERS` name."""
    try:
        return TRACKERS[name]()
    except KeyError:
        raise ValueError(f"unknown tracker {name!r}; choose one of {list(TRACKERS)}") from None
