"""A static background learned online beside the moving object: the probe as a layer over it.

Issue 14 §2's "probe layer over a static background". The template carries, beside the object, the
background that was there in frame 0; once the object has moved, another patch of that background lies
beside it in every frame, and its texture pulls each registration towards where the template was taken
(clutter and textured substrates: frames a pixel or more off with a normal score). The background does
not move: each well-registered frame shows it, away from the object, where the frame's ROI sits. So a
:class:`BackgroundLayer` in frame coordinates accumulates those pixels, in the template's gray levels,
and before a frame is registered its background's texture is taken off where the template, at the
predicted shift, is background (:meth:`BackgroundLayer.detextured`), while the band model sees the
template's background flattened (:func:`~semlab.tracking.band.flattened_background`). What remains
beside the object in both is the background's level, which the photometric model fits.

The texture is the layer's mean minus its local mean (a normalised Gaussian of
:data:`~semlab.tracking.band.FLAT_SIGMA_PX`, the flattening's), shrunk per pixel by
``τ² / (τ² + σ²/n)`` (Wiener shrinkage of a mean of ``n`` noisy samples: ``τ`` the background's
texture, ``σ`` the noise), so a pixel seen once takes off little of its own noise.
"""

from __future__ import annotations

import cv2
import numpy as np

from .band import FLAT_SIGMA_PX, far_from_region

__all__ = ["GATE_PX", "MIN_TEXTURE", "BackgroundLayer", "far_from_region", "far_px", "object_support"]

#: The layer acts once an accepted answer is this far (px) from the origin: beside a still probe the
#: template's background is the frames' background, information, not a pull (a still probe's
#: development seeds lose nothing to the layer gated here, and gain nothing: flattening it costs them).
GATE_PX = 0.75
#: The layer is learned only where frame 0's background texture (:func:`~semlab.tracking.band.background_texture`)
#: is at least this many times the noise: under it there is little texture to take off, and the flattened
#: template alone only costs the fits information (more frames flagged, none fewer wrong).
MIN_TEXTURE = 1.0
#: Pixels this many times the edge's blur (:func:`~semlab.tracking.band.edge_blur`) from the object's
#: region, and at least :data:`MIN_FAR_PX`, are background: nearer, the blurred edge moves with the object.
FAR_PER_EDGE_BLUR = 3.0
MIN_FAR_PX = 1.5
#: A pixel near the region that stands out from the background by this fraction of the object's contrast
#: is the object's (:func:`object_support`): a thin apex's blurred end, a quarter of the contrast and more.
SUPPORT_CONTRAST = 0.25
#: The texture map is recomputed after this many frames added (the mean of n frames changes by about
#: 1/n of itself per frame: every 8 is as good as every frame, at an eighth of the cost).
REFRESH_FRAMES = 8


def far_px(edge_sigma: float) -> float:
    """Distance (px) from the object's region beyond which a pixel is background (:data:`FAR_PER_EDGE_BLUR`)."""
    blur = float(edge_sigma) if np.isfinite(edge_sigma) else 0.0
    return max(MIN_FAR_PX, FAR_PER_EDGE_BLUR * blur)


def object_support(template, region, reach: float) -> np.ndarray:
    """``region`` and the pixels within ``reach`` px of it that still stand out from the background by
    :data:`SUPPORT_CONTRAST` of the object's contrast (bool, the template's shape).

    Otsu's region ends where the blurred object falls to half its contrast: a thin apex, narrower than
    the blur, lies mostly outside it, and so would the pixels that tell the position along the shaft.
    """
    region = np.asarray(region, bool)
    img = np.asarray(template, np.float32)
    if region.all() or not region.any():
        return region
    background = float(np.median(img[~region]))
    contrast = float(np.median(img[region])) - background
    near = ~far_from_region(region, reach)
    standing_out = (img - background) * np.sign(contrast) > SUPPORT_CONTRAST * abs(contrast)
    return region | (near & standing_out)


class BackgroundLayer:
    """The static background in frame coordinates, accumulated from registered frames.

    Parameters
    ----------
    shape : (int, int)
        The frames' shape.
    roi : (x, y, w, h)
        The template's ROI in frame 0: at shift ``s`` the template covers it moved by ``round(s)``.
    texture_var, noise_var : float
        ``τ²`` and ``σ²`` of the shrinkage, in the template's gray levels².
    """

    def __init__(self, shape, roi, texture_var: float, noise_var: float):
        self.sum = np.zeros(shape, np.float32)
        self.count = np.zeros(shape, np.float32)
        self.roi = tuple(int(v) for v in roi)
        self.texture_var, self.noise_var = float(texture_var), float(noise_var)
        self._texture = None
        self._added = 0

    def _boxes(self, shift, shape):
        """``(frame slices, template slices)`` of the ROI moved by ``round(shift)``, clipped to the frame."""
        x0, y0, w, h = self.roi
        fx, fy = x0 + round(shift[0]), y0 + round(shift[1])
        ax, ay = max(fx, 0), max(fy, 0)
        bx, by = min(fx + w, shape[1]), min(fy + h, shape[0])
        if bx <= ax or by <= ay:
            return None
        return (slice(ay, by), slice(ax, bx)), (slice(ay - fy, by - fy), slice(ax - fx, bx - fx))

    def add(self, frame, shift, gain: float, offset: float, rho: float, far) -> None:
        """Accumulate ``frame``'s pixels where the template at ``shift`` is background (``far``, ROI-sized).

        ``gain`` and ``offset`` are the fit's (estimated on whitened images, eq. 4's photometric
        parameters): the frame's gray level ``I`` is ``(I − offset / (1 − ρ)) / gain`` in the template's.
        """
        if frame.shape != self.sum.shape or not (np.isfinite(gain) and gain != 0):
            return
        boxes = self._boxes(shift, frame.shape)
        if boxes is None:
            return
        fbox, tbox = boxes
        mask = far[tbox]
        values = (np.asarray(frame[fbox], np.float32) - offset / (1.0 - rho)) / gain
        self.sum[fbox] += np.where(mask, values, 0.0)
        self.count[fbox] += mask
        self._added += 1
        if self._added >= REFRESH_FRAMES:
            self._texture = None

    def texture(self) -> np.ndarray:
        """The shrunk texture map (frame-sized; 0 where nothing was seen)."""
        if self._texture is None:
            self._added = 0
            known = (self.count > 0).astype(np.float32)
            mean = self.sum / np.maximum(self.count, 1.0)
            local = cv2.GaussianBlur(mean * known, (0, 0), FLAT_SIGMA_PX) / np.maximum(
                cv2.GaussianBlur(known, (0, 0), FLAT_SIGMA_PX), 1e-6)
            tau2 = self.texture_var
            shrink = tau2 / (tau2 + self.noise_var / np.maximum(self.count, 1.0)) if tau2 > 0 else 0.0
            self._texture = (known * (mean - local) * shrink).astype(np.float32)
        return self._texture

    def detextured(self, frame, predicted, gain: float, far) -> np.ndarray:
        """``frame`` with the background's texture taken off where the template, at ``predicted``, is
        background (``far``): ``I − gain × texture``."""
        out = np.array(frame, np.float32, copy=True)
        if frame.shape != self.sum.shape or not np.isfinite(gain):
            return out
        boxes = self._boxes(predicted, frame.shape)
        if boxes is None:
            return out
        fbox, tbox = boxes
        out[fbox] -= gain * self.texture()[fbox] * far[tbox]
        return out
