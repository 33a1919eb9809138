"""The simulated SEM: analytic scene + noise model -> frames like a frame grabber's.

:class:`SimulatedSEM` renders probe tips given in px; :class:`semlab.sim.rig.SimulatedRig`
drives it from the manipulators' positions.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .noise import SEMNoise, ar1_kernel
from .optics import beam_blur_sigma_px
from .scene import (
    DEFAULT_PROBE_ANGLES_DEG,
    Clutter,
    ProbeGeometry,
    make_substrate,
    render_disc,
    render_probe,
)
from .shapes import render_shape

__all__ = ["SimulatedSEM"]

_DTYPES = {np.dtype(np.uint8): 1.0, np.dtype(np.uint16): 257.0,
           np.dtype(np.float32): 1.0, np.dtype(np.float64): 1.0}


class SimulatedSEM:
    """A scanning electron microscope imaging tungsten probes over a substrate.

    Parameters
    ----------
    width, height : int
        Frame size in px (the paper: 640x480).
    pixel_size_nm : float
        nm per px (66 at 3,000x; see :func:`semlab.sim.pixel_size_from_magnification`).
    frame_period : float
        Seconds per frame (the paper: 1/13 s).
    noise : SEMNoise
        Noise and artefacts; ``SEMNoise.off()`` for noise-free frames.
    clutter : Clutter
        Static/drifting particles and the foreground occluder.
    probe : ProbeGeometry
        Shape and brightness of the probes (all probes share it).
    seed : int
        Seeds the scene (substrate, particles) and the noise.
    beam_sigma_px : float or None
        Gaussian beam blur; ``None`` = :func:`semlab.sim.optics.beam_blur_sigma_px`.
    probe_angles_deg : sequence of float or None
        Pointing direction of probe ``i`` (image frame, 0 = +x, 90 = down).
    dtype : numpy dtype
        Output of :meth:`acquire`: uint8 (default, 0-255 gray levels), uint16 (same
        scale x 257), float32/float64 (no rounding or clipping).
    background : (height, width) ndarray or None
        The static background in yield units (e.g. from
        :func:`semlab.sim.substrate.textured_substrate`) instead of
        :func:`semlab.sim.scene.make_substrate`'s; ``clutter.texture`` and
        ``clutter.n_static`` are then unused.

    Notes
    -----
    Time: frame ``k`` is scanned during ``[k T, (k + 1) T)``; everything that moves is
    evaluated at the frame's mid-time ``(k + 0.5) T`` (the probe is rendered rigidly;
    the rolling-shutter shear of a moving probe is not modelled).
    """

    def __init__(self, width=640, height=480, pixel_size_nm=66.0, frame_period=1 / 13,
                 noise: SEMNoise | None = None, clutter: Clutter | None = None,
                 probe: ProbeGeometry | None = None, seed=0, beam_sigma_px=None,
                 probe_angles_deg=None, dtype=np.uint8, background=None):
        for name, v in (("width", width), ("height", height)):
            if int(v) != v or v < 16:
                raise ValueError(f"{name} must be an integer >= 16, got {v!r}")
        if not (np.isfinite(pixel_size_nm) and pixel_size_nm > 0):
            raise ValueError(f"pixel_size_nm must be > 0, got {pixel_size_nm!r}")
        if not (np.isfinite(frame_period) and frame_period > 0):
            raise ValueError(f"frame_period must be > 0 s, got {frame_period!r}")
        self.width, self.height = int(width), int(height)
        self.pixel_size_nm = float(pixel_size_nm)
        self.frame_period = float(frame_period)
        self.noise = SEMNoise() if noise is None else noise
        self.clutter = Clutter() if clutter is None else clutter
        self.probe = ProbeGeometry() if probe is None else probe
        if not isinstance(self.noise, SEMNoise):
            raise TypeError(f"noise must be a SEMNoise, got {type(noise).__name__}")
        if not isinstance(self.clutter, Clutter):
            raise TypeError(f"clutter must be a Clutter, got {type(clutter).__name__}")
        if not isinstance(self.probe, ProbeGeometry):
            raise TypeError(f"probe must be a ProbeGeometry, got {type(probe).__name__}")
        if beam_sigma_px is None:
            beam_sigma_px = beam_blur_sigma_px(self.pixel_size_nm)
        if not (np.isfinite(beam_sigma_px) and beam_sigma_px >= 0):
            raise ValueError(f"beam_sigma_px must be >= 0, got {beam_sigma_px!r}")
        self.beam_sigma_px = float(beam_sigma_px)
        angles = DEFAULT_PROBE_ANGLES_DEG if probe_angles_deg is None else tuple(probe_angles_deg)
        self.probe_angles_deg = tuple(float(a) for a in angles)
        dt = np.dtype(dtype)
        if dt not in _DTYPES:
            raise ValueError(f"dtype must be one of uint8, uint16, float32, float64, got {dt}")
        self.dtype = dt
        self.seed = seed
        self.n_pixels = self.width * self.height
        self.dose = self.noise.dose(self.frame_period, self.n_pixels)
        #: gray levels spanned by yield 1 and gray levels per detected electron
        self.contrast = self.noise.effective_contrast(self.frame_period, self.n_pixels)
        if not self.contrast > 0:
            raise ValueError("the detector maps no signal to gray levels (contrast 0): "
                             "with detector_gain set, the dose must be > 0")
        self.gain_gray_per_electron = self.noise.gain_gray_per_electron(self.frame_period,
                                                                        self.n_pixels)

        scene_rng = np.random.default_rng([seed, 1])
        self._rng = np.random.default_rng([seed, 2])
        if background is None:
            self._background = make_substrate(self.width, self.height, self.clutter,
                                              self.beam_sigma_px, scene_rng)
        else:
            bg = np.asarray(background, dtype=np.float32)
            if bg.shape != (self.height, self.width) or not np.all(np.isfinite(bg)):
                raise ValueError(f"background must be a finite ({self.height}, {self.width}) "
                                 f"yield image, got shape {bg.shape}")
            self._background = bg.copy()
        self._drifters = self._make_drifters(scene_rng)
        if self.noise.drift_angle_deg is None:
            self._drift_angle = float(scene_rng.uniform(0, 2 * math.pi))
        else:
            self._drift_angle = math.radians(self.noise.drift_angle_deg)
        self._kernel = ar1_kernel(self.noise.line_correlation)
        self._xmap = np.arange(self.width, dtype=np.float32)[None, :].repeat(self.height, 0)
        self._ymap = np.arange(self.height, dtype=np.float32)[:, None].repeat(self.width, 1)
        self._noise_buf = np.empty((self.height, self.width), np.float32)
        self.frame_index = 0
        self._gain_state = 0.0
        self._offset_state = 0.0
        self.last_tips = None

    # ---------------------------------------------------------------- geometry
    @property
    def tip_radius_px(self) -> float:
        """Tip radius of the probes in px."""
        return 0.5 * self.probe.tip_diameter_nm / self.pixel_size_nm

    @property
    def rim_width_px(self) -> float:
        """Edge-brightening width in px."""
        return self.probe.rim_width_nm / self.pixel_size_nm

    @property
    def time(self) -> float:
        """Mid-scan time (s) of the next frame to be acquired."""
        return (self.frame_index + 0.5) * self.frame_period

    def drift_at(self, t: float) -> np.ndarray:
        """Image drift (px) at time ``t`` s: everything in the frame is displaced by it."""
        v = self.noise.drift_px_per_s
        return np.array([v * t * math.cos(self._drift_angle), v * t * math.sin(self._drift_angle)])

    def check_tips(self, tips) -> np.ndarray:
        """``tips`` as an ``(n, 2)`` float array of finite positions (px), or a ValueError."""
        arr = np.asarray(tips, dtype=float)
        if arr.ndim == 1 and arr.size == 2:
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"tips must be an (n, 2) array of (x, y) px, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("tips contain NaN/inf")
        if arr.shape[0] > len(self.probe_angles_deg):
            raise ValueError(f"{arr.shape[0]} probes but only {len(self.probe_angles_deg)} "
                             "probe_angles_deg are defined")
        return arr

    def _make_drifters(self, rng):
        n = int(self.clutter.n_drifting)
        pos = np.column_stack([rng.uniform(0, self.width, n), rng.uniform(0, self.height, n)])
        ang = rng.uniform(0, 2 * math.pi, n)
        speed = self.clutter.drift_speed_px_s * rng.uniform(0.5, 1.5, n)
        vel = np.column_stack([speed * np.cos(ang), speed * np.sin(ang)])
        radius = rng.uniform(2.0, 4.5, n)
        return pos, vel, radius

    def drifter_positions(self, t: float) -> np.ndarray:
        """Centres (px) of the drifting particles at time ``t`` (they wrap around the frame)."""
        pos, vel, _ = self._drifters
        p = pos + vel * t
        return np.column_stack([np.mod(p[:, 0], self.width), np.mod(p[:, 1], self.height)])

    def occluder_position(self, t: float) -> np.ndarray | None:
        """Centre (px) of the foreground occluder at time ``t`` or ``None`` if it is off."""
        if not self.clutter.occluder:
            return None
        path = self.clutter.occluder_path
        if path is None:
            x = 0.2 * self.width
            path = ((x, -self.clutter.occluder_radius_px), (x, self.height + self.clutter.occluder_radius_px))
        (x0, y0), (x1, y1) = path
        # triangle wave: there and back once per period
        ph = (t / self.clutter.occluder_period_s) % 1.0
        s = 2 * ph if ph < 0.5 else 2 - 2 * ph
        return np.array([x0 + s * (x1 - x0), y0 + s * (y1 - y0)])

    # ---------------------------------------------------------------- rendering
    def _render_yield(self, tips, t, drift=None, row_shift=None, charge=1.0, dtype=np.float32):
        """Yield image at time t with the probes at ``tips`` (already drifted)."""
        if drift is None and row_shift is None:
            img = self._background.astype(dtype)
        else:
            dx, dy = (0.0, 0.0) if drift is None else (float(drift[0]), float(drift[1]))
            mx = self._xmap - np.float32(dx)
            if row_shift is not None:
                mx += row_shift[:, None].astype(np.float32)
            my = self._ymap - np.float32(dy)
            img = cv2.remap(self._background, mx, my, cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REFLECT)
        off = np.zeros(2) if drift is None else np.asarray(drift, float)
        sigma = self.beam_sigma_px
        if self.clutter.n_drifting:
            for c, r in zip(self.drifter_positions(t), self._drifters[2]):
                render_disc(img, c + off, r, sigma, 0.42, rim_amp=0.15, rim_w_px=0.8,
                            row_shift=row_shift)
        g = self.probe
        r_tip = self.tip_radius_px
        half = math.radians(g.half_angle_deg)
        rim = g.rim_amplitude * (charge if self.noise.charging_scales_rim else 1.0)
        for i, tip in enumerate(tips):
            angle = math.radians(self.probe_angles_deg[i])
            if g.shape is not None:
                render_shape(img, g.shape, tip, angle, self.pixel_size_nm, sigma,
                             g.brightness * charge, rim, self.rim_width_px, row_shift=row_shift,
                             shading=g.shading)
                continue
            render_probe(img, tip, angle, r_tip, half, sigma, g.brightness * charge, rim,
                         self.rim_width_px, row_shift=row_shift, shading=g.shading)
        occ = self.occluder_position(t)
        if occ is not None:
            blur = math.hypot(sigma, self.clutter.occluder_blur_px)
            render_disc(img, occ + off, self.clutter.occluder_radius_px, blur, 0.32,
                        rim_amp=0.1, rim_w_px=2.0, row_shift=row_shift)
        return img

    def render_clean(self, tips, t=None, *, charge=1.0) -> np.ndarray:
        """Noise-free expected frame in gray levels, probes exactly at ``tips``.

        Parameters
        ----------
        tips : (n, 2) array_like
            Tip positions ``(x, y)`` in px of probes ``0..n-1`` (may lie off the frame).
        t : float or None
            Time for the moving clutter; ``None`` = mid-time of the next frame.
        charge : float
            Charging factor of the probes (``noise.charging_factor(t)`` for the frame
            :meth:`acquire` scans at ``t``); 1 = uncharged.

        Returns
        -------
        (H, W) ndarray of float64
            ``brightness + contrast * yield`` (:attr:`contrast`): no noise, drift, jitter,
            gain/offset fluctuation or quantisation.
        """
        tips = self.check_tips(tips)
        t = self.time if t is None else float(t)
        if not (np.isfinite(charge) and charge > 0):
            raise ValueError(f"charge must be a positive factor, got {charge!r}")
        y = self._render_yield(tips, t, charge=float(charge), dtype=np.float64)
        return self.noise.brightness + self.contrast * y

    def acquire(self, tips) -> np.ndarray:
        """Scan one noisy frame and advance the clock by one frame period.

        Parameters
        ----------
        tips : (n, 2) array_like
            Tip positions in px *before* image drift; the rendered (true) positions,
            ``tips + drift``, are stored in :attr:`last_tips`.

        Returns
        -------
        (H, W) ndarray of :attr:`dtype`
        """
        tips = self.check_tips(tips)
        nz = self.noise
        rng = self._rng
        t = self.time
        h = self.height
        drift = self.drift_at(t) if nz.drift_px_per_s > 0 else None
        row_shift = (rng.normal(0.0, nz.line_jitter_px, h).astype(np.float32)
                     if nz.line_jitter_px > 0 else None)
        charge = nz.charging_factor(t)
        true_tips = tips + drift if drift is not None else tips.copy()
        y = self._render_yield(true_tips, t, drift, row_shift, charge)

        # per-frame gray-level fluctuation, AR(1) across frames
        m = nz.fluctuation_memory
        innov = math.sqrt(1 - m * m)
        self._gain_state = m * self._gain_state + innov * rng.standard_normal()
        self._offset_state = m * self._offset_state + innov * rng.standard_normal()
        gain = 1.0 + nz.gain_fluctuation * self._gain_state
        offset = nz.offset_fluctuation_gray * self._offset_state
        # independent per-frame jumps (drawn only when on: sequences without them are unchanged)
        if nz.gain_jitter > 0:
            gain *= 1.0 + rng.uniform(-nz.gain_jitter, nz.gain_jitter)
        if nz.offset_jitter_gray > 0:
            offset += rng.uniform(-nz.offset_jitter_gray, nz.offset_jitter_gray)

        g_e = self.gain_gray_per_electron
        need_noise = nz.shot_noise or nz.read_noise_gray > 0
        if need_noise:
            cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
            z = self._noise_buf
            cv2.randn(z, 0.0, 1.0)
            if nz.shot_noise:
                lam = y * np.float32(self.dose)
                np.maximum(lam, 0, out=lam)
                var = lam * np.float32(g_e * g_e)
                if nz.read_noise_gray > 0:
                    var += np.float32(nz.read_noise_gray ** 2)
                noise = np.sqrt(var) * z
                low = lam < nz.poisson_exact_below
                if low.any():
                    lam_low = lam[low]
                    exact = (rng.poisson(lam_low) - lam_low) * g_e
                    if nz.read_noise_gray > 0:
                        exact = exact + nz.read_noise_gray * rng.standard_normal(lam_low.size)
                    noise[low] = exact
            else:
                noise = z * np.float32(nz.read_noise_gray)
            if self._kernel.size > 1:
                k = self._kernel[::-1].reshape(1, -1)
                # causal filter along x: anchor at the kernel's last tap
                noise = cv2.filter2D(noise, -1, k, anchor=(k.shape[1] - 1, 0),
                                     borderType=cv2.BORDER_REFLECT)
        else:
            noise = None
        img = y
        img *= np.float32(self.contrast * gain)
        img += np.float32(nz.brightness + offset)
        if noise is not None:
            img += noise * np.float32(gain)
        if nz.line_offset_gray > 0:
            img += rng.normal(0.0, nz.line_offset_gray, (h, 1)).astype(np.float32)

        self.frame_index += 1
        self.last_tips = true_tips
        self.last_time = t
        return self._to_output(img)

    def _to_output(self, img: np.ndarray) -> np.ndarray:
        dt = self.dtype
        if dt == np.uint8:
            return np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if dt == np.uint16:
            return np.clip(np.rint(img * np.float32(257.0)), 0, 65535).astype(np.uint16)
        return img.astype(dt)

    @property
    def output_scale(self) -> float:
        """Gray levels of the output per 8-bit gray level (257 for uint16, else 1)."""
        return _DTYPES[self.dtype]

    @property
    def quantisation_variance(self) -> float:
        """Variance (8-bit gray levels squared) added by rounding to the output dtype."""
        if self.dtype == np.uint8:
            return 1.0 / 12.0
        if self.dtype == np.uint16:
            return 1.0 / 12.0 / 257.0**2
        return 0.0
