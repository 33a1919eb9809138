"""A recording played through the Microscope protocol gives the tracker what the frames give it directly;
a servo run saved with its provenance; the target picker."""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np
import pandas as pd
import pytest

import semlab
from semlab.instruments.picker import TargetPicker
from semlab.instruments.record import save_run
from semlab.instruments.replay import RecordingExhausted, ReplayMicroscope
from semlab.positioning import PositionerCalibration
from semlab.protocols import Microscope, ScaledMicroscope, TimedMicroscope
from semlab.tracking import Tracker


@pytest.fixture(scope="module")
def sample():
    return semlab.load_sample("synthetic_moves_200px")


def test_replay_plays_every_frame_at_the_recording_period(sample):
    scope = ReplayMicroscope(sample)
    assert isinstance(scope, Microscope) and isinstance(scope, TimedMicroscope)
    assert isinstance(scope, ScaledMicroscope) and scope.pixel_size_nm == pytest.approx(66.0)
    assert scope.frame_period == pytest.approx(1 / 13)  # from the synthetic sample's record
    for k in range(len(sample)):
        np.testing.assert_array_equal(scope.grab(), sample.frames[k])
        assert scope.last_frame_time == pytest.approx(k / 13)
    with pytest.raises(RecordingExhausted, match="12 frames"):
        scope.grab()
    scope.rewind()
    np.testing.assert_array_equal(scope.grab(), sample.frames[0])


def test_replayed_frames_are_read_only_and_loop(sample):
    scope = ReplayMicroscope(sample.frames[:3], frame_period=0.1, loop=True)
    frames = [scope.grab() for _ in range(5)]
    np.testing.assert_array_equal(frames[3], sample.frames[0])
    with pytest.raises(ValueError):
        frames[0][0, 0] = 1
    assert scope.pixel_size_nm is None


def test_the_tracker_sees_the_same_through_the_protocol(sample):
    direct = semlab.track(sample.frames, sample.roi, method="ic")
    replayed = semlab.track(ReplayMicroscope(sample), sample.roi, method="ic")
    pd.testing.assert_frame_equal(direct, replayed)
    # and a hand-written grab loop, as a live instrument is read
    scope = ReplayMicroscope(sample)
    tracker = Tracker()
    tracker.init(scope.grab(), sample.roi)
    xs = [tracker.update(scope.grab()).x for _ in range(len(sample) - 1)]
    np.testing.assert_allclose(xs, direct["x"].iloc[1:], atol=1e-9)


def test_files_replay_once_their_period_is_given(tmp_path):
    pattern = str(semlab.data_path("real-sem/contact_brightness_seq") / "liftout_contact_brightness_*_ib.png")
    with pytest.raises(ValueError, match="frame_period"):
        ReplayMicroscope(pattern)
    scope = ReplayMicroscope(pattern, frame_period=2.0, pixel_size_nm=52.0)
    assert len(scope) == 11 and scope.grab().ndim == 2 and scope.pixel_size_nm == 52.0


def test_realtime_replay_is_paced():
    scope = ReplayMicroscope(np.zeros((4, 20, 20), np.uint8), frame_period=0.05, realtime=True)
    start = time.monotonic()
    for _ in range(4):
        scope.grab()
    assert time.monotonic() - start >= 0.15 - 0.01  # frames 1-3 are due 0.05 s apart


@pytest.mark.parametrize("bad, words", [(np.zeros((0, 8, 8)), "at least one"), (np.zeros(5), "at least one")])
def test_bad_recordings_are_refused(bad, words):
    with pytest.raises(ValueError, match=words):
        ReplayMicroscope(bad, frame_period=0.1)


def test_a_nonpositive_period_is_refused():
    with pytest.raises(ValueError, match="frame_period"):
        ReplayMicroscope(np.zeros((2, 8, 8)), frame_period=0.0)


def test_a_run_is_saved_with_its_provenance(tmp_path):
    cal = PositionerCalibration(np.array([[0.02, -0.001], [0.001, 0.018]]), np.full((2, 2), 1e-4), 0.1, 0.05,
                                600.0, pd.DataFrame({"move": [0]}), {"roi": [1, 2, 3, 4]})
    table = pd.DataFrame({"frame": [0, 1], "x": [1.0, 2.0], "ok": [True, False]})
    sidecar = save_run(table, tmp_path / "run" / "servo.csv", calibration=cal, roi=(1, 2, 3, 4),
                       target=(10.0, 20.0), params={"gain": 0.7}, note="test")
    record = json.loads(sidecar.read_text())
    csv = tmp_path / "run" / "servo.csv"
    assert record["sha256"] == hashlib.sha256(csv.read_bytes()).hexdigest()
    assert record["calibration"]["jacobian_px_per_nm"] == cal.jacobian.tolist()
    assert record["n_ok"] == 1 and record["target_px"] == [10.0, 20.0] and record["note"] == "test"
    assert "semlab" in record["environment"]


def test_the_picker_takes_a_click_as_the_target():
    frame = np.zeros((480, 640), np.uint8)
    picker = TargetPicker(frame, (100, 100, 200, 200), target=(320.0, 240.0), width=320)
    assert picker.target == (320.0, 240.0) and picker.image.value
    # a click on CSS pixel (10, 20) of a 320x240 display: frame pixel (20.5, 40.5)
    picker._on_event({"event": "click", "relativeX": 10, "relativeY": 20, "boundingRectWidth": 320,
                      "boundingRectHeight": 240})
    assert picker.target == pytest.approx((20.5, 40.5))
    picker._on_event({"event": "click"})  # no geometry: ignored
    assert picker.target == pytest.approx((20.5, 40.5))
    with pytest.raises(ValueError, match="not a point"):
        picker.set_target((700.0, 10.0))
