"""The paper's methods and the conventional baseline: ``"contour"``, ``"ssd"`` and ``"hb"``.

``"contour"`` (Ru et al. 2012)
    In the window around the last position, Gaussian smoothing and adaptive-threshold Canny
    (eq. 10), the contour-template match (score from the template's contour pixels only), then one
    step of the gradient sub-pixel method (eq. 9) on the contour band.
``"ssd"``
    The conventional baseline the paper improves on: full-template SSD (eq. 2) at integer
    positions (``subpixel=True`` adds one step of eq. 9 on the whole template).
``"hb"``
    The paper's parametric SSD tracker (eqs. 2-5, Hager & Belhumeur 1998): integer SSD, then the
    increment ``Δμ = −(M₀ᵀM₀)⁻¹M₀ᵀ[I(f(R; μ), tₙ) − I(R, t₀)]`` with the offline matrix ``M₀``
    iterated to convergence on the whole template.

Each searches the window around the last position (the whole image after a loss) and has no
prediction to follow and no re-acquisition.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..edges import canny_edges
from ..matching import (
    contour_match,
    hager_belhumeur_solver,
    hager_belhumeur_step,
    offline_matrix,
    ssd_match,
)
from ..subpixel import (
    five_point_gradients,
    gradient_subpixel_shift,
    sample_shifted_filtered,
    weighted_ncc,
)
from ..template import to_uint8
from .band import contour_core, inner_mask
from .frames import crop
from .method import Method, Setup, Verdict
from .search import search_window
from .uncertainty import INTEGER_VARIANCE_PX2, Uncertainty, least_squares_covariance, position_sigma

__all__ = ["ContourMethod", "HBMethod", "IntegerMatch", "SSDMethod"]

#: One linearised step of eq. 9 is only trusted within this many px.
MAX_EQ9_STEP_PX = 1.0
#: ``"hb"``: ``M₀`` from the template smoothed by this many px (with the raw one, its noise inflates
#: ``M₀ᵀM₀`` and every increment falls short: eq. 5 then needs dozens of iterations), over the
#: template but a 3-px border (the 5-point derivative's reach and a margin).
HB_TEMPLATE_SIGMA = 1.0
HB_BORDER_PX = 3
#: ``"hb"`` has converged when the increment is below this (px), and gives up beyond this move (px).
HB_TOLERANCE_PX = 2e-3
HB_MAX_MOVE_PX = 3


@dataclass(frozen=True)
class IntegerMatch:
    """The integer top-left of the template's best match in the frame, and its score."""

    left: int
    top: int
    score: float


#: Eq. 9 sums over the template less this border (the 5-point mask's reach).
EQ9_BORDER_PX = 2


class _IntegerMethod(Method):
    """An integer match, optionally refined by one step of the paper's eq. 9."""

    refine_mask = None

    def verdict(self, arr, match: IntegerMatch, predicted) -> Verdict:
        min_score = self.options.loss.min_score
        if match.score < min_score:
            return Verdict.lose(f"no match (score {match.score:.2f} < {min_score:.2f})")
        x0, y0, w, h = self.roi
        dx = dy = 0.0
        patch = crop(arr, match.left, match.top, match.left + w, match.top + h)
        if self.options.contour.subpixel:
            dx, dy = gradient_subpixel_shift(self.template, patch, mask=self.refine_mask)
            if not (np.isfinite(dx) and np.isfinite(dy)):
                dx = dy = 0.0
            dx, dy = (float(np.clip(dx, -MAX_EQ9_STEP_PX, MAX_EQ9_STEP_PX)),
                      float(np.clip(dy, -MAX_EQ9_STEP_PX, MAX_EQ9_STEP_PX)))
        return Verdict.accept((match.left - x0 + dx, match.top - y0 + dy), match.score,
                              found=self._step_covariance(patch, dx, dy))

    def _step_covariance(self, patch, dx: float, dy: float) -> np.ndarray:
        """The eq. 9 step's covariance from its own least squares (plus the rounding of an integer
        match that no step refined)."""
        gx, gy = five_point_gradients(patch)
        use = inner_mask(patch.shape, EQ9_BORDER_PX)
        if self.refine_mask is not None:
            use &= np.asarray(self.refine_mask, bool)
        jac = np.stack([gx[use], gy[use]], axis=1).astype(np.float64)
        residual = (self.template - patch)[use].astype(np.float64) - jac @ np.array([dx, dy])
        cov = least_squares_covariance(jac, residual)
        if not self.options.contour.subpixel:
            cov = cov + INTEGER_VARIANCE_PX2 * np.eye(2)
        return cov

    def sigma(self, verdict: Verdict) -> Uncertainty | None:
        if verdict.found is None:
            return None
        sigma = position_sigma(verdict.found)
        return Uncertainty(sigma, sigma)


class ContourMethod(_IntegerMethod):
    """The paper's contour-template match and eq. 9 on the contour band."""

    name = "contour"

    def start(self, setup: Setup) -> None:
        super().start(setup)
        self.core = contour_core(self.contour)
        self.refine_mask = self.band
        self.edge_offset = (0, 0)
        # The contour (an Otsu boundary) and the Canny edges it is matched against need not
        # coincide: the integer match in frame 0 itself is the reference that later integer
        # matches are compared with, so that such an offset cancels in the displacement; eq. 9
        # then refines from the corrected integer position.
        zero = np.zeros(2)
        window = search_window(self.roi, self.options.search.search_size, zero, setup.image.shape)
        left, top, _ = self._integer(setup.image, window, zero)
        self.edge_offset = (left - self.roi[0], top - self.roi[1])

    def _integer(self, arr, window, shift):
        """Integer top-left of the contour template's best match (paper: adaptive Canny, eq. 10,
        then the score from the contour pixels only), and its score."""
        wx, wy, ww, wh = window
        image = crop(arr, wx, wy, wx + ww, wy + wh)
        if float(image.max() - image.min()) <= 0:
            raise ValueError("constant search window")
        edges = canny_edges(to_uint8(image), **self.options.contour.canny_kwargs())
        x0, y0 = self.roi[:2]
        prefer = (x0 + self.edge_offset[0] + shift[0] - wx, y0 + self.edge_offset[1] + shift[1] - wy)
        ix, iy, score, _ = contour_match(edges, self.core, tolerance_px=self.options.contour.contour_tolerance,
                                         prefer=prefer)
        return wx + ix, wy + iy, score

    def search(self, arr, window, predicted, found) -> IntegerMatch:
        left, top, score = self._integer(arr, window, predicted)
        return IntegerMatch(left - self.edge_offset[0], top - self.edge_offset[1], score)


class SSDMethod(_IntegerMethod):
    """The conventional full-template SSD at integer positions."""

    name = "ssd"

    def search(self, arr, window, predicted, found) -> IntegerMatch:
        wx, wy, ww, wh = window
        image = crop(arr, wx, wy, wx + ww, wy + wh)
        ix, iy, _ = ssd_match(image, self.template)
        _x0, _y0, w, h = self.roi
        patch = image[iy:iy + h, ix:ix + w]
        return IntegerMatch(wx + ix, wy + iy, weighted_ncc(patch.ravel(), self.template.ravel()))


@dataclass(frozen=True)
class HBFit:
    """``"hb"``'s answer: the shift, the normalised correlation at it, and whether eq. 5 converged."""

    shift: np.ndarray
    score: float
    converged: bool
    covariance: np.ndarray | None = None


class HBMethod(Method):
    """Integer SSD, then the Hager–Belhumeur increment (eq. 5) iterated on the whole template."""

    name = "hb"

    def start(self, setup: Setup) -> None:
        super().start(setup)
        h, w = self.template.shape
        inner = inner_mask((h, w), HB_BORDER_PX)
        self.m0 = offline_matrix(cv2.GaussianBlur(self.template, (0, 0), HB_TEMPLATE_SIGMA), inner)
        self.solver = hager_belhumeur_solver(self.m0)  # (M₀ᵀM₀)⁻¹M₀ᵀ: offline, once per template
        yy, xx = np.nonzero(inner)
        self.points = np.stack([xx, yy], axis=1).astype(np.float64)
        self.values = self.template[yy, xx].astype(np.float64)

    def search(self, arr, window, predicted, found) -> HBFit:
        wx, wy, ww, wh = window
        image = crop(arr, wx, wy, wx + ww, wy + wh)
        ix, iy, _ = ssd_match(image, self.template)
        x0, y0, _w, _h = self.roi
        start = np.array([wx + ix - x0, wy + iy - y0], float)
        p = start.copy()
        pts = self.points + (x0 - wx, y0 - wy)
        converged = False
        warped = self.values
        for _ in range(self.options.stages.max_iterations):
            warped = sample_shifted_filtered(image, pts, p)  # I(f(R; μ), tₙ), eq. 3
            # Eq. 5: I(f(R; μ + Δμ), tₙ) ≈ I(f(R; μ), tₙ) + M₀Δμ, with the template's gradients
            # standing in for the image's, so that M₀ is constant; μ ← μ + Δμ.
            delta = hager_belhumeur_step(self.solver, warped, self.values)
            p += delta
            if float(np.hypot(*delta)) < HB_TOLERANCE_PX:
                converged = True
                break
            if np.max(np.abs(p - start)) > HB_MAX_MOVE_PX:
                break
        residual = warped - self.values
        return HBFit(p, weighted_ncc(warped, self.values), converged, least_squares_covariance(self.m0, residual))

    def verdict(self, arr, fit: HBFit, predicted) -> Verdict:
        if not fit.converged:
            return Verdict.lose(f"no convergence (score {fit.score:.2f})")
        min_score = self.options.loss.min_score
        if fit.score < min_score:
            return Verdict.lose(f"no match (score {fit.score:.2f} < {min_score:.2f})")
        return Verdict.accept(fit.shift, fit.score, found=fit.covariance)

    def sigma(self, verdict: Verdict) -> Uncertainty | None:
        if verdict.found is None:
            return None
        sigma = position_sigma(verdict.found)
        return Uncertainty(sigma, sigma)
