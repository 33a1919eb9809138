"""SEM noise and artefacts at video rate (the paper's "additive noise" and "gray-level fluctuation").

Signal chain for one frame, in the order the instrument applies it:

1. The beam delivers ``dose`` primary electrons per pixel (beam current x dwell time);
   a pixel of yield ``Y`` emits a Poisson number of detected electrons with mean
   ``lam = dose * Y`` (shot noise).
2. The detector maps electrons to gray levels with gain ``g = contrast / dose`` (the
   operator sets contrast so that yield 1 spans ``contrast`` gray levels; or a fixed
   ``detector_gain`` in gray levels per electron, then ``contrast = g * dose``) on top of
   the black level ``brightness``; Gaussian read noise is added.
3. The video amplifier's limited bandwidth correlates the noise along the scan line:
   an AR(1) process along x with coefficient ``line_correlation`` (variance preserved).
4. Each scan line gets a random offset (``line_offset_gray``) and a random horizontal
   position error (``line_jitter_px``, applied to the scene coordinates).
5. Per frame, gain and offset wander (AR(1) across frames): gray-level fluctuation; on top,
   optional independent jumps uniform in ``+-gain_jitter`` and ``+-offset_jitter_gray`` (an
   auto-contrast that re-adjusts every frame). The probe charges up, its brightness rising as
   ``1 + A (1 - exp(-t / tau))``; the substrate does not charge, and the edge brightening
   (a topographic effect) scales with the charging only if ``charging_scales_rim``.
6. The whole image drifts slowly (stage/beam drift); the probe truth includes it.
7. The frame grabber rounds and clips to 8 bits (quantisation variance 1/12).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

__all__ = ["ELEMENTARY_CHARGE", "SEMNoise", "ar1_kernel"]

ELEMENTARY_CHARGE = 1.602176634e-19


@dataclass(frozen=True)
class SEMNoise:
    """Noise model of a video-rate SEM; every effect can be switched off (0 / False).

    Parameters
    ----------
    beam_current_pA : float
        Probe current. 50 pA at 640x480 and 13 Hz gives ~60 primary e-/px.
    dwell_time_s : float or None
        Dwell time per pixel; ``None`` derives it from the frame period,
        ``frame_period * scan_efficiency / (width * height)``.
    scan_efficiency : float
        Fraction of the frame period spent on pixels (the rest is fly-back).
    dose_e_per_px : float or None
        Primary electrons per pixel; overrides ``beam_current_pA`` x dwell time.
    shot_noise : bool
        Poisson shot noise of the detected electrons.
    poisson_exact_below : float
        Pixels with a mean count below this draw exact Poisson numbers; above it a
        Gaussian of the same mean and variance is used (speed; skewness < 0.32).
    contrast : float
        Gray levels spanned by yield 1 (the operator's contrast setting).
    detector_gain : float or None
        Fixed detector gain in gray levels per detected electron; overrides
        ``contrast`` (which becomes ``detector_gain * dose``: less dose, darker image).
    brightness : float
        Black level in gray levels.
    read_noise_gray : float
        Standard deviation of the detector/amplifier Gaussian noise, gray levels.
    line_correlation : float
        AR(1) coefficient of the noise along the scan line, in [0, 1).
    line_offset_gray : float
        Standard deviation of a per-line offset.
    line_jitter_px : float
        Standard deviation of a per-line horizontal scan position error.
    gain_fluctuation : float
        Relative standard deviation of the per-frame gain.
    offset_fluctuation_gray : float
        Standard deviation of the per-frame offset.
    fluctuation_memory : float
        Frame-to-frame AR(1) coefficient of the gain/offset fluctuation, in [0, 1).
    gain_jitter : float
        Independent per-frame relative gain jump, uniform in ``[-gain_jitter, gain_jitter]``
        (on top of ``gain_fluctuation``); 0: off.
    offset_jitter_gray : float
        Independent per-frame offset jump, uniform in ``+-offset_jitter_gray`` gray levels.
    charging_amplitude : float
        Relative brightness increase of the probes when fully charged.
    charging_time_s : float
        Time constant of the charging.
    charging_scales_rim : bool
        Whether the edge brightening (rim) brightens with the charging like the probe's body
        (True, the historical model) or stays as it is (False: the rim is topographic contrast,
        the charging a change of the body's surface potential).
    drift_px_per_s : float
        Speed of the slow image drift.
    drift_angle_deg : float or None
        Direction of the drift; ``None`` draws one from the seed.

    Notes
    -----
    The defaults describe the paper's conditions (3,000x, 13 Hz, 640x480): a
    signal-to-noise ratio of ~4 on the substrate and ~6 on the probe.
    """

    beam_current_pA: float = 50.0
    dwell_time_s: float | None = None
    scan_efficiency: float = 0.8
    dose_e_per_px: float | None = None
    shot_noise: bool = True
    poisson_exact_below: float = 10.0
    contrast: float = 200.0
    detector_gain: float | None = None
    brightness: float = 30.0
    read_noise_gray: float = 2.0
    line_correlation: float = 0.5
    line_offset_gray: float = 1.5
    line_jitter_px: float = 0.1
    gain_fluctuation: float = 0.02
    offset_fluctuation_gray: float = 2.0
    fluctuation_memory: float = 0.9
    gain_jitter: float = 0.0
    offset_jitter_gray: float = 0.0
    charging_amplitude: float = 0.08
    charging_time_s: float = 20.0
    charging_scales_rim: bool = True
    drift_px_per_s: float = 0.05
    drift_angle_deg: float | None = None

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None or isinstance(v, bool):
                continue
            if not np.isfinite(v):
                raise ValueError(f"SEMNoise.{f.name} must be finite, got {v!r}")
            if f.name != "drift_angle_deg" and v < 0:
                raise ValueError(f"SEMNoise.{f.name} must be >= 0, got {v!r}"
                                 + (" (negative dose)" if "dose" in f.name or "current" in f.name
                                    else ""))
        if self.dose_e_per_px is not None and self.dose_e_per_px == 0 and self.shot_noise:
            raise ValueError("SEMNoise.dose_e_per_px is 0: no electrons, no image")
        if self.dwell_time_s is not None and self.dwell_time_s == 0:
            raise ValueError("SEMNoise.dwell_time_s must be > 0")
        if not 0 < self.scan_efficiency <= 1:
            raise ValueError(f"SEMNoise.scan_efficiency must lie in (0, 1], got {self.scan_efficiency}")
        if self.gain_jitter >= 1:
            raise ValueError(f"SEMNoise.gain_jitter must lie in [0, 1), got {self.gain_jitter}")
        for name in ("line_correlation", "fluctuation_memory"):
            if not 0 <= getattr(self, name) < 1:
                raise ValueError(f"SEMNoise.{name} must lie in [0, 1), got {getattr(self, name)}")
        if self.charging_amplitude > 0 and self.charging_time_s <= 0:
            raise ValueError("SEMNoise.charging_time_s must be > 0 when charging is on")
        if self.contrast <= 0:
            raise ValueError(f"SEMNoise.contrast must be > 0, got {self.contrast}")
        if self.detector_gain is not None and self.detector_gain <= 0:
            raise ValueError(f"SEMNoise.detector_gain must be > 0, got {self.detector_gain}")

    @classmethod
    def off(cls) -> SEMNoise:
        """All effects off: ``acquire`` then returns ``render_clean`` (up to quantisation)."""
        return cls(shot_noise=False, read_noise_gray=0.0, line_correlation=0.0,
                   line_offset_gray=0.0, line_jitter_px=0.0, gain_fluctuation=0.0,
                   offset_fluctuation_gray=0.0, charging_amplitude=0.0, drift_px_per_s=0.0)

    def replace(self, **changes) -> SEMNoise:
        """A copy with some parameters changed (validated)."""
        return replace(self, **changes)

    def as_dict(self) -> dict:
        """Parameters as a plain dict (for ``meta``)."""
        return asdict(self)

    def dose(self, frame_period: float, n_pixels: int) -> float:
        """Primary electrons per pixel.

        Parameters
        ----------
        frame_period : float
            Seconds per frame.
        n_pixels : int
            Pixels per frame.

        Returns
        -------
        float
            ``dose_e_per_px`` if given, else beam current x dwell time / e.
        """
        if self.dose_e_per_px is not None:
            return float(self.dose_e_per_px)
        dwell = self.dwell_time_s
        if dwell is None:
            dwell = frame_period * self.scan_efficiency / n_pixels
        dose = self.beam_current_pA * 1e-12 * dwell / ELEMENTARY_CHARGE
        if self.shot_noise and dose <= 0:
            raise ValueError("SEMNoise: the dose is 0 (beam current 0); switch shot_noise off instead")
        return dose

    def effective_contrast(self, frame_period: float, n_pixels: int) -> float:
        """Gray levels spanned by yield 1: ``contrast``, or ``detector_gain * dose``."""
        if self.detector_gain is None:
            return float(self.contrast)
        return self.detector_gain * self.dose(frame_period, n_pixels)

    def gain_gray_per_electron(self, frame_period: float, n_pixels: int) -> float:
        """Detector gain in gray levels per detected electron (``contrast / dose``)."""
        if self.detector_gain is not None:
            return float(self.detector_gain)
        d = self.dose(frame_period, n_pixels)
        return self.contrast / d if d > 0 else 0.0

    def charging_factor(self, t: float) -> float:
        """Relative probe brightness at time ``t`` (s) due to charging."""
        if self.charging_amplitude == 0:
            return 1.0
        return 1.0 + self.charging_amplitude * (1.0 - math.exp(-t / self.charging_time_s))


def ar1_kernel(rho: float, tol: float = 1e-6) -> np.ndarray:
    """Causal FIR truncation of a unit-variance AR(1) filter along the scan line.

    ``h[k] = sqrt(1 - rho**2) * rho**k`` for ``k < K`` with ``rho**K < tol``, so that
    white noise of variance ``s**2`` filtered by ``h`` is an AR(1) process of variance
    ``s**2`` and lag-1 correlation ``rho``.
    """
    if rho <= 0:
        return np.ones(1, np.float32)
    k = max(math.ceil(math.log(tol) / math.log(rho)), 1)
    return (math.sqrt(1 - rho * rho) * rho ** np.arange(k)).astype(np.float32)
