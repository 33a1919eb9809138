"""Template matching inside a search window (Ru et al. 2012, eqs. 2-5 and "The Template Matching
Based Contour Model").

- :func:`ssd_match`: the conventional full-template SSD (eq. 2) at integer positions, the paper's
  baseline, whose template includes background and clutter (Fig. 1b).
- :func:`contour_match`: the paper's contour-template match — the score counts the edge pixels of
  the new frame that fall on the contour template's pixels (Fig. 1c).
- :func:`offline_matrix` and :func:`hager_belhumeur_increment`: the parametric SSD increment
  ``Δμ = −(M₀ᵀM₀)⁻¹M₀ᵀ[I(f(R; μ), tₙ) − I(R, t₀)]`` with the constant matrix ``M₀`` of the
  template's gradients (eqs. 3-5; Hager & Belhumeur 1998).
"""

from __future__ import annotations

import cv2
import numpy as np

from .subpixel import five_point_gradients

__all__ = ["contour_match", "hager_belhumeur_increment", "hager_belhumeur_solver", "hager_belhumeur_step", "offline_matrix",
           "parabola_peak", "ssd_match"]


def parabola_peak(scores: np.ndarray, ix: int, iy: int) -> tuple[float, float]:
    """Sub-pixel peak of a score map by a 3-point parabola along x and along y."""
    def vertex(a, b, c):
        den = a - 2 * b + c
        return 0.0 if den == 0 else float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))

    h, w = scores.shape
    dx = vertex(scores[iy, ix - 1], scores[iy, ix], scores[iy, ix + 1]) if 0 < ix < w - 1 else 0.0
    dy = vertex(scores[iy - 1, ix], scores[iy, ix], scores[iy + 1, ix]) if 0 < iy < h - 1 else 0.0
    return ix + dx, iy + dy


def _check_sizes(window, template):
    if template.shape[0] > window.shape[0] or template.shape[1] > window.shape[1]:
        raise ValueError(f"template {template.shape} is larger than the search window {window.shape}")


def ssd_match(window, template) -> tuple[int, int, float]:
    """Integer position of the template in the window by the sum of squared differences (eq. 2).

    Returns
    -------
    (x, y, ssd) : the top-left offset of the best match in the window and its mean squared difference.
    """
    w = np.asarray(window, np.float32)
    t = np.asarray(template, np.float32)
    _check_sizes(w, t)
    scores = cv2.matchTemplate(w, t, cv2.TM_SQDIFF)
    _, _, (x, y), _ = cv2.minMaxLoc(scores)
    return int(x), int(y), float(scores[y, x]) / t.size


def contour_match(edges, contour_mask, *, tolerance_px: int = 0, prefer=None) -> tuple[int, int, float, np.ndarray]:
    """Match a contour template against an edge map (the paper's contour-template match).

    For every placement of the template in the window, the score is the fraction of the
    template's contour pixels that land on an edge pixel of the window (edges dilated by
    ``tolerance_px`` so that a one-pixel wobble of Canny's edge still counts).

    Parameters
    ----------
    edges : (H, W) array_like of bool
        Edge map of the search window (e.g. :func:`semlab.edges.canny_edges`).
    contour_mask : (h, w) array_like of bool
        The contour template (:attr:`semlab.template.ContourTemplate.mask`).
    tolerance_px : int
        0 is the paper's score: the edge image's pixels under the contour pixels are added.
    prefer : (float, float), optional
        Top-left offset to prefer among equal best scores (e.g. the last position); default:
        the first in raster order.

    Returns
    -------
    (x, y, score, scores) : best top-left offset, its score in [0, 1] and the score map.
    """
    e = np.asarray(edges, np.uint8)
    m = np.asarray(contour_mask, np.float32)
    _check_sizes(e, m)
    n = float(m.sum())
    if n == 0:
        raise ValueError("the contour template has no pixels")
    if tolerance_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * tolerance_px + 1, 2 * tolerance_px + 1))
        e = cv2.dilate(e, k)
    scores = cv2.matchTemplate(e.astype(np.float32), m, cv2.TM_CCORR) / n
    _, best, _, (x, y) = cv2.minMaxLoc(scores)
    if prefer is not None:
        # Counts tie often (a straight edge matches equally well along itself).
        ys, xs = np.nonzero(scores >= best - 0.5 / n)
        k = int(np.argmin((xs - prefer[0]) ** 2 + (ys - prefer[1]) ** 2))
        x, y = int(xs[k]), int(ys[k])
    return int(x), int(y), float(best), scores


def offline_matrix(template, mask=None) -> np.ndarray:
    """``M₀ = [I_x(x, t₀) | I_y(x, t₀)]`` over the template pixels R (eqs. 4-5), 5-point derivatives."""
    ix, iy = five_point_gradients(template)
    use = np.ones(ix.shape, bool) if mask is None else np.asarray(mask, bool)
    return np.stack([ix[use], iy[use]], axis=1).astype(np.float64)


def hager_belhumeur_solver(m0) -> np.ndarray:
    """``(M₀ᵀM₀)⁻¹M₀ᵀ``: the constant matrix of the increment (eq. 5), computed once per template.

    Parameters
    ----------
    m0 : (K, 2) ndarray
        :func:`offline_matrix`.

    Returns
    -------
    (2, K) ndarray
    """
    m0 = np.asarray(m0, np.float64)
    return np.linalg.inv(m0.T @ m0) @ m0.T


def hager_belhumeur_step(solver, warped, template) -> np.ndarray:
    """``Δμ = −(M₀ᵀM₀)⁻¹M₀ᵀ[I(f(R; μ), tₙ) − I(R, t₀)]`` from :func:`hager_belhumeur_solver` and the
    pixels R of the warped frame and of the template, as (K,) vectors (eqs. 3-5)."""
    return -solver @ (np.asarray(warped, np.float64) - np.asarray(template, np.float64))


def hager_belhumeur_increment(template, warped, m0=None, mask=None) -> np.ndarray:
    """The parametric SSD increment ``Δμ = −(M₀ᵀM₀)⁻¹ M₀ᵀ [I(f(R; μ), tₙ) − I(R, t₀)]`` (eqs. 2-5).

    Parameters
    ----------
    template : (h, w) array_like
        ``I(R, t₀)``.
    warped : (h, w) array_like
        ``I(f(R; μ), tₙ)``: the new frame sampled at the current estimate.
    m0 : (K, 2) ndarray, optional
        Precomputed :func:`offline_matrix` (same mask).
    mask : (h, w) array_like of bool, optional
        The pixels R.

    Returns
    -------
    (2,) ndarray
        ``Δμ = (Δu, Δv)``; the new estimate is ``μ + Δμ``. Linearising
        ``I(f(x; μ + Δμ), tₙ) ≈ I(f(x; μ), tₙ) + M₀ Δμ`` with the template's gradients standing in
        for the image's is what makes ``M₀`` constant, computed once offline: a tracker keeps
        :func:`hager_belhumeur_solver` and calls :func:`hager_belhumeur_step` per iteration.
    """
    t = np.asarray(template, np.float64)
    i = np.asarray(warped, np.float64)
    if t.shape != i.shape:
        raise ValueError(f"template {t.shape} and warped image {i.shape} differ in shape")
    use = np.ones(t.shape, bool) if mask is None else np.asarray(mask, bool)
    if m0 is None:
        m0 = offline_matrix(t, use)
    return hager_belhumeur_step(hager_belhumeur_solver(m0), i[use], t[use])
