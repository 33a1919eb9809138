"""Sub-pixel registration's parts: the paper's gradient method (eq. 9), interpolation, the noise model.

:func:`gradient_subpixel_shift` is the paper's one-step refinement: the 5-point derivative
``[1, −8, 0, 8, −1]/12`` and the closed-form 2×2 least-squares solve of eq. 9.
:func:`~semlab.gauss_newton.gauss_newton_translation` (:mod:`semlab.gauss_newton`) goes further: inverse-compositional Gauss–Newton on a set of
template pixels (the contour band), bicubic interpolation, a gain/offset model against gray-level
fluctuation and Huber weights against occlusion and clutter, on line-whitened images weighted by
the shot-noise variance (:func:`estimate_noise`, :func:`whiten_lines`), which is what brings it
close to the Cramér–Rao bound of an SEM frame whose noise is correlated along the scan line.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "FIVE_POINT_KERNEL",
    "NoiseModel",
    "estimate_noise",
    "five_point_gradients",
    "gradient_subpixel_shift",
    "keys_shift_filter",
    "keys_weights",
    "median",
    "noise_variance",
    "sample_bicubic",
    "sample_shifted",
    "sample_shifted_filtered",
    "weighted_ncc",
    "whiten_lines",
]

#: The paper's derivative mask (eq. 8): truncation error O(h⁴).
FIVE_POINT_KERNEL = np.array([1.0, -8.0, 0.0, 8.0, -1.0], np.float32) / 12.0

#: Robust standard deviation from the median absolute deviation (Gaussian noise).
MAD_TO_SD = 1.4826
#: :func:`noise_variance` reads every 8th pair of rows: a 200-px square still gives ~5000 differences
#: (the variance to ~3 %, against the factor of 2 the template averaging's dose gate tests), at an
#: eighth of the cost.
NOISE_ROW_STEP = 8


def five_point_gradients(image) -> tuple[np.ndarray, np.ndarray]:
    """Image derivatives ``(I_x, I_y)`` with the 5-point mask ``[1, −8, 0, 8, −1]/12`` (paper, eq. 8).

    Borders are reflected, so the two outermost rows/columns are approximate.
    """
    img = np.asarray(image, np.float32)
    k = FIVE_POINT_KERNEL.reshape(1, 5)
    ix = cv2.filter2D(img, cv2.CV_32F, k, borderType=cv2.BORDER_REFLECT_101)
    iy = cv2.filter2D(img, cv2.CV_32F, k.T, borderType=cv2.BORDER_REFLECT_101)
    return ix, iy


def gradient_subpixel_shift(template, target, mask=None) -> tuple[float, float]:
    """Sub-pixel displacement of ``target`` relative to ``template`` (paper, eqs. 6-9).

    With ``I(x + u + Δx, y + v + Δy, tₙ) ≈ I(x + u, y + v, tₙ) + Δx·I_x + Δy·I_y`` (eq. 8), the
    least-squares ``(Δx, Δy)`` that makes the target match the template is the closed form of
    eq. 9, with the derivatives of the target taken by the 5-point mask.

    Parameters
    ----------
    template : (h, w) array_like
        ``I(x, t₀)``.
    target : (h, w) array_like
        ``I(f(x; μ), tₙ)``: the target image at the integer match position.
    mask : (h, w) array_like of bool, optional
        The pixels ``R`` to sum over (e.g. the contour band); default: all but a 2-px border.

    Returns
    -------
    (dx, dy) : tuple of float
        Add to the integer position. ``(nan, nan)`` if the 2×2 system is singular (no texture).
    """
    t = np.asarray(template, np.float32)
    i = np.asarray(target, np.float32)
    if t.shape != i.shape:
        raise ValueError(f"template {t.shape} and target {i.shape} differ in shape")
    ix, iy = five_point_gradients(i)
    use = np.zeros(t.shape, bool)
    use[2:-2, 2:-2] = True
    if mask is not None:
        use &= np.asarray(mask, bool)
    gx, gy, diff = ix[use].astype(np.float64), iy[use].astype(np.float64), (t - i)[use].astype(np.float64)
    a = np.array([[gx @ gx, gx @ gy], [gx @ gy, gy @ gy]])
    b = np.array([diff @ gx, diff @ gy])
    if np.linalg.cond(a) > 1e8:
        return float("nan"), float("nan")
    dx, dy = np.linalg.solve(a, b)
    return float(dx), float(dy)


def keys_weights(t) -> np.ndarray:
    """Keys' cubic convolution weights (a = −0.5) for fractional offsets ``t`` in [0, 1).

    Returns
    -------
    ndarray of float64
        ``(4,)`` for one offset, ``(4, K)`` for ``K`` offsets: the weights of the samples at
        ``−1, 0, 1, 2`` px from the offset's integer part.
    """
    # One offset on Python floats (the per-iteration hot path: numpy scalars cost ten times more).
    t = float(t) if np.ndim(t) == 0 else np.asarray(t, np.float64)
    t2, t3 = t * t, t * t * t
    return np.array([-0.5 * t3 + t2 - 0.5 * t,
                     1.5 * t3 - 2.5 * t2 + 1.0,
                     -1.5 * t3 + 2.0 * t2 + 0.5 * t,
                     0.5 * t3 - 0.5 * t2])


def keys_shift_filter(image, frac_x: float, frac_y: float) -> np.ndarray:
    """``image`` sampled at ``(x + frac_x, y + frac_y)`` at every pixel, by Keys' cubic kernel.

    One separable 4×4 filter, ``out(x, y) = Σᵢⱼ wx[i]·wy[j]·img(x − 1 + i, y − 1 + j)`` (a
    correlation anchored at tap 1), border replicated: a gather from it samples the image at any
    set of points that share one fractional shift (the band moved by a translation).
    """
    wx, wy = keys_weights(frac_x).astype(np.float32), keys_weights(frac_y).astype(np.float32)
    return cv2.sepFilter2D(np.asarray(image, np.float32), -1, wx.reshape(1, 4), wy.reshape(4, 1), anchor=(1, 1),
                           borderType=cv2.BORDER_REPLICATE)


def sample_bicubic(image, xs, ys) -> np.ndarray:
    """Sample ``image`` at real coordinates by bicubic (Keys) interpolation, border replicated.

    Exact in the sub-pixel position, unlike ``cv2.remap``, whose interpolation tables quantise
    positions to 1/32 px — a floor that would sit at the Cramér–Rao bound of a good SEM image.
    The 16 taps are read in one gather; each point's sum is taken in the same order as the
    separable formula ``Σⱼ wy[j]·(Σᵢ wx[i]·img(…))``, tap by tap (the same float64 values).
    """
    img = np.asarray(image, np.float32)
    xs = np.asarray(xs, np.float64).ravel()
    ys = np.asarray(ys, np.float64).ravel()
    x0, y0 = np.floor(xs), np.floor(ys)
    wx, wy = keys_weights(xs - x0), keys_weights(ys - y0)
    rows, cols = img.shape
    ix = _stencil_indices(x0, cols)
    iy = _stencil_indices(y0, rows)
    # taps[j, i]: the pixel of stencil row j, column i, for every point.
    taps = img.ravel().take(iy[:, None, :] * cols + ix[None, :, :])
    weighted = wx[None, :, :] * taps
    # ((w0 + w1) + w2) + w3 per stencil row, times its weight, summed row after row (in place).
    out = None
    for j in range(4):
        row = weighted[j]
        acc = np.add(row[0], row[1])
        acc += row[2]
        acc += row[3]
        acc *= wy[j]
        if out is None:
            out = acc
        else:
            out += acc
    return out


def _stencil_indices(start, size: int) -> np.ndarray:
    """``(4, K)`` indices of the Keys stencil ``start − 1 … start + 2`` along one axis, clipped to
    ``[0, size − 1]`` (the border replicated)."""
    idx = start.astype(np.intp)[None, :] + np.arange(-1, 3)[:, None]
    np.maximum(idx, 0, out=idx)
    np.minimum(idx, size - 1, out=idx)
    return idx


def sample_shifted_filtered(image, points, shift) -> np.ndarray:
    """As :func:`sample_shifted`, by one separable 4×4 Keys filter over the image and a gather.

    Faster than 16 gathers when the points fill a good part of ``image`` (a crop around them).
    Points whose stencil leaves the image see its border replicated.
    """
    img = np.asarray(image, np.float32)
    fx, fy = np.floor(shift[0]), np.floor(shift[1])
    rows, cols = img.shape
    px = points[:, 0].astype(np.intp) + int(fx)
    py = points[:, 1].astype(np.intp) + int(fy)
    if px.min() < 0 or py.min() < 0 or px.max() >= cols or py.max() >= rows:
        # a point shifted off the image: clipping its index would read the interpolation at the
        # border pixel + fraction, not the replicated border at the point's own position
        return sample_bicubic(img, points[:, 0] + shift[0], points[:, 1] + shift[1])
    filtered = keys_shift_filter(img, shift[0] - fx, shift[1] - fy)
    return filtered[py, px].astype(np.float64)


def sample_shifted(image, points, shift) -> np.ndarray:
    """Bicubic samples of ``image`` at integer ``points`` (K, 2) moved by one real ``shift``.

    All points share the fractional part of the shift, so the 4×4 Keys weights are computed once
    and the interpolation is 16 gathers — the hot path of :func:`gauss_newton_translation`.
    Falls back to :func:`sample_bicubic` (border replicated) when the stencil leaves the image.
    """
    img = np.asarray(image, np.float32)
    rows, cols = img.shape
    fx, fy = np.floor(shift[0]), np.floor(shift[1])
    px = points[:, 0].astype(np.intp) + int(fx)
    py = points[:, 1].astype(np.intp) + int(fy)
    if px.min() < 1 or py.min() < 1 or px.max() > cols - 3 or py.max() > rows - 3:
        return sample_bicubic(img, points[:, 0] + shift[0], points[:, 1] + shift[1])
    wx, wy = keys_weights(shift[0] - fx), keys_weights(shift[1] - fy)
    flat = img.ravel()
    base = py * cols + px
    out = np.zeros(len(points), np.float64)
    for j in range(4):
        row = base + (j - 1) * cols
        out += wy[j] * (wx[0] * flat[row - 1] + wx[1] * flat[row] + wx[2] * flat[row + 1] + wx[3] * flat[row + 2])
    return out



@dataclass(frozen=True)
class NoiseModel:
    """Noise of an SEM frame as the tracker sees it: estimated from the image, never assumed.

    Attributes
    ----------
    rho : float
        Correlation of neighbouring pixels along the scan line (the video amplifier's limited
        bandwidth: an AR(1) process along x), in [0, 0.95].
    variance_at_zero, variance_slope : float
        Pixel noise variance ``a + b · I`` as a function of the gray level ``I`` (read noise plus
        shot noise, whose variance grows with the signal above the black level, so ``a`` may be
        negative), before the line correlation.
    variance_floor : float
        Smallest variance the model returns (a quarter of the smallest measured one).
    """

    rho: float = 0.0
    variance_at_zero: float = 1.0
    variance_slope: float = 0.0
    variance_floor: float = 1e-6

    def variance(self, level) -> np.ndarray:
        """Pixel noise variance at gray level(s) ``level`` (never below ``variance_floor``)."""
        v = self.variance_at_zero + self.variance_slope * np.asarray(level, np.float64)
        return np.maximum(v, self.variance_floor)


def _row_pair_differences(img: np.ndarray, row_step: int = 1) -> np.ndarray:
    """``I(x, y) − I(x, y + 1)`` for the row pairs ``(0, 1), (row_step, row_step + 1), ...``, each
    pair's median taken off: the scene cancels where it varies slowly, the per-line offsets cancel
    everywhere, and two rows' noise is left (in ``img``'s dtype)."""
    d = img[0:-1:row_step] - img[1::row_step]
    d -= np.median(d, axis=1, keepdims=True)
    return d


def estimate_noise(image, *, flat_quantile: float = 0.6) -> NoiseModel:
    """Estimate the line correlation and the signal-dependent variance from ONE image.

    Vertical neighbours ``d = I(x, y) − I(x, y + 1)`` cancel the scene wherever it varies slowly,
    and each row pair's median is subtracted, which also cancels per-line offsets. What is left is
    the difference of two independent rows of noise: its lag-1 autocorrelation along x is the
    line correlation ``ρ``, and ``d²/2`` regressed on the local gray level gives ``a + b·I``.
    Only "flat" pixels (gradient below the ``flat_quantile`` of the image) are used.

    Parameters
    ----------
    image : (M, N) array_like
        At least 8×8 px.
    flat_quantile : float
        Fraction of the pixels, those with the weakest smoothed gradient, that count as flat.

    Returns
    -------
    NoiseModel
    """
    img = np.asarray(image, np.float32)
    if img.ndim != 2 or min(img.shape) < 8:
        raise ValueError(f"need a 2-D image of at least 8x8 px to estimate the noise, got {img.shape}")
    smooth = cv2.GaussianBlur(img, (0, 0), 2.0)
    gy, gx = np.gradient(smooth)
    grad = np.hypot(gx, gy)
    flat = grad <= np.quantile(grad, flat_quantile)
    flat = flat[:-1] & flat[1:]
    d = _row_pair_differences(img.astype(np.float64))
    level = 0.5 * (smooth[:-1] + smooth[1:]).astype(np.float64)
    pairs = flat[:, 1:] & flat[:, :-1]
    a, b = d[:, 1:][pairs], d[:, :-1][pairs]
    if a.size < 50:
        return NoiseModel()
    rho = float(np.clip(np.mean(a * b) / max(np.sqrt(np.mean(a * a) * np.mean(b * b)), 1e-12), 0.0, 0.95))
    lv, d2 = level[flat], 0.5 * d[flat] ** 2
    # Robust straight line through the binned medians (d² is chi-square: median/0.455 = mean).
    edges = np.quantile(lv, np.linspace(0, 1, 9))
    xs, ys = [], []
    for lo, hi in itertools.pairwise(edges):
        sel = (lv >= lo) & (lv <= hi)
        if sel.sum() >= 20:
            xs.append(float(np.median(lv[sel])))
            ys.append(float(np.median(d2[sel])) / 0.4549)
    if not ys:
        return NoiseModel(rho=rho)
    if float(np.mean(ys)) < 0.1:
        # Below the 8-bit quantisation (1/12 gray level²): a noise-free (e.g. synthetic) image,
        # whose row differences are scene structure, not noise.
        return NoiseModel(rho=0.0, variance_at_zero=0.1, variance_slope=0.0, variance_floor=0.1)
    if len(xs) >= 2 and np.ptp(xs) > 1e-6:
        slope = max(float(np.polyfit(xs, ys, 1)[0]), 0.0)
    else:
        slope = 0.0
    intercept = float(np.mean(ys) - slope * np.mean(xs))
    floor = max(0.25 * float(np.min(ys)), 1e-6)
    return NoiseModel(rho=rho, variance_at_zero=intercept, variance_slope=slope, variance_floor=floor)


def noise_variance(image, *, row_step: int = NOISE_ROW_STEP) -> float:
    """The pixel noise variance of ``image``, one number, robustly: a quick check of the dose.

    As in :func:`estimate_noise`, vertical neighbours' differences ``d = I(x, y) − I(x, y + 1)``
    cancel the scene wherever it varies slowly, and each row pair's median cancels the per-line
    offsets; their median absolute value (× 1.4826, squared, halved: ``d`` holds two pixels' noise)
    is the variance, which edges and particles, a few % of the pixels, do not move. Unlike
    :func:`estimate_noise` it neither splits the variance by gray level nor separates the line
    correlation, and reads only every ``row_step``-th row pair.

    Parameters
    ----------
    image : (M, N) array_like
        At least 2 rows.
    row_step : int
        Row pairs ``(0, 1), (row_step, row_step + 1), ...`` are read.

    Returns
    -------
    float
        Gray levels², 0 for a noise-free flat image.
    """
    img = np.asarray(image, np.float32)
    if img.ndim != 2 or img.shape[0] < 2:
        raise ValueError(f"need a 2-D image of at least 2 rows to measure the noise, got {img.shape}")
    d = _row_pair_differences(img, row_step)
    spread = MAD_TO_SD * float(np.median(np.abs(d)))
    return 0.5 * spread * spread


def whiten_lines(image, rho: float) -> np.ndarray:
    """Undo the scan line's AR(1) correlation: ``w(x) = I(x) − ρ·I(x − 1)`` along every row.

    A translation commutes with this filter, so registering whitened images registers the
    images, with the noise made white (the weighting the Cramér–Rao bound assumes). The first
    column keeps ``(1 − ρ)·I`` so that a constant stays a constant.
    """
    img = np.asarray(image, np.float32)
    if rho == 0:
        return img.copy()
    out = np.empty_like(img)
    np.multiply(img[:, :-1], np.float32(-rho), out=out[:, 1:])
    out[:, 1:] += img[:, 1:]
    out[:, 0] = (1.0 - rho) * img[:, 0]
    return out


def _median(x) -> float:
    """``np.median`` of a 1-D array without its overhead (the same value)."""
    n = x.size
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, [k - 1, k])
    return 0.5 * (float(part[k - 1]) + float(part[k]))


def median(x) -> float:
    """``float(np.median(x))`` of a 1-D float64 array, the same value without numpy's overhead (a few µs
    where the per-frame checks take many); numpy's own when ``x`` holds NaN or inf (NaN propagates)."""
    x = np.asarray(x, np.float64)
    if x.size == 0 or not math.isfinite(float(np.add.reduce(x))):
        return float(np.median(x))
    return _median(x)


def weighted_ncc(a, b, weights=None) -> float:
    """Weighted normalised cross-correlation of two sample vectors, in [-1, 1] (0 if flat)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    w = np.ones_like(a) if weights is None else np.asarray(weights, np.float64)
    sw = w.sum()
    if not sw > 0:
        return 0.0
    w = w / sw
    da, db = a - w @ a, b - w @ b
    den = np.sqrt((w @ (da * da)) * (w @ (db * db)))
    return float((w @ (da * db)) / den) if den > 0 and np.isfinite(den) else 0.0


#: What moved to :mod:`semlab.gauss_newton`, still importable from here.
_MOVED = ("GaussNewtonResult", "gauss_newton_setup", "gauss_newton_translation")


def __getattr__(name: str):
    """The Gauss–Newton registration's names, from :mod:`semlab.gauss_newton` (imported when first asked:
    it builds on this module)."""
    if name in _MOVED:
        import importlib

        return getattr(importlib.import_module("semlab.gauss_newton"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
