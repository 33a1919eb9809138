"""The Zyvex S100 nanomanipulator as the paper describes it ("Nanomanipulation System Setup").

Each of the four manipulators has x/y/z axes with two stages:

* MACRO stepper: 100 nm resolution, 12 mm travel in x and z, 10 mm in y.
* NANO piezo: 5 nm nominal resolution, 50 um travel in x and z, 10 um in y, driven
  through the APC8620 carrier's DACs, 16-bit for x and z, 12-bit for y.

The piezo command range is 0-100 V (a unipolar piezo amplifier); full travel is reached
at 100 V from the relaxed state. Commands take effect from the next frame.
"""

from __future__ import annotations

from ..protocols import as_finite, check_command
from .piezo import DAC, PiezoAxis, PiezoParameters, PreisachHysteresis

__all__ = [
    "AXES",
    "DAC_BITS",
    "MACRO_RESOLUTION_NM",
    "MACRO_TRAVEL_NM",
    "NANO_TRAVEL_NM",
    "PIEZO_VOLTS",
    "MacroStepper",
    "Manipulator",
    "NanoAxis",
]

AXES = ("x", "y", "z")
NANO_TRAVEL_NM = {"x": 50_000.0, "y": 10_000.0, "z": 50_000.0}
MACRO_TRAVEL_NM = {"x": 12_000_000.0, "y": 10_000_000.0, "z": 12_000_000.0}
DAC_BITS = {"x": 16, "y": 12, "z": 16}
PIEZO_VOLTS = (0.0, 100.0)
MACRO_RESOLUTION_NM = 100.0


def check_axis_name(axis) -> str:
    """Return the axis name or raise a ValueError naming the valid ones."""
    if axis not in AXES:
        raise ValueError(f"unknown axis {axis!r}; the manipulator has axes {AXES}")
    return axis


class MacroStepper:
    """Coarse stepper of one axis: position in nm, quantised to 100 nm.

    Attributes
    ----------
    limits : (float, float)
        Travel in nm, ``(0, 12e6)`` for x/z and ``(0, 10e6)`` for y.
    """

    def __init__(self, name: str, axis: str):
        self.name = name
        self.limits = (0.0, MACRO_TRAVEL_NM[axis])
        self.resolution_nm = MACRO_RESOLUTION_NM
        self._home = 0.5 * self.limits[1]
        self._position = self._home
        self._pending = None

    @property
    def home_nm(self) -> float:
        """Position at which the probe sits at its base image position."""
        return self._home

    @property
    def position_nm(self) -> float:
        """Commanded (and, once the next frame is grabbed, actual) position in nm."""
        return self._pending if self._pending is not None else self._position

    def move_to(self, nm: float) -> float:
        """Move to ``nm`` (quantised to 100 nm); takes effect from the next frame.

        Returns
        -------
        float
            The quantised target.

        Raises
        ------
        ValueError
            If ``nm`` is not finite or outside :attr:`limits`.
        """
        v = as_finite(nm, f"{self.name}: position")
        lo, hi = self.limits
        if not lo <= v <= hi:
            raise ValueError(f"{self.name}: position {v:.6g} nm outside the travel [{lo:.6g}, {hi:.6g}] nm")
        q = round(v / self.resolution_nm) * self.resolution_nm
        self._pending = min(max(q, lo), hi)
        return self._pending

    def latch(self) -> None:
        """The pending move takes effect (the rig calls this at the start of each frame)."""
        if self._pending is not None:
            self._position = self._pending
            self._pending = None

    def _offset_nm(self) -> float:
        return self._position - self._home


class NanoAxis:
    """One piezo channel; implements :class:`semlab.protocols.Axis`.

    ``volts``, ``bits`` and ``creep`` override the Zyvex defaults (the alternative rig of
    :class:`~semlab.sim.SimulatedRig`: a 0-150 V amplifier, 16-bit DACs on every axis).

    Attributes
    ----------
    limits : (float, float)
        ``(0.0, 100.0)`` V by default.
    bits : int
        DAC resolution (16 for x/z, 12 for y by default).
    lsb_volts : float
        DAC step, ``(limits[1] - limits[0]) / 2**bits``.
    travel_nm : float
        Nominal travel at full command.
    """

    def __init__(self, name: str, axis: str, params: PiezoParameters | None = None,
                 hysteresis: PreisachHysteresis | None = None, *, volts=PIEZO_VOLTS, bits=None, creep=None):
        self.name = name
        self.axis = axis
        self.limits = (float(volts[0]), float(volts[1]))
        self.bits = DAC_BITS[axis] if bits is None else int(bits)
        self._dac = DAC(self.bits, *self.limits)
        self.lsb_volts = self._dac.lsb
        self.travel_nm = NANO_TRAVEL_NM[axis]
        self._piezo = PiezoAxis(self.travel_nm, *self.limits, params=params, hysteresis=hysteresis, creep=creep)
        self._applied = self.limits[0]
        self._pending = None

    def apply(self, volts: float) -> None:
        """Command ``volts``; the DAC output changes at the start of the next frame.

        Raises
        ------
        ValueError
            NaN/inf or outside :attr:`limits` (via :func:`semlab.protocols.check_command`).
        """
        v = check_command(volts, self.limits, self.name)
        self._pending = self._dac.quantise(v)

    @property
    def command(self) -> float:
        """The last commanded voltage after DAC quantisation (what the DAC will output)."""
        return self._pending if self._pending is not None else self._applied

    def latch(self, t: float) -> None:
        """The DAC outputs the pending command from time ``t`` (the rig calls this at the start of
        each frame: a command applied during a frame acts from the next one)."""
        if self._pending is not None:
            self._applied = self._pending
            self._pending = None
        self._piezo.set_target(self._applied, t)

    def _position_nm(self, t: float) -> float:
        return self._piezo.position_nm(t)

    def __repr__(self):
        return f"NanoAxis({self.name!r}, limits={self.limits}, bits={self.bits})"


class Manipulator:
    """A 3-DOF manipulator: a macro stepper and a nano piezo per axis.

    ``hysteresis_factory(index, axis)`` and ``creep_factory(index, axis)`` give each piezo its own
    hysteresis and creep (default: Preisach, log creep); ``nano_options`` go to every
    :class:`NanoAxis` (``volts``, ``bits``).
    """

    def __init__(self, index: int, params: PiezoParameters | None = None,
                 hysteresis_factory=None, *, creep_factory=None, nano_options=None):
        self.index = index
        self.nano = {}
        self.macro = {}
        for a in AXES:
            hyst = hysteresis_factory(index, a) if hysteresis_factory is not None else None
            creep = creep_factory(index, a) if creep_factory is not None else None
            self.nano[a] = NanoAxis(f"manipulator {index} {a} piezo", a, params, hyst, creep=creep,
                                    **(nano_options or {}))
            self.macro[a] = MacroStepper(f"manipulator {index} {a} macro", a)

    def latch(self, t: float) -> None:
        """Every axis takes its pending command from time ``t``."""
        for a in AXES:
            self.nano[a].latch(t)
            self.macro[a].latch()

    def displacement_nm(self, t: float) -> dict:
        """Total displacement from home per axis (macro offset + piezo), nm."""
        return {a: self.macro[a]._offset_nm() + self.nano[a]._position_nm(t) for a in AXES}
