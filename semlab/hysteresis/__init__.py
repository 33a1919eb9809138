"""Piezo hysteresis: models and their inverses, fitted to a characterisation by visual tracking.

The paper (Ru et al., "Visual Servo Control Incorporating a Feed-Forward Controller", Fig. 8)
characterises one piezo axis by applying voltages incrementally from U0 to Un and back while the visual
tracker records the probe displacement, fits the ascending and descending major branches Pn(u), Dn(u)
with fourth-order polynomials, describes curves that start at a reversal inside the loop with eq. 11,
and inverts the model by Newton-Raphson to obtain the feed-forward command.

This module provides the models; the experiment that measures them (the voltage path of Fig. 8b and
:func:`semlab.experiments.characterise_hysteresis`) drives a rig and lives in :mod:`semlab.experiments`,
the creep law in :mod:`semlab.creep` (their old import paths from here keep working):

* :class:`PolynomialHysteresis` -- Pn, Dn, eq. 11, its mirror for reversals on the ascending branch,
  reversal-point memory (wiping-out) and the Newton-Raphson inverse;
* :class:`PIHysteresis` -- a Prandtl-Ishlinskii model (play operators, weights by bounded/non-negative
  least squares) with the analytic inverse of Krejci & Kuhnen (2001), the paper's recommendation for a
  more accurate model;
* :func:`fit_hysteresis` -- fits either model to a characterisation.

Both models share one interface: ``forward`` (commit voltages, return displacements), ``displacement``
(peek), ``inverse`` (voltage that produces a desired displacement from the current memory state),
``reset``, ``state``, ``check_axis``, ``u_range`` and ``displacement_range``.

The characterised range ``u_range`` limits what the model *knows*, not where the axis may go: beyond it
the models extrapolate linearly (:attr:`HysteresisModel.extrapolation_slopes`, deliberately steeper than
anything measured, so that a feed-forward move beyond the range stops short rather than overshoots) and
remember an excursion out there like any other history (the curve back from it starts at it). The axis
limits are the servo's business (:mod:`semlab.control`).

Displacements are in image pixels along the measured image direction of the axis; the sign is chosen
so that rising voltage increases the displacement.

Modules: :mod:`.model` (the shared interface :class:`HysteresisModel`, its memory
:class:`HysteresisState`, :func:`axis_identity`, :data:`BRANCHES`), :mod:`.polynomial` (eq. 11,
the Newton-Raphson root finder, :class:`PolynomialHysteresis`), :mod:`.prandtl_ishlinskii`
(:func:`play_operator`, :class:`PIHysteresis`), :mod:`.fit` (:func:`fit_hysteresis`).
"""

from __future__ import annotations

# EXTRAPOLATION_SLOPE_FACTOR, SHAPED_ROUND_OFF and _newton_bisect are not in __all__ but were
# reachable as semlab.hysteresis.<name> before the split (tests/test_hysteresis_theory.py tests the
# root finder directly)
from .fit import fit_hysteresis
from .model import BRANCHES, HysteresisModel, HysteresisState, axis_identity
from .model import EXTRAPOLATION_SLOPE_FACTOR as EXTRAPOLATION_SLOPE_FACTOR
from .polynomial import PolynomialHysteresis, inner_loop_displacement
from .polynomial import _newton_bisect as _newton_bisect
from .prandtl_ishlinskii import SHAPED_ROUND_OFF as SHAPED_ROUND_OFF
from .prandtl_ishlinskii import PIHysteresis, play_operator

__all__ = [
    "BRANCHES",
    "HysteresisModel",
    "HysteresisState",
    "PIHysteresis",
    "PolynomialHysteresis",
    "axis_identity",
    "fit_hysteresis",
    "inner_loop_displacement",
    "play_operator",
]


# What drives a rig (and plans its voltages) moved to semlab.experiments, the creep law to
# semlab.creep; their old import paths keep working.
_MOVED = {"characterise_hysteresis": "experiments", "characterise_creep": "experiments",
          "characterisation_voltages": "experiments", "label_branches": "experiments",
          "DEFAULT_INNER_TURNS": "experiments", "CreepModel": "creep", "fit_creep": "creep"}


def __getattr__(name: str):
    if name in _MOVED:
        import importlib

        # relative to semlab (this package's parent): semlab.experiments, semlab.creep
        return getattr(importlib.import_module(f"..{_MOVED[name]}", __package__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
