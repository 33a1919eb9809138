"""What drives a rig lives in semlab.experiments, what measures in semlab.measure; the old import
paths (semlab.hysteresis, semlab.control) still give the same objects."""

from __future__ import annotations

import math

import pytest

import semlab
from semlab import creep, experiments, measure
from semlab.protocols import VisualTracker
from semlab.tracking import Tracker, TrackResult


@pytest.mark.parametrize("module, name, home", [
    ("semlab.hysteresis", "characterise_hysteresis", experiments),
    ("semlab.hysteresis", "characterise_creep", experiments),
    ("semlab.hysteresis", "characterisation_voltages", experiments),
    ("semlab.hysteresis", "label_branches", experiments),
    ("semlab.hysteresis", "CreepModel", creep),
    ("semlab.hysteresis", "fit_creep", creep),
    ("semlab.control", "drive_voltages", experiments),
])
def test_moved_names_keep_their_old_import_path(module, name, home):
    import importlib

    assert getattr(importlib.import_module(module), name) is getattr(home, name)
    if name in semlab.__all__:  # the package's export table points at the new home
        assert getattr(semlab, name) is getattr(home, name)


def test_unknown_names_still_raise_attribute_error():
    import semlab.control
    import semlab.hysteresis

    for module in (semlab.control, semlab.hysteresis):
        with pytest.raises(AttributeError):
            module.no_such_thing  # noqa: B018


def test_default_tracker_is_the_tracker_with_a_window_that_holds_the_jump():
    assert isinstance(measure.default_tracker(), Tracker)
    # 200-px ROI and a 100-px jump: 200 + 2 x ceil(1.1 x 100 + 20) = 460 px (the paper's 300 at least).
    assert measure.default_tracker(jump_px=100.0, roi=(0, 0, 200, 200)).options.search.search_size == 460
    assert measure.default_tracker(jump_px=1.0, roi=(0, 0, 20, 20)).options.search.search_size == 300
    assert isinstance(Tracker(), VisualTracker)


def test_a_tracker_without_init_and_update_is_refused():
    with pytest.raises(TypeError, match="init"):
        measure.default_tracker(object())

    class OnlyInit:
        def init(self, frame, roi):
            pass

    with pytest.raises(TypeError, match="update"):
        measure.default_tracker(OnlyInit())


def test_results_are_read_from_attributes_or_tuples():
    assert measure.read_result(TrackResult(1.0, 2.0, 0.5, True)) == (1.0, 2.0, 0.5, True)
    x, y, score, ok = measure.read_result((1, 2, None, 0))
    assert (x, y, ok) == (1.0, 2.0, False) and math.isnan(score)


def test_start_point_is_the_roi_centre_of_a_valid_roi():
    assert measure.start_point((10, 20, 5, 8)) == (12.0, 23.5)
    for bad in [(1, 2, 0, 5), (1, 2, 3), (0, 0, float("nan"), 4), "roi"]:
        with pytest.raises(ValueError, match="roi"):
            measure.start_point(bad)
