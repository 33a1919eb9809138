"""Simulated SEM and nanomanipulator rig with exact ground truth.

Everything the tracker and the servo are measured against: an analytic SEM renderer of
tungsten probes over a substrate (:mod:`.scene`), the SEM's noise and artefacts
(:mod:`.noise`), the Zyvex S100 manipulators with Preisach piezo hysteresis, creep, lag
and DACs (:mod:`.piezo`, :mod:`.manipulator`; or an independently built alternative:
Prandtl-Ishlinskii hysteresis with a static nonlinearity, ``SimulatedRig(piezo_model=...)``), the rig that couples them
(:mod:`.rig`), standard sequences (:mod:`.sequences`) and the Cramér–Rao bound of a
one-frame translation estimate (:mod:`.crb`).

Only tests, benchmarks and notebooks may read the ground truth; the tracker and the
servo see the rig through :mod:`semlab.protocols`.
"""

from .crb import translation_crb, translation_fisher
from .manipulator import MacroStepper, NanoAxis
from .noise import SEMNoise
from .optics import beam_blur_sigma_px, pixel_size_from_magnification
from .piezo import (
    DAC,
    ExponentialCreep,
    LogCreep,
    PiezoParameters,
    PrandtlIshlinskiiHysteresis,
    PreisachHysteresis,
)
from .rig import SimulatedMicroscope, SimulatedRig
from .scene import Clutter, ProbeGeometry
from .sem import SimulatedSEM
from .sequences import SEQUENCE_KINDS, Sequence, make_sequence

__all__ = [
    "DAC",
    "SEQUENCE_KINDS",
    "Clutter",
    "ExponentialCreep",
    "LogCreep",
    "MacroStepper",
    "NanoAxis",
    "PiezoParameters",
    "PrandtlIshlinskiiHysteresis",
    "PreisachHysteresis",
    "ProbeGeometry",
    "SEMNoise",
    "Sequence",
    "SimulatedMicroscope",
    "SimulatedRig",
    "SimulatedSEM",
    "beam_blur_sigma_px",
    "make_sequence",
    "pixel_size_from_magnification",
    "translation_crb",
    "translation_fisher",
]
