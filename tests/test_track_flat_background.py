"""The template's background flattened over a strongly textured substrate (semlab.tracking.band, issue 14)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from test_track_attached import silent_frames

from semlab.tracking import Tracker, ic
from semlab.tracking.band import (
    FLAT_BACKGROUND_TEXTURE,
    FLAT_FROM_PX,
    FLAT_SIGMA_PX,
    flattened_background,
)


def _disc_region(shape=(80, 80), centre=(40, 40), radius=15):
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    return np.hypot(xx - centre[0], yy - centre[1]) <= radius


def test_the_object_and_its_edge_stay_and_the_texture_goes():
    # A texture of white noise blurred by s = 1.5 px, averaged by the Gaussian of sigma = FLAT_SIGMA_PX = 4:
    # its standard deviation falls to s / sqrt(s^2 + sigma^2) = 0.35 of itself (more near the object, where
    # the normalised window is one-sided and smaller).
    region = _disc_region()
    rng = np.random.default_rng(0)
    texture = cv2.GaussianBlur(rng.normal(0.0, 20.0, region.shape).astype(np.float32), (0, 0), 1.5)
    template = np.where(region, 200.0, 60.0 + texture).astype(np.float32)
    flat = flattened_background(template, region)
    distance = cv2.distanceTransform((~region).astype(np.uint8), cv2.DIST_L2, 3)
    kept = distance < FLAT_FROM_PX
    assert np.array_equal(flat[kept], template[kept])  # the object and the pixels at its edge
    far = distance >= 6
    expected = 1.5 / math.hypot(1.5, FLAT_SIGMA_PX)
    assert abs(float(flat[far].mean()) - 60.0) < 1.0
    assert flat[far].std() < 1.2 * expected * template[far].std()


def test_a_flat_background_is_unchanged():
    region = _disc_region()
    template = np.where(region, 200.0, 60.0).astype(np.float32)
    assert np.allclose(flattened_background(template, region), template, atol=1e-3)


def test_only_a_strongly_textured_substrate_is_flattened():
    from semlab.evaluation import make_family_sequence

    seen = {}
    for family, seed in (("substrates", 221), ("still", 100), ("clutter", 100)):
        seq = make_family_sequence(family, seed)
        t = Tracker()
        t.init(seq.frames[0], seq.roi)
        seen[family] = (t.texture >= FLAT_BACKGROUND_TEXTURE, t.algorithm.flatten)
    assert seen == {"substrates": (True, True), "still": (False, False), "clutter": (False, False)}


@pytest.mark.slow
def test_a_textured_substrate_no_longer_holds_the_probe_back(monkeypatch):
    # Substrates spare seed 221: a probe over strongly textured grains (texture 1.5x the noise and more). The
    # grains beside its edges, kept in the template, hold the track about 1 px back on 27 frames that say
    # ok; flattened, 3.
    from semlab.evaluation import make_family_sequence

    seq = make_family_sequence("substrates", 221)

    assert silent_frames(seq) <= 5
    monkeypatch.setattr(ic, "FLAT_BACKGROUND_TEXTURE", math.inf)
    assert silent_frames(seq) >= 20
