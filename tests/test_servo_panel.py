"""The workbench's servo panel: click where the tip should go, the paper's 1-D step, and what it shows
(on the fake stage of ``servo_fakes``; the simulated rig's panel test is in test_widgets)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ipywidgets")

from servo_fakes import FakeStage, FakeTracker, characterise, roi_at, set_voltages

from semlab.widgets import ServoPanel, display_to_frame

SHAPE = (480, 640)


@pytest.fixture
def panel():
    stage = FakeStage(n_probes=1, frame_shape=SHAPE)
    models = characterise(stage, 0)
    set_voltages(stage, 0, models, [45.0, 50.0])
    roi = tuple(round(v) for v in roi_at(stage, 0))
    # the fake tracker is re-initialised at every run, as a real one would be
    p = ServoPanel(stage, stage.axes(0), roi, models, step_px=40.0, n_frames=20, tracker=FakeTracker(stage, 0))
    return stage, models, p


def test_nothing_is_drawn_and_no_broken_image_shows_before_the_first_run(panel):
    _, _, p = panel
    assert p.image.layout.display == "none" and p.point_image.layout.display == "none"
    assert p.response is None and p.point_response is None
    p.run()
    assert p.image.layout.display != "none" and p.image.value
    p.clear()
    assert p.image.layout.display == "none" and p.image.value == b""


def test_the_zoomed_view_shows_every_run_its_legend_lists(panel):
    _, _, p = panel
    for ff, step in [(True, 40.0), (False, -30.0), (True, 25.0)]:
        p.controls["feedforward"].value = ff
        p.controls["step_px"].value = step
        p.run()
        assert p.error == "", p.error
    left, zoom = p.step_figure.axes[:2]
    assert len(left.get_legend().get_texts()) == 3
    lines = [ln for ln in zoom.get_lines() if len(ln.get_xdata()) == 20]
    assert len(lines) == 3
    lo, hi = zoom.get_ylim()
    for ln in lines:  # each run ends inside the view (its error near 0), whatever its target
        assert lo < ln.get_ydata()[-1] < hi


def test_a_click_on_the_frame_moves_the_tip_there(panel):
    stage, _, p = panel
    assert p.overview is not None and p.overview.value  # the clickable frame is shown from the start
    width, height = 320, 240  # the overview as displayed: half the frame's size
    tip = stage.position(0).copy()
    x0, y0, w, h = p.roi()
    centre = np.array([x0 + (w - 1) / 2, y0 + (h - 1) / 2])
    event = {"event": "click", "relativeX": 0.5 * (centre[0] + 30) - 0.25, "relativeY": 0.5 * (centre[1] - 20) - 0.25,
             "boundingRectWidth": width, "boundingRectHeight": height}
    target = np.array(display_to_frame((event["relativeX"], event["relativeY"]), (width, height), SHAPE))
    np.testing.assert_allclose(target, centre + (30.0, -20.0), atol=1e-9)
    p._on_overview_event(event)
    assert p.error == "", p.error
    resp = p.point_response
    assert (resp["target_x"].iloc[-1], resp["target_y"].iloc[-1]) == tuple(target)
    # the fake tracker is the truth: the tip moved by the click's offset from the ROI centre
    assert np.hypot(*(stage.position(0) - tip - (target - centre))) < 0.1
    assert p.point_image.layout.display != "none" and p.point_figure is not None
    err_ax, path_ax = p.point_figure.axes[:2]
    assert err_ax.get_yscale() == "log" and "path" in path_ax.get_title()
    assert "distance" in p.readout.value
    # the ROI followed the probe: the next click is measured from where the tip is now
    x0, y0, w, h = p.roi()
    assert abs(x0 + (w - 1) / 2 - resp["x"].iloc[-1]) <= 1 and abs(y0 + (h - 1) / 2 - resp["y"].iloc[-1]) <= 1


def test_a_click_the_axes_cannot_reach_is_refused_and_nothing_moves(panel):
    stage, _, p = panel
    for a in stage.axes(0):
        a.sent.clear()
    p.go_to((-5000.0, 100.0))
    assert "refused" in p.readout.value and "can reach" in p.error
    assert p.point_response is None and all(a.sent == [] for a in stage.axes(0))
    p._on_overview_event({"event": "mousemove"})  # other events and broken messages are ignored
    p._on_overview_event({"event": "click"})
    assert p.point_response is None


def test_a_panel_on_one_axis_runs_steps_and_says_clicks_need_two():
    stage = FakeStage(n_probes=1, frame_shape=SHAPE)
    models = characterise(stage, 0)
    set_voltages(stage, 0, models, [45.0, 50.0])
    roi = tuple(round(v) for v in roi_at(stage, 0))
    p = ServoPanel(stage, stage.axes(0)[0], roi, models[0], step_px=30.0, n_frames=15, tracker=FakeTracker(stage, 0))
    assert p.overview is None and p.controls["step_axis"].disabled
    assert p.run() is not None
    assert p.go_to((10.0, 10.0)) is None and "two axes" in p.error
