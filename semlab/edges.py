"""Canny edges with adaptive thresholds (Ru et al. 2012, eq. 10, after Zhi et al. 2005).

The paper turns every new frame into a contour image with a Canny detector whose two thresholds
come from the histogram of the gradient magnitude, so that gray-level fluctuation does not make a
fixed threshold miss edges or flood the image with weak ones (the paper's Fig. 3).
"""

from __future__ import annotations

import cv2
import numpy as np

from .template import to_uint8

__all__ = ["adaptive_canny_thresholds", "canny_edges", "image_gradients"]


def image_gradients(image, *, sigma: float = 1.0):
    """Sobel gradients of the Gaussian-smoothed image, as Canny sees them.

    Returns
    -------
    dx, dy : (M, N) ndarray of int16
    magnitude : (M, N) ndarray of float32
        ``sqrt(dx² + dy²)`` (Canny's L2 gradient).
    """
    gray = to_uint8(image)
    smoothed = cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else gray
    dx = cv2.Sobel(smoothed, cv2.CV_16S, 1, 0, ksize=3)
    dy = cv2.Sobel(smoothed, cv2.CV_16S, 0, 1, ksize=3)
    magnitude = cv2.magnitude(dx.astype(np.float32), dy.astype(np.float32))
    return dx, dy, magnitude


def adaptive_canny_thresholds(image, *, sigma: float = 1.0, bins: int = 256) -> tuple[float, float]:
    """Canny's low and high thresholds from the gradient histogram (paper, eq. 10).

    The paper: the histogram ``H(i)`` of the gradient magnitude is computed and its maximum
    ``H_max`` located; ``σ₁ = sqrt(Σ [H(i) − H_max]² / N)`` (eq. 10); ``T_h = H_max + σ₁``;
    ``σ₁′`` is recomputed without the pixels whose gradient exceeds ``T_h``; ``T_l = H_max + σ₁′``.

    Because ``T_h`` and ``T_l`` are gradient values, ``H_max`` is read as the gradient magnitude
    at the histogram's peak (the most frequent gradient, i.e. the noise level of flat regions),
    and ``σ₁`` as the root-mean-square deviation of the ``N`` pixels' gradients from it — the
    sum over histogram bins weighted by their counts, which is what eq. 10 denotes when ``H(i)``
    stands for the gradient of pixel ``i``.

    Parameters
    ----------
    image : (M, N) array_like
    sigma : float
        Gaussian smoothing before the Sobel gradients, px.
    bins : int
        Histogram bins between 0 and the largest gradient.

    Returns
    -------
    (T_l, T_h) : tuple of float
        In the units of OpenCV's L2 Sobel magnitude, ready for :func:`canny_edges`.
    """
    _, _, magnitude = image_gradients(image, sigma=sigma)
    g = magnitude.ravel()
    top = float(g.max())
    if top <= 0:
        return 0.0, 0.0
    counts, edges = np.histogram(g, bins=bins, range=(0.0, top))
    centres = 0.5 * (edges[:-1] + edges[1:])
    h_max = float(centres[np.argmax(counts)])
    sigma1 = float(np.sqrt(np.mean((g - h_max) ** 2)))
    t_high = h_max + sigma1
    below = g[g <= t_high]
    sigma1_low = float(np.sqrt(np.mean((below - h_max) ** 2))) if below.size else 0.0
    t_low = h_max + sigma1_low
    return t_low, t_high


def canny_edges(image, *, low: float | None = None, high: float | None = None, sigma: float = 1.0) -> np.ndarray:
    """Canny edge map; thresholds adaptive (eq. 10) unless both are given.

    Parameters
    ----------
    image : (M, N) array_like
    low, high : float or None
        Fixed hysteresis thresholds (L2 Sobel magnitude units). ``None`` for both: adaptive.
    sigma : float
        Gaussian smoothing before the gradients, px.

    Returns
    -------
    (M, N) ndarray of bool
    """
    if (low is None) != (high is None):
        raise ValueError("give both low and high thresholds, or neither for adaptive ones")
    if low is None:
        low, high = adaptive_canny_thresholds(image, sigma=sigma)
    if not (np.isfinite(low) and np.isfinite(high)) or low < 0 or high < low:
        raise ValueError(f"Canny thresholds need 0 <= low <= high, got low={low}, high={high}")
    dx, dy, _ = image_gradients(image, sigma=sigma)
    return cv2.Canny(dx, dy, float(low), float(high), L2gradient=True) > 0
