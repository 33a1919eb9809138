"""Noise physics: shot noise statistics, line correlation, offsets, charging, and the CRB."""

import math

import numpy as np
import pytest

from semlab.sim import Clutter, ProbeGeometry, SEMNoise, SimulatedSEM, translation_crb
from semlab.sim.noise import ELEMENTARY_CHARGE

OFF = SEMNoise.off()
TIP = np.array([[70.0, 60.0]])


def _sem(noise, **kw):
    kw.setdefault("width", 128)
    kw.setdefault("height", 96)
    kw.setdefault("clutter", Clutter(n_static=4))
    kw.setdefault("dtype", np.float64)
    return SimulatedSEM(noise=noise, **kw)


def _stack(sem, n, tips=TIP):
    return np.stack([sem.acquire(tips) for _ in range(n)])


def test_dose_follows_dwell_time():
    n = SEMNoise(beam_current_pA=50.0)
    d1 = n.dose(1 / 13, 640 * 480)
    assert d1 == pytest.approx(50e-12 * (0.8 / 13 / (640 * 480)) / ELEMENTARY_CHARGE)
    # twice the dwell time (half the scan speed), twice the electrons
    n2 = n.replace(dwell_time_s=2 * 0.8 / 13 / (640 * 480))
    assert n2.dose(1 / 13, 640 * 480) == pytest.approx(2 * d1)
    assert SEMNoise(dose_e_per_px=7.0).dose(1.0, 1) == 7.0
    # a fixed detector gain: half the dose, half the contrast
    g = SEMNoise(detector_gain=2.0)
    assert g.effective_contrast(1 / 13, 640 * 480) == pytest.approx(2.0 * d1)
    sem = SimulatedSEM(noise=g, seed=0)
    assert sem.contrast == pytest.approx(2.0 * d1) and sem.gain_gray_per_electron == 2.0


@pytest.mark.parametrize("dose", [200.0, 4.0])  # Gaussian and exact-Poisson regimes
def test_shot_noise_variance_follows_mean(dose):
    noise = OFF.replace(shot_noise=True, dose_e_per_px=dose)
    sem = _sem(noise, seed=1)
    clean = sem.render_clean(TIP)
    frames = _stack(sem, 60)
    mean = frames.mean(0)
    var = frames.var(0, ddof=1)
    g_e = noise.contrast / dose  # gray levels per detected electron
    np.testing.assert_allclose(mean.mean(), clean.mean(), rtol=3e-3)
    # var = g_e * (mean - black level): regression slope through the origin
    x = (clean - noise.brightness).ravel()
    slope = float(x @ var.ravel() / (x @ x))
    # sampling error of 60-frame variances averaged over ~12k pixels: < 1 %
    assert slope == pytest.approx(g_e, rel=0.03)


def test_low_dose_counts_are_integers():
    # exact Poisson below poisson_exact_below: gray levels sit on the electron lattice
    noise = OFF.replace(shot_noise=True, dose_e_per_px=3.0)
    sem = _sem(noise, seed=2, clutter=Clutter.none())
    frame = sem.acquire(TIP)
    counts = (frame - noise.brightness) / (noise.contrast / 3.0)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-3)
    assert (np.round(counts) == 0).mean() > 0.3  # P(0) = exp(-0.6) = 0.55 on the substrate


def test_line_correlation_and_offsets():
    rho, read, off = 0.6, 5.0, 3.0
    noise = OFF.replace(read_noise_gray=read, line_correlation=rho, line_offset_gray=off)
    sem = _sem(noise, seed=3, width=256, height=128, clutter=Clutter.none())
    clean = sem.render_clean(np.empty((0, 2)))
    frames = _stack(sem, 20, np.empty((0, 2))) - clean
    rows = frames.mean(axis=2)  # per-line offset + averaged AR(1) noise
    ar_var_of_row_mean = read**2 * (1 + rho) / (1 - rho) / 256  # long-run variance / n
    assert rows.var() == pytest.approx(off**2 + ar_var_of_row_mean, rel=0.15)
    e = frames - rows[..., None]
    lag1_x = (e[..., 1:] * e[..., :-1]).mean() / e.var()
    lag1_y = (e[:, 1:] * e[:, :-1]).mean() / e.var()
    assert lag1_x == pytest.approx(rho, abs=0.02)
    assert abs(lag1_y) < 0.02
    assert e.var() == pytest.approx(read**2, rel=0.05)


def test_gray_level_fluctuation_gain_and_offset():
    noise = OFF.replace(gain_fluctuation=0.1, offset_fluctuation_gray=8.0, fluctuation_memory=0.0)
    sem = _sem(noise, seed=4)
    clean = sem.render_clean(TIP)
    x = clean - noise.brightness
    gains, offsets = [], []
    for _ in range(300):
        f = sem.acquire(TIP)
        a, b = np.polyfit(x.ravel(), (f - noise.brightness).ravel(), 1)
        gains.append(a)
        offsets.append(b)
    assert np.std(gains) == pytest.approx(0.1, rel=0.15)
    assert np.std(offsets) == pytest.approx(8.0, rel=0.15)
    assert abs(np.mean(gains) - 1) < 0.03


def test_charging_brightens_the_probe():
    noise = OFF.replace(charging_amplitude=0.5, charging_time_s=1.0)
    sem = _sem(noise, seed=5, clutter=Clutter.none(), probe=ProbeGeometry(shading=0.0))
    tip = np.array([[100.0, 48.0]])
    clean = sem.render_clean(tip)
    plateau = noise.brightness + noise.contrast * sem.probe.brightness
    deep = np.abs(clean - plateau) < 1e-6  # fully covered, no rim: pure probe yield
    assert deep.sum() > 100
    for _ in range(30):
        f = sem.acquire(tip)
    factor = 1 + 0.5 * (1 - math.exp(-sem.last_time / 1.0))
    np.testing.assert_allclose((f[deep] - noise.brightness) / (plateau - noise.brightness),
                               factor, rtol=1e-5)
    assert factor > 1.4


def test_bad_noise_parameters_raise():
    with pytest.raises(ValueError, match="dose"):
        SEMNoise(dose_e_per_px=-3.0)
    with pytest.raises(ValueError, match="beam_current"):
        SEMNoise(beam_current_pA=-1.0)
    with pytest.raises(ValueError, match="line_correlation"):
        SEMNoise(line_correlation=1.0)
    with pytest.raises(ValueError, match="finite"):
        SEMNoise(read_noise_gray=float("nan"))


def _gls_fit(sem, tips, roi, frame, c_row, iters=4):
    """Gauss-Newton ML estimate of the probe translation; noise rows ~ N(0, c_row)."""
    x0, y0, w, h = roi
    sl = (slice(y0, y0 + h), slice(x0, x0 + w))
    w_row = np.linalg.inv(np.linalg.cholesky(c_row))  # whitening of one ROI row

    def whiten(a):
        return a @ w_row.T

    p = np.zeros(2)
    for _ in range(iters):
        tt = tips.copy()
        tt[0] += p
        m = sem.render_clean(tt)[sl]
        jx = (sem.render_clean(tt + [[1e-3, 0]])[sl] - sem.render_clean(tt - [[1e-3, 0]])[sl]) / 2e-3
        jy = (sem.render_clean(tt + [[0, 1e-3]])[sl] - sem.render_clean(tt - [[0, 1e-3]])[sl]) / 2e-3
        J = np.stack([whiten(jx).ravel(), whiten(jy).ravel()], 1)
        r = whiten(frame[sl] - m).ravel()
        p = p + np.linalg.lstsq(J, r, rcond=None)[0]
    return p


@pytest.mark.parametrize(("rho", "line_offset"), [(0.0, 0.0), (0.5, 0.0), (0.5, 6.0)])
def test_crb_matches_an_efficient_estimator(rho, line_offset):
    # With Gaussian noise the ML estimator is efficient: its spread over noise
    # realisations must match the Cramér–Rao bound (100 trials: +-14 % at 2 sigma).
    # Each ROI row's noise is AR(1) along x plus a per-line offset: the estimator uses
    # the explicit row covariance, translation_crb its own whitening + Woodbury update.
    read = 12.0
    noise = OFF.replace(read_noise_gray=read, line_correlation=rho, line_offset_gray=line_offset)
    sem = SimulatedSEM(width=96, height=64, noise=noise, clutter=Clutter.none(), seed=6,
                       dtype=np.float64, probe_angles_deg=(20.0,), beam_sigma_px=0.8)
    tips = np.array([[60.3, 32.6]])
    roi = (20, 12, 60, 40)
    lag = np.abs(np.subtract.outer(np.arange(60), np.arange(60)))
    c_row = read**2 * rho**lag + line_offset**2
    crb = np.array(translation_crb(sem, tips, roi, nuisance=False))
    est = np.array([_gls_fit(sem, tips, roi, sem.acquire(tips), c_row) for _ in range(100)])
    std = est.std(0, ddof=1)
    assert np.all(np.abs(est.mean(0)) < 3 * crb / 10 + 1e-3)  # unbiased
    np.testing.assert_allclose(std, crb, rtol=0.2)


def test_fisher_equals_explicit_row_covariance():
    # whitening + Woodbury in translation_fisher == J^T C^-1 J with each row's covariance
    # written out: AR(1) read noise + per-line offset + linearised per-line jitter
    read, rho, off, jit = 10.0, 0.6, 5.0, 0.3
    noise = OFF.replace(read_noise_gray=read, line_correlation=rho, line_offset_gray=off,
                        line_jitter_px=jit)
    sem = SimulatedSEM(width=96, height=64, noise=noise, clutter=Clutter.none(), seed=6,
                       dtype=np.float64, probe_angles_deg=(20.0,))
    tips = np.array([[60.3, 32.6]])
    x0, y0, w, h = roi = (20, 12, 60, 40)
    from semlab.sim.crb import translation_fisher
    F = translation_fisher(sem, tips, roi, nuisance=False)
    m = sem.render_clean(tips)
    jx = (sem.render_clean(tips + [[1e-2, 0]]) - sem.render_clean(tips - [[1e-2, 0]])) / 2e-2
    jy = (sem.render_clean(tips + [[0, 1e-2]]) - sem.render_clean(tips - [[0, 1e-2]])) / 2e-2
    gx = np.gradient(m, axis=1)
    lag = np.abs(np.subtract.outer(np.arange(w), np.arange(w)))
    F_ref = np.zeros((2, 2))
    for r in range(y0, y0 + h):
        g = gx[r, x0:x0 + w]
        C = read**2 * rho**lag + off**2 + jit**2 * np.outer(g, g)
        J = np.stack([jx[r, x0:x0 + w], jy[r, x0:x0 + w]], 1)
        F_ref += J.T @ np.linalg.solve(C, J)
    np.testing.assert_allclose(F, F_ref, rtol=1e-6)


def test_crb_scales_with_dose():
    # shot-noise limited: the bound scales as 1 / sqrt(dose)
    tips = np.array([[150.0, 250.0]])
    roi = (50, 150, 200, 200)
    base = OFF.replace(shot_noise=True)
    s1 = translation_crb(SimulatedSEM(noise=base.replace(dose_e_per_px=100.0), seed=0, dtype=np.float32),
                         tips, roi)
    s4 = translation_crb(SimulatedSEM(noise=base.replace(dose_e_per_px=400.0), seed=0, dtype=np.float32),
                         tips, roi)
    np.testing.assert_allclose(np.array(s1) / np.array(s4), 2.0, rtol=1e-6)


def test_crb_bad_inputs():
    sem = SimulatedSEM(seed=0)
    tips = np.array([[150.0, 250.0]])
    with pytest.raises(ValueError, match="roi"):
        translation_crb(sem, tips, (-1, 0, 200, 200))
    with pytest.raises(ValueError, match="roi"):
        translation_crb(sem, tips, (0, 0, 200))
    with pytest.raises(ValueError, match="probe"):
        translation_crb(sem, tips, (50, 150, 200, 200), probe=3)
    with pytest.raises(ValueError, match="off the"):
        translation_crb(sem, [[-20.0, 250.0]], (50, 150, 200, 200))
    with pytest.raises(ValueError, match="infinite"):
        translation_crb(SimulatedSEM(seed=0, noise=OFF, dtype=np.float64), tips, (50, 150, 200, 200))
