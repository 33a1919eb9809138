"""semlab.edges against its specification: Canny (L2) on the Sobel gradients of the Gaussian-smoothed
image, thresholds from eq. 10 of the paper computed independently here.

The references call OpenCV's primitives directly, so the comparison is exact (integer Sobel
gradients, the same blur): any change of smoothing, kernel, norm or threshold shows.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from semlab.edges import adaptive_canny_thresholds, canny_edges, image_gradients


def noisy_disc(seed=0, shape=(96, 96), radius=25.0, noise=6.0, ramp=0.0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    d = np.hypot(xx - shape[1] / 2, yy - shape[0] / 2) - radius
    img = 60 + 140 * ndtr(-d / 1.2) + ramp * xx + noise * rng.standard_normal(shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def reference_gradients(gray, sigma):
    smoothed = cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else gray
    return cv2.Sobel(smoothed, cv2.CV_16S, 1, 0, ksize=3), cv2.Sobel(smoothed, cv2.CV_16S, 0, 1, ksize=3)


def reference_thresholds(gray, sigma, bins=256):
    """Eq. 10: peak of the gradient histogram on [0, max], RMS deviation from it, recomputed below T_h."""
    dx, dy = reference_gradients(gray, sigma)
    g = np.hypot(dx.astype(float), dy.astype(float)).ravel()
    counts, edges = np.histogram(g, bins=bins, range=(0.0, g.max()))
    peak = 0.5 * (edges[np.argmax(counts)] + edges[np.argmax(counts) + 1])
    t_high = peak + np.sqrt(np.mean((g - peak) ** 2))
    t_low = peak + np.sqrt(np.mean((g[g <= t_high] - peak) ** 2))
    return t_low, t_high


@pytest.mark.parametrize("sigma", [1.0, 0.5, 2.0, 0.0])
def test_image_gradients_are_sobel_of_the_smoothed_image(sigma):
    gray = noisy_disc()
    dx, dy, mag = image_gradients(gray, sigma=sigma) if sigma != 1.0 else image_gradients(gray)
    rdx, rdy = reference_gradients(gray, sigma)
    np.testing.assert_array_equal(dx, rdx)
    np.testing.assert_array_equal(dy, rdy)
    assert dx.dtype == np.int16 and mag.dtype == np.float32
    np.testing.assert_allclose(mag, np.hypot(rdx.astype(float), rdy.astype(float)), rtol=1e-6)


def test_image_gradients_stretch_a_float_image_first():
    # a float image is stretched onto 0-255 before the uint8 Sobel (to_uint8): scaling it changes nothing
    f = noisy_disc().astype(float) / 255.0
    a = image_gradients(f)
    b = image_gradients(7.0 * f + 3.0)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_allclose(a[2], b[2], rtol=1e-6)  # cv2.magnitude's float32 rounding


@pytest.mark.parametrize("sigma, ramp", [(1.0, 0.0), (2.0, 0.0), (1.0, 1.5)])
def test_adaptive_thresholds_are_eq_10(sigma, ramp):
    # ramp > 0: every pixel has a gradient, so the histogram must start at 0, not at the smallest one
    gray = noisy_disc(seed=1, ramp=ramp)
    got = adaptive_canny_thresholds(gray, sigma=sigma) if sigma != 1.0 else adaptive_canny_thresholds(gray)
    assert got == pytest.approx(reference_thresholds(gray, sigma), rel=1e-6)
    assert adaptive_canny_thresholds(gray, sigma=sigma, bins=64) == pytest.approx(
        reference_thresholds(gray, sigma, bins=64), rel=1e-6)


def test_a_flat_image_has_zero_thresholds():
    assert adaptive_canny_thresholds(np.full((20, 20), 90, np.uint8)) == (0.0, 0.0)
    assert not canny_edges(np.full((20, 20), 90, np.uint8)).any()


@pytest.mark.parametrize("sigma", [1.0, 2.0])
def test_canny_edges_is_l2_canny_on_those_gradients(sigma):
    gray = noisy_disc(seed=2)
    dx, dy = reference_gradients(gray, sigma)
    low, high = reference_thresholds(gray, sigma)
    want = cv2.Canny(dx, dy, low, high, L2gradient=True) > 0
    got = canny_edges(gray, sigma=sigma) if sigma != 1.0 else canny_edges(gray)
    np.testing.assert_array_equal(got, want)
    assert got.dtype == bool and want.sum() > 100
    fixed = canny_edges(gray, low=20.0, high=60.0, sigma=sigma)
    np.testing.assert_array_equal(fixed, cv2.Canny(dx, dy, 20.0, 60.0, L2gradient=True) > 0)
    # the L1 norm would find a different edge set on a disc (diagonal gradients are larger in L1)
    assert not np.array_equal(fixed, cv2.Canny(dx, dy, 20.0, 60.0, L2gradient=False) > 0)


def test_canny_threshold_validation():
    gray = noisy_disc()
    canny_edges(gray, low=0.0, high=0.0)  # 0 <= low <= high holds with equality
    canny_edges(gray, low=5.0, high=5.0)
    for low, high in ((-1.0, 5.0), (6.0, 5.0), (float("nan"), 5.0), (1.0, float("inf"))):
        with pytest.raises(ValueError, match=r"^Canny thresholds need 0 <= low <= high"):
            canny_edges(gray, low=low, high=high)
    for kw in ({"low": 1.0}, {"high": 1.0}):
        with pytest.raises(ValueError, match=r"^give both low and high thresholds, or neither"):
            canny_edges(gray, **kw)


def test_canny_on_a_texture_depends_on_every_threshold_and_on_sigma():
    # A blurred random texture has gradients at every level, so the edge map changes with each
    # threshold and with the smoothing (a disc's clean edge would hide such changes).
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (96, 96)).astype(np.uint8), (0, 0), 1.5)
    for sigma in (1.0, 2.0):
        dx, dy = reference_gradients(tex, sigma)
        low, high = reference_thresholds(tex, sigma)
        assert reference_thresholds(tex, 1.0) != pytest.approx(reference_thresholds(tex, 2.0), rel=0.05)
        np.testing.assert_array_equal(canny_edges(tex, sigma=sigma), cv2.Canny(dx, dy, low, high, L2gradient=True) > 0)
        np.testing.assert_array_equal(canny_edges(tex, low=5.0, high=high, sigma=sigma),
                                      cv2.Canny(dx, dy, 5.0, high, L2gradient=True) > 0)
        assert (canny_edges(tex, low=5.0, high=high, sigma=sigma) != canny_edges(tex, sigma=sigma)).any()
