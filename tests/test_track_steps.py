"""The paper's steps one by one, on small analytic images (Ru et al. 2012, Figs. 2-3, eqs. 2-10).

Every image here is rendered analytically (a Gaussian-blurred disc or wedge, ``erf`` edges), so
the true geometry and shifts are known exactly and the tolerances come from theory: the
truncation error of the 5-point derivative, the linearisation error of one Gauss–Newton step,
the interpolation error of a cubic kernel on a blurred edge.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.special import ndtr

from semlab.edges import adaptive_canny_thresholds, canny_edges, image_gradients
from semlab.matching import (
    contour_match,
    hager_belhumeur_increment,
    offline_matrix,
    parabola_peak,
    ssd_match,
)
from semlab.metrics import LOSS_PX, summarize_errors, tracking_errors
from semlab.roi import (
    as_gray_float,
    check_roi,
    clip_window,
    roi_centre,
    roi_from_click,
    roi_from_motion,
)
from semlab.subpixel import (
    estimate_noise,
    five_point_gradients,
    gauss_newton_translation,
    gradient_subpixel_shift,
    sample_bicubic,
    sample_shifted,
    sample_shifted_filtered,
    whiten_lines,
)
from semlab.template import identify_contour_template


def disc(shape=(80, 80), centre=(40.0, 40.0), radius=15.0, sigma=1.0, inside=200.0, outside=60.0):
    """A disc with a Gaussian-blurred edge (exact for a straight edge, close for r ≫ σ)."""
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    d = np.hypot(xx - centre[0], yy - centre[1]) - radius
    return outside + (inside - outside) * ndtr(-d / sigma)


def wedge(shape=(120, 160), tip=(100.0, 60.0), half_angle_deg=14.0, sigma=1.0, inside=200.0, outside=60.0):
    """A probe-like wedge pointing to +x with its apex at ``tip``, blurred edges."""
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    vx, vy = xx - tip[0], yy - tip[1]
    a = np.radians(half_angle_deg)
    # Outward normals of the two edges of the cone {behind the tip, within ±a of the −x axis}.
    d1 = vx * np.sin(a) + vy * np.cos(a)
    d2 = vx * np.sin(a) - vy * np.cos(a)
    apex = (d1 > 0) & (d2 > 0)
    d = np.where(apex, np.hypot(vx, vy), np.maximum(d1, d2))
    return outside + (inside - outside) * ndtr(-d / sigma)


# --------------------------------------------------------------------------- ROI (step 1)
def test_roi_from_click_centres_and_clips():
    frame = np.zeros((480, 640), np.uint8)
    roi = roi_from_click(frame, (320.0, 240.0))
    assert roi[2:] == (200, 200)
    assert roi_centre(roi) == pytest.approx((320.0, 240.0), abs=0.5)
    # Near the border the ROI is shifted, not shrunk, and lies inside the frame.
    x, y, w, h = roi_from_click(frame, (5, 470), size=(120, 80))
    assert (w, h) == (120, 80) and x == 0 and y + h == 480
    with pytest.raises(ValueError, match="outside"):
        roi_from_click(frame, (700, 10))
    with pytest.raises(ValueError, match="does not fit"):
        roi_from_click(frame, (10, 10), size=500)
    with pytest.raises(ValueError, match="too small"):
        roi_from_click(frame, (10, 10), size=4)


def test_check_roi_rejects_bad_rois():
    shape = (100, 120)
    assert check_roi((10, 20, 30, 40), shape) == (10, 20, 30, 40)
    for roi, msg in [((110, 10, 30, 30), "not wholly inside"), ((-5, 10, 30, 30), "not wholly inside"),
                     ((500, 500, 30, 30), "not wholly inside"), ((10, 10, 4, 30), "too small"),
                     (("a", 1, 2, 3), "four numbers"), ((1, 2, 3), "four numbers")]:
        with pytest.raises(ValueError, match=msg):
            check_roi(roi, shape)
    assert clip_window(5, 5, 50, 50, shape) == (0, 0, 50, 50)
    assert clip_window(200, 200, 50, 50, shape) == (70, 50, 50, 50)


@pytest.mark.parametrize("frame, error, msg", [
    (np.zeros((10, 10, 3), np.uint8), ValueError, "RGB"),
    (np.zeros((10, 10), bool), TypeError, "gray levels"),
    (np.zeros((10, 10), complex), TypeError, "gray levels"),
    (np.zeros(10), ValueError, "2-D"),
    (np.zeros((0, 10)), ValueError, "empty"),
    (np.full((10, 10), np.nan), ValueError, "NaN"),
    (np.array([["a", "b"]]), TypeError, "gray levels"),
])
def test_frames_are_checked(frame, error, msg):
    with pytest.raises(error, match=msg):
        as_gray_float(frame)


def test_roi_from_motion_finds_the_stepping_probe_within_ten_frames():
    rng = np.random.default_rng(1)
    background = 60 + 25 * rng.standard_normal((240, 320))  # static texture
    frames = []
    for k in range(8):  # the probe stepped 4 px along x per frame (paper, step 1)
        tip = (120.0 + 4 * k, 110.0)
        frames.append(np.where(wedge((240, 320), tip) > 130, wedge((240, 320), tip), background))
    roi = roi_from_motion(frames, size=100)
    x, y, w, h = roi
    assert (w, h) == (100, 100)
    assert x <= 120 + 4 * 7 <= x + w - 1 and y <= 110 <= y + h - 1
    with pytest.raises(ValueError, match="no motion"):
        roi_from_motion([background] * 5)
    with pytest.raises(ValueError, match="at least 3"):
        roi_from_motion([background] * 2)


# --------------------------------------------------------------------------- template (steps 2-5)
def test_contour_template_of_a_disc():
    img = disc(radius=15.0, sigma=1.5)
    t = identify_contour_template(img)
    # The Otsu threshold of a two-level image lies between the levels, so the contour is the
    # half-level line of the symmetric blur: the disc's radius, up to the pixel grid.
    assert t.area == pytest.approx(np.pi * 15.0 ** 2, rel=0.06)
    assert t.hierarchy.shape[1] == 4
    assert t.region.sum() >= t.area
    assert t.mask.sum() == t.length and 70 < t.length < 110  # ~ 2πr, one pixel wide
    for im in (t.smoothed, t.binary, t.morphed):
        assert im.shape == img.shape and im.dtype == np.uint8
    assert 60 < t.threshold < 200


def test_two_level_hierarchy_and_largest_external_contour():
    # A ring (a disc with a hole) beside a small blob: RETR_CCOMP gives the hole as a child of
    # the ring's outer boundary, and the template is the largest external contour (the ring).
    img = disc((100, 140), (50, 50), 25, 1.0) - (disc((100, 140), (50, 50), 10, 1.0) - 60)
    img = np.maximum(img, disc((100, 140), (115, 50), 6, 1.0))
    t = identify_contour_template(img)
    parents = t.hierarchy[:, 3]
    assert (parents >= 0).sum() == 1 and (parents < 0).sum() == 2
    ring_area = np.pi * (25 ** 2)
    assert t.area == pytest.approx(ring_area, rel=0.06)
    assert t.points[:, 0].max() < 80  # not the blob on the right


def test_template_errors():
    with pytest.raises(ValueError, match="constant"):
        identify_contour_template(np.full((50, 50), 7.0))
    speck = np.zeros((50, 50))
    speck[25, 25] = 255.0
    with pytest.raises(ValueError, match="no contour|no usable template"):
        identify_contour_template(speck, sigma=0)


# --------------------------------------------------------------------------- adaptive Canny (eq. 10)
def test_adaptive_thresholds_follow_eq_10():
    rng = np.random.default_rng(0)
    img = np.clip(disc((120, 120), (60, 60), 30, 1.2) + 6 * rng.standard_normal((120, 120)), 0, 255)
    img = img.astype(np.uint8)
    t_low, t_high = adaptive_canny_thresholds(img, sigma=1.0, bins=256)
    # Independent computation of the paper's recipe from the same gradient magnitude.
    _, _, mag = image_gradients(img, sigma=1.0)
    g = mag.ravel().astype(float)
    counts, edges = np.histogram(g, bins=256, range=(0, g.max()))
    peak = 0.5 * (edges[np.argmax(counts)] + edges[np.argmax(counts) + 1])
    s1 = np.sqrt(np.mean((g - peak) ** 2))
    s1p = np.sqrt(np.mean((g[g <= peak + s1] - peak) ** 2))
    assert t_high == pytest.approx(peak + s1, rel=1e-6)
    assert t_low == pytest.approx(peak + s1p, rel=1e-6)
    assert 0 < t_low < t_high


def test_adaptive_canny_keeps_the_contour_where_a_fixed_threshold_loses_it():
    # Gray-level fluctuation: the same disc at a third of the contrast (paper, Fig. 3).
    rng = np.random.default_rng(2)
    faint = 80 + 0.3 * (disc((120, 120), (60, 60), 30, 1.2) - 60) + 2 * rng.standard_normal((120, 120))
    faint = np.clip(faint, 0, 255).astype(np.uint8)
    truth = identify_contour_template(disc((120, 120), (60, 60), 30, 1.2)).mask

    def recall(edges):
        near = np.zeros_like(edges)
        ys, xs = np.nonzero(edges)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                near[np.clip(ys + dy, 0, 119), np.clip(xs + dx, 0, 119)] = True
        return near[truth].mean()

    adaptive = canny_edges(faint, sigma=1.0)
    fixed = canny_edges(faint, low=100.0, high=200.0, sigma=1.0)
    assert recall(adaptive) > 0.9
    assert recall(fixed) < 0.5
    with pytest.raises(ValueError, match="both"):
        canny_edges(faint, low=10.0)


# --------------------------------------------------------------------------- matching (eqs. 2-5)
def test_ssd_and_contour_match_find_integer_shifts():
    big = disc((140, 140), (70, 70), 20, 1.0)
    template = big[40:100, 40:100]
    moved = disc((140, 140), (70 + 7, 70 - 4), 20, 1.0)
    x, y, ssd = ssd_match(moved, template)
    assert (x, y) == (47, 36) and ssd < 1.0
    t = identify_contour_template(template)
    edges = canny_edges(moved.astype(np.uint8), sigma=1.0)
    cx, cy, score, scores = contour_match(edges, t.mask, tolerance_px=1)
    assert abs(cx - 47) <= 1 and abs(cy - 36) <= 1 and score > 0.9
    assert scores.shape == (81, 81)
    with pytest.raises(ValueError, match="larger"):
        ssd_match(template, big)
    with pytest.raises(ValueError, match="no pixels"):
        contour_match(edges, np.zeros_like(t.mask))


def test_parabola_peak_recovers_a_quadratic_vertex():
    yy, xx = np.mgrid[:9, :9].astype(float)
    scores = -((xx - 4.3) ** 2) - 2 * (yy - 3.8) ** 2
    assert parabola_peak(scores, 4, 4) == pytest.approx((4.3, 3.8), abs=1e-9)


def test_hager_belhumeur_increment_eq_5():
    template = disc((60, 60), (30, 30), 12, 2.0)
    true = np.array([0.3, -0.2])
    warped = disc((60, 60), (30 + true[0], 30 + true[1]), 12, 2.0)  # I(f(R; 0), t_n)
    m0 = offline_matrix(template)
    assert m0.shape == (60 * 60, 2)
    delta = hager_belhumeur_increment(template, warped, m0)
    # The object moved by d, so I(x + d, t_n) = I(x, t_0): from μ = 0 one step gives Δμ ≈ d, up
    # to the linearisation's second-order error, |d|²/(2σ) ≈ 0.03 px here.
    assert delta == pytest.approx(true, abs=0.03)


# --------------------------------------------------------------------------- sub-pixel (eqs. 6-9)
def test_five_point_derivative_is_exact_for_quartics():
    yy, xx = np.mgrid[:20, :20].astype(float)
    img = xx ** 4 / 100 - 2 * yy ** 3 + xx * yy
    ix, iy = five_point_gradients(img)
    inner = (slice(2, -2), slice(2, -2))
    # Truncation error O(h⁴): zero for polynomials up to degree 4 (float32 rounding aside).
    np.testing.assert_allclose(ix[inner], (4 * xx ** 3 / 100 + yy)[inner], rtol=1e-5, atol=1e-2)
    np.testing.assert_allclose(iy[inner], (-6 * yy ** 2 + xx)[inner], rtol=1e-5, atol=1e-2)


@pytest.mark.parametrize("shift", [(0.3, -0.2), (-0.45, 0.1), (0.0, 0.0)])
def test_gradient_subpixel_shift_eq_9(shift):
    template = disc((60, 60), (30, 30), 12, 2.0)
    target = disc((60, 60), (30 + shift[0], 30 + shift[1]), 12, 2.0)
    dx, dy = gradient_subpixel_shift(template, target)
    # Eq. 9 is one linearised step: the error is second order, |d|²/(2σ) ≲ 0.05 px here.
    assert (dx, dy) == pytest.approx(shift, abs=0.05)
    assert np.isnan(gradient_subpixel_shift(np.ones((20, 20)), np.ones((20, 20)))[0])


def test_interpolators_agree_and_reproduce_quadratics():
    yy, xx = np.mgrid[:30, :30].astype(np.float32)
    img = 0.5 * xx ** 2 - yy * xx + 3 * yy
    pts = np.array([[10, 12], [15, 7], [20, 20]], float)
    shift = (0.37, -1.62)
    exact = 0.5 * (pts[:, 0] + shift[0]) ** 2 - (pts[:, 1] + shift[1]) * (pts[:, 0] + shift[0]) + 3 * (pts[:, 1] + shift[1])
    for f in (lambda: sample_shifted(img, pts, shift), lambda: sample_shifted_filtered(img, pts, shift),
              lambda: sample_bicubic(img, pts[:, 0] + shift[0], pts[:, 1] + shift[1])):
        np.testing.assert_allclose(f(), exact, rtol=1e-5)  # Keys (a = −0.5) is exact for quadratics


def test_noise_model_is_estimated_from_one_image():
    rng = np.random.default_rng(3)
    level = np.where(np.arange(256)[None, :] < 128, 60.0, 180.0).repeat(256, 0)
    white = rng.standard_normal(level.shape) * np.sqrt(4.0 + 2.0 * level)
    noise = np.empty_like(white)
    noise[:, 0] = white[:, 0]
    for k in range(1, white.shape[1]):  # AR(1) along the line, variance preserved
        noise[:, k] = 0.5 * noise[:, k - 1] + np.sqrt(1 - 0.25) * white[:, k]
    model = estimate_noise(level + noise)
    assert model.rho == pytest.approx(0.5, abs=0.05)
    assert model.variance(60.0) == pytest.approx(124.0, rel=0.15)
    assert model.variance(180.0) == pytest.approx(364.0, rel=0.15)
    w = whiten_lines(noise, model.rho)
    lag1 = np.mean(w[:, 1:] * w[:, :-1]) / np.mean(w * w)
    assert abs(lag1) < 0.05


def _band_points(img):
    t = identify_contour_template(img)
    from semlab.tracking.band import contour_band

    band = contour_band(t.mask, 3)
    ys, xs = np.nonzero(band)
    return np.stack([xs, ys], 1).astype(float), t.region[ys, xs]


def test_gauss_newton_recovers_shift_gain_and_offset():
    template = wedge(sigma=1.2).astype(np.float32)
    pts, inside = _band_points(template)
    gx, gy = five_point_gradients(template)
    ys, xs = pts[:, 1].astype(int), pts[:, 0].astype(int)
    shift = (1.3, -0.7)
    image = (1.7 * wedge(tip=(100 + shift[0], 60 + shift[1]), sigma=1.2) - 20.0).astype(np.float32)
    # Joint regression of gain and offset: noise-free, what is left is the cubic interpolation
    # error on a σ = 1.2 px edge (< 0.01 px). Two-level photometry (region means, frozen once the
    # steps fall below 0.01 px) adds a lag of the same order as that threshold along the
    # weakly constrained axis: 0.03 px.
    for regions, tol in ((None, 0.01), (inside, 0.03)):
        fit = gauss_newton_translation(image, pts, template[ys, xs], gx[ys, xs], gy[ys, xs], (0.0, 0.0),
                                       regions=regions)
        assert fit.converged
        assert tuple(fit.shift) == pytest.approx(shift, abs=tol)
        assert fit.gain == pytest.approx(1.7, rel=0.01)


def test_gauss_newton_setup_and_early_stop_change_nothing_that_matters():
    # The per-template constants computed once (setup=) are what every call would compute: the
    # same answer to rounding. Early stop ends one extrapolated step early, so within a few
    # times the tolerance of the full iteration (noisy image: the iterations shrink geometrically).
    from semlab.subpixel import gauss_newton_setup

    template = wedge(sigma=1.2).astype(np.float32)
    pts, inside = _band_points(template)
    gx, gy = five_point_gradients(template)
    ys, xs = pts[:, 1].astype(int), pts[:, 0].astype(int)
    rng = np.random.default_rng(3)
    image = (1.2 * wedge(tip=(100.8, 59.6), sigma=1.2) + 5.0 + 3.0 * rng.standard_normal(template.shape)).astype(np.float32)
    weights = np.linspace(0.5, 1.0, len(ys))
    args = (image, pts, template[ys, xs], gx[ys, xs], gy[ys, xs], (0.0, 0.0))
    for regions in (None, inside):
        setup = gauss_newton_setup(template[ys, xs], gx[ys, xs], gy[ys, xs], weights=weights, regions=regions)
        plain = gauss_newton_translation(*args, weights=weights, regions=regions)
        cached = gauss_newton_translation(*args, weights=weights, regions=regions, setup=setup)
        early = gauss_newton_translation(*args, weights=weights, regions=regions, setup=setup, early_stop=True)
        assert plain.converged and cached.converged and early.converged
        np.testing.assert_allclose(cached.shift, plain.shift, atol=1e-9)
        assert cached.gain == pytest.approx(plain.gain, rel=1e-9)
        assert np.hypot(*(early.shift - plain.shift)) < 5 * 2e-3
        assert early.iterations <= plain.iterations


def test_huber_weights_resist_an_occluder():
    template = wedge(sigma=1.2).astype(np.float32)
    pts, _ = _band_points(template)
    gx, gy = five_point_gradients(template)
    ys, xs = pts[:, 1].astype(int), pts[:, 0].astype(int)
    image = wedge(tip=(100.4, 60.2), sigma=1.2).astype(np.float32)
    image[40:70, 40:70] = 250.0  # a bright particle over part of the shaft's edges
    robust = gauss_newton_translation(image, pts, template[ys, xs], gx[ys, xs], gy[ys, xs], (0, 0), huber=2.0,
                                      tukey=True)
    plain = gauss_newton_translation(image, pts, template[ys, xs], gx[ys, xs], gy[ys, xs], (0, 0), huber=None)
    err_robust = np.hypot(*(robust.shift - (0.4, 0.2)))
    err_plain = np.hypot(*(plain.shift - (0.4, 0.2)))
    assert err_robust < 0.05 and err_robust < 0.5 * err_plain
    assert robust.inliers < 0.95


# --------------------------------------------------------------------------- metrics
def test_metrics_against_known_errors():
    truth = pd.DataFrame({"frame": range(5), "x": [10.0, 11.0, 12.0, 13.0, 14.0], "y": 20.0,
                          "visible": [True, True, True, True, False]})
    roi = (0, 0, 21, 41)  # centre (10, 20)
    result = pd.DataFrame({"frame": range(5), "x": [10.0, 11.3, 11.9, np.nan, 99.0],
                           "y": [20.0, 20.0, 20.4, np.nan, 20.0], "score": 1.0,
                           "ok": [True, True, True, False, True]})
    e = tracking_errors(result, truth, roi)
    np.testing.assert_allclose(e["ex"].to_numpy()[:3], [0.0, 0.3, -0.1], atol=1e-12)
    s = summarize_errors(e, crb=(0.1, 0.1))
    # Frame 0 is the origin and frame 4 is invisible: frames 1-3 count, frame 3 is lost.
    assert s["n"] == 3
    assert s["loss_rate"] == pytest.approx(1 / 3)
    assert s["rmse"] == pytest.approx(np.sqrt((0.3 ** 2 + 0.1 ** 2 + 0.4 ** 2) / 2))
    assert s["crb"] == pytest.approx(np.hypot(0.1, 0.1))
    assert LOSS_PX == 2.0
    with pytest.raises(ValueError, match="frame 0"):
        tracking_errors(result[result.frame > 0], truth, roi)
