"""Rough substrates (semlab.sim.substrate): the spectrum, the strength, the yield floor."""

from __future__ import annotations

import numpy as np
import pytest

from semlab.sim import SEMNoise, SimulatedSEM
from semlab.sim.substrate import MIN_YIELD, fractal_field, grain_field, textured_substrate


@pytest.mark.parametrize("beta", [2.0, 3.0])
def test_fractal_field_has_the_requested_power_law(beta):
    rng = np.random.default_rng(1)
    f = fractal_field(256, 256, rng, beta=beta).astype(float)
    P = np.abs(np.fft.fft2(f)) ** 2
    fy, fx = np.meshgrid(np.fft.fftfreq(256), np.fft.fftfreq(256), indexing="ij")
    r = np.hypot(fx, fy)
    bins = np.geomspace(0.02, 0.4, 12)
    idx = np.digitize(r, bins)
    centres = [np.exp(np.mean(np.log(r[idx == i]))) for i in range(1, len(bins))]
    power = [P[idx == i].mean() for i in range(1, len(bins))]
    slope = np.polyfit(np.log(centres), np.log(power), 1)[0]
    # each bin averages >= 40 independent exponential draws: the fitted slope scatters by ~0.05
    assert slope == pytest.approx(-beta, abs=0.15)
    assert f.mean() == pytest.approx(0, abs=1e-6) and f.std() == pytest.approx(1, rel=1e-6)


def test_grains_are_piecewise_constant_cells():
    rng = np.random.default_rng(2)
    g = grain_field(200, 150, rng, grain_px=15.0, boundary=0.0)
    # away from boundaries neighbours share a level: most horizontal differences are exactly zero
    same = np.mean(np.diff(g, axis=1) == 0)
    assert same > 0.85  # a 15-px grain has a boundary every ~15 px along a row: ~1/15 differ
    n_levels = len(np.unique(g))
    expected = int(200 * 150 / (0.785 * 15**2))
    assert 0.8 * expected <= n_levels <= expected


@pytest.mark.parametrize("kind", ["fractal", "grains"])
def test_substrate_strength_is_its_standard_deviation(kind):
    img = textured_substrate(320, 240, np.random.default_rng(3), kind=kind, strength=0.05, sigma_px=0.6)
    assert img.mean() == pytest.approx(0.2, abs=2e-3)
    assert img.std() == pytest.approx(0.05, rel=0.02)  # exact before the floor, which clips nothing here
    assert img.min() >= MIN_YIELD


def test_flat_substrate_and_the_floor():
    flat = textured_substrate(64, 48, np.random.default_rng(0), kind="flat", strength=0.1)
    assert np.all(flat == np.float32(0.2))
    rough = textured_substrate(128, 96, np.random.default_rng(0), kind="fractal", strength=0.3)
    assert rough.min() == pytest.approx(MIN_YIELD)  # a texture deeper than the mean yield is floored


def test_bad_substrate_arguments():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="unknown substrate kind"):
        textured_substrate(32, 32, rng, kind="mud")
    with pytest.raises(ValueError, match="strength"):
        textured_substrate(32, 32, rng, strength=-1)
    with pytest.raises(ValueError, match="beta"):
        fractal_field(32, 32, rng, beta=-1)


def test_sem_uses_a_given_background_and_checks_it():
    bg = textured_substrate(96, 64, np.random.default_rng(5), kind="grains", strength=0.05)
    sem = SimulatedSEM(96, 64, noise=SEMNoise.off(), seed=0, dtype=np.float64, background=bg)
    far = sem.render_clean([[-500.0, -500.0]])  # the probe far off the frame: only the background
    np.testing.assert_allclose(far, sem.noise.brightness + sem.contrast * bg.astype(float), atol=1e-4)
    with pytest.raises(ValueError, match="background"):
        SimulatedSEM(96, 64, seed=0, background=np.zeros((10, 10)))
