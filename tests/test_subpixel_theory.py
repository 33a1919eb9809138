"""The sub-pixel step (semlab.subpixel) against closed forms: derivative masks, cubic interpolation,
the eq.-9 solve, the noise model and Gauss–Newton registration, through public signatures only.

Images are analytic (a Gaussian-blurred disc, polynomials), so the truth is known exactly; the
tolerances come from the order of each approximation, said where used.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from semlab.subpixel import (
    FIVE_POINT_KERNEL,
    NoiseModel,
    estimate_noise,
    five_point_gradients,
    gauss_newton_translation,
    gradient_subpixel_shift,
    sample_bicubic,
    sample_shifted,
    sample_shifted_filtered,
    weighted_ncc,
    whiten_lines,
)


def disc(shape=(64, 64), centre=(32.0, 32.0), radius=12.0, sigma=1.5, inside=200.0, outside=60.0):
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    d = np.hypot(xx - centre[0], yy - centre[1]) - radius
    return outside + (inside - outside) * ndtr(-d / sigma)


def keys(t):
    """Keys' cubic kernel (a = -0.5) at distance t (the textbook piecewise form)."""
    t = abs(t)
    if t < 1:
        return 1.5 * t ** 3 - 2.5 * t ** 2 + 1
    if t < 2:
        return -0.5 * t ** 3 + 2.5 * t ** 2 - 4 * t + 2
    return 0.0


def keys_reference(img, x, y):
    """Direct 4x4 Keys interpolation with the border replicated."""
    rows, cols = img.shape
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    out = 0.0
    for j in range(-1, 3):
        for i in range(-1, 3):
            yy, xx = min(max(y0 + j, 0), rows - 1), min(max(x0 + i, 0), cols - 1)
            out += keys(x - (x0 + i)) * keys(y - (y0 + j)) * img[yy, xx]
    return out


# ------------------------------------------------------------------------- derivatives (eq. 8)
def test_five_point_mask_and_derivatives_of_a_plane():
    np.testing.assert_allclose(FIVE_POINT_KERNEL * 12, [1, -8, 0, 8, -1])
    yy, xx = np.mgrid[:16, :20].astype(float)
    ix, iy = five_point_gradients(3.0 * xx - 2.0 * yy + 7.0)
    # a plane's derivative is exact for any consistent difference formula (inner pixels)
    np.testing.assert_allclose(ix[2:-2, 2:-2], 3.0, atol=1e-4)
    np.testing.assert_allclose(iy[2:-2, 2:-2], -2.0, atol=1e-4)
    # border reflected (101): the mirrored ramp is symmetric about column 0, so its derivative is 0
    np.testing.assert_allclose(ix[:, 0], 0.0, atol=1e-4)
    assert ix.dtype == np.float32 and ix.shape == (16, 20)


# ------------------------------------------------------------------------- eq. 9
@pytest.mark.parametrize("shift", [(0.2, -0.1), (-0.3, 0.25), (0.05, 0.4), (-0.45, 0.0)])
def test_eq_9_recovers_a_sub_pixel_shift(shift):
    template = disc()
    target = disc(centre=(32 + shift[0], 32 + shift[1]))
    dx, dy = gradient_subpixel_shift(template, target)
    # one linearised step; on a point-symmetric object the second-order term of the Taylor
    # expansion cancels over the disc, leaving O(|d|³/σ²) <= 0.45³/1.5² ≈ 0.04 px (σ = 1.5 px edge)
    assert (dx, dy) == pytest.approx(shift, abs=0.04)


def wedge(shape=(60, 80), tip=(50.0, 30.0), half_angle_deg=14.0, sigma=1.5):
    """A probe-like wedge entering from the left border (its shaft is cut by the window)."""
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    vx, vy = xx - tip[0], yy - tip[1]
    a = np.radians(half_angle_deg)
    d1, d2 = vx * np.sin(a) + vy * np.cos(a), vx * np.sin(a) - vy * np.cos(a)
    d = np.where((d1 > 0) & (d2 > 0), np.hypot(vx, vy), np.maximum(d1, d2))
    return 60 + 140 * ndtr(-d / sigma)


@pytest.mark.parametrize("shift", [(0.3, -0.2), (-0.25, 0.15), (0.1, 0.3)])
def test_eq_9_on_a_probe_cut_by_the_window(shift):
    # No symmetry to cancel the second-order term here: the error is |d|²/(2σ) <= 0.36²/3 ≈ 0.04 px.
    # (On a disc inside a uniform background Σ i ∇i = 0, which would hide a sign error of the
    # residual; a shaft that leaves the window does not.)
    dx, dy = gradient_subpixel_shift(wedge(), wedge(tip=(50 + shift[0], 30 + shift[1])))
    assert (dx, dy) == pytest.approx(shift, abs=0.04)


def texture(seed, shape=(40, 48)):
    """A smooth random texture: gradients everywhere, up to the image border."""
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), 2.0) * 4.0


def test_eq_9_is_the_least_squares_solution_over_the_inner_pixels():
    # eq. 9 = the 2x2 normal equations of min Σ (t - i - Δ·∇i)² over R (all but a 2-px border),
    # ∇i by the 5-point mask: the same numbers as a generic least-squares solver, to rounding.
    # A texture has gradients up to the border, so every row and column of R counts.
    t, i = texture(1), texture(2)
    ix, iy = five_point_gradients(i)
    rng = np.random.default_rng(5)
    mask = rng.random(t.shape) < 0.7
    for m in (None, mask, mask.astype(np.uint8)):
        use = np.zeros(t.shape, bool)
        use[2:-2, 2:-2] = True
        if m is not None:
            use &= m.astype(bool)
        a = np.stack([ix[use], iy[use]], 1).astype(np.float64)
        want = np.linalg.lstsq(a, (t - i)[use].astype(np.float64), rcond=None)[0]
        assert gradient_subpixel_shift(t, i, mask=m) == pytest.approx(tuple(want), rel=1e-9, abs=1e-12)
    # 8-bit frames are differenced as numbers (no wrap-around of t - i)
    t8, i8 = np.clip(t / 4, 0, 255).astype(np.uint8), np.clip(i / 4, 0, 255).astype(np.uint8)
    assert gradient_subpixel_shift(t8, i8) == pytest.approx(
        gradient_subpixel_shift(t8.astype(np.float32), i8.astype(np.float32)), rel=1e-9)


def test_eq_9_uses_the_mask_and_ignores_the_two_pixel_border():
    template = disc()
    target = disc(centre=(32.3, 31.8))
    base = gradient_subpixel_shift(template, target)
    # the template enters only through t - i on the pixels used: garbage on its 2-px border and
    # outside the mask changes nothing
    spoiled = template.copy()
    spoiled[:2], spoiled[-2:], spoiled[:, :2], spoiled[:, -2:] = 0.0, 999.0, -50.0, 3e3
    assert gradient_subpixel_shift(spoiled, target) == pytest.approx(base, abs=1e-9)
    ring = np.abs(np.hypot(*np.mgrid[:64, :64][::-1] - 32.0) - 12.0) < 4  # the edge band
    masked = gradient_subpixel_shift(template, target, mask=ring)
    spoiled = template.copy()
    spoiled[~ring] = 0.0
    assert gradient_subpixel_shift(spoiled, target, mask=ring) == pytest.approx(masked, abs=1e-9)
    assert masked == pytest.approx((0.3, -0.2), abs=0.06)  # the edge holds all the information
    # a straight edge along y carries no y information: the 2x2 system is singular -> NaN
    xx = np.mgrid[:30, :30][1].astype(float)
    edge = 60 + 140 * ndtr((xx - 15) / 1.5)
    assert np.isnan(gradient_subpixel_shift(edge, np.roll(edge, 1, axis=1))).all()
    with pytest.raises(ValueError, match="differ in shape"):
        gradient_subpixel_shift(template, target[:-1])


# ------------------------------------------------------------------------- interpolation
def test_the_samplers_are_keys_cubic_convolution():
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 255, (20, 24)).astype(np.float32)
    pts = np.array([[5, 6], [10, 3], [17, 15], [3, 12]], float)
    for shift in ((0.37, -1.62), (-2.75, 0.5), (1.0, 2.0), (0.0, 0.999)):
        want = [keys_reference(img, x + shift[0], y + shift[1]) for x, y in pts]
        # float32 image, float64 weights: agreement to ~1e-5 of the gray levels
        np.testing.assert_allclose(sample_shifted(img, pts, shift), want, rtol=0, atol=2e-3)
        np.testing.assert_allclose(sample_shifted_filtered(img, pts, shift), want, rtol=0, atol=2e-3)
        np.testing.assert_allclose(sample_bicubic(img, pts[:, 0] + shift[0], pts[:, 1] + shift[1]), want,
                                   rtol=0, atol=2e-3)


BORDER_POINTS = np.array([[0, 0], [13, 11], [0, 11], [13, 0], [1, 5], [12, 6]], float)


@pytest.mark.parametrize("shift", [(0.3, 0.6), (0.9, 0.0), (0.0, 0.25), (-1.0, -1.0)])
def test_the_samplers_replicate_the_border(shift):
    # points whose 4x4 stencil leaves the 14x12 image on every side, positions inside it
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 255, (12, 14)).astype(np.float32)
    pts = BORDER_POINTS[(BORDER_POINTS[:, 0] + shift[0] >= 0) & (BORDER_POINTS[:, 1] + shift[1] >= 0)]
    want = [keys_reference(img, x + shift[0], y + shift[1]) for x, y in pts]
    np.testing.assert_allclose(sample_shifted(img, pts, shift), want, atol=2e-3)
    np.testing.assert_allclose(sample_shifted_filtered(img, pts, shift), want, atol=2e-3)
    np.testing.assert_allclose(sample_bicubic(img, pts[:, 0] + shift[0], pts[:, 1] + shift[1]), want, atol=2e-3)


@pytest.mark.parametrize("shift", [(-0.4, -0.7), (-1.5, 1.25), (1.5, 0.25), (0.25, 1.5), (-0.5, 0.0)])
def test_points_shifted_off_the_image_see_the_border_replicated(shift):
    # off the left/top, off the right only, off the bottom only
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 255, (12, 14)).astype(np.float32)
    want = [keys_reference(img, x + shift[0], y + shift[1]) for x, y in BORDER_POINTS]
    np.testing.assert_allclose(sample_shifted(img, BORDER_POINTS, shift), want, atol=2e-3)
    np.testing.assert_allclose(sample_shifted_filtered(img, BORDER_POINTS, shift), want, atol=2e-3)
    np.testing.assert_allclose(sample_bicubic(img, BORDER_POINTS[:, 0] + shift[0], BORDER_POINTS[:, 1] + shift[1]),
                               want, atol=2e-3)


def test_sample_shifted_filtered_off_the_image_matches_the_replicated_border():
    # (it used to clip the shifted INDEX into the image, so a point shifted off the image read the
    # filtered value at the border pixel, the interpolation at border + fraction: up to 90 gray
    # levels off here)
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 255, (12, 14)).astype(np.float32)
    shift = (-0.4, -0.7)
    want = [keys_reference(img, x + shift[0], y + shift[1]) for x, y in BORDER_POINTS]
    np.testing.assert_allclose(sample_shifted_filtered(img, BORDER_POINTS, shift), want, atol=2e-3)


def test_integer_shifts_are_exact_copies():
    img = np.arange(100, dtype=np.float32).reshape(10, 10)
    pts = np.array([[3, 4], [5, 5], [6, 2]], float)
    for f in (sample_shifted, sample_shifted_filtered):
        np.testing.assert_array_equal(f(img, pts, (2.0, -1.0)), img[[3, 4, 1], [5, 7, 8]])


# ------------------------------------------------------------------------- noise model
def test_noise_model_variance_is_a_line_with_a_floor():
    m = NoiseModel(rho=0.3, variance_at_zero=-4.0, variance_slope=0.5, variance_floor=2.0)
    np.testing.assert_allclose(m.variance([0.0, 10.0, 100.0]), [2.0, 2.0, 46.0])
    assert NoiseModel().variance(50.0) == 1.0


def test_estimate_noise_on_white_noise_of_constant_variance():
    rng = np.random.default_rng(4)
    img = 100.0 + 5.0 * rng.standard_normal((200, 200))
    m = estimate_noise(img)
    # white noise: ρ = 0 (clipped at 0 from below; sd of the estimate ~ 1/sqrt(#pairs) ≈ 0.005)
    assert m.rho < 0.03
    # variance 25 at every level (a flat image has no level spread: slope 0)
    assert m.variance(100.0) == pytest.approx(25.0, rel=0.1)
    assert m.variance_floor == pytest.approx(0.25 * 25.0, rel=0.2)


def test_estimate_noise_cancels_line_offsets_and_follows_the_level_down_the_image():
    # Per-line offsets (sd 10 gray levels) cancel in each row pair's median-subtracted difference;
    # the variance a + b I is regressed on the local level, here rising down the image (60 on
    # the top half, 180 on the bottom), variance 4 + 2 I: 124 and 364.
    rng = np.random.default_rng(8)
    level = np.where(np.arange(256)[:, None] < 128, 60.0, 180.0).repeat(256, 1)
    img = level + rng.standard_normal(level.shape) * np.sqrt(4.0 + 2.0 * level)
    img += rng.normal(0, 10.0, (256, 1))
    m = estimate_noise(img)
    assert m.rho < 0.05
    # ±15 %: the level bins mix the two halves near the step (blurred by the 2-px smoothing)
    assert m.variance(60.0) == pytest.approx(124.0, rel=0.15)
    assert m.variance(180.0) == pytest.approx(364.0, rel=0.15)


def test_estimate_noise_degenerate_images():
    # noise-free (synthetic) image: row differences are scene, not noise -> the quantisation floor
    clean = disc((64, 64))
    assert estimate_noise(clean) == NoiseModel(rho=0.0, variance_at_zero=0.1, variance_slope=0.0,
                                               variance_floor=0.1)
    # too few flat pixel pairs to estimate anything: the neutral default
    assert estimate_noise(np.random.default_rng(0).normal(size=(8, 8))) == NoiseModel()
    for bad in (np.zeros((7, 30)), np.zeros((30, 30, 3))):
        with pytest.raises(ValueError, match="8x8"):
            estimate_noise(bad)


def test_whiten_lines_is_the_ar1_inverse_filter():
    rng = np.random.default_rng(2)
    img = rng.uniform(0, 100, (6, 9)).astype(np.float32)
    rho = 0.4
    w = whiten_lines(img, rho)
    np.testing.assert_allclose(w[:, 1:], img[:, 1:] - rho * img[:, :-1], rtol=1e-6)
    np.testing.assert_allclose(w[:, 0], (1 - rho) * img[:, 0], rtol=1e-6)
    const = whiten_lines(np.full((3, 5), 10.0), rho)
    np.testing.assert_allclose(const, 6.0, rtol=1e-6)  # a constant stays a constant
    u8 = np.arange(45, dtype=np.uint8).reshape(5, 9)  # 8-bit frames are whitened as numbers
    np.testing.assert_allclose(whiten_lines(u8, rho), whiten_lines(u8.astype(np.float32), rho))
    same = whiten_lines(img, 0.0)
    np.testing.assert_array_equal(same, img)
    assert same is not img  # a copy: the caller's frame is never modified


def test_weighted_ncc():
    a = np.array([1.0, 3.0, 2.0, 5.0, 4.0])
    assert weighted_ncc(a, 2 * a + 3) == pytest.approx(1.0)
    assert weighted_ncc(a, -a) == pytest.approx(-1.0)
    assert weighted_ncc(a, np.ones(5)) == 0.0  # flat: no correlation defined
    assert weighted_ncc(a, a, np.zeros(5)) == 0.0
    w = np.array([1.0, 1.0, 1.0, 0.0, 0.0])
    b = np.array([2.0, 1.0, 7.0, -100.0, 50.0])
    # zero weights drop samples: the weighted NCC is the plain one on the rest
    assert weighted_ncc(a, b, w) == pytest.approx(np.corrcoef(a[:3], b[:3])[0, 1])
    # normalised weights (sum 1) and small signals (variance << 1) are as good as any
    assert weighted_ncc(a, b, w / 3) == pytest.approx(weighted_ncc(a, b, w))
    assert weighted_ncc(0.01 * a, 0.01 * b) == pytest.approx(weighted_ncc(a, b))
    w2 = np.array([1.0, 2.0, 1.0, 3.0, 1.0])  # integer weights = repeated samples
    rep = np.repeat(np.arange(5), w2.astype(int))
    assert weighted_ncc(a, b, w2) == pytest.approx(np.corrcoef(a[rep], b[rep])[0, 1])


# ------------------------------------------------------------------------- Gauss–Newton
def _band(shape=(64, 64), centre=(32.0, 32.0), radius=12.0, half_width=4):
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    band = np.abs(np.hypot(xx - centre[0], yy - centre[1]) - radius) <= half_width
    ys, xs = np.nonzero(band)
    inside = np.hypot(xs - centre[0], ys - centre[1]) < radius
    return np.stack([xs, ys], 1).astype(float), ys, xs, inside


def _template(sigma=1.5):
    t = disc(sigma=sigma).astype(np.float32)
    gx, gy = five_point_gradients(t)
    pts, ys, xs, inside = _band()
    return t, pts, t[ys, xs], gx[ys, xs], gy[ys, xs], inside


@pytest.mark.parametrize("shift", [(0.4, -0.3), (-1.6, 2.2), (0.0, 0.0)])
@pytest.mark.parametrize("photometric, regions", [(True, False), (True, True), (False, False)])
def test_gauss_newton_recovers_the_shift_of_a_noise_free_disc(shift, photometric, regions):
    _, pts, values, gx, gy, inside = _template()
    gain, offset = (1.4, -15.0) if photometric else (1.0, 0.0)
    image = (gain * disc(centre=(32 + shift[0], 32 + shift[1])) + offset).astype(np.float32)
    fit = gauss_newton_translation(image, pts, values, gx, gy, (0.0, 0.0), photometric=photometric,
                                   regions=inside if regions else None)
    assert fit.converged and 1 <= fit.iterations <= 20
    # noise-free: what is left is the cubic interpolation error on a σ = 1.5 px edge (< 0.01 px)
    # and, for region-mean photometry frozen below 0.01 px steps, a lag of that order
    tol = 0.03 if regions else 0.01
    assert tuple(fit.shift) == pytest.approx(shift, abs=tol)
    assert fit.gain == pytest.approx(gain, rel=0.01) and fit.offset == pytest.approx(offset, abs=1.5)
    assert fit.inliers == pytest.approx(np.count_nonzero(fit.weights >= 1.0) / len(values))
    assert fit.samples.shape == values.shape


def test_gauss_newton_without_photometry_holds_gain_and_offset():
    _, pts, values, gx, gy, _ = _template()
    image = (0.5 * disc(centre=(32.3, 32.0)) + 40.0).astype(np.float32)
    fit = gauss_newton_translation(image, pts, values, gx, gy, (0.0, 0.0), photometric=False, gain0=0.5,
                                   offset0=40.0)
    assert (fit.gain, fit.offset) == (0.5, 40.0)
    assert tuple(fit.shift) == pytest.approx((0.3, 0.0), abs=0.01)


def test_gauss_newton_starts_from_shift0_and_gives_up_beyond_max_move():
    _, pts, values, gx, gy, _ = _template()
    image = disc(centre=(35.2, 30.1)).astype(np.float32)
    near = gauss_newton_translation(image, pts, values, gx, gy, (3.0, -2.0))
    assert near.converged and tuple(near.shift) == pytest.approx((3.2, -1.9), abs=0.01)
    capped = gauss_newton_translation(image, pts, values, gx, gy, (0.0, 0.0), max_move=0.5)
    assert not capped.converged
    assert max(abs(capped.shift[0]), abs(capped.shift[1])) > 0.5
    one = gauss_newton_translation(image, pts, values, gx, gy, (0.0, 0.0), max_iterations=1, tolerance=1e-9)
    assert one.iterations == 1 and not one.converged


def test_gauss_newton_opencv_remap_is_within_its_quantisation():
    _, pts, values, gx, gy, _ = _template()
    image = disc(centre=(32.45, 31.7)).astype(np.float32)
    fit = gauss_newton_translation(image, pts, values, gx, gy, (0.0, 0.0), exact=False)
    exact = gauss_newton_translation(image, pts, values, gx, gy, (0.0, 0.0))
    # remap rounds positions to 1/32 px (±1/64 px) and its kernel (a = -0.75) biases a σ = 1.5 px edge
    # by a few hundredths of a px (the docstring's figure); the exact Keys path is within 0.01 px
    assert tuple(exact.shift) == pytest.approx((0.45, -0.3), abs=0.01)
    assert tuple(fit.shift) == pytest.approx((0.45, -0.3), abs=0.05)
    assert np.hypot(*(fit.shift - exact.shift)) > 1e-4  # it did take the other path


def test_gauss_newton_on_white_noise_reaches_the_cramer_rao_bound():
    # Translation-only least squares on white noise of variance s² is efficient: the estimate's
    # covariance is s² (Σ ∇T ∇Tᵀ)⁻¹ (Cramér–Rao). 60 noisy frames: the sample std is within ±35 %
    # of the bound (3 standard errors of a std from 60 samples: 3/sqrt(120) ≈ 27 %, plus the small
    # interpolation and template-gradient approximations).
    _, pts, values, gx, gy, _ = _template()
    s = 8.0
    fisher = np.array([[gx @ gx, gx @ gy], [gx @ gy, gy @ gy]]) / s ** 2
    crb = np.sqrt(np.diag(np.linalg.inv(fisher)))
    rng = np.random.default_rng(7)
    clean = disc(centre=(32.3, 31.6))
    shifts = np.array([gauss_newton_translation((clean + s * rng.standard_normal(clean.shape)).astype(np.float32),
                                                pts, values, gx, gy, (0.0, 0.0), photometric=False,
                                                huber=None).shift for _ in range(60)])
    bias = shifts.mean(0) - (0.3, -0.4)
    assert np.all(np.abs(bias) < 3 * crb / np.sqrt(60) + 0.01)
    np.testing.assert_allclose(shifts.std(0, ddof=1), crb, rtol=0.35)


def test_gauss_newton_weights_are_inverse_variances():
    # Pixels on the right half noisier (s = 20) than on the left (s = 2): weighting by 1/s² must
    # beat equal weights (the weighted estimate is the efficient one), by a wide margin here.
    _, pts, values, gx, gy, _ = _template()
    right = pts[:, 0] > 32
    sd = np.where(right, 20.0, 2.0)
    rng = np.random.default_rng(3)
    clean = disc(centre=(32.2, 32.1))
    errs_w, errs_eq = [], []
    for _ in range(30):
        noise = rng.standard_normal(clean.shape) * np.where(np.mgrid[:64, :64][1] > 32, 20.0, 2.0)
        img = (clean + noise).astype(np.float32)
        kw = {"photometric": False, "huber": None}
        errs_w.append(gauss_newton_translation(img, pts, values, gx, gy, (0, 0), weights=1 / sd ** 2, **kw).shift)
        errs_eq.append(gauss_newton_translation(img, pts, values, gx, gy, (0, 0), **kw).shift)
    rms_w = np.sqrt(np.mean((np.array(errs_w) - (0.2, 0.1)) ** 2))
    rms_eq = np.sqrt(np.mean((np.array(errs_eq) - (0.2, 0.1)) ** 2))
    assert rms_w < 0.6 * rms_eq


def test_gauss_newton_robust_weights_reject_an_occluder():
    _, pts, values, gx, gy, _ = _template()
    image = disc(centre=(32.4, 31.8)).astype(np.float32)
    image[14:30, 36:52] = 250.0  # a bright particle over a part of the edge
    plain = gauss_newton_translation(image, pts, values, gx, gy, (0, 0), huber=None)
    huber = gauss_newton_translation(image, pts, values, gx, gy, (0, 0), huber=2.0)
    tukey = gauss_newton_translation(image, pts, values, gx, gy, (0, 0), huber=2.0, tukey=True)
    err = {k: np.hypot(*(f.shift - (0.4, -0.2))) for k, f in (("plain", plain), ("huber", huber), ("tukey", tukey))}
    assert err["huber"] < 0.5 * err["plain"]
    assert err["tukey"] < 0.05 and err["tukey"] <= err["huber"] + 1e-3
    assert plain.inliers == 1.0 and huber.inliers < 0.95
    assert np.all((tukey.weights >= 0) & (tukey.weights <= 1))
    occluded = (pts[:, 0] >= 36) & (pts[:, 0] < 52) & (pts[:, 1] >= 14) & (pts[:, 1] < 30)
    assert tukey.weights[occluded].mean() < 0.2 < tukey.weights[~occluded].mean()


def test_gauss_newton_with_the_band_partly_off_the_image():
    # The same disc registered in a crop that cuts through its band: the points that the shift
    # moves off the crop see the replicated border (an outlier that the Huber weights bound), the
    # rest carry the shift. Against the full image the answer moves by less than 0.05 px.
    _, pts, values, gx, gy, _ = _template()
    full = disc(centre=(33.2, 31.6)).astype(np.float32)
    ref = gauss_newton_translation(full, pts, values, gx, gy, (0.0, 0.0))
    crop_x0 = int(pts[:, 0].min()) + 1  # the leftmost band column is cut off, then shifted further
    crop = np.ascontiguousarray(full[:, crop_x0:])
    fit = gauss_newton_translation(crop, pts - (crop_x0, 0), values, gx, gy, (0.0, 0.0))
    assert ref.converged and tuple(ref.shift) == pytest.approx((1.2, -0.4), abs=0.01)
    assert np.hypot(*(fit.shift - ref.shift)) < 0.05


def test_gauss_newton_setup_refuses_regions_without_two_levels():
    from semlab.subpixel import gauss_newton_setup

    _, _, values, gx, gy, inside = _template()
    for bad in (np.ones_like(inside), np.zeros_like(inside)):
        with pytest.raises(ValueError, match=r"^regions must mark both object and background pixels$"):
            gauss_newton_setup(values, gx, gy, regions=bad)
    one = np.zeros_like(inside)
    one[0] = True  # a single object pixel is enough to define a level
    gauss_newton_setup(values, gx, gy, regions=one)
    with pytest.raises(ValueError, match=r"^the template has no contrast between object and background$"):
        # (a constant 0: exactly equal means; the check compares the two means with ==, so a
        # constant such as 7.0 can escape it by rounding -- noted, not this file's business)
        gauss_newton_setup(np.zeros_like(values), gx, gy, regions=inside)
    gauss_newton_setup(values, gx, gy, regions=np.ones_like(inside), photometric=False)  # not used then


def test_gauss_newton_sectors_absorb_a_local_background_level():
    # A local level (+25 gray levels) on the right half of the band, which the template does not
    # have: without sectors it pulls the fit; with that half as a sector of its own, its mean
    # residual is removed at each iteration and the shift is the noise-free one again.
    _, pts, values, gx, gy, _ = _template()
    image = disc(centre=(32.3, 31.8))
    right = pts[:, 0] > 36
    image[:, 37:] += 25.0
    image = image.astype(np.float32)
    kw = {"photometric": False, "huber": None}
    biased = gauss_newton_translation(image, pts, values, gx, gy, (0, 0), **kw)
    sectors = np.where(right, 0, -1)
    fit = gauss_newton_translation(image, pts, values, gx, gy, (0, 0), sectors=sectors, **kw)
    assert np.hypot(*(biased.shift - (0.3, -0.2))) > 0.1
    assert tuple(fit.shift) == pytest.approx((0.3, -0.2), abs=0.02)


def test_gauss_newton_curvature_allows_a_smoothed_template_gradient():
    # A smoothed template gradient is smaller than the true one at a sharp edge, so plain
    # Gauss-Newton over-steps; with the image's own gradients in the normal matrix (curvature=) it
    # is the Newton step of the same estimating equation and converges to the same shift.
    template, pts, values, _, _, _ = _template(sigma=1.0)
    sgx, sgy = (cv2.GaussianBlur(g, (0, 0), 1.0) for g in five_point_gradients(template))
    ys, xs = pts[:, 1].astype(int), pts[:, 0].astype(int)
    image = disc(centre=(32.35, 31.75), sigma=1.0).astype(np.float32)
    curv = five_point_gradients(image)
    fit = gauss_newton_translation(image, pts, values, sgx[ys, xs], sgy[ys, xs], (0, 0), curvature=curv,
                                   photometric=False)
    assert fit.converged and tuple(fit.shift) == pytest.approx((0.35, -0.25), abs=0.02)
    # one step: the Newton step is exact to second order, the plain step with the smaller smoothed
    # gradients is off to first order (by the ratio of Σ ∇T̃ ∇I to Σ ∇T̃ ∇T̃)
    args = (image, pts, values, sgx[ys, xs], sgy[ys, xs], (0, 0))
    one_newton = gauss_newton_translation(*args, curvature=curv, photometric=False, max_iterations=1)
    one_plain = gauss_newton_translation(*args, photometric=False, max_iterations=1)
    assert np.hypot(*(one_newton.shift - fit.shift)) < 0.5 * np.hypot(*(one_plain.shift - fit.shift))


def test_gauss_newton_gain_of_a_noisy_template_is_unbiased_with_the_correction():
    # Errors in variables: regressing the image on a template with noise variance v shrinks the
    # gain by var(T) / (var(T) + v). Both the variance correction and a denoised instrument remove
    # that bias (the instrument's own smoothing error aside).
    template, pts, values, gx, gy, _ = _template()
    rng = np.random.default_rng(11)
    v = 30.0 ** 2
    noisy = values + rng.normal(0, 30.0, values.size)
    image = (1.5 * template + 10.0).astype(np.float32)  # the image itself noise-free
    kw = {"huber": None}
    plain = gauss_newton_translation(image, pts, noisy, gx, gy, (0, 0), **kw)
    attenuation = np.var(values) / (np.var(values) + v)
    assert plain.gain == pytest.approx(1.5 * attenuation, rel=0.1)
    corrected = gauss_newton_translation(image, pts, noisy, gx, gy, (0, 0), template_variance=np.full(values.size, v),
                                         **kw)
    assert corrected.gain == pytest.approx(1.5, rel=0.05)
    instrumented = gauss_newton_translation(image, pts, noisy, gx, gy, (0, 0), instrument=values, **kw)
    assert instrumented.gain == pytest.approx(1.5, rel=0.05)
