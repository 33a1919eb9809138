"""Sub-pixel registration by inverse-compositional Gauss–Newton (:func:`gauss_newton_translation`).

Beyond the paper's one-step refinement (eq. 9, :func:`semlab.subpixel.gradient_subpixel_shift`): on a set of
template pixels (the contour band), Keys bicubic interpolation (:func:`semlab.subpixel.keys_shift_filter`), a
gain/offset model against gray-level fluctuation (joint, or two region levels as Hager & Belhumeur's
illumination basis, eqs. 2-5), Huber weights against occlusion and clutter, on line-whitened images weighted
by the shot-noise variance (:func:`semlab.subpixel.whiten_lines`). :func:`gauss_newton_setup` is what the
template alone fixes, computed once; :class:`_GaussNewton` one fit's iteration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .subpixel import MAD_TO_SD, _median, keys_shift_filter, sample_shifted_filtered

__all__ = ["GaussNewtonResult", "gauss_newton_setup", "gauss_newton_translation"]

#: Tukey's biweight constant in robust spreads (95 % efficient for Gaussian noise), and the step
#: (px) below which ``tukey=True`` switches to it.
TUKEY_C = 4.685
TUKEY_FROM_STEP_PX = 0.05
#: A step that reverses more than this fraction of a previous one longer than 0.1 px (squared:
#: 0.01) halves the steps from then on, down to an eighth.
OVERSHOOT_REVERSAL = 0.25
OVERSHOOT_MIN_STEP_SQ = 0.01
MIN_DAMPING = 0.125
#: ``early_stop``: the steps must shrink by at least this factor for the extrapolation to hold.
EARLY_STOP_RATIO = 0.6
#: A gain below this is no image of the template: the iteration stops.
MIN_GAIN = 1e-6
#: The Keys stencil reads this many px before a pixel, and spans this many along each axis.
KEYS_BEFORE = 1
KEYS_STENCIL = 4


@dataclass
class GaussNewtonResult:
    """Outcome of :func:`gauss_newton_translation`.

    Attributes
    ----------
    shift : (2,) ndarray
        Translation ``(dx, dy)`` that maps template coordinates into the image.
    gain, offset : float
        Photometric parameters: ``image ≈ gain · template + offset``.
    weights : (K,) ndarray
        Final robust (Huber) weights, 1 for inliers.
    inliers : float
        Fraction of pixels with full Huber weight.
    iterations : int
    converged : bool
    samples : (K,) ndarray
        The image at the position before the last (sub-tolerance) step.
    normal_matrix : ndarray or None
        The normal matrix of the last step: 2×2 (the translation's), or 4×4 with joint photometry
        (translation, gain, offset); the Fisher information of the shift up to the noise scale.
        None when no step was computed.
    weighted_ssr : float
        ``Σ prior·weights·r²`` of the last residuals ``r`` (those of ``samples``).
    n_pixels : int
        Template pixels in the fit.
    weight_total : float
        ``Σ weights``: the robust weights' total (``n_pixels`` when every pixel is an inlier).
    robust_ssr : float
        ``Σ prior·weights²·residual²``: the squared influence ``ψ(r)²`` of the residuals, which an
        outlier bounds (Huber's M-estimator variance; ``weighted_ssr`` grows with its residual).
    information : ndarray or None
        The normal matrix the shift's covariance takes: as ``normal_matrix``, but with two-level
        photometry always with the levels eliminated (the step switches to the plain one once it
        is small).
    residual : (K,) ndarray or None
        The last residuals ``I(x + p) − g·T − o`` (each background sector's level removed), those
        of ``samples``; None when no step was computed.
    """

    shift: np.ndarray
    gain: float
    offset: float
    weights: np.ndarray
    inliers: float
    iterations: int
    converged: bool
    samples: np.ndarray
    normal_matrix: np.ndarray | None = None
    weighted_ssr: float = float("nan")
    n_pixels: int = 0
    weight_total: float = float("nan")
    robust_ssr: float = float("nan")
    information: np.ndarray | None = None
    residual: np.ndarray | None = None


def _remap_points(image, xs, ys):
    out = cv2.remap(image, xs.reshape(1, -1), ys.reshape(1, -1), cv2.INTER_CUBIC,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1).astype(np.float64)


def _absorb(grad, inside, ind_in, ind_out):
    """What is left of a derivative once the two region levels have followed it."""
    mean_in, mean_out = float(grad @ ind_in), float(grad @ ind_out)
    return grad - inside * (mean_in - mean_out) - mean_out


def _sector_bins(sectors, setup: dict | None) -> tuple[np.ndarray, int]:
    """``(bins, n)``: the sectors' labels with -1 (no level of its own) moved to the extra bin ``n``, and
    ``n``, the number of sectors. Kept in ``setup`` (the template's constants) for the same ``sectors``
    array: a tracker passes the same one at every call."""
    cached = None if setup is None else setup.get("sector_bins")
    if cached is not None and cached[0] is sectors:
        return cached[1], cached[2]
    sec = np.asarray(sectors, np.intp)
    n_sec = int(sec.max()) + 1
    bins = np.where(sec < 0, n_sec, sec)  # no local level: the extra bin, whose level stays 0
    if setup is not None:
        setup["sector_bins"] = (sectors, bins, n_sec)
    return bins, n_sec


def gauss_newton_setup(values, gx, gy, *, weights=None, regions=None, photometric: bool = True,
                       like: dict | None = None) -> dict:
    """What :func:`gauss_newton_translation` derives from the template alone, computed once.

    A tracker registers every frame against the same template pixels: passing this as
    ``setup=`` saves rebuilding the same products at every call.

    Parameters
    ----------
    values, gx, gy, weights, regions, photometric
        As in :func:`gauss_newton_translation`, and the same arrays as given to it.
    like : dict, optional
        A setup of the same ``values, gx, gy, regions`` arrays (the same objects) with other weights:
        what does not depend on the weights is taken from it rather than computed again.

    Returns
    -------
    dict
        The template's values, gradients and weights as float64, and the products that the
        normal equations of the 2×2 (translation) and region-level steps are made of.

    Raises
    ------
    ValueError
        ``regions`` (with ``photometric``) marks only object or only background pixels, or the
        template has no contrast between them.
    """
    t = np.asarray(values, np.float64)
    tx, ty = np.asarray(gx, np.float64), np.asarray(gy, np.float64)
    prior = np.ones_like(t) if weights is None else np.asarray(weights, np.float64)
    out = {"t": t, "tx": tx, "ty": ty, "prior": prior, "sqrt_prior": np.sqrt(prior)}
    joint = photometric and regions is None
    two_level = photometric and regions is not None
    key = (photometric, regions is None)
    if two_level:
        inside = np.asarray(regions, bool)
        same = like is not None and like["key"] == key and all(like.get(k) is v for k, v in (
            ("t", t), ("tx", tx), ("ty", ty), ("inside", inside)))
        out.update({k: like[k] for k in _REGION_CONSTANTS} if same else _region_constants(t, tx, ty, inside))
        if same and "sector_bins" in like:
            out["sector_bins"] = like["sector_bins"]  # (:func:`_sector_bins`: kept with its sectors array)
    if not joint:
        # Everything but the robust weights is fixed during the iteration, so the 2×2 normal
        # matrix is g²·Σ robust·(prior·J·E) with E the plain or the level-absorbed gradient
        # (_absorb is linear: absorbing g·T_x is g times absorbing T_x), and the right-hand
        # side g·Σ (robust·residual)·(prior·J): one matrix-vector product each.
        ptx, pty = prior * tx, prior * ty
        out["plain_hess"] = np.stack([ptx * tx, ptx * ty, pty * tx, pty * ty], axis=1)
        if two_level:
            ax, ay = out["absorbed"]
            out["absorbed_hess"] = np.stack([ptx * ax, ptx * ay, pty * ax, pty * ay], axis=1)
        out["rhs_basis"] = np.stack([ptx, pty], axis=1)
    out["key"] = key
    return out


#: The entries of :func:`gauss_newton_setup` that two-level photometry adds and the weights do not change.
_REGION_CONSTANTS = ("inside", "ind_in", "ind_out", "levels", "regions2", "absorbed")


def _region_constants(t, tx, ty, inside) -> dict:
    """The two-level photometry's constants of :func:`gauss_newton_setup` (:data:`_REGION_CONSTANTS`).

    Raises
    ------
    ValueError
        ``inside`` marks only object or only background pixels, or the template has no contrast
        between them.
    """
    n_in = int(inside.sum())
    if n_in == 0 or n_in == len(inside):
        raise ValueError("regions must mark both object and background pixels")
    ind_in = inside / n_in
    ind_out = ~inside / (len(inside) - n_in)
    if float(t @ ind_in) == float(t @ ind_out):
        raise ValueError("the template has no contrast between object and background")
    outside = (~inside).astype(np.float64)
    inside_f = inside.astype(np.float64)
    # Σ r·[inside·t, outside·t, inside, outside] for robust weights r: the weighted region
    # means of the template in one product.
    return {"inside": inside, "ind_in": ind_in, "ind_out": ind_out,
            "levels": np.stack([inside_f * t, outside * t, inside_f, outside], axis=1),
            "regions2": np.stack([inside_f, outside], axis=1),
            # The gradients less what the two levels absorb of them.
            "absorbed": (_absorb(tx, inside, ind_in, ind_out), _absorb(ty, inside, ind_in, ind_out))}


def gauss_newton_translation(image, points, values, gx, gy, shift0, *, weights=None, gain0=1.0,
                             offset0=0.0, max_iterations: int = 20, tolerance: float = 2e-3,
                             huber: float | None = 2.0, photometric: bool = True, regions=None,
                             exact: bool = True, curvature=None, tukey: bool = False,
                             template_variance=None, instrument=None, freeze: float = 0.01,
                             max_move: float = np.inf, setup: dict | None = None,
                             early_stop: bool = False, sectors=None) -> GaussNewtonResult:
    """Inverse-compositional Gauss–Newton for a translation with gain/offset (beyond eq. 9).

    Minimises ``Σ wᵢ ρ(I(xᵢ + p) − g·T(xᵢ) − o)`` over the template pixels ``xᵢ`` (eq. 2 with a
    gain and an offset), linearising the template, not the image (Hager & Belhumeur 1998; Baker &
    Matthews 2004): the steepest-descent images ``[g·T_x, g·T_y, T, 1]`` use the template's
    gradients — the paper's offline matrix ``M₀`` (eqs. 4-5) extended by two photometric columns.
    ``ρ`` is Huber's loss on residuals scaled by their robust spread, so occluded or cluttered
    pixels drop out; ``wᵢ`` are inverse noise variances.

    Parameters
    ----------
    image : (M, N) ndarray of float32
    points : (K, 2) ndarray
        Template pixel coordinates ``(x, y)`` in ``image`` at zero shift (integers for
        ``exact=True``).
    values, gx, gy : (K,) ndarray
        Template gray levels and their derivatives at those pixels.
    shift0 : (2,) array_like
        Starting translation.
    weights : (K,) ndarray, optional
        Inverse noise variances (default: equal).
    gain0, offset0 : float
        Starting photometric parameters.
    max_iterations : int
    tolerance : float
        Stop when the translation update is below this many px.
    huber : float or None
        Huber threshold in robust standard deviations (the spread is the MAD of the first
        iteration's residuals); ``None`` for plain least squares.
    template_variance : (K,) ndarray, optional
        Noise variance of ``values``. With ``photometric`` (joint regression), the gain's
        normal equation is corrected for it (errors in variables: a noisy template's own noise
        otherwise drags the gain towards 0), ``Σ w T² → Σ w (T² − σ_T²)`` and
        ``Σ w T r → Σ w (T r + g σ_T²)``.
    instrument : (K,) ndarray, optional
        With ``photometric`` (joint regression): a denoised version of ``values`` (e.g. the
        smoothed template) used as the instrument of the gain's normal equation,
        ``Σ w T̃ r = 0`` with ``T̃`` in place of ``T`` (instrumental variables): the template's
        noise then neither biases the gain (errors in variables) nor leaks into the translation.
    freeze : float
        Step (px) below which the ``regions`` gain and offset stop following the image.
    tukey : bool
        Once the steps are below 0.05 px, switch from Huber's weights to Tukey's biweight
        (c = 4.685 spreads), which gives grossly wrong pixels (an occluder) no influence at all
        where Huber's only bounds it.
    photometric : bool
        Estimate gain and offset (True) or hold them at ``gain0``, ``offset0``.
    regions : (K,) array_like of bool, optional
        With ``photometric``: take gain and offset from the mean levels of the object pixels
        (True) and the background pixels (False), weighted by the robust weights, while the
        steps exceed ``freeze`` px, instead of
        regressing the image on the template. Means over hundreds of pixels are unbiased even
        when the template is noisy, whereas the regression's gain shrinks towards 0 when the
        template's noise is comparable with its contrast (errors in variables; low dose).
    exact : bool
        Interpolate with exact Keys cubic weights (a = −0.5, :func:`sample_shifted_filtered`)
        instead of OpenCV's bicubic ``remap`` (a = −0.75, positions rounded to 1/32 px:
        faster, but the rounding leaves the iteration cycling between neighbouring cells and a
        0.01-px floor, and its different kernel biases sharp edges by a few hundredths of a px).
    curvature : (ndarray, ndarray), optional
        Gradients ``(I_x, I_y)`` of ``image``. Then the translation block of the normal matrix is
        ``Σ w J ∇I(x + p)ᵀ`` (at the start) instead of ``Σ w J Jᵀ``: the Newton step of the
        estimating equation ``Σ w J r = 0``. This lets ``gx, gy`` be a denoised (smoothed)
        template gradient — lower variance when the template is noisy — without the overshoot
        that the smaller smoothed gradients would otherwise cause.

    max_move : float
        Give up (``converged=False``) as soon as the translation has moved more than this many
        px (in x or y) from ``shift0``: a caller that rejects such fits need not wait for
        ``max_iterations``.
    setup : dict, optional
        :func:`gauss_newton_setup` of the same ``values, gx, gy, weights, regions,
        photometric`` (the template's constants, computed once by the caller).
    early_stop : bool
        Stop as well when the next update, extrapolated from the last two (shrinking by a
        factor of at most 0.6), would be below ``tolerance``: one iteration fewer, the answer
        within about ``tolerance`` of where the full iteration ends.
    sectors : (K,) ndarray of int, optional
        Pixels with the same label ``>= 0`` share a level of their own: each iteration removes
        the sector's weighted mean residual (a local background level that the template does not
        share); ``-1``: no level of its own.

    Returns
    -------
    GaussNewtonResult
    """
    return _GaussNewton(image, points, values, gx, gy, weights=weights, regions=regions, photometric=photometric,
                        exact=exact, curvature=curvature, setup=setup, sectors=sectors).run(
        shift0, gain0, offset0, max_iterations=max_iterations, tolerance=tolerance, huber=huber, tukey=tukey,
        template_variance=template_variance, instrument=instrument, freeze=freeze, max_move=max_move,
        early_stop=early_stop)


class _GaussNewton:
    """The iteration of :func:`gauss_newton_translation`: the template's constants, the sampler of
    the image at the moved band, and the steps (photometry, residual, robust weights, normal
    equations, solve), each a method; :meth:`run` is the loop."""

    def __init__(self, image, points, values, gx, gy, *, weights, regions, photometric, exact, curvature, setup,
                 sectors):
        self.img = img = np.asarray(image, np.float32)
        self.pts = pts = np.asarray(points, np.float64)
        if not exact or curvature is not None:
            self.px, self.py = pts[:, 0].astype(np.float32), pts[:, 1].astype(np.float32)
        if setup is None or setup["key"] != (photometric, regions is None):
            setup = gauss_newton_setup(values, gx, gy, weights=weights, regions=regions, photometric=photometric)
        self.setup = setup
        self.t, self.tx, self.ty, self.prior = (setup[k] for k in ("t", "tx", "ty", "prior"))
        self.joint = photometric and regions is None
        self.two_level = photometric and regions is not None
        self.exact, self.curvature = exact, curvature
        self.sec = None
        if sectors is not None:
            self.sec, self.n_sec = _sector_bins(sectors, setup)
        if exact:
            # The crop is filtered once per iteration; the band's flat indices are fixed.
            self.rows, self.cols = img.shape
            self.ix0, self.iy0 = ix0, iy0 = pts[:, 0].astype(np.intp), pts[:, 1].astype(np.intp)
            self.flat_base = None  # the band's flat indices in the whole image (made when first needed)
            # (Column by column: numpy's axis-0 reductions of an (N, 2) array are several times slower.)
            self.bounds = lo_x, hi_x, lo_y, hi_y = int(ix0.min()), int(ix0.max()), int(iy0.min()), int(iy0.max())
            # Only the band's box and the Keys stencil around it are filtered (``_stencil_window``): the
            # band's flat indices in that window do not depend on the shift.
            self.window = (hi_x - lo_x + KEYS_STENCIL, hi_y - lo_y + KEYS_STENCIL)
            self.window_base = (iy0 - lo_y + KEYS_BEFORE) * self.window[0] + (ix0 - lo_x + KEYS_BEFORE)

    def sample(self, shift) -> np.ndarray:
        """The image at the band's points moved by ``shift`` (Keys, or OpenCV's ``remap``)."""
        if not self.exact:
            return _remap_points(self.img, self.px + np.float32(shift[0]), self.py + np.float32(shift[1]))
        fx, fy = math.floor(shift[0]), math.floor(shift[1])
        lo_x, hi_x, lo_y, hi_y = self.bounds
        if not (lo_x + fx >= 0 and lo_y + fy >= 0 and hi_x + fx < self.cols and hi_y + fy < self.rows):
            return sample_shifted_filtered(self.img, self.pts, shift)  # border replicated
        window = self._stencil_window(fx, fy)
        if window is not None:
            filtered = keys_shift_filter(window, shift[0] - fx, shift[1] - fy)
            return filtered.ravel().take(self.window_base).astype(np.float64)
        if self.flat_base is None:
            self.flat_base = self.iy0 * self.cols + self.ix0
        filtered = keys_shift_filter(self.img, shift[0] - fx, shift[1] - fy)
        return filtered.ravel().take(self.flat_base + (fy * self.cols + fx)).astype(np.float64)

    def _stencil_window(self, fx: int, fy: int) -> np.ndarray | None:
        """The part of the image that the band moved by the integer ``(fx, fy)`` reads through the Keys
        stencil (its box, 1 px before and 2 after), or None when that reaches past the image's border
        (there the whole image is filtered, its border replicated). Inside the image the filter's value at
        a pixel is the same whatever part of the image is filtered (OpenCV's separable filter, bit for bit),
        and a crop holds several times the band's pixels: the window is the cheaper one to filter."""
        x0, y0 = self.bounds[0] + fx - KEYS_BEFORE, self.bounds[2] + fy - KEYS_BEFORE
        w, h = self.window
        if x0 < 0 or y0 < 0 or x0 + w > self.cols or y0 + h > self.rows:
            return None
        return self.img[y0:y0 + h, x0:x0 + w]

    def region_levels(self, robust, samples):
        """Gain and offset from the robust-weighted mean levels of object and background pixels,
        or None when a region has no weight or the template no contrast."""
        swt_in, swt_out, swi, swo = (robust @ self.setup["levels"]).tolist()
        if swi <= 0 or swo <= 0:
            return None
        ti, to = swt_in / swi, swt_out / swo
        if ti == to:
            return None
        si, so = ((robust * samples) @ self.setup["regions2"]).tolist()
        g = (si / swi - so / swo) / (ti - to)
        return g, so / swo - g * to

    def residual(self, samples, g, o, robust) -> np.ndarray:
        """``I(x + p) − g·T − o``, less each background sector's weighted mean (its own level)."""
        # (In place, in the same order of operations as ``samples - (g * T + o)``.)
        residual = self.t * g
        residual += o
        np.subtract(samples, residual, out=residual)
        if self.sec is not None:
            # Each sector's own level: its weighted mean residual is the local background's
            # change, not the object's displacement.
            sec, n_sec = self.sec, self.n_sec
            sw = self.prior * robust
            totals = np.bincount(sec, weights=sw, minlength=n_sec)[:n_sec]
            sw *= residual
            # The pixels without a level of their own (bin n_sec) take the extra entry, 0.
            local = np.zeros(n_sec + 1)
            np.divide(np.bincount(sec, weights=sw, minlength=n_sec)[:n_sec], np.maximum(totals, 1e-12),
                      out=local[:n_sec])
            residual -= local.take(sec)
        return residual

    def robust_weights(self, residual, huber, spread, tukey: bool):
        """Huber's (or, with ``tukey``, Tukey's) weights of the residuals scaled by their robust
        spread, which the first call measures; returns ``(weights, spread)``."""
        z = residual * self.setup["sqrt_prior"]
        if spread is None:
            spread = MAD_TO_SD * _median(np.abs(z - _median(z))) + 1e-9
        if not tukey:
            # min(1, c/|z|) with c = huber · spread.
            c = huber * spread
            return c / np.maximum(np.abs(z), c), spread
        # Close to the answer, Tukey's biweight gives occluded pixels no influence at all, where
        # Huber's only bounds it.
        u = np.minimum(np.abs(z) / (TUKEY_C * spread), 1.0)
        return (1.0 - u * u) ** 2, spread

    def normal_equations(self, g, robust, residual, p, block, *, levels_move, instrument, template_variance):
        """The normal matrix and right-hand side of the step; ``block`` is the curvature block
        (None: not yet computed at the start, False: unusable). Returns ``(hess, rhs, block)``."""
        t, tx, ty = self.t, self.tx, self.ty
        if self.joint or (self.curvature is not None and block is None):
            w = self.prior * robust
            jx, jy = g * tx, g * ty
            wjx, wjy = w * jx, w * jy
        if self.joint:
            jac = np.stack([jx, jy, t, np.ones_like(t)], axis=1)
            inst = jac if instrument is None else np.stack([jx, jy, instrument, np.ones_like(t)], axis=1)
            jw = inst * w[:, None]
            hess = jw.T @ jac
            rhs = jw.T @ residual
            if template_variance is not None:
                correction = float(w @ template_variance)
                hess[2, 2] -= correction
                rhs[2] += g * correction
        else:
            # With two-level photometry, gain and offset move with p: the residual's derivative
            # is the gradient minus what the levels absorb of it (region indicator, not the noisy
            # template, carries the levels). Only the step uses it; the estimating equation
            # Σ w J r = 0 keeps the plain template gradient, uncorrelated with the residual's noise.
            basis = self.setup["absorbed_hess"] if levels_move else self.setup["plain_hess"]
            hess = (g * g * (robust @ basis)).reshape(2, 2)
            rhs = g * ((robust * residual) @ self.setup["rhs_basis"])
        if self.curvature is not None:
            if block is None:
                block = self._curvature_block(p, wjx, wjy)
            if block is not False:
                hess[:2, :2] = block
        return hess, rhs, block

    def _curvature_block(self, p, wjx, wjy):
        """``Σ w J ∇I(x + p)ᵀ`` at the start, or False when it is not positive definite."""
        curvature, px, py = self.curvature, self.px, self.py
        gix = _remap_points(curvature[0], px + np.float32(p[0]), py + np.float32(p[1]))
        giy = _remap_points(curvature[1], px + np.float32(p[0]), py + np.float32(p[1]))
        if self.two_level:
            inside, ind_in, ind_out = (self.setup[k] for k in ("inside", "ind_in", "ind_out"))
            gix, giy = _absorb(gix, inside, ind_in, ind_out), _absorb(giy, inside, ind_in, ind_out)
        block = np.array([[wjx @ gix, wjx @ giy], [wjy @ gix, wjy @ giy]])
        sym = 0.5 * (block + block.T)
        return block if (np.linalg.det(sym) > 0 and np.trace(sym) > 0) else False

    def solve(self, hess, rhs):
        """``(dx, dy, delta)`` of the step (``delta``: all parameters, joint photometry only), or
        None when the system is singular or the step not finite."""
        if self.joint:
            try:
                delta = np.linalg.solve(hess, rhs)
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(delta)):
                return None
            return float(delta[0]), float(delta[1]), delta
        # The 2×2 solve in closed form, on Python floats (cheaper than LAPACK at this size).
        h00, h01, h10, h11 = hess.ravel().tolist()
        r0, r1 = rhs.tolist()
        det = h00 * h11 - h01 * h10
        if det == 0:
            return None
        dx, dy = (h11 * r0 - h01 * r1) / det, (h00 * r1 - h10 * r0) / det
        if not (math.isfinite(dx) and math.isfinite(dy)):
            return None
        return dx, dy, None

    def run(self, shift0, gain0, offset0, *, max_iterations, tolerance, huber, tukey, template_variance,
            instrument, freeze, max_move, early_stop) -> GaussNewtonResult:
        """The inverse-compositional iteration from ``shift0``, ``gain0``, ``offset0``."""
        # The position as two Python floats (the same float64 arithmetic, without numpy's scalar overhead).
        p = [float(v) for v in np.asarray(shift0, np.float64)]
        start = tuple(p)
        g, o = float(gain0), float(offset0)
        converged, step, spread, block, prev, damping = False, np.inf, None, None, None, 1.0
        robust = np.ones_like(self.t)
        it, samples, residual, hess = 0, None, None, None
        for it in range(1, max_iterations + 1):
            samples = self.sample(p)
            if self.two_level and step > freeze:
                # Gain and offset follow the region means while the translation still moves, then
                # stay fixed (the means move with p, a coupling Gauss–Newton does not model).
                levels = self.region_levels(robust, samples)
                if levels is None:
                    break
                g, o = levels
                if abs(g) < MIN_GAIN:
                    break
            residual = self.residual(samples, g, o, robust)
            if huber is not None:
                robust, spread = self.robust_weights(residual, huber, spread, tukey and step <= TUKEY_FROM_STEP_PX)
            hess, rhs, block = self.normal_equations(
                g, robust, residual, p, block, levels_move=self.two_level and step > freeze, instrument=instrument,
                template_variance=template_variance)
            solved = self.solve(hess, rhs)
            if solved is None:
                break
            dx, dy, delta = solved
            # A step that reverses a good part of a previous one longer than 0.1 px means the
            # linearisation overshoots (noisy Jacobian, a far start): halve the steps from then on.
            if prev is not None:
                pp = prev[0] * prev[0] + prev[1] * prev[1]
                if pp > OVERSHOOT_MIN_STEP_SQ and dx * prev[0] + dy * prev[1] < -OVERSHOOT_REVERSAL * pp:
                    damping = max(0.5 * damping, MIN_DAMPING)
            prev = (dx, dy)
            # Inverse composition: the template moved by delta[:2], so the image position moves back.
            p[0] -= damping * dx
            p[1] -= damping * dy
            if self.joint:
                g += delta[2]
                o += delta[3]
            if abs(g) < MIN_GAIN:
                break
            last_step, step = step, damping * math.hypot(dx, dy)
            # Near the answer the steps shrink geometrically: stop as well when the next one,
            # extrapolated from the last two, would be below the tolerance.
            if step < tolerance or (early_stop and it > 1 and step < EARLY_STOP_RATIO * last_step
                                    and step * step < tolerance * last_step):
                converged = True
                break
            if max(abs(p[0] - start[0]), abs(p[1] - start[1])) > max_move:
                break
        else:
            # Huber re-weighting can make the last digits wander: a step well below a tenth of a
            # pixel after max_iterations still counts as converged.
            converged = step < 10 * tolerance
        return self._result(np.array(p), g, o, robust, it, converged, samples, residual, hess)

    def _result(self, p, g, o, robust, it, converged, samples, residual, hess) -> GaussNewtonResult:
        total = self.prior * robust
        information = hess
        if self.two_level and self.setup.get("absorbed_hess") is not None:
            # The shift's information with the two levels eliminated (they follow the object's and
            # the background's means), whatever the last step used.
            information = (g * g * (robust @ self.setup["absorbed_hess"])).reshape(2, 2)
        return GaussNewtonResult(
            information=information, residual=residual,
            shift=p, gain=g, offset=o, weights=robust, inliers=np.count_nonzero(robust >= 1.0) / robust.size,
            iterations=it, converged=converged,
            samples=samples if samples is not None else np.full_like(self.t, np.nan),
            normal_matrix=hess, n_pixels=int(robust.size), weight_total=float(robust.sum()),
            weighted_ssr=float(total @ (residual * residual)) if residual is not None else float("nan"),
            robust_ssr=float((total * robust) @ (residual * residual)) if residual is not None else float("nan"))
