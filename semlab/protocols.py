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


# ---------------------------------------------------------------------------------------------
# What real instruments have beyond the simulated rig (issue 17). Each is a separate protocol, so
# the two above stay the contract every existing rig and user class already meets; code asks for
# the extra with ``isinstance`` instead of probing attributes.

__all__ += ["CommandedAxis", "Positioner", "ScaledMicroscope", "TimedMicroscope", "frame_time"]


@runtime_checkable
class TimedMicroscope(Microscope, Protocol):
    """A :class:`Microscope` that stamps each frame with the instrument's clock.

    A real microscope's frames do not arrive at exactly ``frame_period``: acquisition overhead,
    the network and auto-functions add to the scan time. The servo's time axis comes from here
    when the microscope has it, else from ``frame_index * frame_period`` (:func:`frame_time`).

    Attributes
    ----------
    last_frame_time : float or None
        Seconds (any fixed origin, e.g. the Unix epoch) at which the frame last returned by
        :meth:`grab` was acquired; None before the first frame.
    """

    last_frame_time: float | None


@runtime_checkable
class ScaledMicroscope(Microscope, Protocol):
    """A :class:`Microscope` that knows its pixel size (from the image metadata or a calibration).

    Attributes
    ----------
    pixel_size_nm : float or None
        nm per px of the frames; None when unknown.
    """

    pixel_size_nm: float | None


@runtime_checkable
class CommandedAxis(Axis, Protocol):
    """An :class:`Axis` that reports the command it holds (after DAC quantisation), so a controller
    can start from it instead of assuming one.

    Attributes
    ----------
    command : float
        The last command in volts, as the axis will output it.
    """

    command: float


@runtime_checkable
class Positioner(Protocol):
    """A closed-loop stage or manipulator moved by relative steps in its own two axes.

    Unlike an :class:`Axis` (one piezo channel, absolute volts), a positioner takes relative moves in
    nanometres along its own axes (e.g. a FIB/SEM manipulator's RAW x and y), which the image sees
    rotated, skewed and scaled: :func:`semlab.calibrate_positioner` measures that mapping.

    Attributes
    ----------
    limits : ((float, float), (float, float)) or None
        ``((x_lo, x_hi), (y_lo, y_hi))`` in nm, in the frame of :attr:`position_nm`; None when the
        travel is not known (then only the instrument itself refuses moves past its travel).
    resolution_nm : float
        The smallest move the positioner makes (0 when it is not known): a servo sends no
        smaller command.
    position_nm : (float, float) or None
        The encoder reading in nm, or None when the positioner has no (usable) encoder.
    """

    limits: tuple[tuple[float, float], tuple[float, float]] | None
    resolution_nm: float
    position_nm: tuple[float, float] | None

    def move_by(self, dx_nm: float, dy_nm: float) -> None:
        """Move by ``(dx_nm, dy_nm)`` along the positioner's own axes; the move has ended (or, for a
        non-blocking instrument, is in progress) when this returns, and shows from the next frame.

        Raises
        ------
        ValueError
            A command that is NaN/inf, or a move that would leave :attr:`limits`.
        RuntimeError
            The instrument reports that the move failed.
        """
        ...


def frame_time(microscope, frame_index: int, t0: float | None = None) -> float:
    """Seconds since ``t0`` of the frame just grabbed: the microscope's own time stamp when it is a
    :class:`TimedMicroscope` with one, else ``frame_index * frame_period``.

    Parameters
    ----------
    microscope : Microscope
    frame_index : int
        Frames grabbed since the start of the run, this one counted from 0.
    t0 : float or None
        Time stamp of the run's first frame (ignored without time stamps).
    """
    stamp = microscope.last_frame_time if isinstance(microscope, TimedMicroscope) else None
    if stamp is not None and math.isfinite(stamp):
        return float(stamp - (stamp if t0 is None else t0))
    return float(frame_index * float(microscope.frame_period))


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
