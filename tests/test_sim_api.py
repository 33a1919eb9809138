"""The simulator's public API as the team brief specifies it (fast smoke + contract checks)."""

import numpy as np
import pandas as pd
import pytest

from semlab.protocols import Axis, Microscope
from semlab.sim import (
    Clutter,
    ProbeGeometry,
    SEMNoise,
    SimulatedRig,
    SimulatedSEM,
    make_sequence,
    pixel_size_from_magnification,
    translation_crb,
)


def test_pixel_size_matches_paper():
    assert pixel_size_from_magnification(3000) == pytest.approx(66.0)
    assert pixel_size_from_magnification(30000) == pytest.approx(6.6)
    with pytest.raises(ValueError):
        pixel_size_from_magnification(-5)


def test_sem_render_and_acquire_shapes():
    sem = SimulatedSEM(width=320, height=240, seed=1)
    tips = np.array([[100.0, 120.0]])
    clean = sem.render_clean(tips)
    assert clean.shape == (240, 320) and clean.dtype == np.float64
    frame = sem.acquire(tips)
    assert frame.shape == (240, 320) and frame.dtype == np.uint8
    assert sem.frame_index == 1


def test_rig_implements_protocols_and_truth():
    rig = SimulatedRig(seed=0)
    assert isinstance(rig.microscope, Microscope)
    ax = rig.axis(0, "x")
    assert isinstance(ax, Axis)
    assert ax.limits == (0.0, 100.0)
    frame = rig.microscope.grab()
    assert frame.shape == (480, 640)
    t = rig.truth
    assert list(t.columns) == ["frame", "t", "probe", "x", "y", "visible"]
    assert len(t) == 4 and t["visible"].all()
    assert rig.macro(0, "x").limits == (0.0, 12e6)
    assert rig.macro(0, "y").limits == (0.0, 10e6)


@pytest.mark.parametrize("kind", ["static", "moves_200px", "low_dose", "gray_fluctuation",
                                  "clutter_occluder"])
def test_make_sequence_contract(kind):
    seq = make_sequence(kind, n_frames=4, seed=3, width=320, height=240, n_manipulators=1,
                        base_positions=[(120.0, 120.0)])
    assert seq.frames.shape == (4, 240, 320) and seq.frames.dtype == np.uint8
    assert isinstance(seq.truth, pd.DataFrame)
    assert {"frame", "x", "y"} <= set(seq.truth.columns) and len(seq.truth) == 4
    x, y, w, h = seq.roi
    assert (w, h) == (200, 200) and 0 <= x <= 320 - w and 0 <= y <= 240 - h
    assert all(0 < s < 5 for s in seq.crb)
    assert seq.meta["kind"] == kind and seq.meta["pixel_size_nm"] == 66.0
    # the probe moves in every kind but "static" (tests/test_sim_rig.py checks the sweep)
    assert seq.meta["motion"] == {"static": "still", "moves_200px": "steps"}.get(kind, "sweep")
    assert len(seq.commands) == 4 and seq.commands["u"].iloc[0] == 0.0


def test_crb_is_finite_and_bad_roi_raises():
    sem = SimulatedSEM(seed=0)
    tips = np.array([[150.0, 250.0]])
    sx, sy = translation_crb(sem, tips, (50, 150, 200, 200))
    assert 0 < sx < 1 and 0 < sy < 1
    with pytest.raises(ValueError, match="roi"):
        translation_crb(sem, tips, (500, 400, 200, 200))


def test_dataclass_defaults_and_off():
    assert SEMNoise.off().shot_noise is False
    assert ProbeGeometry().tip_diameter_nm == 200.0
    assert Clutter.none().n_static == 0
