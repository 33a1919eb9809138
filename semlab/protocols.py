"""Interfaces that a real instrument can implement as well as the simulated rig.

The tracker and the visual servo talk to hardware only through these two
protocols, so the same code drives :class:`semlab.sim.SimulatedRig` today and a
real SEM frame grabber and manipulator DAC tomorrow.

Conventions
-----------
Frames are 2-D arrays indexed ``frame[y, x]``; pixel centres sit at integer
coordinates, x grows to the right and y downwards.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Axis", "Microscope", "as_finite", "check_command"]


@runtime_checkable
class Microscope(Protocol):
    """A source of SEM frames at a fixed frame period.

    Attributes
    ----------
    frame_period : float
        Seconds between two frames (the paper's rig: 1/13 s at 640x480).
    """

    frame_period: float

    def grab(self) -> np.ndarray:
        """Return the next frame as a 2-D array (in simulation: advance the clock one frame)."""
        ...


@runtime_checkable
class Axis(Protocol):
    """One actuator channel, e.g. the x piezo of a manipulator driven by a DAC.

    Attributes
    ----------
    limits : tuple of float
        ``(U0, Un)``, the lowest and highest command in volts.
    """

    limits: tuple[float, float]

    def apply(self, volts: float) -> None:
        """Command ``volts``; it takes effect from the next frame.

        Raises
        ------
        ValueError
            If ``volts`` is NaN/inf or outside ``limits``: an axis never drives past its limits.
        """
        ...


def as_finite(value, what: str, why: str = "") -> float:
    """``value`` as a finite float, or a ValueError naming ``what`` (and ``why`` it matters)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} {value!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{what} {v} is not finite" + (f"; {why}" if why else ""))
    return v


def check_command(volts: float, limits: tuple[float, float], name: str = "axis") -> float:
    """Validate an actuator command against the axis limits.

    Parameters
    ----------
    volts : float
        The requested command.
    limits : (float, float)
        ``(U0, Un)`` of the axis.
    name : str
        Used in the error message.

    Returns
    -------
    float
        ``volts`` as a Python float.

    Raises
    ------
    ValueError
        If the command is not finite or lies outside the limits.
    """
    value = as_finite(volts, f"{name}: command", "refusing to drive blind")
    lo, hi = limits
    if not lo <= value <= hi:
        raise ValueError(f"{name}: command {value:.6g} V is outside the axis limits [{lo:.6g}, {hi:.6g}] V")
    return value


@runtime_checkable
class VisualTracker(Protocol):
    """Measures where the target is in each frame: what the experiments and the visual servo read.

    :class:`semlab.tracking.Tracker`, the :mod:`semlab.peers` trackers and anything with these two
    methods. ``update`` returns an object with ``x``, ``y``, ``ok`` (and ``score``) attributes,
    such as :class:`semlab.tracking.TrackResult`, or a tuple ``(x, y, score, ok)``
    (:func:`semlab.measure.read_result` reads either).
    """

    def init(self, frame: np.ndarray, roi) -> object:
        """Take the target from ``frame`` inside ``roi = (x, y, w, h)``."""
        ...

    def update(self, frame: np.ndarray) -> object:
        """Locate the target in the next frame (never raising for a lost one: ``ok`` is False)."""
        ...


__all__ += ["VisualTracker"]
