"""A change of dose mid-sequence: the flags and sigmas must still tell the frames that are off (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest
from test_track_uncertainty import CENTRE, ROI, wedge_frame

from semlab.subpixel import noise_variance
from semlab.tracking import Tracker
from semlab.tracking.ic import AVERAGE_MAX_NOISE_RATIO

STEP_PX = 2.0  # along the wedge's axis, per frame
LOW_NOISE, HIGH_NOISE = 2.0, 40.0  # gray levels, on the wedge's contrast of 130


def _after_a_dose_drop(n_frames, *, noise=HIGH_NOISE):
    """The tracker started on a frame at LOW_NOISE, and its results on ``n_frames`` later frames at ``noise``."""
    tracker = Tracker()
    tracker.init(wedge_frame(0.0, 0.0, noise=LOW_NOISE, seed=0), ROI)
    results = [tracker.update(wedge_frame(STEP_PX * k, 0.0, noise=noise, seed=k)) for k in range(1, n_frames + 1)]
    return tracker, results


def test_no_silent_frame_after_a_dose_drop():
    # Frame 0 at noise 2, every later frame at noise 40. Averaged into the template, the noisy frames made
    # it noisier than frame 0 alone, and 6 of 40 frames were 1.0-1.7 px off along the axis (where only the
    # apex tells x) at sigma_x 0.34-0.44 px. A frame more than 1 px off is a 3-sigma event for a sigma
    # under 0.35 px (0.3 % a frame): over 40 frames at most one.
    _, results = _after_a_dose_drop(40)
    silent = sum(bool(r.ok and abs(r.x - CENTRE[0] - STEP_PX * (k + 1)) > 1.0) for k, r in enumerate(results))
    assert silent <= 1


def test_frames_after_a_dose_drop_stay_out_of_the_template():
    # 400 times frame 0's noise variance: no frame enters the average, whatever it scores.
    tracker, _ = _after_a_dose_drop(8)
    assert tracker.algorithm.averager.count == 1


def test_frames_at_the_same_dose_enter_the_template():
    tracker, results = _after_a_dose_drop(8, noise=LOW_NOISE)
    assert all(r.ok for r in results) and tracker.algorithm.averager.count == 9


def test_frames_under_a_raised_contrast_enter_the_template():
    # The detector's contrast raised 1.6x: the noise grows with the signal (2.6x the variance in gray
    # levels), but not against the probe's contrast; the registration's gain takes the change.
    tracker = Tracker()
    tracker.init(wedge_frame(0.0, 0.0, noise=LOW_NOISE, seed=0), ROI)
    for k in range(1, 9):
        r = tracker.update(1.6 * wedge_frame(STEP_PX * k, 0.0, noise=LOW_NOISE, seed=k))
        assert r.ok
    assert tracker.algorithm.averager.count == 9


@pytest.mark.parametrize("sd", [2.0, 10.0, 40.0])
def test_noise_variance_reads_the_noise_not_the_scene(sd):
    # A wedge (edges on a few % of the pixels) with per-line offsets of 5 gray levels: the row pairs'
    # medians take the offsets out, the median absolute difference the edges. 25 row pairs (every 8th) x 260 px:
    # the MAD's variance is within ~3 % (1 sd), so 12 % is 4 sd.
    rng = np.random.default_rng(int(sd))
    frame = wedge_frame(0.0, 0.0, noise=sd, seed=int(sd)) + rng.normal(0.0, 5.0, (200, 1)).astype(np.float32)
    assert noise_variance(frame) == pytest.approx(sd * sd, rel=0.12)


def test_the_dose_gate_lets_a_few_percent_through():
    # The frames of one dose agree to well within the gate: the gate is not a threshold on their scatter.
    variances = [noise_variance(wedge_frame(0.0, 0.0, noise=10.0, seed=s)) for s in range(10)]
    assert max(variances) / min(variances) < AVERAGE_MAX_NOISE_RATIO / 1.5
