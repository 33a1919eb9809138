"""Semi-real composites (semlab.sim.composite): exact Fourier shifts, the alpha matte, shot noise, the bound."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.registration import phase_cross_correlation

from semlab.sim.composite import (
    MIN_GRAY,
    ShiftableLayer,
    add_shot_noise,
    composite,
    composite_crb,
    cut_out_object,
    fourier_shift,
)
from semlab.sim.crb import crb_from_fisher, fisher_information


def test_fourier_shift_of_a_band_limited_signal_is_its_analytic_shift():
    # a sum of sinusoids below Nyquist, periodic on the (odd) canvas: the shifted samples are known
    h, w = 63, 81
    yy, xx = np.mgrid[:h, :w].astype(float)

    def signal(dx, dy):
        x, y = xx - dx, yy - dy
        return (np.cos(2 * np.pi * 5 * x / w + 0.3) + 0.5 * np.sin(2 * np.pi * (7 * x / w + 4 * y / h))
                + 0.25 * np.cos(2 * np.pi * 30 * y / h))

    out = fourier_shift(np.fft.rfft2(signal(0, 0)), (h, w), 0.37, -1.61)
    np.testing.assert_allclose(out, signal(0.37, -1.61), atol=1e-12)


def _blob_layer(max_shift=10.0):
    """A smooth bright object in a 160 x 140 'source' frame and its layer on a 100 x 80 window."""
    yy, xx = np.mgrid[:140, :160].astype(float)
    source = 60 + 150 * np.exp(-(((xx - 80) / 12) ** 2 + ((yy - 70) / 8) ** 2))
    alpha = cut_out_object(source, (80, 70), threshold=100.0)
    return source, alpha, ShiftableLayer(source, alpha, (30, 30, 100, 80), max_shift_px=max_shift)


def test_integer_shift_is_a_roll_and_shifts_compose():
    _, _, layer = _blob_layer()
    lay0, a0 = layer.shifted(0, 0)
    lay, a = layer.shifted(3, -2)
    # the object is far from the window's border: an integer shift equals moving the pixels
    np.testing.assert_allclose(lay[2:-3, 3:], lay0[4:-1, :-3], atol=1e-9)
    np.testing.assert_allclose(a[2:-3, 3:], a0[4:-1, :-3], atol=1e-9)
    # the all-pass shift loses nothing: there and back again is the identity (on an odd-sized
    # array, as the layer's canvas is: an even side has a Nyquist bin the real inverse FFT halves)
    odd = lay0[:-1, :-1]
    spec = np.fft.rfft2(odd)
    back = fourier_shift(np.fft.rfft2(fourier_shift(spec, odd.shape, 0.3, 0.7)), odd.shape, -0.3, -0.7)
    np.testing.assert_allclose(back, odd, atol=1e-9)


@pytest.mark.parametrize("shift", [(0.25, -0.5), (1.37, 2.91), (-4.6, 0.13)])
def test_composite_moves_the_object_by_the_requested_subpixel_shift(shift):
    _, _, layer = _blob_layer()
    bg = np.full((80, 100), 40.0)
    a = composite(bg, layer, 0, 0) - 40
    b = composite(bg, layer, *shift) - 40
    est, _, _ = phase_cross_correlation(a, b, upsample_factor=1000, normalization=None)
    # registering b onto a takes -shift (rows, cols); the cross-correlation peak of a band-limited
    # object and its shifted copy is at the shift, found to 1/1000 px by the upsampled DFT
    np.testing.assert_allclose([-est[1], -est[0]], shift, atol=0.005)


def test_cut_out_keeps_the_object_and_softens_its_edge():
    source, alpha, _ = _blob_layer()
    assert alpha[70, 80] == pytest.approx(1.0)
    assert alpha[5, 5] == pytest.approx(0.0)
    assert 0 < alpha.max() <= 1 and np.any((alpha > 0.05) & (alpha < 0.95))  # a soft edge
    with pytest.raises(ValueError, match="not on the object"):
        cut_out_object(source, (5, 5), threshold=100.0)
    with pytest.raises(ValueError, match="outside"):
        cut_out_object(source, (500, 5), threshold=100.0)


def test_layer_refuses_a_window_without_room_and_a_too_large_shift():
    source, alpha, layer = _blob_layer(max_shift=10.0)
    with pytest.raises(ValueError, match="does not fit"):
        ShiftableLayer(source, alpha, (0, 0, 100, 80), max_shift_px=10.0)
    with pytest.raises(ValueError, match="max_shift_px"):
        layer.shifted(11.0, 0.0)


def test_shot_noise_has_the_poisson_mean_and_variance():
    rng = np.random.default_rng(0)
    clean = np.full((400, 400), 120.0)
    frame = add_shot_noise(clean, 20.0, rng)
    # 160,000 pixels: mean to ~0.03 %, variance to ~0.5 % (1 sigma); 255 * 120 / 20 = 1530
    assert frame.mean() == pytest.approx(120.0, rel=2e-3)
    assert frame.var() == pytest.approx(255 * 120 / 20, rel=0.03)
    assert frame.dtype == np.float32
    with pytest.raises(ValueError, match="dose"):
        add_shot_noise(clean, 0.0, rng)


def test_composite_bound_scales_as_one_over_root_dose():
    # F is proportional to the dose for Poisson noise (variance 255 m / dose): sigma ~ dose^-1/2 exactly
    _, _, layer = _blob_layer()
    bg = np.full((80, 100), 40.0)
    s1 = np.array(composite_crb(bg, layer, (0.3, 0.1), (0, 0, 100, 80), 10.0))
    s4 = np.array(composite_crb(bg, layer, (0.3, 0.1), (0, 0, 100, 80), 40.0))
    np.testing.assert_allclose(s4, s1 / 2, rtol=1e-9)
    assert MIN_GRAY > 0


def test_fisher_information_of_an_edge_in_white_noise():
    # m = a + b (x - dx): J_x = -b everywhere, so F_xx = N b^2 / s^2 and y carries no information
    h, w, b, s2 = 20, 30, 3.0, 4.0
    xx = np.arange(w, dtype=float)[None, :].repeat(h, 0)

    def render(dx, dy):
        return 10 + b * (xx - dx) + 0 * dy

    F = fisher_information(render, np.full((h, w), s2), (0, 0, w, h))
    assert F[0, 0] == pytest.approx(h * w * b * b / s2, rel=1e-9)
    assert F[1, 1] == 0
    assert crb_from_fisher(F) == (float("inf"), float("inf"))  # y is not identifiable
