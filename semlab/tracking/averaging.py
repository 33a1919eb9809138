"""Template averaging: the first well-registered frames, registered and averaged into a less noisy template.

A one-frame template doubles the variance of every estimate (its noise enters each of them).
:class:`TemplateAverager` keeps the area around the ROI of the first ``template_frames`` registered
frames (:class:`StoredFrame`) and their running mean; the tracker refreshes its template from
that mean whenever the count doubles, and at the end registers every stored frame again against
the averaged template and averages anew (:meth:`TemplateAverager.reregister`), so that the early
registrations against a noisy template do not blur the final one. :func:`consistency_weights`
then tells the band pixels that did not move with the object (static background) from those
that did.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..subpixel import keys_shift_filter, noise_variance
from ..template import ContourTemplate
from .frames import crop

__all__ = ["STORED_MARGIN_PX", "StoredFrame", "TemplateAverager", "consistency_weights", "registered_patch",
           "store_frame"]

#: The stored area reaches this many px around the ROI: room for the band's crop and the
#: re-registration's moves.
STORED_MARGIN_PX = 16
#: Consistency: frames within this many px of the start, and those more than this far from it,
#: at least this many of each.
NEAR_START_PX = 1.0
AWAY_FROM_START_PX = 3.0
MIN_FRAMES_PER_GROUP = 3
#: Only background pixels at least this far (px) from the contour can be flagged static; a flagged
#: pixel takes its neighbours within a 5×5 disc along (a feature is a few px across).
FLAG_FROM_CONTOUR_PX = 1.0
FLAG_DILATION = 5
#: More than half the band inconsistent: no object model to trust, and none is flagged.
MIN_CONSISTENT_FRACTION = 0.5


@dataclass
class StoredFrame:
    """The area of one frame around the ROI, and where the template sits in it.

    ``at`` is the frame pixel of the area's [0, 0]; ``shift``, ``gain``, ``offset`` the
    registration's answer (updated when the frame is registered again); ``noise`` the area's pixel
    noise variance (gray levels², :func:`~semlab.subpixel.noise_variance`).
    """

    area: np.ndarray
    at: tuple[int, int]
    shift: np.ndarray
    gain: float
    offset: float
    noise: float


def store_frame(arr, roi, shift, gain: float, offset: float) -> StoredFrame | None:
    """The area of ``arr`` around the ROI moved by ``shift`` (rounded), or None when it leaves the frame."""
    x0, y0, w, h = roi
    m = STORED_MARGIN_PX
    sx, sy = round(shift[0]), round(shift[1])
    ax0, ay0 = x0 + sx - m, y0 + sy - m
    if ax0 < 0 or ay0 < 0 or ax0 + w + 2 * m > arr.shape[1] or ay0 + h + 2 * m > arr.shape[0]:
        return None
    area = crop(arr, ax0, ay0, ax0 + w + 2 * m, ay0 + h + 2 * m).copy()
    return StoredFrame(area, (ax0, ay0), np.array(shift, float), gain, offset, noise_variance(area))


def registered_patch(stored: StoredFrame, roi, rho: float) -> np.ndarray:
    """The ROI-sized patch of the stored area at its shift, in the template's gray levels.

    Raises
    ------
    ValueError
        The patch leaves the stored area.
    """
    x0, y0, w, h = roi
    # The same exact Keys interpolation as the registration: another kernel (OpenCV's
    # a = −0.75, positions rounded to 1/32 px) would shift sharp edges by a few hundredths
    # of a pixel at every averaging step, and the template would drift.
    px, py = x0 + stored.shift[0] - stored.at[0], y0 + stored.shift[1] - stored.at[1]
    ix, iy = int(np.floor(px)), int(np.floor(py))
    patch = keys_shift_filter(stored.area, px - ix, py - iy)[iy:iy + h, ix:ix + w]
    if patch.shape != (h, w):
        raise ValueError("the registered patch leaves the stored area")
    # Gain and offset were estimated on whitened images: a constant c whitens to (1 − ρ)·c.
    return (patch - stored.offset / (1.0 - rho)) / stored.gain


def consistency_weights(patches, shifts, band, contour: ContourTemplate, cut: float) -> np.ndarray | None:
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

    Returns
    -------
    (K,) ndarray or None
        1 (keep) or 0 per band pixel (in ``np.nonzero(band)`` order); None: keep all.
    """
    moved = np.hypot(*(np.asarray(shifts, float) - np.asarray(shifts[0], float)).T)
    near, far = moved < NEAR_START_PX, moved > AWAY_FROM_START_PX
    if near.sum() < MIN_FRAMES_PER_GROUP or far.sum() < MIN_FRAMES_PER_GROUP:
        return None
    ys, xs = np.nonzero(band)
    values = patches[:, ys, xs].astype(np.float64)
    a, b = values[near], values[far]
    se = np.sqrt(a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b))
    t = np.abs(a.mean(axis=0) - b.mean(axis=0)) / np.maximum(se, 1e-9)
    distance = cv2.distanceTransform((~contour.mask).astype(np.uint8), cv2.DIST_L2, 3)
    eligible = ~contour.region & (distance >= FLAG_FROM_CONTOUR_PX)
    flagged = np.zeros(band.shape, np.uint8)
    flagged[ys[t > cut], xs[t > cut]] = 1
    flagged = cv2.dilate(flagged, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (FLAG_DILATION, FLAG_DILATION)))
    keep = (flagged[ys, xs] == 0) | ~eligible[ys, xs]
    if keep.mean() < MIN_CONSISTENT_FRACTION:
        return None
    return keep.astype(np.float64)


class TemplateAverager:
    """The frames stored for the averaged template, and their running sum.

    Parameters
    ----------
    first : StoredFrame
        Frame 0, which defines the origin of every displacement.
    frames_wanted : int
        How many frames the final template averages.
    roi, rho
        The ROI of frame 0 and the whitening's line correlation (:func:`registered_patch`).
    """

    def __init__(self, first: StoredFrame, frames_wanted: int, roi, rho: float):
        self.frames = [first]
        self.frames_wanted = int(frames_wanted)
        self.roi, self.rho = roi, rho
        self._sum = None

    @property
    def count(self) -> int:
        """Frames stored (frame 0 included)."""
        return len(self.frames)

    @property
    def complete(self) -> bool:
        return self.count >= self.frames_wanted

    def as_noisy_as_the_first(self, stored: StoredFrame, max_ratio: float) -> bool:
        """Whether ``stored``'s noise variance is at most ``max_ratio`` times frame 0's, in the frames' gray
        levels or in the template's (the variance over the registration's gain squared).

        A dose drop makes a frame noisier both ways. A change of the detector's contrast scales the
        noise with the signal (noisier in gray levels, not in the template's), and an occluder over
        the band pulls the registration's gain (noisier in the template's levels, not in gray levels):
        neither is a change of dose. A frame 0 without noise admits only frames without noise.
        """
        first = self.frames[0]
        # (Cross-multiplied: a gain of 0 compares, it does not divide.)
        in_template_levels = stored.noise * first.gain ** 2 <= max_ratio * first.noise * stored.gain ** 2
        return stored.noise <= max_ratio * first.noise or in_template_levels

    def shifts(self) -> list[np.ndarray]:
        return [stored.shift for stored in self.frames]

    def add(self, stored: StoredFrame, template) -> np.ndarray | None:
        """Store a registered frame; the running mean when the template is due for a refresh.

        The mean of ``template`` (the template when the sum starts: frame 0's patch) and the
        registered patches, returned when the count has doubled (2, 4, 8, ...: cheaper than every
        frame) and the stack is not complete yet; None otherwise.
        """
        self.frames.append(stored)
        n = self.count
        if self.complete:
            return None
        patch = registered_patch(stored, self.roi, self.rho)
        self._sum = (self._sum if self._sum is not None else template.astype(np.float64)) + patch
        if n & (n - 1):
            return None
        return (self._sum / n).astype(np.float32)

    def reregister(self, register) -> np.ndarray:
        """Register every stored frame again and return their patches ``(N, h, w)``.

        ``register(stored) -> FitResult`` fits the current template to a stored area; a converged
        answer replaces the stored one.
        """
        patches = []
        for stored in self.frames:
            ref = register(stored)
            if ref.converged:
                stored.shift, stored.gain, stored.offset = ref.shift.copy(), ref.gain, ref.offset
            patches.append(registered_patch(stored, self.roi, self.rho))
        return np.stack(patches)
