"""The simulated rig: an SEM looking at four manipulators' probes (the paper's Fig. 5).

The probe of manipulator ``m`` appears in the image at::

    tip_m = base_m + (e_x dx_nm + e_y dy_nm) / pixel_size + z_view * dz_nm / pixel_size + drift

where ``d*_nm`` are the displacements from home (macro offset + piezo), ``e_x`` the image
direction of the manipulator's x axis (at ``theta_m``) and ``e_y`` that of its y axis (at
``theta_m + 90 deg + skew_m``: the axes need not look orthogonal in the view; no skew by
default, a rotation ``R(theta_m)`` then), and ``z_view`` a small
projection of the z axis (the column looks at the tilted stage: moving in z shifts
the tip by ``-sin 5 deg`` of the displacement along the image's y; set
``z_view=(0, 0)`` for none). ``drift`` is the SEM image drift (:class:`SEMNoise`).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .manipulator import AXES, Manipulator, check_axis_name
from .piezo import (
    ExponentialCreep,
    PiezoParameters,
    PrandtlIshlinskiiHysteresis,
    PreisachHysteresis,
)
from .scene import DEFAULT_PROBE_ANGLES_DEG
from .sem import SimulatedSEM

__all__ = [
    "DEFAULT_BASE_POSITIONS",
    "DEFAULT_VIEW_ANGLES_DEG",
    "SimulatedMicroscope",
    "SimulatedRig",
    "alternative_creep",
    "alternative_hysteresis",
    "default_hysteresis",
]

#: Tip positions (px, 640x480 frame) with all piezos at 0 V and the steppers at home.
#: Probe 0 sits centre-left with > 400 px of room along +x.
DEFAULT_BASE_POSITIONS = ((150.0, 250.0), (540.0, 140.0), (400.0, 80.0), (470.0, 400.0))
#: Image direction (deg) of each manipulator's +x axis; its +y axis is 90 deg further.
DEFAULT_VIEW_ANGLES_DEG = (2.0, 182.0, 92.0, -88.0)
#: Image displacement per unit z displacement: the column sees the stage tilted by 5 deg.
DEFAULT_Z_VIEW = (0.0, -math.sin(math.radians(5.0)))
_TRUTH_COLUMNS = ["frame", "t", "probe", "x", "y", "visible"]
#: The piezo families a rig can be built with: the default Preisach/log-creep Zyvex rig, and an
#: independently built alternative (Prandtl-Ishlinskii hysteresis with a static output nonlinearity,
#: Kelvin-Voigt creep, a 0-150 V amplifier and 16-bit DACs on every axis).
PIEZO_MODELS = ("preisach", "prandtl-ishlinskii")
#: The alternative rig's amplifier range (V) and DAC resolution (every axis).
ALTERNATIVE_VOLTS = (0.0, 150.0)
ALTERNATIVE_DAC_BITS = 16
#: Its creep at the default creep setting: 0.8 %, 1.2 % and 1.5 % of each step relaxing with 0.3 s, 3 s
#: and 30 s (3.5 % in all, about what the log law's 1.5 %/decade gives between 0.1 s and 20 s).
ALTERNATIVE_CREEP = ((0.008, 0.012, 0.015), (0.3, 3.0, 30.0))
#: PiezoParameters' default creep per decade, against which the alternative creep is scaled.
_DEFAULT_CREEP_PER_DECADE = PiezoParameters().creep_per_decade


def default_hysteresis(manipulator: int, axis: str, seed: int = 0) -> PreisachHysteresis:
    """The Preisach model of one axis: the default one with small per-axis variations."""
    rng = np.random.default_rng([seed, 7, manipulator, AXES.index(axis)])
    return PreisachHysteresis(lambdas=(3.0 * rng.uniform(0.9, 1.1), 14.0 * rng.uniform(0.9, 1.1)),
                              weights=(0.45, 0.55), kappa=0.7 * rng.uniform(0.85, 1.15),
                              reversible=0.22 * rng.uniform(0.9, 1.1), nu=0.4)


def alternative_hysteresis(manipulator: int, axis: str, seed: int = 0) -> PrandtlIshlinskiiHysteresis:
    """The alternative rig's hysteresis of one axis, with small per-axis variations."""
    rng = np.random.default_rng([seed, 11, manipulator, AXES.index(axis)])
    return PrandtlIshlinskiiHysteresis(max_threshold=0.17 * rng.uniform(0.9, 1.1), decay=4.0 * rng.uniform(0.8, 1.2),
                                       reversible=0.25 * rng.uniform(0.9, 1.1), quadratic=0.45 * rng.uniform(0.7, 1.3),
                                       cubic=0.2 * rng.uniform(0.7, 1.3))


def alternative_creep(params: PiezoParameters) -> ExponentialCreep:
    """The alternative rig's creep, scaled by ``params.creep_per_decade`` (0 switches it off)."""
    scale = params.creep_per_decade / _DEFAULT_CREEP_PER_DECADE
    fractions, taus = ALTERNATIVE_CREEP
    return ExponentialCreep(tuple(scale * c for c in fractions), taus)


class SimulatedMicroscope:
    """The rig's SEM seen through :class:`semlab.protocols.Microscope`."""

    def __init__(self, rig: SimulatedRig):
        self._rig = rig
        self.frame_period = rig.sem.frame_period

    def grab(self) -> np.ndarray:
        """Scan the next frame (advances the clock by one frame period)."""
        return self._rig._grab()


class SimulatedRig:
    """Four manipulators in a simulated SEM with exact ground truth.

    Parameters
    ----------
    n_manipulators : int
        1 to 4; manipulator ``m`` carries probe ``m``.
    pixel_size_nm : float
        nm/px of the SEM view.
    seed : int
        Seeds the scene, the noise and the per-axis hysteresis variations.
    noise : SEMNoise or None
    clutter : Clutter or None
    probe : ProbeGeometry or None
    width, height : int
    frame_period : float
    base_positions : sequence of (x, y) or None
        Tip positions in px at 0 V / home; default :data:`DEFAULT_BASE_POSITIONS`.
    view_angles_deg : sequence of float or None
        Image direction of each manipulator's x axis.
    view_skew_deg : float or sequence of float
        How far each manipulator's y axis is from perpendicular to its x axis in the image (deg;
        default 0: a rotated but orthogonal view).
    probe_angles_deg : sequence of float or None
        Pointing direction of each probe.
    piezo : PiezoParameters or None
        Lag/creep of all piezo axes.
    piezo_model : {"preisach", "prandtl-ishlinskii"}
        :data:`PIEZO_MODELS`: the Zyvex rig's Preisach hysteresis with log creep on 0-100 V (default),
        or the independently built alternative: :func:`alternative_hysteresis` (PI plays and a static
        output nonlinearity), :func:`alternative_creep` (Kelvin-Voigt relaxations), a 0-150 V amplifier
        and 16-bit DACs on every axis.
    z_view : (float, float)
        Image displacement per unit z displacement.
    dtype : numpy dtype
        Frame dtype (uint8 by default).
    """

    def __init__(self, n_manipulators=4, pixel_size_nm=66.0, seed=0, noise=None, clutter=None,
                 probe=None, width=640, height=480, frame_period=1 / 13, base_positions=None,
                 view_angles_deg=None, probe_angles_deg=None, piezo=None,
                 z_view=DEFAULT_Z_VIEW, dtype=np.uint8, beam_sigma_px=None, piezo_model="preisach",
                 view_skew_deg=0.0):
        if int(n_manipulators) != n_manipulators or not 1 <= n_manipulators <= 4:
            raise ValueError(f"n_manipulators must be 1..4, got {n_manipulators!r}")
        n = int(n_manipulators)
        self.n_manipulators = n
        base = DEFAULT_BASE_POSITIONS if base_positions is None else base_positions
        views = DEFAULT_VIEW_ANGLES_DEG if view_angles_deg is None else view_angles_deg
        pang = DEFAULT_PROBE_ANGLES_DEG if probe_angles_deg is None else probe_angles_deg
        if len(base) < n or len(views) < n or len(pang) < n:
            raise ValueError("base_positions, view_angles_deg and probe_angles_deg need one "
                             f"entry per manipulator ({n})")
        self.base_positions = np.asarray(base[:n], float)
        if self.base_positions.shape != (n, 2) or not np.all(np.isfinite(self.base_positions)):
            raise ValueError("base_positions must be finite (x, y) pairs")
        self.view_angles_deg = tuple(float(a) for a in views[:n])
        skew = np.broadcast_to(np.asarray(view_skew_deg, float), (n,)) if np.ndim(view_skew_deg) == 0 \
            else np.asarray(view_skew_deg, float)[:n]
        if skew.shape != (n,) or not np.all(np.abs(skew) < 80.0):
            raise ValueError(f"view_skew_deg must be one angle or one per manipulator, |skew| < 80 deg; got {view_skew_deg!r}")
        self.view_skew_deg = tuple(float(a) for a in skew)
        self.z_view = np.asarray(z_view, float)
        self.sem = SimulatedSEM(width, height, pixel_size_nm, frame_period, noise=noise,
                                clutter=clutter, probe=probe, seed=seed,
                                probe_angles_deg=tuple(pang[:n]), dtype=dtype,
                                beam_sigma_px=beam_sigma_px)
        self.pixel_size_nm = self.sem.pixel_size_nm
        params = PiezoParameters() if piezo is None else piezo
        if not isinstance(params, PiezoParameters):
            raise TypeError(f"piezo must be a PiezoParameters, got {type(piezo).__name__}")
        self.piezo = params
        self._rng = np.random.default_rng([seed, 3])
        if piezo_model not in PIEZO_MODELS:
            raise ValueError(f"piezo_model must be one of {PIEZO_MODELS}, got {piezo_model!r}")
        self.piezo_model = piezo_model
        if piezo_model == "preisach":
            self._manipulators = [Manipulator(m, params, lambda i, a: default_hysteresis(i, a, seed))
                                  for m in range(n)]
        else:
            self._manipulators = [
                Manipulator(m, params, lambda i, a: alternative_hysteresis(i, a, seed),
                            creep_factory=lambda i, a: alternative_creep(params),
                            nano_options={"volts": ALTERNATIVE_VOLTS, "bits": ALTERNATIVE_DAC_BITS})
                for m in range(n)]
        self.microscope = SimulatedMicroscope(self)
        self._truth = pd.DataFrame(columns=_TRUTH_COLUMNS)
        self._log = []
        self._log_cache = (0, None)  # (frames covered, their concatenated truth)

    # ------------------------------------------------------------ hardware access
    def _check_m(self, m) -> int:
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or not 0 <= m < self.n_manipulators:
            raise ValueError(f"unknown manipulator {m!r}; this rig has 0..{self.n_manipulators - 1}")
        return int(m)

    def axis(self, m: int, axis: str):
        """Nano piezo axis ``axis`` ('x', 'y', 'z') of manipulator ``m`` (an :class:`Axis`)."""
        return self._manipulators[self._check_m(m)].nano[check_axis_name(axis)]

    def macro(self, m: int, axis: str):
        """Macro stepper of axis ``axis`` of manipulator ``m``."""
        return self._manipulators[self._check_m(m)].macro[check_axis_name(axis)]

    @property
    def frame_index(self) -> int:
        """Number of frames grabbed so far."""
        return self.sem.frame_index

    # ------------------------------------------------------------ ground truth
    def _tips_nominal(self, t: float) -> np.ndarray:
        """Tip positions (px) without image drift at time ``t`` (advances the piezos)."""
        tips = np.empty((self.n_manipulators, 2))
        sd = self.piezo.position_noise_nm
        for m, man in enumerate(self._manipulators):
            d = man.displacement_nm(t)
            if sd > 0:
                for a in AXES:
                    d[a] += sd * self._rng.standard_normal()
            th = math.radians(self.view_angles_deg[m])
            ty = th + math.radians(90.0 + self.view_skew_deg[m])
            px = self.pixel_size_nm
            tips[m, 0] = (self.base_positions[m, 0] + (math.cos(th) * d["x"] + math.cos(ty) * d["y"]) / px
                          + self.z_view[0] * d["z"] / px)
            tips[m, 1] = (self.base_positions[m, 1] + (math.sin(th) * d["x"] + math.sin(ty) * d["y"]) / px
                          + self.z_view[1] * d["z"] / px)
        return tips

    def _grab(self) -> np.ndarray:
        sem = self.sem
        k = sem.frame_index
        t_start = k * sem.frame_period
        for man in self._manipulators:
            man.latch(t_start)
        t_mid = sem.time
        tips = self._tips_nominal(t_mid)
        frame = sem.acquire(tips)
        true = sem.last_tips
        w, h = sem.width, sem.height
        vis = (true[:, 0] >= 0) & (true[:, 0] <= w - 1) & (true[:, 1] >= 0) & (true[:, 1] <= h - 1)
        self._truth = pd.DataFrame({"frame": np.full(self.n_manipulators, k), "t": t_mid,
                                    "probe": np.arange(self.n_manipulators),
                                    "x": true[:, 0], "y": true[:, 1], "visible": vis})
        self._log.append(self._truth)
        return frame

    @property
    def truth(self) -> pd.DataFrame:
        """Ground truth of the last grabbed frame.

        Columns ``frame, t, probe, x, y, visible``: one row per probe (``visible`` is
        False when the tip lies outside the frame); ``x, y`` in px including image drift;
        ``t`` the frame's mid-scan time in s.
        """
        return self._truth.copy()

    @property
    def truth_log(self) -> pd.DataFrame:
        """Ground truth of every frame grabbed so far (same columns as :attr:`truth`)."""
        if not self._log:
            return pd.DataFrame(columns=_TRUTH_COLUMNS)
        # concatenated incrementally: all of it at every call took ~1 s per call at 10^4 frames
        done, cache = self._log_cache
        if done < len(self._log):
            cache = pd.concat([cache, *self._log[done:]] if cache is not None else self._log, ignore_index=True)
            self._log_cache = (len(self._log), cache)
        return cache.copy()
