"""The rows and attrs of a positioner move (the positioner form of ``move_probe_to``), on fibsem's offline
Demo and semlab's simulated needle (the adapter tests' fixtures). Skips without fibsem, like them."""

from __future__ import annotations

import numpy as np
import pytest
import test_instruments_fibsem as adapter_tests  # skips this module as well when fibsem is missing
from test_pointing_positioner import calibrated, centre

import semlab
from semlab.measure import start_point

fib, demo = adapter_tests.fib, adapter_tests.demo


def test_positioner_rows_say_their_stage_and_limits_and_the_attrs_the_geometry(demo):
    _bridge, scope, arm, roi, cal = calibrated(demo, seed=1)
    target = centre(roi) + (20.0, -10.0)
    df = semlab.move_probe_to(scope, arm, roi, tuple(target), model=cal, n_frames=4)
    assert list(df["stage"]) == ["start", "servo", "servo", "servo"]
    assert df["at_limit"].dtype == bool and not df["at_limit"].any()  # a 22-px move, far inside the travel
    assert df.attrs["origin"] == pytest.approx(start_point(roi)) and df.attrs["axes"] == ["x", "y"]
    np.testing.assert_allclose(df.attrs["jacobian"], cal.jacobian, atol=0)
    with pytest.raises(TypeError, match=r"^for a positioner, model= is its PositionerCalibration"):
        semlab.move_probe_to(scope, arm, roi, tuple(target), model=[cal], n_frames=4)
