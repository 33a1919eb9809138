"""Other probe outlines (semlab.sim.shapes): exact distances, exact translation, the right geometry."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from semlab.sim import ProbeGeometry, SEMNoise, SimulatedSEM
from semlab.sim.shapes import (
    AFMTip,
    BluntProbe,
    GripperJaws,
    ProbeShape,
    polygon_signed_distance,
    render_shape,
)


def test_polygon_distance_is_exact_for_a_rectangle():
    rng = np.random.default_rng(0)
    X, Y = rng.uniform(-10, 10, 2000), rng.uniform(-10, 10, 2000)
    d = polygon_signed_distance(X, Y, [(-3, -2), (3, -2), (3, 2), (-3, 2)])
    # the distance to an axis-aligned box (Inigo Quilez's closed form)
    qx, qy = np.abs(X) - 3, np.abs(Y) - 2
    exact = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0)
    np.testing.assert_allclose(d, exact, atol=1e-12)


@dataclass(frozen=True)
class _Square(ProbeShape):
    """A finite rounded square (its area and centroid are known), for the rendering tests."""

    side_nm: float = 600.0
    corner_radius_nm: float = 66.0

    def half_width_nm(self):
        return self.side_nm / 2

    def polygons_nm(self, far_nm):
        h = self.side_nm / 2 - self.corner_radius_nm
        return [np.array([(-h, -h), (h, -h), (h, h), (-h, h)])]


#: 6.6 nm/px: the square is 91 px wide with 10-px corners; the blur 0.6 px is << the corners'
#: radius, where the straight-edge coverage Phi(-d / sigma) of a rounded convex outline integrates
#: exactly to area + pi sigma^2 (the parallel bodies at +-t differ in perimeter by 4 pi t, and
#: int_0^inf t Phi(-t / sigma) dt = sigma^2 / 4).
PX_NM, SIGMA = 6.6, 0.6


def _coverage(shape, tip, angle=0.3):
    buf = np.zeros((160, 160))
    render_shape(buf, shape, tip, angle, PX_NM, SIGMA, 1.0, 0.0, 1.0)
    return buf


def test_rendered_area_is_the_rounded_polygons_area():
    sq = _Square()
    r = sq.corner_radius_nm / PX_NM
    a = sq.side_nm / PX_NM - 2 * r
    area = a * a + 4 * a * r + math.pi * r * r + math.pi * SIGMA**2
    # pixel sums of a function blurred by 0.6 px equal its integral to ~exp(-2 pi^2 0.6^2) ~ 1e-3
    # of the outline's Fourier coefficient at 1 cycle/px (Poisson summation): << pi sigma^2 = 1.13
    assert _coverage(sq, (80.0, 80.0)).sum() == pytest.approx(area, abs=0.05)


@pytest.mark.parametrize("shift", [(0.37, -0.21), (1.5, 0.25), (-2.9, 3.3)])
def test_a_rendered_shift_is_the_requested_one(shift):
    # the centroid of the coverage moves by exactly the translation: the render is a function of
    # (x - tip), and sampling it loses ~1e-3 / 8,000 px^2 of its mass (see above) -> ~1e-5 px
    def centroid(img):
        yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
        return np.array([(img * xx).sum(), (img * yy).sum()]) / img.sum()

    a = _coverage(_Square(), (80.0, 80.0))
    b = _coverage(_Square(), (80.0 + shift[0], 80.0 + shift[1]))
    np.testing.assert_allclose(centroid(b) - centroid(a), shift, atol=1e-4)


def _sem(shape, angle=0.0):
    return SimulatedSEM(256, 192, pixel_size_nm=50.0, noise=SEMNoise.off(), probe=ProbeGeometry(shape=shape, shading=0.0,
                        rim_amplitude=0.0), seed=0, probe_angles_deg=(angle,), dtype=np.float64,
                        background=np.full((192, 256), 0.2))


def test_gripper_truth_point_is_in_the_gap_between_the_jaws():
    g = GripperJaws(jaw_length_nm=2000, jaw_width_nm=600, jaw_tip_width_nm=400, gap_nm=800, corner_radius_nm=40)
    sem = _sem(g)
    img = sem.render_clean([[150.0, 96.0]])
    bg = sem.noise.brightness + sem.contrast * 0.2
    body = sem.noise.brightness + sem.contrast * sem.probe.brightness
    assert img[96, 150] == pytest.approx(bg, abs=1e-3)  # the truth point: empty gap
    assert img[96, 149 - 10] == pytest.approx(bg, abs=1e-3)  # still in the gap, 10 px behind
    finger = 96 + round((400 + 300) / 50)  # 8 px + 6 px across: inside the lower-image finger
    assert img[finger, 145] == pytest.approx(body, abs=1e-3)
    assert img[96, 150 - 50] == pytest.approx(body, abs=1e-3)  # the body behind the 40-px jaws


def test_blunt_and_afm_reach_the_truth_point():
    # along the axis the outline ends exactly at the truth point: coverage 1/2 there (blurred edge)
    for shape in (BluntProbe(width_nm=800, corner_radius_nm=100), AFMTip(cantilever_width_nm=2000,
                                                                        point_length_nm=1500, corner_radius_nm=50)):
        sem = _sem(shape)
        img = sem.render_clean([[150.0, 96.0]])
        bg = sem.noise.brightness + sem.contrast * 0.2
        body = sem.noise.brightness + sem.contrast * sem.probe.brightness
        assert (img[96, 150] - bg) / (body - bg) == pytest.approx(0.5, abs=0.02)


@pytest.mark.parametrize("bad", [{"width_nm": -1}, {"width_nm": 100, "corner_radius_nm": 60}])
def test_blunt_refuses_bad_geometry(bad):
    with pytest.raises(ValueError):
        BluntProbe(**bad)


def test_gripper_and_afm_refuse_bad_geometry():
    with pytest.raises(ValueError, match="jaw_tip_width_nm"):
        GripperJaws(jaw_width_nm=300, jaw_tip_width_nm=500)
    with pytest.raises(ValueError, match="corner_radius_nm"):
        AFMTip(cantilever_width_nm=200, corner_radius_nm=80)


def test_a_shape_off_the_frame_renders_nothing():
    buf = np.zeros((50, 50))
    assert render_shape(buf, BluntProbe(), (500.0, 500.0), 0.0, 66.0, 0.5, 1.0, 0.0, 1.0) is None
    assert not buf.any()
