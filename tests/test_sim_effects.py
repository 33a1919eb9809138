"""New physical effects of the SEM model: probe-only charging with an unscaled rim, per-frame jitter."""

from __future__ import annotations

import numpy as np
import pytest

from semlab.sim import ProbeGeometry, SEMNoise, SimulatedSEM
from semlab.sim.crb import sem_has_photometric_nuisance


def _sem(**noise):
    return SimulatedSEM(160, 120, noise=SEMNoise.off().replace(**noise), seed=0, dtype=np.float64,
                        probe=ProbeGeometry(shading=0.0), probe_angles_deg=(0.0,))


@pytest.mark.parametrize("scales_rim", [True, False])
def test_charging_brightens_the_body_and_only_the_rim_if_asked(scales_rim):
    sem = _sem(charging_scales_rim=scales_rim)
    tip = [[100.0, 60.0]]
    base, charged = sem.render_clean(tip), sem.render_clean(tip, charge=1.5)
    diff = charged - base
    assert np.all(diff[5, :] == 0)  # the substrate far from the probe does not charge
    g = sem.probe
    # deep in the shaft: the body's yield x 0.5 x contrast, plus the rim's share where it reaches
    body_gain = 0.5 * g.brightness * sem.contrast
    assert diff[60, 60] == pytest.approx(body_gain, rel=1e-6)
    # the same difference as a probe without any rim, or not: only the body scales
    norim = SimulatedSEM(160, 120, noise=sem.noise, seed=0, dtype=np.float64, probe_angles_deg=(0.0,),
                         probe=ProbeGeometry(shading=0.0, rim_amplitude=0.0))
    d0 = norim.render_clean(tip, charge=1.5) - norim.render_clean(tip)
    if scales_rim:
        assert np.max(np.abs(diff - d0)) > 1.0  # the rim brightened too
    else:
        np.testing.assert_allclose(diff, d0, atol=1e-9)


def test_gain_and_offset_jitter_stay_within_their_bounds():
    # a flat scene, no other noise: frame k's mean is (black + contrast * 0.2) * ... gain_k + offset_k
    sem = SimulatedSEM(64, 48, noise=SEMNoise.off().replace(gain_jitter=0.15), seed=1, dtype=np.float64,
                       clutter=None, probe_angles_deg=(0.0,))
    sem._background[:] = 0.2
    level = 0.2 * sem.contrast
    gains = np.array([(sem.acquire([[-900.0, -900.0]]).mean() - sem.noise.brightness) / level for _ in range(400)])
    assert np.all(np.abs(gains - 1) <= 0.15 + 1e-9)
    # uniform in +-0.15: standard deviation 0.15 / sqrt(3) = 0.0866; 400 draws: +-5 % (3 sigma ~ 11 %)
    assert gains.std() == pytest.approx(0.15 / np.sqrt(3), rel=0.12)
    sem = SimulatedSEM(64, 48, noise=SEMNoise.off().replace(offset_jitter_gray=20.0), seed=1, dtype=np.float64,
                       probe_angles_deg=(0.0,))
    sem._background[:] = 0.2
    offsets = np.array([sem.acquire([[-900.0, -900.0]]).mean() - sem.noise.brightness - level for _ in range(400)])
    assert np.all(np.abs(offsets) <= 20.0 + 1e-6)
    assert offsets.std() == pytest.approx(20 / np.sqrt(3), rel=0.12)


def test_jitter_off_leaves_old_sequences_unchanged():
    # the new draws happen only when the jitter is on: the default noise gives the same frames
    a = SimulatedSEM(80, 60, seed=3).acquire([[40.0, 30.0]])
    b = SimulatedSEM(80, 60, seed=3, noise=SEMNoise(gain_jitter=0.0)).acquire([[40.0, 30.0]])
    np.testing.assert_array_equal(a, b)


def test_jitter_makes_gain_and_offset_nuisance_parameters_of_the_bound():
    assert not sem_has_photometric_nuisance(SEMNoise.off())
    assert sem_has_photometric_nuisance(SEMNoise.off().replace(gain_jitter=0.1))
    assert sem_has_photometric_nuisance(SEMNoise.off().replace(offset_jitter_gray=3.0))
    with pytest.raises(ValueError, match="gain_jitter"):
        SEMNoise(gain_jitter=1.5)


def test_render_clean_refuses_a_bad_charge():
    with pytest.raises(ValueError, match="charge"):
        _sem().render_clean([[50.0, 50.0]], charge=0.0)
