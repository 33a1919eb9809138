"""semlab.template against the paper's steps 2-5 done directly with OpenCV's primitives: Gaussian
smoothing, Otsu's threshold, an opening (erosion then dilation), a two-level contour hierarchy and
its largest external contour. Each intermediate image must be exactly the reference's."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from semlab.template import identify_contour_template, to_uint8


def scene(shape=(90, 110), seed=0):
    """A blurred disc (r = 18) with a dark hole, a small bright blob and a 1-px speck, noisy."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(float)
    disc = ndtr(-(np.hypot(xx - 45, yy - 45) - 18) / 1.2)
    hole = ndtr(-(np.hypot(xx - 45, yy - 45) - 5) / 1.2)
    blob = ndtr(-(np.hypot(xx - 92, yy - 20) - 6) / 1.2)
    img = 50 + 150 * (disc - hole) + 150 * blob + 4 * rng.standard_normal(shape)
    img[80, 100] = 255.0
    return np.clip(img, 0, 255).astype(np.uint8)


def reference(gray, sigma=2.0, kernel=3, iterations=1, bright=True, threshold=None):
    smoothed = cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else gray
    mode = cv2.THRESH_BINARY if bright else cv2.THRESH_BINARY_INV
    if threshold is None:
        t, binary = cv2.threshold(smoothed, 0, 255, mode | cv2.THRESH_OTSU)
    else:
        t, binary = cv2.threshold(smoothed, threshold, 255, mode)
    morphed = binary
    if kernel > 1 and iterations > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (kernel, kernel))
        morphed = cv2.dilate(cv2.erode(binary, k, iterations=iterations), k, iterations=iterations)
    contours, hierarchy = cv2.findContours(morphed, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    hierarchy = hierarchy.reshape(-1, 4)
    best = max((i for i in range(len(contours)) if hierarchy[i, 3] < 0), key=lambda i: cv2.contourArea(contours[i]))
    mask = np.zeros(gray.shape, np.uint8)
    cv2.drawContours(mask, contours, best, 1, thickness=1)
    region = np.zeros(gray.shape, np.uint8)
    cv2.drawContours(region, contours, best, 1, thickness=cv2.FILLED)
    return {"smoothed": smoothed, "binary": binary, "morphed": morphed, "threshold": t, "hierarchy": hierarchy,
            "contours": contours, "best": best, "mask": mask.astype(bool), "region": region.astype(bool),
            "area": cv2.contourArea(contours[best])}


def check(t, ref):
    for key in ("smoothed", "binary", "morphed", "mask", "region", "hierarchy"):
        np.testing.assert_array_equal(getattr(t, key), ref[key], err_msg=key)
    assert t.threshold == ref["threshold"] and t.area == ref["area"]
    assert len(t.contours) == len(ref["contours"])
    np.testing.assert_array_equal(t.points, ref["contours"][ref["best"]].reshape(-1, 2))
    assert t.length == int(ref["mask"].sum())
    assert t.mask[t.points[:, 1], t.points[:, 0]].all()  # (x, y) points on the 1-px contour


def test_the_default_pipeline_is_the_papers_steps():
    gray = scene()
    t = identify_contour_template(gray)
    ref = reference(gray)
    check(t, ref)
    # the ring (disc minus hole) is the template: its outer boundary has the hole as its child
    assert (t.hierarchy[:, 3] >= 0).sum() == 1
    assert t.area == pytest.approx(np.pi * 18 ** 2, rel=0.06)


@pytest.mark.parametrize("kw", [{"sigma": 0.0}, {"sigma": 1.0}, {"threshold": 120.0}, {"morph_kernel": 5},
                                {"morph_kernel": 2},
                                {"morph_kernel": 1}, {"morph_kernel": 0}, {"morph_iterations": 0},
                                {"morph_iterations": 2}])
def test_every_parameter_acts_as_documented(kw):
    gray = scene(seed=1)
    t = identify_contour_template(gray, **kw)
    ref = reference(gray, sigma=kw.get("sigma", 2.0), kernel=kw.get("morph_kernel", 3),
                    iterations=kw.get("morph_iterations", 1), threshold=kw.get("threshold"))
    check(t, ref)


def test_sigma_zero_takes_a_copy_and_the_opening_removes_the_speck():
    gray = scene()
    t = identify_contour_template(gray, sigma=0.0)
    assert t.smoothed is not gray
    np.testing.assert_array_equal(t.smoothed, gray)
    # without smoothing the 1-px speck survives thresholding; the 3-px opening removes it, so it
    # is a contour only when the morphology is off
    with_opening = identify_contour_template(gray, sigma=0.0)
    without = identify_contour_template(gray, sigma=0.0, morph_kernel=0)
    assert len(without.contours) > len(with_opening.contours)
    assert without.binary[80, 100] == 255 and with_opening.morphed[80, 100] == 0


def test_a_dark_object_needs_bright_object_false():
    gray = 255 - scene(seed=2)
    dark = identify_contour_template(gray, bright_object=False)
    check(dark, reference(gray, bright=False))
    bright = identify_contour_template(255 - gray)
    assert dark.area == pytest.approx(bright.area, rel=0.02)
    fixed = identify_contour_template(gray, bright_object=False, threshold=120.0)
    check(fixed, reference(gray, bright=False, threshold=120.0))


def test_the_smallest_usable_template_encloses_4_px2():
    # contours run through pixel centres: a 3x3 block encloses 2 x 2 = 4 px², the least accepted
    block = np.zeros((20, 20), np.uint8)
    block[8:11, 8:11] = 200
    t = identify_contour_template(block, sigma=0.0, morph_kernel=0)
    assert t.area == 4.0 and t.length == 8


def test_to_uint8_stretches_linearly_and_rounds():
    np.testing.assert_array_equal(to_uint8(np.array([[0.0, 1.0, 2.0, 3.0, 4.0]])), [[0, 64, 128, 191, 255]])
    np.testing.assert_array_equal(to_uint8(np.array([[10, 20]], np.uint16)), [[0, 255]])
    u8 = np.array([[3, 7]], np.uint8)
    assert to_uint8(u8) is u8  # uint8 passes through untouched
    assert to_uint8(np.full((2, 3), 5.0)).dtype == np.uint8 and not to_uint8(np.full((2, 3), 5.0)).any()
    with pytest.raises(TypeError, match=r"^image must hold real gray levels"):
        to_uint8(np.zeros((2, 2), bool))


def test_template_errors_name_the_problem():
    with pytest.raises(ValueError, match=r"^the ROI is constant: there is no object to take a contour from$"):
        identify_contour_template(np.full((30, 30), 9, np.uint8))
    with pytest.raises(ValueError, match=r"^image must be a non-empty 2-D array, got shape \(3, 30, 30\)$"):
        identify_contour_template(np.zeros((3, 30, 30), np.uint8))
    with pytest.raises(ValueError, match=r"^image must be a non-empty 2-D array, got shape \(0, 5\)$"):
        identify_contour_template(np.zeros((0, 5), np.uint8))
    with pytest.raises(ValueError, match=r"^image must be a 2-D gray image"):
        identify_contour_template(np.zeros((3, 30, 30)))
    with pytest.raises(ValueError, match=r"^threshold must be finite, got nan$"):
        identify_contour_template(scene(), threshold=float("nan"))
    tiny = np.zeros((30, 30), np.uint8)
    tiny[10:12, 10:12] = 200  # a 2x2 square: its contour encloses 1 px²
    with pytest.raises(ValueError, match=r"^the largest contour in the ROI encloses less than 4 px²"):
        identify_contour_template(tiny, sigma=0.0, morph_kernel=0)
    with pytest.raises(ValueError, match=r"^no contour in the ROI: the threshold leaves no object \(threshold 250\.0\)"):
        identify_contour_template(scene(), threshold=250.0, sigma=3.0)


def needle_and_blob(tip=(60, 45), blob_at=(95, 75), blob_radius=13, shape=(90, 110)):
    """A thin bright triangle from the left border to ``tip`` and a larger bright disc, on a dark ROI."""
    img = np.full(shape, 50, np.uint8)
    needle = np.array([[0, tip[1] - 8], [tip[0], tip[1]], [0, tip[1] + 8]], np.int32)
    cv2.fillPoly(img, [needle], 200)
    cv2.circle(img, blob_at, blob_radius, 200, -1)
    return img


def holds(t, point):
    return cv2.pointPolygonTest(t.points.reshape(-1, 1, 2).astype(np.int32), point, False) >= 0


def test_central_takes_the_contour_at_the_roi_centre_not_the_largest():
    img = needle_and_blob()  # the needle's tip at the centre (54.5, 44.5): inside it, 5 px from its apex
    largest, central = identify_contour_template(img), identify_contour_template(img, choose="central")
    assert holds(largest, (95, 75)) and not holds(largest, (54.5, 44.5))
    assert holds(central, (54.5, 44.5)) and central.area < largest.area
    check(largest, reference(img))  # "largest", the default, is the paper's as before


def test_central_takes_the_nearest_contour_when_none_holds_the_centre():
    img = needle_and_blob(tip=(48, 45))  # the tip 6.5 px short of the centre; the blob 30 px away
    assert holds(identify_contour_template(img, choose="central"), (40, 45))


def test_central_passes_over_specks_under_a_tenth_of_the_largest():
    img = needle_and_blob(tip=(48, 45))
    cv2.circle(img, (55, 45), 2, 200, -1)  # a 13-px² speck on the centre, the needle ~400 px²
    central = identify_contour_template(img, choose="central", morph_kernel=0)
    assert holds(central, (40, 45)) and not holds(central, (55, 45))


def probe_over_substrate(shape=(90, 110)):
    """A bright probe (210) from the left border to the centre over a substrate (130), a dark
    trench (40) in front of its tip: at Otsu's level the probe and the substrate are one region."""
    img = np.full(shape, 130, np.uint8)
    img[25:65, 62:] = 40
    cv2.fillPoly(img, [np.array([[0, 36], [54, 44], [0, 52]], np.int32)], 210)
    return img


def test_central_tells_a_probe_from_the_brighter_substrate_it_reaches_over():
    img = probe_over_substrate()
    merged = identify_contour_template(img)  # the paper's: Otsu's level, the largest contour
    assert merged.region.mean() > 0.5 and holds(merged, (30, 10))  # the substrate is part of it
    check(merged, reference(img))
    central = identify_contour_template(img, choose="central")
    assert central.region.mean() < 0.1 and holds(central, (50, 44)) and not holds(central, (30, 10))
    assert 130 <= central.threshold < 210  # between the substrate and the probe: the brightest class
    assert (central.otsu_classes, merged.otsu_classes) == (3, 2)
    # a threshold the user gives is the user's, the region whatever it holds
    given = identify_contour_template(img, choose="central", threshold=merged.threshold)
    assert given.region.mean() > 0.5 and given.otsu_classes is None


def test_central_keeps_otsus_level_when_the_region_is_a_probe():
    img = needle_and_blob(tip=(56, 45))
    assert (identify_contour_template(img, choose="central").threshold
            == identify_contour_template(img).threshold)


def test_an_unknown_choice_is_refused():
    with pytest.raises(ValueError, match="choose must be one of"):
        identify_contour_template(needle_and_blob(), choose="nearest")
