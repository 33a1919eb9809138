"""Where to look: the search window, the coarse search and the re-acquisition.

These find candidate positions of the template in a frame by normalised correlation — the coarse
search at ``1/coarse_factor`` scale for a start the Gauss–Newton registration can converge from,
the re-acquisition of the object when its appearance has changed — and never touch a tracker's
state: the tracker decides what to do with a candidate.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..matching import parabola_peak
from ..roi import clip_window, roi_centre
from ..subpixel import five_point_gradients
from .band import inner_mask
from .frames import crop
from .uncertainty import least_squares_covariance

__all__ = ["Candidate", "border_overhang", "coarse_mask", "coarse_search", "coarse_template", "extended_over_border",
           "reacquire", "search_window"]

#: The coarse search sees the object's region and band dilated by this many coarse pixels.
COARSE_MASK_REACH = 4
#: Fewest coarse pixels the coarse search's mask must keep to be used.
MIN_COARSE_MASK_PIXELS = 4
#: Re-acquisition: Gaussian smoothing (px) of image and template before the correlation.
REACQUIRE_SIGMA = 1.5
#: Re-acquisition: the object's region dilated by a 9×9 disc (4 px: its immediate surroundings,
#: so static background in the ROI counts little), away from the ROI's 2-px border.
REACQUIRE_DILATION = 9
REACQUIRE_BORDER_PX = 2
MIN_REACQUIRE_PIXELS = 10
#: Lowest normalised correlation of a re-acquired object.
REACQUIRE_MIN_NCC = 0.6
#: The peak must beat the best rival more than this many px away by this much (else ambiguous).
REACQUIRE_MIN_MARGIN = 0.05
RIVAL_DISTANCE_PX = 8
#: Half-width (px) of the full-resolution refinement around the half-resolution peak.
REACQUIRE_REFINE_PX = 3
#: Smoothing (px) of the template before the gradients of a re-acquired match's covariance.
MATCH_GRADIENT_SIGMA = 1.0
#: Variance (px²) of a correlation peak's parabola fit about the true sub-pixel peak: a parabola
#: through three samples of a peak a few px wide is off by up to about 0.1 px ("pixel locking").
PARABOLA_VARIANCE_PX2 = 0.1 ** 2


@dataclass(frozen=True)
class Candidate:
    """Where the template may be: its shift against the ROI, the photometric start (gain, offset
    in whitened units) and the correlation that found it."""

    shift: np.ndarray
    gain: float
    offset: float
    score: float
    covariance: np.ndarray | None = None


def search_window(roi, search_size: int, shift, shape, *, whole: bool = False) -> tuple[int, int, int, int]:
    """Search window ``(x0, y0, w, h)`` centred on the template at ``shift``; the whole image
    when ``whole`` (a lost target)."""
    if whole:
        return 0, 0, shape[1], shape[0]
    _x0, _y0, w, h = roi
    size = max(search_size, w + 2, h + 2)
    cx, cy = roi_centre(roi)
    return clip_window(cx + shift[0], cy + shift[1], size, size, shape)


def coarse_mask(region, band, factor: int) -> np.ndarray:
    """The object's neighbourhood (its region and band, dilated) at the coarse scale.

    The coarse search sees the object and its immediate surroundings only, so that static
    background in the ROI does not pull the match back when the probe moves.
    """
    h, w = region.shape
    hc, wc = h - h % factor, w - w % factor
    k = 2 * COARSE_MASK_REACH * factor + 1
    near = cv2.dilate((region | band).astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    return cv2.resize(near[:hc, :wc].astype(np.float32), (wc // factor, hc // factor),
                      interpolation=cv2.INTER_AREA) > 0.5


def coarse_template(template, mask, factor: int) -> np.ndarray:
    """The template block-averaged by ``factor``, flat (its mean) outside ``mask``.

    Outside the object's neighbourhood the template is flat, so it adds nothing to the
    correlation's numerator: a mask at the price of none.
    """
    h, w = template.shape
    hc, wc = h - h % factor, w - w % factor
    small = cv2.resize(template[:hc, :wc], (wc // factor, hc // factor), interpolation=cv2.INTER_AREA)
    if mask.sum() >= MIN_COARSE_MASK_PIXELS and np.ptp(small[mask]) > 0:
        small = np.where(mask, small, float(small[mask].mean())).astype(np.float32)
    return small


def coarse_search(arr, window, small, factor: int, roi, mask=None) -> np.ndarray:
    """Coarse template position (its shift against ``roi``) by normalised correlation of the
    :func:`coarse_template` ``small`` at ``1/factor`` scale over ``window``.

    With the template's ``mask`` (:func:`coarse_mask`), the template may hang over the image's
    border by what lies outside the mask's bounding box: a probe near the border, whose ROI reaches
    past the frame while the object and its neighbourhood are inside, is still found. Where the
    window meets the border, the image is extended by its edge's pixels that far
    (:func:`border_overhang`); the flat template adds nothing to the correlation there.

    Raises
    ------
    ValueError
        A constant window, NaN pixels in it, or a window smaller than the template.
    """
    wx, wy, ww, wh = window
    f = factor
    image = crop(arr, wx, wy, wx + ww - ww % f, wy + wh - wh % f)
    if float(image.max() - image.min()) <= 0:
        raise ValueError("the search window is constant")
    reduced = image if f == 1 else cv2.resize(image, (ww // f, wh // f), interpolation=cv2.INTER_AREA)
    reduced, (left, top) = extended_over_border(reduced, window, arr.shape, mask)
    if reduced.shape[0] < small.shape[0] or reduced.shape[1] < small.shape[1]:
        raise ValueError("the search window is smaller than the template")
    scores = cv2.matchTemplate(reduced, small, cv2.TM_CCOEFF_NORMED)
    scores = np.nan_to_num(scores, nan=-1.0, posinf=-1.0, neginf=-1.0)
    _, _, _, (ix, iy) = cv2.minMaxLoc(scores)
    px, py = parabola_peak(scores, ix, iy)
    # Block-averaging by f maps both images alike: an offset k in the small image is f·k.
    return np.array([wx + f * (px - left) - roi[0], wy + f * (py - top) - roi[1]])


def border_overhang(window, shape, mask) -> tuple[int, int, int, int]:
    """``(top, bottom, left, right)``: how far (px at ``mask``'s scale) a template may hang over each
    side of ``window`` that is the image's border (an image of ``shape``), keeping its ``mask``
    inside the image: the rows and columns outside the mask's bounding box. None, or a mask too
    small for :func:`coarse_template` to have flattened the template outside it: no overhang."""
    if mask is None or np.count_nonzero(mask) < MIN_COARSE_MASK_PIXELS:
        return 0, 0, 0, 0
    rows, cols = np.flatnonzero(np.any(mask, axis=1)), np.flatnonzero(np.any(mask, axis=0))
    wx, wy, ww, wh = window
    return (int(rows[0]) if wy <= 0 else 0, int(mask.shape[0] - 1 - rows[-1]) if wy + wh >= shape[0] else 0,
            int(cols[0]) if wx <= 0 else 0, int(mask.shape[1] - 1 - cols[-1]) if wx + ww >= shape[1] else 0)


def extended_over_border(image, window, shape, mask) -> tuple[np.ndarray, tuple[int, int]]:
    """``image`` (the ``window`` of an image of ``shape``, at ``mask``'s scale) extended by its edge's
    pixels by :func:`border_overhang`, and ``(left, top)``: how far its ``[0, 0]`` moved up and left."""
    top, bottom, left, right = border_overhang(window, shape, mask)
    if top or bottom or left or right:
        image = cv2.copyMakeBorder(image, top, bottom, left, right, cv2.BORDER_REPLICATE)
    return image, (left, top)


def _masked_ncc(image, template, mask):
    scores = cv2.matchTemplate(image, template, cv2.TM_CCOEFF_NORMED, mask=mask.astype(np.float32))
    return np.nan_to_num(scores, nan=-1.0, posinf=-1.0, neginf=-1.0)


def reacquire(arr, window, template, region, roi, rho: float) -> Candidate | None:
    """Where in ``window`` the object looks most alike, whatever its gray levels.

    The fallback when Gauss–Newton fails (an edge's contrast vanished at contact with a sample, a
    brightness jump). The object and its immediate surroundings (``region`` dilated by 4 px, so
    static background in the ROI counts little) are matched by masked normalised correlation of
    the smoothed images — blind to gain and offset and degrading gracefully when one edge loses its
    contrast — over the whole window, at half resolution and then at full resolution around the
    peak. The best match over the window, not the one nearest the prediction: near the prediction a
    probe that jumped along its own shaft leaves shaft behind, which correlates well too. The peak
    must stand out from the best match more than 8 px away, or the answer is ambiguous. As in
    :func:`coarse_search`, the template may hang over the image's border by what lies outside its
    mask (:func:`border_overhang`).

    Parameters
    ----------
    arr : (H, W) ndarray
        The frame.
    window : (x0, y0, w, h)
        Where to search (:func:`search_window`).
    template : (h, w) ndarray
        The ROI's template; ``region`` its object mask; ``roi`` the ROI in frame 0.
    rho : float
        The scan line's correlation the tracker whitens with: the candidate's offset is in
        whitened units (a constant ``c`` whitens to ``(1 − ρ)·c``).

    Returns
    -------
    Candidate or None
        None: nothing found well enough.
    """
    x0, y0, w, h = roi
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (REACQUIRE_DILATION, REACQUIRE_DILATION))
    mask = cv2.dilate(region.astype(np.uint8), kernel) > 0
    mask &= inner_mask(mask.shape, REACQUIRE_BORDER_PX)
    plain, (left, top) = extended_over_border(crop(arr, window[0], window[1], window[0] + window[2],
                                                   window[1] + window[3]), window, arr.shape, mask)
    wx, wy = window[0] - left, window[1] - top  # the frame pixel of plain[0, 0]
    wh, ww = plain.shape
    if ww < w + 4 or wh < h + 4:
        return None
    image = cv2.GaussianBlur(plain, (0, 0), REACQUIRE_SIGMA)
    tmpl = cv2.GaussianBlur(template, (0, 0), REACQUIRE_SIGMA)
    if mask.sum() < MIN_REACQUIRE_PIXELS or mask.all() or np.ptp(tmpl[mask]) <= 0:
        return None
    # Half resolution over the window (a quarter of the work), full resolution near its peak.
    half = cv2.resize(image, (ww // 2, wh // 2), interpolation=cv2.INTER_AREA)
    th, tw_ = h // 2, w // 2
    tmpl_half = cv2.resize(tmpl[:2 * th, :2 * tw_], (tw_, th), interpolation=cv2.INTER_AREA)
    mask_half = cv2.resize(mask[:2 * th, :2 * tw_].astype(np.float32), (tw_, th), interpolation=cv2.INTER_AREA)
    coarse = _masked_ncc(half, tmpl_half, mask_half > 0.5)
    _, peak, _, (cx, cy) = cv2.minMaxLoc(coarse)
    # The runner-up: the best other local maximum more than 8 px away (a ridge through the
    # peak, e.g. along an edge, is the same peak's shoulder, not a rival).
    yy, xx = np.ogrid[:coarse.shape[0], :coarse.shape[1]]
    local_max = coarse >= cv2.dilate(coarse, np.ones((5, 5), np.uint8))
    apart = RIVAL_DISTANCE_PX // 2  # half-resolution pixels
    rivals = local_max & ((np.abs(xx - cx) > apart) | (np.abs(yy - cy) > apart))
    runner_up = float(coarse[rivals].max()) if rivals.any() else -1.0
    if peak < REACQUIRE_MIN_NCC or peak - runner_up < REACQUIRE_MIN_MARGIN:
        return None
    r = REACQUIRE_REFINE_PX
    fx0, fy0 = max(2 * cx - r, 0), max(2 * cy - r, 0)
    fx1, fy1 = min(2 * cx + r + w, ww), min(2 * cy + r + h, wh)
    fine = _masked_ncc(image[fy0:fy1, fx0:fx1], tmpl, mask)
    _, peak, _, (ix, iy) = cv2.minMaxLoc(fine)
    if peak < REACQUIRE_MIN_NCC or not (0 < ix < fine.shape[1] - 1 and 0 < iy < fine.shape[0] - 1):
        return None
    px, py = parabola_peak(fine, ix, iy)
    shift = np.array([wx + fx0 + px - x0, wy + fy0 + py - y0])
    # Gain and offset of the match (whitened units: a constant c whitens to (1 − ρ)·c).
    a = image[fy0 + iy:fy0 + iy + h, fx0 + ix:fx0 + ix + w][mask].astype(np.float64)
    b = tmpl[mask].astype(np.float64)
    gain = float(np.cov(a, b)[0, 1] / np.var(b, ddof=1))
    offset = (1.0 - rho) * float(a.mean() - gain * b.mean())
    cov = _match_covariance(plain[fy0 + iy:fy0 + iy + h, fx0 + ix:fx0 + ix + w], template, mask, gain)
    return Candidate(shift, gain, offset, float(peak), cov)


def _match_covariance(patch, template, mask, gain: float) -> np.ndarray:
    """The re-acquired shift's covariance (px²): the least squares of the unsmoothed frame on the
    template (gradients lightly smoothed) at the integer peak, whose residuals say how well the
    object still looks like its template, plus the parabola's sub-pixel error
    (:data:`PARABOLA_VARIANCE_PX2`)."""
    gx, gy = five_point_gradients(cv2.GaussianBlur(template, (0, 0), MATCH_GRADIENT_SIGMA))
    t = template[mask].astype(np.float64)
    i = patch[mask].astype(np.float64)
    level_gain = float(np.cov(i, t)[0, 1] / np.var(t, ddof=1))
    residual = i - level_gain * t - float(i.mean() - level_gain * t.mean())
    jac = gain * np.stack([gx[mask], gy[mask]], axis=1).astype(np.float64)
    return least_squares_covariance(jac, residual) + PARABOLA_VARIANCE_PX2 * np.eye(2)
