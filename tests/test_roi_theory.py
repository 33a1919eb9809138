"""semlab.roi against its specification: exact ROI geometry, frame checks, motion differencing on
synthetic stacks whose background median and change image are known in closed form."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from semlab.roi import (
    as_gray_float,
    check_roi,
    clip_window,
    motion_energy,
    roi_centre,
    roi_from_click,
    roi_from_motion,
)


def test_as_gray_float_keeps_the_values_as_c_contiguous_float32():
    for arr in (np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000, np.arange(12, dtype=np.int8).reshape(3, 4) - 6,
                np.linspace(0, 1, 12).reshape(4, 3).T):
        out = as_gray_float(arr)
        assert out.dtype == np.float32 and out.flags.c_contiguous and out.shape == arr.shape
        np.testing.assert_array_equal(out, arr.astype(np.float32))
    with pytest.raises(ValueError, match=r"^probe frame holds NaN or infinite pixels$"):
        as_gray_float(np.array([[1.0, np.inf]]), name="probe frame")
    with pytest.raises(ValueError, match=r"^frame has shape \(4, 4, 4\): an RGB\(A\) frame; convert it to gray "
                       r"first \(e\.g\. semlab\.io\.read_image does\)$"):
        as_gray_float(np.zeros((4, 4, 4)))
    with pytest.raises(ValueError, match=r"^frame must be a 2-D gray image"):
        as_gray_float(np.zeros((4, 4, 2)))
    with pytest.raises(TypeError, match=r"^frame must hold real gray levels"):
        as_gray_float(np.zeros((4, 4), bool))


def test_check_roi_limits_are_inclusive():
    shape = (100, 120)
    assert check_roi((0, 0, 120, 100), shape) == (0, 0, 120, 100)  # the whole image
    assert check_roi((112, 92, 8, 8), shape) == (112, 92, 8, 8)  # touching the far corner, 8 px
    assert check_roi((10.4, 19.6, 30.2, 40.0), shape) == (10, 20, 30, 40)  # rounded
    assert check_roi((0, 0, 5, 5), shape, min_size=5) == (0, 0, 5, 5)
    assert check_roi((0, 0, 120, 100), (100, 120, 3)) == (0, 0, 120, 100)  # an RGB shape's first two
    assert clip_window(500, 500, 20, 10, (100, 120, 3)) == (100, 90, 20, 10)
    for roi in ((113, 0, 8, 8), (0, 93, 8, 8), (0, -1, 8, 8)):
        with pytest.raises(ValueError, match=r"^roi .* is not wholly inside the 120x100 image$"):
            check_roi(roi, shape)
    for roi in ((0, 0, 7, 8), (0, 0, 8, 7)):
        with pytest.raises(ValueError, match=r"^window .* is smaller than 8x8 px"):
            check_roi(roi, shape, name="window")


def test_roi_centre_and_clip_window():
    assert roi_centre((10, 20, 5, 8)) == (12.0, 23.5)  # pixel centres at integers: x + (w - 1)/2
    shape = (100, 120)
    assert clip_window(60.0, 50.0, 21, 11, shape) == (50, 45, 21, 11)  # centred exactly
    assert clip_window(59.4, 50.6, 20, 10, shape) == (50, 46, 20, 10)  # round(cx - 9.5), round(cy - 4.5)
    assert clip_window(-30, 500, 20, 10, shape) == (0, 90, 20, 10)  # shifted in, not shrunk
    assert clip_window(119, 0, 20, 10, shape) == (100, 0, 20, 10)
    assert clip_window(10, 10, 500, 300, shape) == (0, 0, 120, 100)  # window larger: the whole image


def test_roi_from_click_edges_of_the_frame():
    frame = np.zeros((60, 80))
    # pixel centres are integers, so the frame spans [-0.5, cols - 0.5]: both ends are inside
    assert roi_from_click(frame, (-0.5, -0.5), size=20) == (0, 0, 20, 20)
    assert roi_from_click(frame, (79.5, 59.5), size=20) == (60, 40, 20, 20)
    assert roi_from_click(frame, (40, 30), size=(80, 60)) == (0, 0, 80, 60)  # as large as the frame
    assert roi_from_click(frame, (40, 30), size=(8, 8)) == (36, 26, 8, 8)
    for click in ((-0.51, 10), (10, -0.51), (79.51, 10), (10, 59.51), (np.nan, 10), (10, np.inf)):
        with pytest.raises(ValueError, match=r"^click .* lies outside the 80x60 frame$"):
            roi_from_click(frame, click, size=20)
    for size in ((81, 20), (20, 61)):
        with pytest.raises(ValueError, match=r"^a \d+x\d+ ROI does not fit in the 80x60 frame$"):
            roi_from_click(frame, (40, 30), size=size)
    for size in (7, (8, 7), (7, 8)):
        with pytest.raises(ValueError, match=r"^ROI size .* is too small \(at least 8x8 px\)$"):
            roi_from_click(frame, (40, 30), size=size)
    # an RGB-shaped frame only lends its first two dimensions
    assert roi_from_click(np.zeros((60, 80, 3)), (40, 30), size=20) == (30, 20, 20, 20)


def _stack_with_a_moving_square(n=6, shape=(80, 100), amplitude=50.0, step=10, y0=30, size=10, x0=15):
    frames = []
    for k in range(n):
        f = np.full(shape, 40.0)
        f[y0:y0 + size, x0 + step * k:x0 + step * k + size] += amplitude
        frames.append(f)
    return frames


def test_motion_energy_is_the_mean_absolute_difference_from_the_median():
    frames = _stack_with_a_moving_square()
    stack = np.stack(frames).astype(np.float32)
    raw = np.mean(np.abs(stack - np.median(stack, axis=0)), axis=0).astype(np.float32)
    np.testing.assert_allclose(motion_energy(frames, sigma=0), raw, rtol=1e-6)
    np.testing.assert_allclose(motion_energy(frames), cv2.GaussianBlur(raw, (0, 0), 3.0), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(motion_energy(frames, sigma=0.5), cv2.GaussianBlur(raw, (0, 0), 0.5), rtol=1e-5,
                               atol=1e-5)
    # each square position is covered in 1 of 6 frames (the median is the background): energy 50/6
    assert motion_energy(frames, sigma=0)[35, 22] == pytest.approx(50.0 / 6)
    assert motion_energy(frames, sigma=0)[10, 10] == 0.0
    assert motion_energy(frames[:3], sigma=0).shape == (80, 100)  # three frames are enough
    with pytest.raises(ValueError, match=r"^motion differencing needs at least 3 frames$"):
        motion_energy(frames[:2])
    bad = [frames[0], np.full((80, 100), np.nan), frames[2]]
    with pytest.raises(ValueError, match=r"^frame 1 holds NaN"):
        motion_energy(bad)


def test_roi_from_motion_centres_on_a_blob_that_does_not_touch_the_border():
    # the square steps by its own size, so each position is covered in one frame only (the median is
    # the background) and the change in the last frame is the square itself, symmetric after the
    # blur: the weighted centroid is its centre exactly
    frames = _stack_with_a_moving_square()
    last_x0 = 15 + 10 * 5
    cx, cy = last_x0 + 4.5, 30 + 4.5
    for size in (20, (30, 16)):
        w, h = (size, size) if np.isscalar(size) else size
        assert roi_from_motion(frames, size=size) == clip_window(cx, cy, w, h, (80, 100))
    assert roi_from_motion(frames, size=20, sigma=0) == clip_window(cx, cy, 20, 20, (80, 100))
    # only the first max_frames count: with 4 frames the last position is x0 = 15 + 10*3
    assert roi_from_motion(frames, size=20, max_frames=4) == clip_window(15 + 30 + 4.5, cy, 20, 20, (80, 100))
    assert roi_from_motion(frames + frames[:1] * 5, size=20)[2:] == (20, 20)  # default max_frames = 10


def test_roi_from_motion_takes_the_tip_of_a_region_entering_from_the_border():
    # a bar entering from the left border, its front 60 px in, only in the last frame: the tip is
    # the point farthest from where the region touches the border
    shape = (80, 120)
    frames = [np.full(shape, 40.0) for _ in range(4)]
    frames[-1] = frames[-1].copy()
    frames[-1][36:44, 0:60] += 80.0
    x, y, w, h = roi_from_motion(frames, size=20, sigma=0)
    assert (w, h) == (20, 20)
    tip_x = x + (w - 1) / 2
    assert 58 <= tip_x <= 60 and abs(y + (h - 1) / 2 - 39.5) <= 4  # the front, within the bar's height
    # the same bar entering from the right (mirror): the tip is at the mirrored front
    mirrored = [f[:, ::-1].copy() for f in frames]
    xm, _, _, _ = roi_from_motion(mirrored, size=20, sigma=0)
    assert 119 - 60 <= xm + 9.5 <= 119 - 58
    # from the top and from the bottom (transposed geometry)
    top = [np.full((120, 80), 40.0) for _ in range(4)]
    top[-1][0:60, 36:44] += 80.0
    _, yt, _, _ = roi_from_motion(top, size=20, sigma=0)
    assert 58 <= yt + 9.5 <= 60
    bottom = [f[::-1].copy() for f in top]
    _, yb, _, _ = roi_from_motion(bottom, size=20, sigma=0)
    assert 119 - 60 <= yb + 9.5 <= 119 - 58


def test_the_background_is_the_per_pixel_median():
    # a textured static background: only the per-pixel median cancels it (a single global level
    # would leave the texture as "motion")
    rng = np.random.default_rng(3)
    background = rng.uniform(20, 220, (80, 100))
    frames = [background + (f - 40.0) for f in _stack_with_a_moving_square()]
    np.testing.assert_allclose(motion_energy(frames, sigma=0)[:20], 0.0, atol=1e-4)  # rows without the square
    assert roi_from_motion(frames, size=20) == clip_window(65 + 4.5, 34.5, 20, 20, (80, 100))


def test_roi_from_motion_picks_the_largest_moving_region_and_needs_three_frames():
    shape = (80, 100)
    frames = [np.zeros(shape) for _ in range(3)]
    frames[-1] = frames[-1].copy()
    frames[-1][10:14, 10:14] = 50.0  # small blob: label 1 in raster order
    frames[-1][40:56, 60:76] = 50.0  # the larger one: label 2
    assert roi_from_motion(frames, size=20, sigma=0) == clip_window(67.5, 47.5, 20, 20, shape)
    assert roi_from_motion(frames, sigma=0)[2:] == (100, 80)  # default 200 px, clipped to the frame
    # a faint change (0.8 gray levels) on a still, noise-free background is still motion
    faint = [np.zeros(shape) for _ in range(3)]
    faint[-1] = faint[-1].copy()
    faint[-1][40:56, 60:76] = 0.8
    assert roi_from_motion(faint, size=20, sigma=0) == clip_window(67.5, 47.5, 20, 20, shape)
    # the peak must reach 5x the median change: a uniform change of 1 with a blob of 5.5 passes
    level = [np.zeros(shape), np.zeros(shape), np.ones(shape)]
    level[-1][40:56, 60:76] = 5.5
    assert roi_from_motion(level, size=20, sigma=0) == clip_window(67.5, 47.5, 20, 20, shape)
    level[-1][40:56, 60:76] = 4.5
    with pytest.raises(ValueError, match="no motion found"):
        roi_from_motion(level, size=20, sigma=0)


def test_roi_from_motion_refuses_still_or_too_few_frames():
    still = [np.full((40, 40), 9.0)] * 4
    with pytest.raises(ValueError, match=r"^no motion found in the frames: step the probe"):
        roi_from_motion(still)
    rng = np.random.default_rng(0)
    noise_only = [50 + rng.standard_normal((60, 60)) for _ in range(5)]  # no change above 5x the median
    with pytest.raises(ValueError, match=r"^no motion found"):
        roi_from_motion(noise_only, size=20)
    with pytest.raises(ValueError, match=r"^motion differencing needs at least 3 frames$"):
        roi_from_motion(still[:2])
    with pytest.raises(ValueError, match=r"^frame 2 holds NaN"):
        roi_from_motion([still[0], still[0], np.full((40, 40), np.nan)])
