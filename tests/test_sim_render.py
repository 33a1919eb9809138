"""Rendering physics: sub-pixel translations are exact, probes do not interfere."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semlab.sim import Clutter, ProbeGeometry, SEMNoise, SimulatedSEM
from semlab.sim.scene import clip_polygon, probe_bbox, probe_signed_distance


def _sem(**kw):
    kw.setdefault("width", 200)
    kw.setdefault("height", 160)
    kw.setdefault("clutter", Clutter.none())
    kw.setdefault("noise", SEMNoise.off())
    return SimulatedSEM(**kw)


def _centroid(img, axis):
    coords = np.arange(img.shape[axis], dtype=float)
    prof = img.sum(axis=1 - axis)
    return float(prof @ coords / prof.sum())


# A sampled centroid equals the continuous one up to aliasing, ~|F(2 pi)| of the
# profile's spectrum. With a 1 px beam blur, no edge rim and a 15 px tip radius (6.6 nm/px)
# the rendered profile is a Gaussian-blurred shape without creases: aliasing < 1e-8 px.
# With the default sub-pixel tip (1.5 px radius), its edge rim and its shading, the signed
# distance has a crease on the probe's axis inside the narrow tip, where the blurred edges
# meet; that creased region (~10 px long, ~3 px wide, out of ~2000 px^2 of probe signal)
# aliases the centroid by at most (area ratio) / (2 pi) ~ 2e-3 px.
_SMOOTH = {"beam_sigma_px": 1.0, "pixel_size_nm": 6.6, "probe": ProbeGeometry(rim_amplitude=0.0)}


@settings(max_examples=25, deadline=None)
@given(dy=st.floats(-2.5, 2.5), y0=st.floats(70.0, 90.0))
def test_subpixel_shift_across_shaft_moves_centroid_exactly(dy, y0):
    # Probe pointing along +x: a y-shift leaves the frame-edge cut of the shaft unchanged,
    # so the y-centroid of the probe's signal must move by exactly dy.
    sem = _sem(probe_angles_deg=(0.0,), **_SMOOTH)
    bg = sem.render_clean(np.empty((0, 2)))
    a = sem.render_clean([[120.0, y0]]) - bg
    b = sem.render_clean([[120.0, y0 + dy]]) - bg
    assert _centroid(b, 0) - _centroid(a, 0) == pytest.approx(dy, abs=1e-6)


@settings(max_examples=25, deadline=None)
@given(dx=st.floats(-2.5, 2.5))
def test_subpixel_shift_across_vertical_probe_is_exact(dx):
    sem = _sem(probe_angles_deg=(90.0,), **_SMOOTH)
    bg = sem.render_clean(np.empty((0, 2)))
    a = sem.render_clean([[100.3, 100.0]]) - bg
    b = sem.render_clean([[100.3 + dx, 100.0]]) - bg
    assert _centroid(b, 1) - _centroid(a, 1) == pytest.approx(dx, abs=1e-6)


@pytest.mark.parametrize("dy", [0.1, 0.37, 0.5, 1.75, -0.83])
def test_subpixel_shift_default_probe_within_aliasing_bound(dy):
    sem = _sem(probe_angles_deg=(0.0,), beam_sigma_px=1.0)
    bg = sem.render_clean(np.empty((0, 2)))
    a = sem.render_clean([[120.0, 80.0]]) - bg
    b = sem.render_clean([[120.0, 80.0 + dy]]) - bg
    assert _centroid(b, 0) - _centroid(a, 0) == pytest.approx(dy, abs=2e-3)


@pytest.mark.parametrize("angle", [10.0, 37.0, 190.0])
def test_integer_shift_equals_pixel_shift(angle):
    # translating by whole pixels must reproduce the pixel grid shifted (no interpolation)
    sem = _sem(probe_angles_deg=(angle,))
    tip = np.array([[100.37, 80.61]])
    a = sem.render_clean(tip)
    b = sem.render_clean(tip + [3.0, -2.0])
    np.testing.assert_allclose(b[10:-10, 10:-10], a[12:-8, 7:-13], atol=1e-9)


def test_tip_is_the_extreme_point_of_the_shape():
    r, half = 5.0, math.radians(8)
    tip = (50.0, 40.0)
    d = probe_signed_distance(np.array([50.0, 50.0 + 1e-6, 45.0]), np.array([40.0, 40.0, 40.0]),
                              tip, 0.0, r, half)
    assert d[0] == pytest.approx(0.0, abs=1e-12)  # the tip point is on the boundary
    assert d[1] > 0  # just ahead of it is outside
    assert d[2] == pytest.approx(-5.0)  # the tip circle's centre is r deep
    # 100 px behind the tip the shaft's side is where the tangent line says it is
    u = 100.0
    v_side = r / math.cos(half) + (u - r) * math.tan(half)
    d_side = probe_signed_distance(np.array([50.0 - u, 50.0 - u]),
                                   np.array([40.0 + v_side, 40.0 - v_side - 2.0]), tip, 0.0, r, half)
    assert d_side[0] == pytest.approx(0.0, abs=1e-9)
    assert d_side[1] == pytest.approx(2.0 * math.cos(half), abs=1e-9)


def test_probe_bbox_contains_everything_visible():
    h, w = 120, 160
    Y, X = np.mgrid[0:h, 0:w].astype(float)
    rng = np.random.default_rng(3)
    for _ in range(30):
        tip = rng.uniform([-50, -50], [w + 50, h + 50])
        ang = rng.uniform(0, 2 * math.pi)
        r = rng.uniform(0.5, 20)
        d = probe_signed_distance(X, Y, tip, ang, r, math.radians(8))
        bb = probe_bbox(tip, ang, r, math.radians(8), 6.0, w, h)
        need = d < 6.0
        have = np.zeros_like(need)
        if bb is not None:
            have[bb[2]:bb[3], bb[0]:bb[1]] = True
        assert not np.any(need & ~have)


def test_probes_do_not_interfere():
    sem = SimulatedSEM(noise=SEMNoise.off(), seed=2)
    tips = np.array([[150.0, 250.0], [540.0, 140.0], [400.0, 80.0], [470.0, 400.0]])
    alone = sem.render_clean(tips[:1])
    together = sem.render_clean(tips)
    y, x = 250, 150
    win = (slice(y - 60, y + 61), slice(max(x - 150, 0), x + 61))
    assert np.max(np.abs(together[win] - alone[win])) < 1e-9
    # and each other probe does change its own neighbourhood
    for tx, ty in tips[1:]:
        tx, ty = int(tx), int(ty)
        assert np.max(np.abs(together[ty - 3:ty + 4, tx - 3:tx + 4] - alone[ty - 3:ty + 4, tx - 3:tx + 4])) > 20


def test_probe_brighter_than_substrate_with_bright_rim():
    sem = _sem(probe_angles_deg=(0.0,), pixel_size_nm=6.6)  # tip radius 15 px
    img = sem.render_clean([[150.0, 80.0]])
    substrate = img[10, 190]
    centre = img[80, 60]  # deep inside the shaft
    profile = img[:, 60]
    assert centre > substrate + 50
    assert profile.max() > centre + 10  # edge brightening
    top = np.argmax(profile > 0.5 * (centre + substrate))
    assert profile[top:top + 25].argmax() > 0  # the rim lies inside the edge


def test_noise_off_acquire_equals_render_clean():
    sem = SimulatedSEM(noise=SEMNoise.off(), seed=5, dtype=np.float64,
                       clutter=Clutter(n_static=10, n_drifting=3, occluder=True))
    tips = np.array([[150.0, 250.0], [540.0, 140.0]])
    for _ in range(3):
        clean = sem.render_clean(tips)
        frame = sem.acquire(tips)
        np.testing.assert_allclose(frame, clean, atol=2e-3)  # float32 pipeline vs float64
    sem8 = SimulatedSEM(noise=SEMNoise.off(), seed=5)
    clean = sem8.render_clean(tips)
    frame = sem8.acquire(tips)
    assert np.max(np.abs(frame.astype(float) - np.clip(clean, 0, 255))) <= 0.5 + 2e-3


def test_drift_moves_the_probe_and_truth_includes_it():
    noise = SEMNoise.off().replace(drift_px_per_s=3.0, drift_angle_deg=30.0)
    sem = _sem(noise=noise, dtype=np.float64, width=240, height=200)
    tips = np.array([[120.0, 100.0]])
    for _ in range(5):
        frame = sem.acquire(tips)
    t = sem.last_time
    expected = tips[0] + 3.0 * t * np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    np.testing.assert_allclose(sem.last_tips[0], expected, atol=1e-12)
    # the frame is the exact render at the drifted position (flat substrate)
    np.testing.assert_allclose(frame, sem.render_clean(sem.last_tips, t=t), atol=2e-3)


def test_bad_tips_raise():
    sem = _sem()
    with pytest.raises(ValueError, match="tips"):
        sem.render_clean([[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match="NaN"):
        sem.acquire([[np.nan, 2.0]])
    with pytest.raises(ValueError, match="probe_angles"):
        sem.render_clean(np.zeros((5, 2)))
    # a probe far off the frame is fine: nothing rendered, no crash
    img = sem.render_clean([[-1e4, 5e3]])
    assert np.ptp(img) == pytest.approx(0.0)


def _shoelace(pts):
    return 0.5 * abs(sum(p[0] * q[1] - q[0] * p[1] for p, q in zip(pts, pts[1:] + pts[:1])))


def test_clip_polygon_keeps_the_overlap_exactly():
    # a triangle inside is unchanged; one outside is empty; a square over the rectangle's corner
    # keeps the overlap, whose area is exact (straight cuts of straight edges: float rounding only)
    tri = [(1.0, 1.0), (3.0, 1.0), (2.0, 2.0)]
    assert clip_polygon(tri, 0, 4, 0, 4) == tri
    assert clip_polygon([(5.0, 5.0), (6.0, 5.0), (6.0, 6.0)], 0, 4, 0, 4) == []
    square = [(-1.0, -1.0), (2.0, -1.0), (2.0, 2.0), (-1.0, 2.0)]
    clipped = clip_polygon(square, 0, 4, 0, 4)
    assert _shoelace(clipped) == pytest.approx(4.0, abs=1e-12)
    assert all(0 <= x <= 4 and 0 <= y <= 4 for x, y in clipped)
