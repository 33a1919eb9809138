"""semlab's simulated needle inside OpenFIBSEM's offline ``DemoMicroscope``, with ground truth.

The Demo microscope's images are noise with the letters "SEM"/"FIB", and its manipulator moves
exactly as commanded. :class:`SimulatedNeedle` hooks into one Demo instance so that

* every ``acquire_image`` still runs fibsem's own acquisition (settings, metadata, timing), but its
  pixels are replaced by :class:`semlab.sim.SimulatedSEM` rendering a probe tip where the Demo's
  manipulator is, through a mapping (scan rotation, skew, scales) that only this object knows;
* every ``move_manipulator_relative`` is made imperfect, as a real stepper's: short by a few %,
  cross-coupled between the axes, jittered, and optionally lagging (part of a move shows one frame
  late);
* frames can be blanked (the beam off) or lose the needle (out of view), to test that a servo holds.

Tests and the notebook read :attr:`SimulatedNeedle.truth`; the tracker, the calibration and the servo
see only fibsem's API through :mod:`semlab.instruments.fibsem`.
"""

from __future__ import annotations

import importlib
import math

import numpy as np
import pandas as pd

from semlab.sim import SEMNoise, SimulatedSEM

__all__ = ["SimulatedNeedle", "view_jacobian"]

_NM_PER_M = 1e9
#: The paper's frame period: the simulated detector's noise is that of the paper's rig whatever
#: dwell time the Demo is asked for.
NOISE_FRAME_PERIOD = 1 / 13


def view_jacobian(pixel_size_nm: float, *, rotation_deg: float = 0.0, skew_deg: float = 0.0,
                  scale=(1.0, 1.0), flip_y: bool = False) -> np.ndarray:
    """The image Jacobian (px per nm) of a manipulator's x/y seen through a rotated, skewed view.

    Axis x appears along ``rotation_deg`` (0 = image +x, 90 = down) with length ``scale[0] /
    pixel_size_nm`` px per nm; axis y along ``rotation_deg + 90 + skew_deg`` (``- 90`` with
    ``flip_y``), ``scale[1]`` (e.g. ``cos(tilt)`` foreshortening).
    """
    th = math.radians(rotation_deg)
    ty = th + math.radians((-90.0 if flip_y else 90.0) + skew_deg)
    sx, sy = (float(v) / float(pixel_size_nm) for v in scale)
    return np.array([[sx * math.cos(th), sy * math.cos(ty)], [sx * math.sin(th), sy * math.sin(ty)]])


class SimulatedNeedle:
    """Render semlab's needle in a fibsem ``DemoMicroscope`` and make its manipulator imperfect.

    Parameters
    ----------
    demo : fibsem.microscopes.simulator.DemoMicroscope
        Connected; its ``acquire_image`` and ``move_manipulator_relative`` are wrapped (on this
        instance only) until :meth:`remove`.
    tip_xy : (float, float)
        Where the tip appears (px) at the manipulator's position when installed.
    rotation_deg, skew_deg, scale, flip_y
        The true view of the manipulator's x/y axes (:func:`view_jacobian`).
    shortfall : float
        Moves fall short by this fraction (both axes).
    coupling : float
        Each axis' move leaks this fraction into the other axis.
    jitter_nm, jitter_fraction : float
        Per-move random error: standard deviation ``jitter_nm + jitter_fraction * |move|`` per axis.
    lag : float
        Fraction of each move that shows only from the second frame after it.
    seed : int
        Seeds the scene, the noise and the moves.
    noise : SEMNoise, optional
        The detector (default: the paper's conditions).
    probe_angle_deg : float
        Pointing direction of the needle in the image.
    """

    def __init__(self, demo, *, tip_xy=(300.0, 250.0), rotation_deg=25.0, skew_deg=4.0, scale=(1.0, 0.87),
                 flip_y=False, shortfall=0.04, coupling=0.03, jitter_nm=2.0, jitter_fraction=0.01, lag=0.0,
                 seed=0, noise=None, probe_angle_deg=10.0):
        for name, v in (("shortfall", shortfall), ("coupling", coupling), ("lag", lag),
                        ("jitter_fraction", jitter_fraction)):
            if not 0 <= v < 1:
                raise ValueError(f"{name} must lie in [0, 1), got {v!r}")
        if isinstance(getattr(demo.acquire_image, "__self__", None), SimulatedNeedle):
            raise ValueError("this Demo microscope already has a SimulatedNeedle: remove() it first")  # noqa: TRY004
        self.demo = demo
        self.tip0 = np.asarray(tip_xy, float)
        self.view = {"rotation_deg": rotation_deg, "skew_deg": skew_deg, "scale": tuple(scale), "flip_y": flip_y}
        self.move_error = np.array([[1 - shortfall, coupling], [coupling, 1 - shortfall]])
        self.jitter = (float(jitter_nm), float(jitter_fraction))
        self.lag = float(lag)
        self.seed = seed
        self.noise = SEMNoise() if noise is None else noise
        self.probe_angle_deg = float(probe_angle_deg)
        self._rng = np.random.default_rng([seed, 17])
        self._sems = {}
        self._pending = np.zeros(3)
        self._blank = self._hidden = 0
        self._blank_at, self._hide_at = set(), set()
        self._log = []
        self._acquire = demo.acquire_image
        self._move = demo.move_manipulator_relative
        self.origin_nm = self._position_nm()
        demo.acquire_image = self._acquire_image
        demo.move_manipulator_relative = self._move_relative

    # ------------------------------------------------------------------ the truth
    def _position_nm(self) -> np.ndarray:
        p = self.demo.get_manipulator_position()
        return np.array([p.x, p.y, p.z]) * _NM_PER_M

    def jacobian(self, pixel_size_nm: float) -> np.ndarray:
        """The true image Jacobian (px per nm of RAW x, y) at ``pixel_size_nm``."""
        return view_jacobian(pixel_size_nm, **self.view)

    def effective_jacobian(self, pixel_size_nm: float) -> np.ndarray:
        """What one commanded nm does in the image on average: the view times the move error (what
        :func:`semlab.calibrate_positioner` should measure)."""
        return self.jacobian(pixel_size_nm) @ self.move_error

    def tip_px(self, pixel_size_nm: float) -> np.ndarray:
        """Where the tip is (px, before image drift) for the Demo's current manipulator position."""
        d = self._position_nm() - self.origin_nm
        return self.tip0 + self.jacobian(pixel_size_nm) @ d[:2]

    @property
    def truth(self) -> pd.DataFrame:
        """One row per acquired frame: ``frame, x, y`` (true tip, px, with drift), ``visible``, ``blank``,
        ``x_nm, y_nm`` (the manipulator's true RAW position)."""
        return pd.DataFrame(self._log, columns=["frame", "x", "y", "visible", "blank", "x_nm", "y_nm"])

    # ------------------------------------------------------------------ faults
    def blank_frames(self, n: int = 1) -> None:
        """The next ``n`` frames come back blank (beam blanked: the black level and noise only)."""
        self._blank += int(n)

    def hide_needle(self, n: int = 1) -> None:
        """The next ``n`` frames show the substrate without the needle (it left the view)."""
        self._hidden += int(n)

    def schedule(self, *, blank=(), hide=()) -> None:
        """Fault the acquisitions ``k`` from now (0 = the next one): beam blanked in ``blank``, needle
        out of view in ``hide``."""
        now = len(self._log)
        self._blank_at.update(now + int(k) for k in blank)
        self._hide_at.update(now + int(k) for k in hide)

    def remove(self) -> None:
        """Restore the Demo's own acquisition and moves."""
        for name in ("acquire_image", "move_manipulator_relative"):
            self.demo.__dict__.pop(name, None)  # the class's methods show through again

    # ------------------------------------------------------------------ the hooks
    def _sem(self, width: int, height: int, pixel_size_nm: float) -> SimulatedSEM:
        key = (width, height, round(pixel_size_nm, 6))
        if key not in self._sems:
            self._sems[key] = SimulatedSEM(width, height, pixel_size_nm, NOISE_FRAME_PERIOD, noise=self.noise,
                                           seed=self.seed, probe_angles_deg=(self.probe_angle_deg,))
        return self._sems[key]

    def _acquire_image(self, image_settings=None, beam_type=None):
        image = self._acquire(image_settings=image_settings, beam_type=beam_type)
        rows, cols = image.data.shape[:2]
        ps = float(image.metadata.pixel_size.x) * _NM_PER_M
        sem = self._sem(cols, rows, ps)
        tip = self.tip_px(ps)
        index = len(self._log)
        blank = self._blank > 0 or index in self._blank_at
        hidden = self._hidden > 0 or index in self._hide_at
        self._blank, self._hidden = max(0, self._blank - 1), max(0, self._hidden - 1)
        far = np.array([-10.0 * cols, -10.0 * rows])  # the needle well outside the frame
        frame = sem.acquire(far if hidden else tip)
        true = sem.last_tips[0]
        if blank:
            black = self.noise.brightness + self.noise.read_noise_gray * self._rng.standard_normal(frame.shape)
            frame = np.clip(np.rint(black), 0, 255).astype(frame.dtype)
        image.data = frame.astype(image.data.dtype, copy=False)
        pos = self._position_nm()
        self._log.append({"frame": len(self._log), "x": true[0] if not hidden else np.nan,
                          "y": true[1] if not hidden else np.nan, "visible": not (hidden or blank),
                          "blank": blank, "x_nm": pos[0], "y_nm": pos[1]})
        if np.any(self._pending):  # the lagging part of the last move arrives after this frame
            self._apply(self._pending)
            self._pending = np.zeros(3)
        return image

    def _apply(self, d_nm):
        structures = importlib.import_module("fibsem.structures")
        x, y, z = (float(v) / _NM_PER_M for v in d_nm)
        return self._move(structures.FibsemManipulatorPosition(x=x, y=y, z=z, coordinate_system="RAW"))

    def _move_relative(self, position):
        cmd = np.array([position.x, position.y, position.z]) * _NM_PER_M
        real = cmd.copy()
        real[:2] = self.move_error @ cmd[:2]
        sd = self.jitter[0] + self.jitter[1] * np.abs(cmd[:2])
        real[:2] += sd * self._rng.standard_normal(2) * (np.abs(cmd[:2]) > 0)
        now = (1.0 - self.lag) * real
        self._pending = self._pending + (real - now)
        return self._apply(now)
