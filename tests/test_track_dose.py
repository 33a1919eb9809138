"""A change of dose mid-sequence: the flags and sigmas must still tell the frames that are off (issue 14)."""

from __future__ import annotations

import pytest
from test_track_uncertainty import CENTRE, ROI, wedge_frame

from semlab.tracking import Tracker

STEP_PX = 2.0  # along the wedge's axis, per frame


@pytest.mark.xfail(strict=True, reason=(
    "known limitation (measured, issue 14): after a dose drop (frame 0 at noise 2, every later frame at noise 40 "
    "on a contrast of 130) the wedge moving 2 px a frame is reported ok on 38 of 40 frames, 8 of them 1.0-2.2 px "
    "off along the axis (where only the apex tells x) at a median sigma_x of 0.37 px: the fit's local "
    "curvature (its Fisher information) does not cover them; a second minimum of the cost within reach is the "
    "likely cause, not checked"))
def test_no_silent_frame_after_a_dose_drop():
    # With every ok frame's sigma under max_sigma = 0.35 px, a frame more than 1 px off is a ~3-sigma event
    # (0.4 % a frame): over 40 frames at most one.
    tracker = Tracker()
    tracker.init(wedge_frame(0.0, 0.0, noise=2.0, seed=0), ROI)
    silent = 0
    for k in range(1, 41):
        r = tracker.update(wedge_frame(STEP_PX * k, 0.0, noise=40.0, seed=k))
        silent += bool(r.ok and abs(r.x - CENTRE[0] - STEP_PX * k) > 1.0)
    assert silent <= 1
