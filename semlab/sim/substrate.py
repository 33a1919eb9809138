"""Substrates from flat to strongly textured, in yield units, for :class:`semlab.sim.SimulatedSEM`.

:func:`semlab.sim.scene.make_substrate` draws a gently textured substrate (two Gaussian-filtered
noise scales); real samples are often far rougher. Two physical models of a rough surface:

* ``"fractal"``: a self-affine surface whose secondary-electron yield follows its local slope
  and height -- a Gaussian random field with a power-law spectrum ``P(f) ~ f**-beta``
  (``beta`` between 2 and 4 for most sputtered, etched or polished surfaces), synthesised
  exactly in the Fourier domain;
* ``"grains"``: a polycrystalline film -- Voronoi cells of random yield (channelling contrast
  differs from grain to grain), with a darker or brighter line along each grain boundary.

Both are blurred by the beam (the static background is imaged through the same Gaussian
probe as the tip) and scaled to a given standard deviation of yield, ``strength``.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["SUBSTRATE_KINDS", "fractal_field", "grain_field", "textured_substrate"]

SUBSTRATE_KINDS = ("flat", "fractal", "grains")
#: Floor of the yield: a rough texture's deepest valleys still emit (5 % of a flat substrate's).
MIN_YIELD = 0.01


def fractal_field(width: int, height: int, rng: np.random.Generator, beta: float = 3.0,
                  min_wavelength_px: float = 2.0) -> np.ndarray:
    """Zero-mean, unit-variance Gaussian random field with the power spectrum ``f**-beta``.

    Parameters
    ----------
    width, height : int
        Size in px.
    rng : numpy.random.Generator
    beta : float
        Spectral exponent of the radially averaged power spectrum (0 = white noise).
    min_wavelength_px : float
        Shortest wavelength kept (>= 2 px, the Nyquist limit).

    Returns
    -------
    (height, width) ndarray of float32
    """
    if not (np.isfinite(beta) and beta >= 0):
        raise ValueError(f"beta must be >= 0, got {beta!r}")
    if not min_wavelength_px >= 2:
        raise ValueError(f"min_wavelength_px must be >= 2, got {min_wavelength_px!r}")
    fy = np.fft.fftfreq(height)[:, None]
    fx = np.fft.rfftfreq(width)[None, :]
    f = np.hypot(fx, fy)
    f_min = 1.0 / max(width, height)
    amp = np.where(f > 0, np.maximum(f, f_min) ** (-beta / 2.0), 0.0)
    amp[f > 1.0 / min_wavelength_px] = 0.0
    spectrum = amp * (rng.standard_normal(f.shape) + 1j * rng.standard_normal(f.shape))
    field = np.fft.irfft2(spectrum, s=(height, width))
    field -= field.mean()
    sd = field.std()
    return (field / sd if sd > 0 else field).astype(np.float32)


def grain_field(width: int, height: int, rng: np.random.Generator, grain_px: float = 12.0,
                boundary: float = -1.0) -> np.ndarray:
    """Polycrystalline texture: Voronoi grains of random level with a line along each boundary.

    Parameters
    ----------
    width, height : int
        Size in px.
    rng : numpy.random.Generator
    grain_px : float
        Mean grain diameter in px.
    boundary : float
        Level of the grain-boundary line relative to the grains' spread (negative: darker).

    Returns
    -------
    (height, width) ndarray of float32
        Zero mean, unit standard deviation.
    """
    if not grain_px >= 2:
        raise ValueError(f"grain_px must be >= 2, got {grain_px!r}")
    n = max(int(width * height / (0.785 * grain_px**2)), 2)
    seeds = np.column_stack([rng.uniform(0, width, n), rng.uniform(0, height, n)])
    levels = rng.standard_normal(n)
    yy, xx = np.mgrid[0:height, 0:width]
    pts = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    dist, idx = cKDTree(seeds).query(pts, k=2)
    field = levels[idx[:, 0]]
    # a pixel within ~1 px of the bisector between its two nearest seeds lies on a boundary
    gap = dist[:, 1] - dist[:, 0]
    field = field + boundary * np.exp(-0.5 * (gap / 1.0) ** 2)
    field = field.reshape(height, width)
    field -= field.mean()
    sd = field.std()
    return (field / sd if sd > 0 else field).astype(np.float32)


def textured_substrate(width: int, height: int, rng: np.random.Generator, kind: str = "fractal",
                       strength: float = 0.05, sigma_px: float = 0.5, base_yield: float = 0.2,
                       beta: float = 3.0, grain_px: float = 12.0) -> np.ndarray:
    """A static background in yield units: ``base_yield`` plus a texture of std ``strength``.

    Parameters
    ----------
    width, height : int
        Frame size in px.
    rng : numpy.random.Generator
    kind : {"flat", "fractal", "grains"}
        See the module docstring (``"flat"``: the constant ``base_yield``).
    strength : float
        Standard deviation of the texture in yield units, after the beam blur (the substrate's
        mean yield is ~0.2 and a tungsten probe's ~0.55: 0.1 is a very rough sample).
    sigma_px : float
        Beam blur (Gaussian sigma, px).
    base_yield : float
        Mean yield.
    beta, grain_px : float
        Spectral exponent of ``"fractal"``, grain diameter of ``"grains"``.

    Returns
    -------
    (height, width) ndarray of float32
    """
    if kind not in SUBSTRATE_KINDS:
        raise ValueError(f"unknown substrate kind {kind!r}; choose one of {SUBSTRATE_KINDS}")
    if not (np.isfinite(strength) and strength >= 0):
        raise ValueError(f"strength must be >= 0, got {strength!r}")
    img = np.full((height, width), base_yield, np.float32)
    if kind == "flat" or strength == 0:
        return img
    if kind == "fractal":
        field = fractal_field(width, height, rng, beta=beta)
    else:
        field = grain_field(width, height, rng, grain_px=grain_px)
    if sigma_px > 0:
        field = cv2.GaussianBlur(field, (0, 0), sigma_px)
    sd = float(field.std())
    if sd > 0:
        img += np.float32(strength / sd) * (field - np.float32(field.mean()))
    # a yield is never negative (the deepest valleys of a very rough texture would be)
    return np.maximum(img, np.float32(MIN_YIELD))
