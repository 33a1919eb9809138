"""Semi-real frames: a real object cut out of a real SEM frame, moved by exact sub-pixel shifts
over a real background from another frame, with shot noise added at a chosen dose.

The texture and the object's appearance then come from a microscope, not from our renderer;
the ground truth is still exact because the only thing synthetic is the translation:

* **cut-out** (:func:`cut_out_object`): the object is segmented in its source frame (Gaussian
  smoothing, a threshold, the connected component through a point on it, holes filled), the mask
  is dilated by a few px so that the object's real blurred edge is kept whole, and softened into
  an alpha matte by a Gaussian; the layer is ``alpha * frame`` (premultiplied). A thin strip of
  the source frame's own background around the edge (the dilation) travels with the object.
* **exact shift** (:class:`ShiftableLayer`): the layer and its alpha are shifted in the Fourier
  domain (a phase ramp): the shifted image is the band-limited (Shannon) interpolant of the
  sampled layer evaluated at shifted positions -- exact for a band-limited object, and an
  all-pass filter, so the object's texture keeps its power spectrum at every sub-pixel shift
  (a bilinear or bicubic resampling would smooth it by a shift-dependent amount). The canvas
  is odd-sized (no Nyquist bin) and the layer is tapered to zero at the canvas border, beyond
  the frame by more than the largest shift, so the periodic wrap-around never reaches a frame.
* **composite** (:func:`composite`): ``frame = background * (1 - alpha_s) + layer_s``.
* **noise** (:func:`add_shot_noise`): the composite is taken as the expected signal of a lower
  dose: ``dose`` detected electrons per pixel at full scale, Poisson counts, back to gray levels
  (float32, not clipped).

The Cramér–Rao bound (:func:`composite_crb`) treats the composite as the clean image and the
added shot noise as the only noise. It ignores that the real frames' own noise
is frozen into the object and the background (it is part of the "clean" texture here, which
slightly flatters the bound: a real microscope would re-draw that noise every frame) and the
halo of source background that the dilated matte carries.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy import ndimage as ndi

from .crb import check_roi, crb_from_fisher, fisher_information

__all__ = ["FULL_SCALE", "MIN_GRAY", "ShiftableLayer", "add_shot_noise", "composite", "composite_crb",
           "cut_out_object", "fourier_shift"]

#: Gray level of full scale of an 8-bit frame: the dose is counted in electrons at this level.
FULL_SCALE = 255.0
#: Floor (gray levels) of the expected signal: a pixel that is black in the real frame still
#: emits a little (and a Poisson variance of exactly 0 would make the bound infinite).
MIN_GRAY = 1.0


def cut_out_object(frame, seed_xy, *, threshold: float, smooth_px: float = 2.0,
                   dilate_px: int = 3, alpha_sigma_px: float = 1.0, opening_px: int = 3):
    """Alpha matte of the bright object through ``seed_xy`` in a real frame.

    Parameters
    ----------
    frame : (H, W) array_like
        Real gray-level frame.
    seed_xy : (int, int)
        A pixel ``(x, y)`` well inside the object.
    threshold : float
        Gray level separating the object (above) from its surroundings, after smoothing.
    smooth_px : float
        Gaussian smoothing (px) before the threshold (the frame's noise would fray the mask).
    dilate_px : int
        Dilation of the mask (px): keeps the object's blurred edge whole.
    alpha_sigma_px : float
        Gaussian softening (px) of the dilated mask into the matte.
    opening_px : int
        Morphological opening (iterations) that cuts thin bridges to bright neighbours.

    Returns
    -------
    (H, W) ndarray of float64
        Alpha in [0, 1].

    Raises
    ------
    ValueError
        When the seed is outside the frame or not above the threshold.
    """
    img = np.asarray(frame, np.float32)
    x, y = (int(v) for v in seed_xy)
    if not (0 <= x < img.shape[1] and 0 <= y < img.shape[0]):
        raise ValueError(f"seed {seed_xy} is outside the {img.shape[1]}x{img.shape[0]} frame")
    smooth = cv2.GaussianBlur(img, (0, 0), smooth_px) if smooth_px > 0 else img
    above = smooth > threshold
    if not above[y, x]:
        raise ValueError(f"seed {seed_xy} is not on the object (gray {smooth[y, x]:.0f} <= {threshold})")
    labels, _ = ndi.label(above)
    mask = ndi.binary_fill_holes(labels == labels[y, x])
    if opening_px > 0:
        mask = ndi.binary_opening(mask, iterations=opening_px)
        labels, _ = ndi.label(mask)
        mask = labels == labels[y, x]
    if dilate_px > 0:
        mask = ndi.binary_dilation(mask, iterations=dilate_px)
    alpha = mask.astype(np.float64)
    if alpha_sigma_px > 0:
        alpha = ndi.gaussian_filter(alpha, alpha_sigma_px, mode="nearest")
    return np.clip(alpha, 0.0, 1.0)


def _taper(shape, width_px: float) -> np.ndarray:
    """Raised-cosine window: 1 inside, falling to 0 over ``width_px`` at each border."""
    def ramp(n):
        d = np.minimum(np.arange(n), np.arange(n)[::-1]).astype(float)
        return np.where(d >= width_px, 1.0, 0.5 - 0.5 * np.cos(np.pi * d / width_px))
    return ramp(shape[0])[:, None] * ramp(shape[1])[None, :]


def fourier_shift(spectrum, shape, dx: float, dy: float) -> np.ndarray:
    """Inverse real FFT of ``spectrum`` (an ``rfft2`` of a ``shape`` image) shifted by ``(dx, dy)`` px.

    The result at pixel ``(x, y)`` is the band-limited interpolant of the original image at
    ``(x - dx, y - dy)``: the content moves by ``+dx`` along x and ``+dy`` along y.
    """
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    ramp = np.exp(-2j * np.pi * (fx * dx + fy * dy))
    return np.fft.irfft2(spectrum * ramp, s=shape)


class ShiftableLayer:
    """A premultiplied object layer and its alpha on a canvas, shifted exactly in Fourier space.

    Parameters
    ----------
    source : (H, W) array_like
        The real frame the object comes from.
    alpha : (H, W) array_like
        Its matte (:func:`cut_out_object`).
    window : (x0, y0, width, height)
        The part of the source that becomes the frame (before any shift): the object's
        position in the frame is its position in the source minus ``(x0, y0)``.
    max_shift_px : float
        Largest shift (px) that will be asked for; the canvas reaches beyond the window by more
        than this plus the taper.
    taper_px : float
        Width of the raised-cosine taper at the canvas border.

    Raises
    ------
    ValueError
        When the canvas (window + margins) does not fit in the source frame.
    """

    def __init__(self, source, alpha, window, *, max_shift_px: float = 40.0, taper_px: float = 16.0):
        src = np.asarray(source, np.float64)
        alpha = np.asarray(alpha, np.float64)
        if src.shape != alpha.shape:
            raise ValueError(f"alpha has shape {alpha.shape}, the source {src.shape}")
        x0, y0, w, h = (int(v) for v in window)
        margin = math.ceil(max_shift_px + taper_px) + 2
        # odd canvas sides: no Nyquist bin, so the phase ramp is an exact all-pass
        cw = w + 2 * margin + (1 - (w + 2 * margin) % 2)
        ch = h + 2 * margin + (1 - (h + 2 * margin) % 2)
        cx0, cy0 = x0 - margin, y0 - margin
        if cx0 < 0 or cy0 < 0 or cx0 + cw > src.shape[1] or cy0 + ch > src.shape[0]:
            raise ValueError(f"window {window} with a {margin}-px margin does not fit in the "
                             f"{src.shape[1]}x{src.shape[0]} source frame")
        self.window = (x0, y0, w, h)
        self.margin = margin
        self.max_shift_px = float(max_shift_px)
        self.canvas_shape = (ch, cw)
        taper = _taper(self.canvas_shape, taper_px)
        a = alpha[cy0:cy0 + ch, cx0:cx0 + cw] * taper
        layer = src[cy0:cy0 + ch, cx0:cx0 + cw] * a
        self._spectra = (np.fft.rfft2(layer), np.fft.rfft2(a))

    def shifted(self, dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
        """``(layer, alpha)`` inside the window, the object moved by ``(dx, dy)`` px."""
        if max(abs(dx), abs(dy)) > self.max_shift_px:
            raise ValueError(f"shift ({dx:.1f}, {dy:.1f}) px exceeds max_shift_px={self.max_shift_px}")
        m = self.margin
        _, _, w, h = self.window
        out = [fourier_shift(s, self.canvas_shape, dx, dy)[m:m + h, m:m + w] for s in self._spectra]
        return out[0], np.clip(out[1], 0.0, 1.0)


def composite(background, layer: ShiftableLayer, dx: float, dy: float) -> np.ndarray:
    """Noise-free frame: ``background * (1 - alpha) + layer`` with the object shifted by ``(dx, dy)``."""
    bg = np.asarray(background, np.float64)
    lay, a = layer.shifted(dx, dy)
    if bg.shape != lay.shape:
        raise ValueError(f"background has shape {bg.shape}, the layer's window {lay.shape}")
    return bg * (1.0 - a) + lay


def add_shot_noise(clean, dose_e_per_px: float, rng: np.random.Generator) -> np.ndarray:
    """A float32 frame of ``clean`` at ``dose_e_per_px`` detected electrons per pixel at full scale.

    ``counts ~ Poisson(dose * max(clean, MIN_GRAY) / 255)`` and the gray level is
    ``counts * 255 / dose``: mean ``clean``, variance ``255 * clean / dose``. The frame is left
    unrounded and unclipped (float32): at a few electrons per pixel an 8-bit frame grabber would
    clip the brightest counts, and the bound's noise model would no longer be the frames'.
    """
    if not (np.isfinite(dose_e_per_px) and dose_e_per_px > 0):
        raise ValueError(f"dose_e_per_px must be > 0, got {dose_e_per_px!r}")
    lam = np.maximum(np.asarray(clean, np.float64), MIN_GRAY) * (dose_e_per_px / FULL_SCALE)
    return (rng.poisson(lam) * (FULL_SCALE / dose_e_per_px)).astype(np.float32)


def composite_crb(background, layer: ShiftableLayer, shift, roi, dose_e_per_px: float, h: float = 1e-2):
    """Cramér–Rao bound ``(sigma_x, sigma_y)`` px of the object's translation in one noisy composite.

    The clean image is :func:`composite` at ``shift``; the noise is :func:`add_shot_noise`'s
    (white, Poisson, variance ``255 * max(m, MIN_GRAY) / dose``): see the module docstring for what
    this ignores.
    """
    bg = np.asarray(background, np.float64)
    check_roi(roi, bg.shape[1], bg.shape[0])
    sx, sy = (float(v) for v in shift)

    def render(ddx, ddy):
        return composite(bg, layer, sx + ddx, sy + ddy)

    def white(m):
        return np.maximum(m, MIN_GRAY) * (FULL_SCALE / dose_e_per_px)

    return crb_from_fisher(fisher_information(render, white, roi, h=h))
