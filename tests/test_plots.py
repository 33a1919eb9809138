"""Plot helpers: they draw on the axes given, put pixel centres on integer coordinates, label px and nm,
return their artists, and never show anything themselves."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from semlab import plots


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(autouse=True)
def _no_show(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a plot helper called plt.show()")

    monkeypatch.setattr(plt, "show", refuse)


def test_show_frame_puts_pixel_centres_on_integers_and_draws_roi_and_contour():
    frame = np.arange(12, dtype=float).reshape(3, 4)
    _, ax = plt.subplots()
    out = plots.show_frame(frame, ax, roi=(1, 0, 2, 3), contour=[(0, 0), (1, 0), (1, 1)], contour_offset=(1, 0),
                           origin=(10, 20), pixel_size_nm=5.0)
    assert out["image"].get_extent() == [9.5, 13.5, 22.5, 19.5]
    r = out["roi"]
    # The box encloses pixels x = 1..2, y = 0..2: from their outer edges.
    assert (r.get_x(), r.get_y(), r.get_width(), r.get_height()) == (0.5, -0.5, 2, 3)
    xs, ys = out["contour"].get_data()
    assert list(xs) == [1, 2, 2, 1] and list(ys) == [0, 0, 1, 0]   # offset, closed
    assert ax.get_xlabel() == "x (px)" and out["nm_axes"]["x"].get_xlabel() == "x (nm)"


def test_helpers_draw_on_the_current_axes_when_none_given():
    _, ax = plt.subplots()
    out = plots.show_edges(np.eye(5, dtype=bool))
    assert out["image"].axes is ax
    assert "5 px" in ax.get_title()


def test_plot_track_shows_displacements_and_nm():
    track = pd.DataFrame({"frame": [0, 1, 2], "x": [100.0, 101.0, np.nan], "y": [50.0, 50.0, 50.0],
                          "ok": [True, True, False]})
    truth = pd.DataFrame({"frame": [0, 1, 2], "x": [7.0, 8.0, 9.0], "y": [3.0, 3.0, 3.0]})
    _, ax = plt.subplots()
    out = plots.plot_track(track, truth, ax, frame_period=0.5, pixel_size_nm=66.0)
    xs, ys = out["track"].get_data()
    assert list(xs) == [0.0, 0.5, 1.0] and ys[1] == 1.0 and np.isnan(ys[2])
    assert list(out["truth"].get_data()[1]) == [0.0, 1.0, 2.0]
    assert ax.get_xlabel() == "time (s)" and "nm" in out["nm_axis"].get_ylabel()


def test_error_histogram_marks_the_bound_and_the_paper():
    _, ax = plt.subplots()
    out = plots.error_histogram(np.r_[np.zeros(5), np.nan, 1.0], ax, crb=0.1, paper_std=0.2268)
    assert [ln.get_xdata()[0] for ln in out["crb"]] == [-0.1, 0.1]
    assert [ln.get_xdata()[0] for ln in out["paper"]] == [-0.2268, 0.2268]
    assert sum(p.get_height() for p in out["bars"]) == 6   # the NaN is left out


def test_plot_hysteresis_and_step_response():
    char = pd.DataFrame({"u": [0, 10, 20, 10, 0], "displacement": [0, 8, 20, 14, 1],
                         "branch": ["ascending"] * 3 + ["descending"] * 2})
    _, (a1, a2) = plt.subplots(1, 2)
    out = plots.plot_hysteresis(char, a1, pixel_size_nm=66.0)
    assert len(out["data"]) == 2 and a1.get_xlabel() == "applied voltage u (V)"
    resp = pd.DataFrame({"frame": [0, 1, 2], "t": [1.0, 1.5, 2.0], "displacement": [0.0, 90.0, 100.0],
                         "target": 100.0, "ok": [True, True, True]})
    out = plots.plot_step_response(resp, a2, label="ff")
    assert list(out["response"].get_xdata()) == [0.0, 0.5, 1.0]


def test_figure_png_renders_without_pyplot():
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 1))
    fig.subplots().plot([0, 1])
    png = plots.figure_png(fig)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
