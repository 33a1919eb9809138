"""Widgets without a browser: set the controls' values, press buttons, read ``.result``/``.shown``.

The scenes are synthetic so the expected answers follow from geometry: a bright disc of radius R whose edge
is blurred by a Gaussian of width s has, at gray level ``b + (a - b) * p``, an iso-contour of radius
``R - s * Φ⁻¹(p)`` (for R >> s), so the thresholded area shrinks as the threshold rises and equals πR² at the
midpoint threshold.
"""

from __future__ import annotations

import itertools
import math
import sys

import cv2
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import gaussian_filter
from scipy.stats import norm

from semlab.widgets import (
    TemplateExplorer,
    TrackingPlayer,
    display_to_frame,
    explore_template,
    overview_image,
    player_state,
)

BG, FG = 40.0, 200.0      # background and probe gray levels
R, BLUR = 30.0, 2.0       # disc radius and edge blur, px
SHAPE = (160, 200)        # rows, cols
CENTRE = (90.0, 75.0)     # x, y


def disc_frame(centre=CENTRE, noise=0.0, seed=0):
    yy, xx = np.mgrid[: SHAPE[0], : SHAPE[1]]
    inside = ((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= R**2).astype(float)
    img = BG + (FG - BG) * gaussian_filter(inside, BLUR)
    if noise:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


ROI = (40, 25, 100, 100)   # holds the whole disc, with margin


@pytest.fixture
def explorer():
    # No smoothing and no morphology: the contour is the iso-contour of the frame itself.
    return TemplateExplorer(disc_frame(), ROI, sigma=0.0, morph_kernel=1, morph_iterations=0)


def expected_area(threshold):
    p = (threshold - BG) / (FG - BG)
    r = R - BLUR * norm.ppf(p)
    return math.pi * r * r


def test_manual_threshold_area_follows_the_iso_contour(explorer):
    # One pixel of boundary position error allowed: contour points sit on pixel centres.
    for threshold in (80, 120, 160):
        explorer.controls["threshold"].value = threshold
        r = explorer.result
        assert r["ok"] and not r["otsu"]
        assert explorer.params["threshold"] == threshold
        band = 2 * math.pi * R * 1.0
        assert abs(r["area_px"] - expected_area(threshold)) < band, (threshold, r["area_px"])


def test_raising_the_threshold_shrinks_the_bright_probe(explorer):
    areas = []
    for threshold in (70, 100, 130, 160, 190):
        explorer.controls["threshold"].value = threshold
        areas.append(explorer.result["area_px"])
    assert all(a > b for a, b in itertools.pairwise(areas)), areas
    assert "manual" in explorer.readout.value
    assert f"{areas[-1]:.0f} px²" in explorer.readout.value


def test_otsu_is_the_default_and_lands_between_the_two_levels(explorer):
    assert explorer.controls["otsu"].value
    assert explorer.params["threshold"] is None
    t = explorer.result["threshold"]
    assert BG < t < FG
    # The slider shows Otsu's choice without turning it into a manual threshold.
    assert explorer.controls["threshold"].value == round(t)
    assert explorer.controls["otsu"].value
    # Ticking Otsu again after a manual move restores the automatic threshold.
    explorer.controls["threshold"].value = 180
    assert explorer.params["threshold"] == 180
    explorer.controls["otsu"].value = True
    assert explorer.params["threshold"] is None
    assert explorer.result["threshold"] == pytest.approx(t)


def test_a_threshold_above_the_probe_is_reported_not_raised(explorer):
    explorer.controls["threshold"].value = 250
    r = explorer.result
    assert not r["ok"] and r["template"] is None and math.isnan(r["area_px"])
    assert "no contour" in explorer.readout.value


def test_larger_canny_sigma_reduces_the_edge_count_on_a_noisy_frame():
    ex = TemplateExplorer(disc_frame(noise=12.0), ROI, sigma=1.0)
    counts = []
    for s in (0.5, 1.5, 3.0):
        ex.controls["canny_sigma"].value = s
        counts.append(ex.result["n_edges"])
    # Smoothing removes noise gradients: fewer spurious edges (the disc's own edge stays, ~2πR px).
    assert counts[0] > counts[1] > counts[2], counts
    assert counts[2] > 0.5 * 2 * math.pi * R


def test_manual_canny_thresholds_switch_off_the_adaptive_ones(explorer):
    assert explorer.result["adaptive"] and explorer.params["canny_low"] is None
    explorer.controls["canny"].value = [5.0, 10.0]
    assert not explorer.controls["adaptive"].value
    assert explorer.params["canny_low"] == 5.0 and explorer.params["canny_high"] == 10.0
    low_count = explorer.result["n_edges"]
    explorer.controls["canny"].value = [300.0, 390.0]
    # Higher hysteresis thresholds never add edges.
    assert explorer.result["n_edges"] <= low_count
    assert explorer.result["canny"] == (300.0, 390.0)


def test_click_moves_the_roi(explorer):
    explorer.controls["roi_size"].value = 80
    explorer.controls["click_x"].value = 100
    explorer.controls["click_y"].value = 70
    x, y, w, h = explorer.roi
    assert (w, h) == (80, 80)
    assert x + (w - 1) / 2 == pytest.approx(100, abs=0.5) and y + (h - 1) / 2 == pytest.approx(70, abs=0.5)
    assert explorer.result["roi"] == explorer.roi


def test_params_mean_the_same_template_in_the_tracker(explorer):
    from semlab.tracking import Tracker

    explorer.controls["threshold"].value = 120
    tracker = Tracker("contour", **explorer.params)
    assert tracker.init(explorer.frame, explorer.roi).ok
    assert tracker.contour.area == pytest.approx(explorer.result["area_px"])


def test_params_are_accepted_by_the_tracker(explorer):
    from semlab.tracking import Tracker

    explorer.controls["canny"].value = [20.0, 60.0]
    tracker = Tracker("contour", **explorer.params)
    assert tracker.init(explorer.frame, explorer.roi).ok
    # Otsu is invariant to the gray-level stretch: the same object either way.
    assert tracker.contour.area == pytest.approx(explorer.result["area_px"], rel=0.03)


def test_roi_from_motion_button_puts_the_roi_on_the_frame_it_was_found_on():
    frames = [disc_frame(centre=(60.0 + 8 * k, 75.0)) for k in range(8)]
    ex = TemplateExplorer(frames[0], (0, 0, 60, 60), motion_frames=frames, sigma=0.0)
    ex.controls["roi_size"].value = 100
    ex.controls["motion"].click()
    x, y, w, h = ex.roi
    # The ROI is found on the last motion frame, where the disc is at x = 60 + 8 * 7 = 116: the explorer
    # now works on that frame (on frame 0 the disc, at x = 60, would lie half outside the ROI).
    assert ex.frame_label == "motion frame 7" and ex.motion_index == 7 and np.array_equal(ex.frame, frames[-1])
    assert x <= 116 - R and 116 + R <= x + w - 1 and y <= 75 - R and 75 + R <= y + h - 1
    assert ex.controls["click_x"].value == round(x + (w - 1) / 2)
    # The template is the disc's outline in that frame, centred on the disc; its area pi R^2 within one px
    # of boundary position (contour points sit on pixel centres), as in the threshold tests above.
    assert ex.result["ok"] and abs(ex.result["area_px"] - math.pi * R * R) < 2 * math.pi * R * 1.0
    cx, cy = ex.result["template"].points.reshape(-1, 2).mean(axis=0) + (x, y)
    assert (cx, cy) == pytest.approx((116.0, 75.0), abs=1.0)
    assert "motion frame 7" in ex.readout.value


def test_roi_from_motion_on_the_rig_holds_the_tip_in_its_frame():
    """Notebook 01's motion search: the template is the probe's outline around the true tip."""
    from semlab.sim import SimulatedRig

    rig = SimulatedRig(n_manipulators=4, pixel_size_nm=66.0, seed=0)
    frame = rig.microscope.grab()
    axis = rig.axis(0, "x")
    motion, tips = [], []
    for k in range(10):
        axis.apply(axis.limits[0] + 3.0 * k)
        motion.append(rig.microscope.grab())
        tips.append(rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0])
    ex = TemplateExplorer(frame, roi_size=200, motion_frames=motion)
    ex.controls["motion"].click()
    x, y, w, h = ex.roi
    tx, ty = tips[-1]
    assert ex.frame_label == "motion frame 9" and x <= tx <= x + w - 1 and y <= ty <= y + h - 1
    contour = ex.result["template"].points.reshape(-1, 1, 2).astype(np.float32)
    # The tip is on the outline: within the render's edge blur plus the smoothing (a few px) of it.
    assert abs(cv2.pointPolygonTest(contour, (tx - x, ty - y), True)) < 4.0
    tip0 = ex.result["template"]   # the same template as a click at the tip of that frame gives
    direct = explore_template(motion[-1], ex.roi, **ex.params)["template"]
    assert tip0.area == direct.area and tip0.length == direct.length


def test_roi_from_motion_refusal_is_shown_not_raised():
    still = [disc_frame() for _ in range(5)]
    ex = TemplateExplorer(still[0], ROI, motion_frames=still, sigma=0.0)
    ex.controls["motion"].click()
    assert ex.roi == ROI and ex.frame_label == "frame"
    assert "no motion" in ex.motion_error and "refused" in ex.readout.value


def test_explore_template_matches_the_explorer(explorer):
    direct = explore_template(explorer.frame, explorer.roi, **explorer.params)
    assert direct["area_px"] == explorer.result["area_px"]
    assert direct["n_edges"] == explorer.result["n_edges"]


def _wedge_with_a_particle_at_its_apex(particle: bool) -> np.ndarray:
    """A bright wedge (tip at (120, 100), pointing +x, half-angle 14°) and, optionally, a dimmer particle of
    radius 5 touching its upper flank beside the tip (tests/test_track_attached.py's AT_APEX)."""
    yy, xx = np.mgrid[:200, :260].astype(float)
    half = math.radians(14.0)
    wedge = ((np.abs(yy - 100) * math.cos(half) + (xx - 120) * math.sin(half)) < 0).astype(float)
    disc = (np.hypot(xx - 117.0, yy - 94.5) <= 5.0) * 0.6 if particle else 0.0
    img = 50.0 + 130.0 * gaussian_filter(np.maximum(wedge, disc), 1.2)
    return np.clip(img + np.random.default_rng(0).normal(0.0, 2.0, img.shape), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("particle", [True, False])
def test_the_explorer_shows_the_particles_the_tracker_cuts(particle):
    # The contour template (the paper's) takes in a particle touching the tip; the default tracker cuts it off
    # (semlab.tracking.attached), and the explorer shows that cut (magenta) and says so in its readout.
    ex = TemplateExplorer(_wedge_with_a_particle_at_its_apex(particle), (60, 40, 120, 120))
    cut = ex.result["attached"]
    assert cut.shape == (120, 120)
    if particle:
        ys, xs = np.nonzero(cut)
        assert xs.size >= 15 and math.dist((xs.mean() + 60, ys.mean() + 40), (117.0, 94.5)) < 5.0
        assert "attached particles" in ex.readout.value
    else:
        assert not cut.any() and "attached particles" not in ex.readout.value


# --------------------------------------------------------------------------------------------
# The ROI by a mouse click on the overview (paper: "the operator clicks the mouse near the probe tip, and a
# 200x200 ROI is obtained automatically", Fig. 2b)

FULL = (480, 640)   # rows, cols: the paper's 640x480 frames


def full_frame(centre=(250.0, 150.0)):
    yy, xx = np.mgrid[: FULL[0], : FULL[1]]
    inside = ((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= R**2).astype(float)
    return np.clip(BG + (FG - BG) * gaussian_filter(inside, BLUR), 0, 255).astype(np.uint8)


def click_message(rel_x, rel_y, width, height, event="click"):
    """What ipyevents 2 sends for a mouse event on an Image (the keys of its ``_send_dom_event``)."""
    return {"event": event, "type": event, "altKey": False, "ctrlKey": False, "metaKey": False,
            "shiftKey": False, "timeStamp": 1234.5, "button": 0, "buttons": 0,
            "offsetX": rel_x, "offsetY": rel_y, "layerX": rel_x, "layerY": rel_y, "x": rel_x + 30,
            "y": rel_y + 200, "clientX": rel_x + 30, "clientY": rel_y + 200, "pageX": rel_x + 30,
            "pageY": rel_y + 200, "screenX": rel_x + 30, "screenY": rel_y + 300,
            "relativeX": rel_x, "relativeY": rel_y, "boundingRectWidth": width, "boundingRectHeight": height,
            "boundingRectLeft": 30.0, "boundingRectTop": 200.0, "boundingRectRight": 30.0 + width,
            "boundingRectBottom": 200.0 + height, "dataX": 0, "dataY": 0, "arrayX": 0, "arrayY": 0,
            "movementX": 0, "movementY": 0,
            "target": {"tagName": "IMG", "id": "", "className": "jupyter-widget-image semlab-overview"}}


def test_display_to_frame_is_the_identity_at_one_to_one():
    # Displayed at its own size, CSS pixel k is frame pixel k.
    for k in (0, 1, 37, 639):
        assert display_to_frame((k, min(k, 479)), (640, 480), FULL) == (k, min(k, 479))


def test_display_to_frame_undoes_css_scaling():
    # Shown 160x120 px (a quarter), CSS pixel 0 covers frame x -0.5..3.5 (centre 1.5), CSS pixel 159 covers
    # 635.5..639.5 (centre 637.5); the same place on a display twice as large gives the same frame point.
    assert display_to_frame((0, 0), (160, 120), FULL) == (1.5, 1.5)
    assert display_to_frame((159, 119), (160, 120), FULL) == (637.5, 477.5)
    assert display_to_frame((40, 30), (160, 120), FULL) == pytest.approx(display_to_frame((80.5, 60.5), (320, 240), FULL))
    # Upscaled by CSS (a 200x160 frame shown 500x400 px): 2.5 CSS px per frame px.
    assert display_to_frame((250, 200), (500, 400), (160, 200)) == pytest.approx((99.7, 79.7))
    # Stretched (x by 2, y by 4) is still right: the axes are scaled separately.
    assert display_to_frame((100, 100), (320, 120), FULL) == (200.5, 401.5)
    # A click on the border or just past it stays inside the frame.
    assert display_to_frame((320, -3), (320, 240), FULL) == (639.0, 0.0)


def test_display_to_frame_rejects_a_hidden_image():
    with pytest.raises(ValueError, match="display size"):
        display_to_frame((3, 4), (0, 0), FULL)
    with pytest.raises(ValueError, match="not finite"):
        display_to_frame((float("nan"), 4), (320, 240), FULL)


@settings(max_examples=200, deadline=None)
@given(width=st.integers(20, 2000), height=st.integers(20, 2000), fx=st.floats(0, 0.999), fy=st.floats(0, 0.999))
def test_a_click_lands_in_the_frame_area_under_the_css_pixel(width, height, fx, fy):
    rows, cols = FULL
    kx, ky = int(fx * width), int(fy * height)
    x, y = display_to_frame((kx, ky), (width, height), FULL)
    # CSS pixel k covers frame [k s - 0.5, (k + 1) s - 0.5], s = frame px per CSS px; both ends clipped into
    # the frame's pixel centres.
    sx, sy = cols / width, rows / height
    assert np.clip(kx * sx - 0.5, 0, cols - 1) - 1e-9 <= x <= np.clip((kx + 1) * sx - 0.5, 0, cols - 1) + 1e-9
    assert np.clip(ky * sy - 0.5, 0, rows - 1) - 1e-9 <= y <= np.clip((ky + 1) * sy - 0.5, 0, rows - 1) + 1e-9


@pytest.fixture
def full_explorer():
    return TemplateExplorer(full_frame(), click=(250, 150), roi_size=200, sigma=1.0)


def test_a_click_on_the_overview_moves_the_roi_there(full_explorer):
    ex = full_explorer
    assert ex.overview is not None, "ipyevents is a dependency: the overview should be clickable"
    assert ex.events.source is ex.overview and ex.events.watched_events == ["click"]
    shown = ex.overview.value
    # The overview shown 256x192 px by CSS (2.5 frame px per CSS px): CSS pixel (100, 60) covers frame
    # x 249.5..252, y 149.5..152, centre (250.75, 150.75): the click point becomes (251, 151).
    ex._on_overview_event(click_message(100, 60, 256.0, 192.0))
    assert (ex.controls["click_x"].value, ex.controls["click_y"].value) == (251, 151)
    x, y, w, h = ex.roi
    assert (w, h) == (200, 200)
    assert abs(x + (w - 1) / 2 - 251) <= 0.5 and abs(y + (h - 1) / 2 - 151) <= 0.5
    assert ex.result["roi"] == ex.roi and ex.result["ok"]
    assert f"<b>ROI</b> {ex.roi}" in ex.readout.value
    assert ex.overview.value != shown


def test_a_click_near_the_border_gives_a_roi_clipped_into_the_frame(full_explorer):
    ex = full_explorer
    # Bottom-right corner: (625.75, 475.75) in the frame; the 200x200 ROI is shifted, not shrunk.
    ex._on_overview_event(click_message(250, 190, 256.0, 192.0))
    assert (ex.controls["click_x"].value, ex.controls["click_y"].value) == (626, 476)
    assert ex.roi == (640 - 200, 480 - 200, 200, 200)
    assert "<b>ROI</b> (440, 280, 200, 200)" in ex.readout.value
    # Top-left, on a display CSS-scaled to full size.
    ex._on_overview_event(click_message(3, 2, 640.0, 480.0))
    assert ex.roi == (0, 0, 200, 200)


def test_other_events_and_hidden_images_leave_the_roi_alone(full_explorer):
    ex = full_explorer
    roi, result = ex.roi, ex.result
    ex._on_overview_event(click_message(250, 190, 256.0, 192.0, event="mousemove"))
    ex._on_overview_event(click_message(250, 190, 0.0, 0.0))
    ex._on_overview_event({"event": "click"})
    assert ex.roi == roi and ex.result is result


def test_roi_size_applies_to_the_next_click(full_explorer):
    ex = full_explorer
    ex.controls["roi_size"].value = 120
    ex._on_overview_event(click_message(100, 60, 256.0, 192.0))
    x, y, w, h = ex.roi
    assert (w, h) == (120, 120)
    assert abs(x + (w - 1) / 2 - 251) <= 0.5 and abs(y + (h - 1) / 2 - 151) <= 0.5


def test_overview_image_shows_the_whole_frame_with_the_roi_box():
    frame = full_frame()
    img = cv2.imdecode(np.frombuffer(overview_image(frame, (200, 100, 200, 200), max_width=320), np.uint8),
                       cv2.IMREAD_COLOR)
    assert img.shape == (240, 320, 3)
    # The box's left edge: frame x 199.5 -> display column 100, rows 50..149; yellow (BGR) against gray.
    b, g, r = img[100, 100].astype(int)
    assert r > 180 and g > 150 and b < 100, (b, g, r)
    b, g, r = img[100, 130].astype(int)   # inside the box: gray
    assert abs(r - b) < 30


def test_without_ipyevents_the_sliders_alone_move_the_roi(monkeypatch):
    monkeypatch.setitem(sys.modules, "ipyevents", None)   # ``import ipyevents`` now raises ImportError
    ex = TemplateExplorer(full_frame(), click=(250, 150), roi_size=200)
    assert ex.overview is None and ex.events is None
    ex.controls["click_x"].value = 600
    assert ex.roi == (440, 50, 200, 200)


# --------------------------------------------------------------------------------------------
# Tracking player

def _moving_sequence(n=6, step=(5.0, -2.0)):
    frames = np.stack([disc_frame(centre=(CENTRE[0] + step[0] * k, CENTRE[1] + step[1] * k)) for k in range(n)])
    roi_c = (ROI[0] + (ROI[2] - 1) / 2, ROI[1] + (ROI[3] - 1) / 2)
    truth = pd.DataFrame({"frame": range(n), "x": [CENTRE[0] + step[0] * k for k in range(n)],
                          "y": [CENTRE[1] + step[1] * k for k in range(n)]})
    # A track with a known error of +0.3 px in x from frame 1 on, and frame 3 lost.
    tracks = pd.DataFrame({"frame": range(n),
                           "x": [roi_c[0] + step[0] * k + (0.3 if k else 0.0) for k in range(n)],
                           "y": [roi_c[1] + step[1] * k for k in range(n)],
                           "score": 0.9, "ok": True})
    tracks.loc[3, ["x", "y"]] = np.nan
    tracks.loc[3, "ok"] = False
    return frames, tracks, truth


def test_player_slider_shows_that_frames_track_row():
    frames, tracks, truth = _moving_sequence()
    player = TrackingPlayer(frames, tracks, truth, roi=ROI, pixel_size_nm=66.0)
    assert player.shown["frame"] == 0
    first_png = player.image.value
    player.controls["frame"].value = 4
    st = player.shown
    assert st["frame"] == 4
    assert (st["x"], st["y"]) == (tracks.loc[4, "x"], tracks.loc[4, "y"])
    assert st["err_x"] == pytest.approx(0.3) and st["err_y"] == pytest.approx(0.0, abs=1e-12)
    assert "+0.30, +0.00 px (+20, +0 nm)" in player.readout.value
    assert player.image.value != first_png
    assert player.template is not None and player.template.area > 0


def test_player_shows_a_lost_frame_as_lost():
    frames, tracks, truth = _moving_sequence()
    player = TrackingPlayer(frames, tracks, truth, roi=ROI)
    player.controls["frame"].value = 3
    assert not player.shown["ok"] and math.isnan(player.shown["err_x"])
    assert "lost" in player.readout.value


def test_player_state_rejects_frames_outside_the_track():
    _, tracks, truth = _moving_sequence()
    with pytest.raises(ValueError, match="frame 99"):
        player_state(tracks, 99, truth)


def test_player_needs_enough_frames():
    frames, tracks, _ = _moving_sequence()
    with pytest.raises(ValueError, match="only 3 frames"):
        TrackingPlayer(frames[:3], tracks)


# --------------------------------------------------------------------------------------------
# Servo panel (simulated rig, the tracker in the loop)

@pytest.fixture(scope="module")
def servo_rig():
    from semlab.hysteresis import characterise_hysteresis, fit_hysteresis
    from semlab.roi import roi_from_click
    from semlab.sim import SimulatedRig

    rig = SimulatedRig(seed=0)
    frame = rig.microscope.grab()
    tip = rig.truth.query("probe == 0")[["x", "y"]].to_numpy()[0]
    roi = roi_from_click(frame, tip, size=200)
    axis = rig.axis(0, "x")
    char = characterise_hysteresis(rig.microscope, axis, roi, u_min=0.0, u_max=50.0, n_steps=8)
    return rig, axis, roi, fit_hysteresis(char, kind="polynomial")


def test_servo_panel_runs_and_feedforward_is_faster(servo_rig):
    from semlab.widgets import ServoPanel

    rig, axis, roi, model = servo_rig
    panel = ServoPanel(rig.microscope, axis, roi, model, step_px=50.0, n_frames=20)
    assert panel.response is None and panel.metrics is None
    times = {}
    # From U0 (after the characterisation) up and nearly back, first PID only, then with feed-forward.
    for ff, step in [(False, 50.0), (False, -45.0), (True, 50.0), (True, -45.0)]:
        panel.controls["feedforward"].value = ff
        panel.controls["step_px"].value = step
        panel.controls["run"].click()
        assert panel.error == "", panel.error
        resp = panel.response
        assert len(resp) == 20 and resp["target"].iloc[-1] == step
        # The panel followed the probe: the next ROI is centred on the last tracked position.
        last = resp[resp.ok].iloc[-1]
        x, y, w, h = panel.roi()
        assert abs(x + (w - 1) / 2 - last.x) <= 1 and abs(y + (h - 1) / 2 - last.y) <= 1
        assert abs(panel.metrics["final_mean_px"] - step) < 1.0
        times[(ff, step)] = panel.metrics["response_frames_1px"]
    # Feed-forward makes the move in one frame; the PID alone needs several (paper, Fig. 9).
    assert times[(True, 50.0)] < times[(False, 50.0)], times
    assert len(panel.runs) == 4 and panel.image.value
    assert "response time" in panel.readout.value


def test_servo_panel_reports_a_step_out_of_reach(servo_rig):
    from semlab.widgets import ServoPanel

    rig, axis, roi, model = servo_rig
    panel = ServoPanel(rig.microscope, axis, roi, model, step_px=200.0, n_frames=10)
    panel.controls["step_px"].value = -200.0   # far below U0's displacement: out of the model's reach
    assert panel.run() is None
    assert "reach" in panel.error and "refused" in panel.readout.value
    assert panel.response is None


def test_the_central_checkbox_picks_the_probe_over_a_larger_blob_as_the_tracker_does():
    from semlab.tracking import Tracker

    # A thin bright triangle with its tip at the ROI's centre and, in the same ROI, a larger bright disc:
    # the paper's largest contour is the disc; the default (and the default tracker) take the triangle.
    frame = np.full(SHAPE, BG, np.float32)
    cv2.fillPoly(frame, [np.array([[0, 65], [95, 75], [0, 85]], np.int32)], FG)
    cv2.circle(frame, (150, 120), 24, FG, -1)
    roi = (15, 0, 150, 150)  # centre (89.5, 74.5): inside the triangle, 5 px from its tip
    explorer = TemplateExplorer(frame, roi)
    assert explorer.controls["central"].value and explorer.params["choose"] == "central"
    central = explorer.result["area_px"]
    explorer.controls["central"].value = False
    assert explorer.params["choose"] == "largest"
    assert explorer.result["area_px"] > central  # the disc, ~1800 px² against the triangle's ~800
    tracker = Tracker()
    tracker.init(frame, roi)
    assert tracker.contour.area == pytest.approx(central)


def test_the_explorer_says_when_the_brightest_of_three_classes_was_taken():
    from semlab.tracking import Tracker

    # A probe ending at the ROI's centre over a brighter substrate (a dark trench in front of it): at
    # Otsu's level they are one region over most of the ROI; the explorer shows, as the tracker takes,
    # the probe alone at the level of the brightest of three classes, and says so.
    frame = np.full((150, 200), 130, np.float32)
    frame[40:110, 100:] = 40
    cv2.fillPoly(frame, [np.array([[0, 62], [90, 75], [0, 88]], np.int32)], 210)
    roi = (15, 0, 150, 150)  # centre (89.5, 74.5): 0.5 px inside the tip
    explorer = TemplateExplorer(frame, roi)
    assert explorer.result["template"].otsu_classes == 3 and "brightest of 3 classes" in explorer.readout.value
    tracker = Tracker()
    tracker.init(frame, roi)
    assert tracker.contour.area == pytest.approx(explorer.result["area_px"]) and tracker.contour.region.mean() < 0.2
