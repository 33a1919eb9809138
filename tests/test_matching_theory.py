"""semlab.matching against closed forms: the SSD of eq. 2, the contour score as a pixel count, the
3-point parabola vertex, and the increment of eqs. 3-5 as a linear least-squares solution."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from semlab.matching import (
    contour_match,
    hager_belhumeur_increment,
    offline_matrix,
    parabola_peak,
    ssd_match,
)
from semlab.subpixel import five_point_gradients


def test_parabola_vertex_clipped_flat_and_at_the_border():
    yy, xx = np.mgrid[:7, :9].astype(float)
    scores = -((xx - 4.2) ** 2) - 3 * (yy - 2.7) ** 2
    assert parabola_peak(scores, 4, 3) == pytest.approx((4.2, 2.7), abs=1e-12)
    # the vertex of the parabola through 3 points, 0.5 (a - c) / (a - 2b + c), kept within ±0.5 px
    peak = np.array([[0.0, 0.2, 0.0], [0.0, 1.0, 0.9], [0.0, 0.6, 0.0]])
    assert parabola_peak(peak, 1, 1) == pytest.approx((1 + 0.5 * (0 - 0.9) / (0 - 2 + 0.9),
                                                       1 + 0.5 * (0.2 - 0.6) / (0.2 - 2 + 0.6)), abs=1e-12)
    rising = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 3.0], [0.0, 0.0, 0.0]])
    assert parabola_peak(rising, 1, 1) == pytest.approx((0.5, 1.0))  # vertex offset -1.5 -> -0.5
    falling = np.array([[0.0, 0.0, 0.0], [3.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    assert parabola_peak(falling, 1, 1) == pytest.approx((1.5, 1.0))  # +1.5 -> +0.5
    assert parabola_peak(-falling, 1, 1) == pytest.approx((1.5, 1.0))
    flat = np.ones((3, 3))
    assert parabola_peak(flat, 1, 1) == (1.0, 1.0)  # no curvature: the integer position
    # on the map's border there is no neighbour on one side: that axis stays integer
    assert parabola_peak(scores, 0, 3) == pytest.approx((0.0, 2.7), abs=1e-12)
    assert parabola_peak(scores, 8, 3) == pytest.approx((8.0, 2.7), abs=1e-12)
    assert parabola_peak(scores, 4, 0) == pytest.approx((4.2, 0.0), abs=1e-12)
    assert parabola_peak(scores, 4, 6) == pytest.approx((4.2, 6.0), abs=1e-12)


def test_ssd_match_returns_the_best_offset_and_its_mean_squared_difference():
    rng = np.random.default_rng(0)
    window = rng.uniform(0, 255, (40, 50)).astype(np.float32)
    template = window[12:22, 30:45] + 2.0  # a constant 2 gray-level offset everywhere
    x, y, ssd = ssd_match(window, template)
    assert (x, y) == (30, 12)
    # Mean of 2² over the template. OpenCV's TM_SQDIFF expands Σ(w − t)² = Σw² − 2Σwt + Σt² in float32, so the
    # answer carries the rounding of those large sums: a few float32 epsilons of mean(w² + t²) (~0.02 here; the
    # SIMD path of the CPU decides how many: below 4e-4 on one machine, 8e-4 on another).
    rounding = 4 * float(np.finfo(np.float32).eps) * float(np.mean(window[12:22, 30:45] ** 2) + np.mean(template ** 2))
    assert ssd == pytest.approx(4.0, abs=rounding)
    same = ssd_match(window, window)
    assert same[:2] == (0, 0) and same[2] == pytest.approx(0.0, abs=1e-3)
    with pytest.raises(ValueError, match=r"^template \(10, 51\) is larger than the search window \(40, 50\)$"):
        ssd_match(window, np.zeros((10, 51)))
    with pytest.raises(ValueError, match="larger than the search window"):
        ssd_match(window, np.zeros((41, 10)))


def test_contour_score_is_the_fraction_of_contour_pixels_on_edges():
    mask = np.zeros((5, 5), bool)
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = True  # a square outline of 16 px
    edges = np.zeros((20, 30), bool)
    edges[6:11, 12:17] = mask
    edges[7, 13] = True  # an extra edge pixel inside: not on the contour, no score
    x, y, score, scores = contour_match(edges, mask)
    # cv2.matchTemplate correlates in float32: scores to ~1e-7
    assert (x, y) == (12, 6) and score == pytest.approx(1.0, abs=1e-6)
    assert scores.shape == (16, 26)
    # one pixel to the right: the score is the count of outline pixels that land on edges
    assert scores[6, 13] == pytest.approx((edges[6:11, 13:18] & mask).sum() / 16)
    # the top row and the left column erased (9 of the 16 outline pixels): 7/16 at the same place
    half = edges.copy()
    half[6, 12:17] = False
    half[6:11, 12] = False
    assert contour_match(half, mask)[:3] == (12, 6, pytest.approx(7 / 16))
    with pytest.raises(ValueError, match=r"^the contour template has no pixels$"):
        contour_match(edges, np.zeros((5, 5), bool))
    with pytest.raises(ValueError, match="larger than the search window"):
        contour_match(edges[:4], mask)


def test_contour_tolerance_dilates_the_edges_by_that_many_pixels():
    mask = np.zeros((7, 7), bool)
    mask[3, :] = True  # a 7-px horizontal segment
    edges = np.zeros((15, 15), bool)
    edges[8, 4:11] = True  # the segment, one row lower than where the template sits at y = 4
    # zero tolerance: exact placement (y = 5) scores 1
    assert contour_match(edges, mask)[:3] == (4, 5, pytest.approx(1.0, abs=1e-6))
    # at y = 4 (one px off) the score is 0 without tolerance and 1 with a 1-px tolerance
    assert contour_match(edges, mask)[3][4, 4] == pytest.approx(0.0, abs=1e-6)
    assert contour_match(edges, mask, tolerance_px=1)[3][4, 4] == pytest.approx(1.0, abs=1e-6)
    # a 2-px offset needs a 2-px tolerance (elliptical element of radius 2)
    assert contour_match(edges, mask, tolerance_px=1)[3][3, 4] == pytest.approx(0.0, abs=1e-6)
    assert contour_match(edges, mask, tolerance_px=2)[3][3, 4] == pytest.approx(1.0, abs=1e-6)


def test_contour_tolerance_is_a_disc_in_both_directions():
    # one contour pixel, one edge pixel: the score at an offset (dx, dy) is 1 exactly when the
    # offset lies in the elliptical (disc) structuring element of radius tolerance_px
    mask = np.zeros((3, 3), bool)
    mask[1, 1] = True
    edges = np.zeros((21, 21), bool)
    edges[10, 10] = True
    for tol in (1, 2, 3):
        scores = contour_match(edges, mask, tolerance_px=tol)[3]  # template pixel at (x + 1, y + 1)
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * tol + 1, 2 * tol + 1)).astype(bool)
        got = scores[9 - tol:10 + tol, 9 - tol:10 + tol] > 0.5
        np.testing.assert_array_equal(got, disc)
        assert (scores > 0.5).sum() == disc.sum()  # nothing outside the disc
    # radius 2: (2, 0) and (0, 2) are inside, the corner (2, 2) is not (a square would take it)
    scores = contour_match(edges, mask, tolerance_px=2)[3]
    assert scores[9, 11] > 0.5 and scores[11, 9] > 0.5 and scores[11, 11] < 0.5


def test_contour_ties_are_broken_towards_the_preferred_offset():
    # a straight edge matches equally well along itself: the score map has a ridge of ties
    mask = np.zeros((5, 5), bool)
    mask[2, :] = True
    edges = np.zeros((12, 20), bool)
    edges[6, :] = True
    x, y, score, _ = contour_match(edges, mask)
    assert score == pytest.approx(1.0, abs=1e-6) and y == 4 and x == 0  # first in raster order by default
    assert contour_match(edges, mask, prefer=(9.2, 4.0))[:2] == (9, 4)
    assert contour_match(edges, mask, prefer=(100.0, -3.0))[:2] == (15, 4)  # nearest tie
    # ties in two dimensions: the nearest by Euclidean distance, whatever the direction
    blob = np.ones((12, 20), bool)
    dot = np.zeros((3, 3), bool)
    dot[1, 1] = True
    for prefer, want in (((3.0, 8.0), (3, 8)), ((16.4, 0.2), (16, 0)), ((-5.0, 4.0), (0, 4)), ((9.0, 30.0), (9, 9))):
        assert contour_match(blob, dot, prefer=prefer)[:2] == want
    # a tie means equal counts: a placement one contour pixel short (score 4/5) is not a tie
    edges[6, 15:] = False
    assert contour_match(edges, mask, prefer=(15.0, 4.0))[:2] == (10, 4)


def disc(shape=(50, 50), centre=(25.0, 25.0), radius=10.0, sigma=2.0):
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    return 60 + 140 * ndtr(-(np.hypot(xx - centre[0], yy - centre[1]) - radius) / sigma)


def test_offline_matrix_stacks_the_five_point_gradients_of_the_pixels():
    t = disc()
    ix, iy = five_point_gradients(t)
    m0 = offline_matrix(t)
    np.testing.assert_array_equal(m0, np.stack([ix.ravel(), iy.ravel()], 1).astype(np.float64))
    mask = np.zeros(t.shape, bool)
    mask[10:20, 5:40] = True
    m0m = offline_matrix(t, mask)
    assert m0m.shape == (350, 2) and m0m.dtype == np.float64
    np.testing.assert_array_equal(m0m, np.stack([ix[mask], iy[mask]], 1))


def test_integer_images_and_masks_are_taken_as_numbers():
    # uint8 frames must not wrap around in I(f(R; μ)) - I(R): the increment is computed in floats;
    # a 0/1 integer mask selects pixels like a boolean one
    t = disc()
    w = disc(centre=(25.3, 24.8))
    t8, w8 = np.round(t).astype(np.uint8), np.round(w).astype(np.uint8)
    np.testing.assert_allclose(hager_belhumeur_increment(t8, w8),
                               hager_belhumeur_increment(np.round(t), np.round(w)), rtol=1e-12)
    mask = np.zeros(t.shape, np.uint8)
    mask[10:20, 5:40] = 1
    np.testing.assert_array_equal(offline_matrix(t, mask), offline_matrix(t, mask.astype(bool)))
    np.testing.assert_allclose(hager_belhumeur_increment(t, w, mask=mask),
                               hager_belhumeur_increment(t, w, mask=mask.astype(bool)), rtol=1e-12)


def test_increment_is_the_least_squares_solution_of_eq_5():
    t = disc()
    warped = disc(centre=(25.3, 24.8))
    mask = np.abs(np.hypot(*(np.mgrid[:50, :50][::-1] - 25.0)) - 10.0) < 5
    for m in (None, mask):
        use = np.ones(t.shape, bool) if m is None else m
        m0 = offline_matrix(t, use)
        want = -np.linalg.lstsq(m0, (warped - t)[use], rcond=None)[0]
        np.testing.assert_allclose(hager_belhumeur_increment(t, warped, mask=m), want, rtol=1e-9)
        np.testing.assert_allclose(hager_belhumeur_increment(t, warped, m0, mask=m), want, rtol=1e-9)
    # the object moved by +d, so the template's coordinates move by +d: one step gives ≈ d up to
    # the second-order linearisation error |d|²/(2σ) ≈ 0.02 px (σ = 2 px)
    assert hager_belhumeur_increment(t, warped, mask=mask) == pytest.approx((0.3, -0.2), abs=0.03)
    with pytest.raises(ValueError, match=r"^template \(50, 50\) and warped image \(50, 49\) differ in shape$"):
        hager_belhumeur_increment(t, warped[:, :-1])
