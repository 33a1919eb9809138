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


def test_outlier_fences_are_tukeys_far_out_fences():
    v = [1, 2, 3, 4, 5, 100]
    q1, q3 = np.percentile(v, [25, 75])
    assert plots.outlier_fences(v) == pytest.approx((q1 - 3 * (q3 - q1), q3 + 3 * (q3 - q1)))
    lo, hi = plots.outlier_fences([0.1, 1, 10, np.nan, -1], log=True)   # decades; NaN and <= 0 ignored
    assert lo < 0.1 and hi > 10
    assert np.isnan(plots.outlier_fences([np.nan])[0])


def test_robust_ylim_keeps_the_inliers_and_marks_each_outlier_at_its_edge():
    _, ax = plt.subplots()
    frames = np.arange(11)
    y = np.linspace(0, 50, 11)
    y[8] = -341.0                          # notebook 07's paper-contour frame
    (line,) = ax.plot(frames, y, "o-")
    ax.plot(frames, y + 2, "s-")
    out = plots.robust_ylim(ax, unit=" px")
    lo, hi = out["limits"]
    assert lo > -60 and hi < 80           # the axis is not stretched to -341
    assert lo <= 0 and hi >= 52           # every inlier stays on it
    assert sorted(out["outliers"]) == [(8.0, -341.0), (8.0, -339.0)]
    markers = [m for m in ax.get_lines() if m.get_gid() == "semlab-outlier"]
    assert len(markers) == 2 and markers[0].get_color() == line.get_color()
    assert markers[0].get_marker() == "v"                      # below the axis: a downward triangle
    assert markers[0].get_ydata()[0] == pytest.approx(lo)      # drawn on the bottom edge
    assert any("-341 px" in t.get_text() for t in ax.texts)


def test_robust_ylim_without_outliers_changes_nothing_but_the_padding():
    _, ax = plt.subplots()
    ax.plot([0, 1, 2], [1.0, 2.0, 3.0])
    out = plots.robust_ylim(ax, include=[0.0])
    lo, hi = out["limits"]
    assert out["outliers"] == [] and lo < 0.0 and hi > 3.0


def test_robust_ylim_on_a_log_axis_works_in_decades():
    _, ax = plt.subplots()
    ax.loglog([1, 2, 3, 4, 5], [0.1, 0.12, 0.15, 0.2, 500.0], "o-")
    out = plots.robust_ylim(ax)
    assert out["outliers"] == [(5.0, 500.0)] and out["limits"][1] < 500


def test_mark_missing_draws_nan_points_instead_of_dropping_them():
    _, ax = plt.subplots()
    ax.loglog([6.25, 12.5, 25.0], [np.nan, 0.4, 0.16], "o-", label="paper ssd baseline")
    ax.loglog([6.25, 12.5, 25.0], [0.7, 0.3, 0.16], "o-", label="semlab")
    out = plots.mark_missing(ax, label="all frames lost")
    assert out["missing"] == [("paper ssd baseline", 6.25)]
    (marker,) = out["markers"]
    assert marker.get_xdata()[0] == 6.25 and marker.get_label() == "all frames lost"
    assert marker.get_gid() == "semlab-missing"
    # The marker is in axes coordinates vertically: on the bottom edge whatever the limits.
    assert 0 <= marker.get_ydata()[0] <= 0.05


def test_robust_ylim_labels_only_the_farthest_outliers():
    _, ax = plt.subplots()
    y = np.r_[np.linspace(0, 1, 100), np.arange(1, 11) * 100.0]      # 10 outliers, 100 .. 1000
    ax.plot(np.arange(110), y)
    out = plots.robust_ylim(ax, max_labels=3)
    assert len(out["outliers"]) == 10
    labels = sorted(float(t.get_text()) for t in ax.texts)
    assert labels == [800.0, 900.0, 1000.0]                 # the three farthest


def test_mark_missing_on_a_categorical_axis():
    _, ax = plt.subplots()
    ax.semilogy(["baseline", "12.5 pA", "3 pA"], [0.15, 0.28, np.nan], "o-", label="semlab")
    out = plots.mark_missing(ax)
    assert out["missing"] == [("semlab", 2.0)]          # "3 pA" is the third category, at x = 2
