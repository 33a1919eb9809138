"""The band reaches across a blurred edge: :func:`semlab.tracking.band.edge_blur` and the widths.

A real needle's edge (``data/real-sem``) rises over 1-2 px of blur σ, the simulator's over ~0.5 px;
a band of 2-3 px cuts a blurred edge's slope off. The blur is read from frame 0's steepest slope
along the contour against the object's contrast (an erf edge: slope ``C / (√(2π) σ)``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.special import erf

from semlab.template import identify_contour_template
from semlab.tracking import Tracker
from semlab.tracking.band import EDGE_BAND_SIGMAS, MAX_EDGE_BAND_PX, edge_blur

ROI = (60, 40, 200, 200)
SHAPE = (280, 320)
CENTRE = (150.0, 140.0)
#: A large disc: over the contour its curvature changes the profile by far less than the blur.
RADIUS = 70.0


def disc(sigma: float, *, noise: float = 0.0, dx: float = 0.0, seed: int = 0) -> np.ndarray:
    """A bright disc (contrast 120 over 60) whose edge is a step blurred by ``sigma`` px."""
    yy, xx = np.mgrid[:SHAPE[0], :SHAPE[1]].astype(np.float64)
    r = np.hypot(xx - CENTRE[0] - dx, yy - CENTRE[1])
    img = 60.0 + 120.0 * 0.5 * (1.0 - erf((r - RADIUS) / (math.sqrt(2.0) * sigma)))
    if noise:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    return img.astype(np.float32)


def roi_blur(image) -> float:
    x, y, w, h = ROI
    patch = image[y:y + h, x:x + w]
    contour = identify_contour_template(np.clip(np.rint(patch), 0, 255).astype(np.uint8))
    return edge_blur(patch, contour)


@pytest.mark.parametrize("sigma", [0.8, 1.2, 1.6, 2.2])
def test_the_blur_of_an_erf_edge_is_read_from_its_slope(sigma):
    # Two small biases of opposite sign: the steepest sampled slope lies within half a pixel of
    # the edge's centre, where a Gaussian slope of total width s = √(σ² + 1) is exp(-1/(8 s²)) of
    # its peak (at most 4 % low: σ up to ~6 % high); the region means take in the transition's
    # pixels on each side, which lowers the contrast by ~2σ/√(2π) over the ROI's mean depth of
    # the regions (~30 px here: σ up to ~5 % low at σ = 2.2).
    measured = roi_blur(disc(sigma))
    assert sigma * 0.93 <= measured <= sigma * 1.06


@pytest.mark.parametrize("seed", range(3))
def test_noise_makes_the_blur_look_smaller_never_larger(seed):
    # The steepest of 25 noisy slopes is biased up: the blur can only be underestimated (and the
    # band then keeps its default widths).
    clean = roi_blur(disc(1.5))
    noisy = roi_blur(disc(1.5, noise=6.0, seed=seed))
    assert noisy <= clean + 0.02


def test_no_region_or_no_contour_inside_the_roi_has_no_blur():
    x, y, w, h = ROI
    patch = disc(1.5)[y:y + h, x:x + w]
    contour = identify_contour_template(np.clip(np.rint(patch), 0, 255).astype(np.uint8))
    empty = dataclasses.replace(contour, region=np.zeros_like(contour.region))
    border_only = dataclasses.replace(contour, mask=np.pad(np.ones((h - 2, w - 2), bool), 1) ^ np.ones((h, w), bool))
    assert edge_blur(patch, empty) == 0.0 and edge_blur(patch, border_only) == 0.0


@pytest.mark.parametrize(("sigma", "widths"), [(0.5, (3, 3)), (1.2, (4, 4)), (1.6, (5, 5)), (2.2, (5, 5))])
def test_the_band_covers_the_edges_transition(sigma, widths):
    t = Tracker()
    t.init(disc(sigma), ROI)
    assert t.edge_sigma == pytest.approx(sigma, rel=0.07) if sigma > 1.0 else t.edge_sigma < 1.0
    assert t.band_widths() == widths
    if sigma > 1.0:
        assert widths[0] == min(math.ceil(EDGE_BAND_SIGMAS * t.edge_sigma), MAX_EDGE_BAND_PX)
    # An explicit band_px and the paper's methods keep their widths.
    explicit = Tracker(band_px=3)
    explicit.init(disc(sigma), ROI)
    assert explicit.band_widths() == (3, 3)
    paper = Tracker("contour")
    paper.init(disc(sigma), ROI)
    assert paper.band_widths() == (3, 3)


def test_a_blurred_edge_is_followed_within_its_bound():
    # A disc with a 1.6-px blur moved in steps of 0.37 px under noise 4: the wide band follows it
    # with errors well inside a pixel, and every frame reports a sigma that covers its error at
    # 4 σ (a loose test of calibration on one scene; the corpus measures it properly).
    shifts = [0.37 * k for k in range(12)]
    frames = [disc(1.6, noise=4.0, dx=s, seed=k) for k, s in enumerate(shifts)]
    t = Tracker()
    first = t.init(frames[0], ROI)
    assert t.band_widths() == (5, 5)
    for k in range(1, len(frames)):
        r = t.update(frames[k])
        assert r.ok
        err = r.x - first.x - shifts[k]
        assert abs(err) < 0.2 and abs(err) < 4 * r.sigma_x + 0.05
