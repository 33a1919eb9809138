"""The common interface of the hysteresis models: their memory state and the base class.

:class:`HysteresisModel` holds what both models share (``forward``, ``displacement``, ``inverse``,
``reset``, ``predict``, ``check_axis``, the linear extrapolation beyond the characterised range);
:class:`HysteresisState` is the memory a model carries between commands; :func:`axis_identity` names
the axis a model was fitted on; :data:`BRANCHES` are the branch labels of a characterisation (the
major and inner curves of the paper's Fig. 8b).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..protocols import as_finite

#: Branch labels used in a characterisation DataFrame.
BRANCHES = ("ascending", "descending", "inner_ascending", "inner_descending")

#: Beyond the characterised range the models extrapolate linearly with this many times the steepest
#: slope of their major loop. A piezo's gain keeps growing with the voltage (the simulated Preisach
#: axis characterised over 0-50 V of 0-100 V: 1.07x its steepest in-range slope 10 V beyond, 1.5x at
#: 100 V), and a model that is too steep only makes the feed-forward stop short, which the feedback
#: finishes, while one that is too shallow makes it overshoot.
EXTRAPOLATION_SLOPE_FACTOR = 1.25

# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------


def axis_identity(axis) -> str:
    """A string that identifies an actuator axis, used to refuse a model fitted on another axis.

    The axis' ``name`` (or ``id``/``label``) attribute is used when it has one; otherwise the Python
    object identity, which is only valid within one session.
    """
    if isinstance(axis, str):
        return axis
    for attr in ("name", "id", "label"):
        value = getattr(axis, attr, None)
        if value is not None and not callable(value):
            return str(value)
    return f"{type(axis).__name__}@{id(axis):x}"


# ---------------------------------------------------------------------------------------------
# the models
# ---------------------------------------------------------------------------------------------


@dataclass
class HysteresisState:
    """Memory of a hysteresis model.

    Attributes
    ----------
    u : float
        Last committed voltage.
    y : float
        Displacement there (px).
    rising : bool
        Direction of the last voltage change.
    reversals : list of (float, float)
        Remembered reversal points ``(u, y)`` inside the range, oldest first (polynomial model); they
        alternate maxima and minima and are wiped out when the voltage passes them (closure of a loop).
    plays : ndarray or None
        Play-operator states (Prandtl-Ishlinskii model).
    """

    u: float
    y: float
    rising: bool = True
    reversals: list = field(default_factory=list)
    plays: np.ndarray | None = None


class HysteresisModel:
    """Common interface of the hysteresis models (see the module docstring).

    Attributes
    ----------
    kind : str
        ``"polynomial"`` or ``"pi"``.
    axis : str
        Identity of the axis the model was fitted on (see :func:`axis_identity`).
    direction : (float, float)
        Unit vector of the image direction in which rising voltage moves the probe.
    u_range : (float, float)
        ``(U0, Un)`` of the characterisation: what the model knows. Outside it the model extrapolates
        linearly (:attr:`extrapolation_slopes`); a voltage is only refused when it is not finite.
    extrapolation_slopes : (float, float)
        px/V below ``U0`` and above ``Un`` after a long monotonic run: :data:`EXTRAPOLATION_SLOPE_FACTOR`
        times the model's steepest slope at that end (see each model).
    """

    kind = "base"

    def __init__(self, u_range, *, axis="unknown", direction=(1.0, 0.0), meta=None):
        u0, un = (as_finite(v, "model range bound") for v in u_range)
        if not u0 < un:
            raise ValueError(f"model voltage range {u_range} is empty")
        self.u_range = (u0, un)
        self.axis = axis_identity(axis)
        d = np.asarray(direction, dtype=float)
        if d.shape != (2,) or not np.all(np.isfinite(d)) or np.hypot(*d) == 0:
            raise ValueError(f"direction {direction!r} must be a non-zero 2-vector")
        self.direction = tuple(d / np.hypot(*d))
        self.meta = dict(meta or {})
        self.extrapolation_slopes = self._extrapolation_slopes()
        self.state = None
        self.reset()

    # -- interface to be provided by subclasses -------------------------------------------------
    def _major(self, u: float, rising: bool) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def _advance(self, state: HysteresisState, u: float) -> HysteresisState:  # pragma: no cover
        """The state after a monotonic move from ``state`` to any voltage ``u``."""
        raise NotImplementedError

    def _inverse(self, state: HysteresisState, target: float) -> float:  # pragma: no cover - abstract
        """The voltage whose monotonic move from ``state`` reaches ``target`` (any finite value)."""
        raise NotImplementedError

    # -- shared behaviour -----------------------------------------------------------------------
    @property
    def displacement_range(self) -> tuple[float, float]:
        """Displacements at U0 and Un (px): the range the characterisation covered."""
        return (self._major(self.u_range[0], True), self._major(self.u_range[1], True))

    @property
    def gain(self) -> float:
        """Mean slope of the loop, px per volt (the 'linear fit' of the paper)."""
        lo, hi = self.displacement_range
        return (hi - lo) / (self.u_range[1] - self.u_range[0])

    def steepest_slope(self, n: int = 201) -> float:
        """The steepest slope (px/V) of the two major branches over the characterised range."""
        grid = np.linspace(*self.u_range, int(n))
        slopes = [np.max(np.diff([self._major(u, rising) for u in grid]) / np.diff(grid))
                  for rising in (True, False)]
        return float(max(max(slopes), self.gain))

    def _extrapolation_slopes(self) -> tuple[float, float]:
        slope = EXTRAPOLATION_SLOPE_FACTOR * self.steepest_slope()
        return (slope, slope)

    def reset(self, u: float | None = None, branch: str = "ascending") -> HysteresisState:
        """Forget all reversals and put the model on a major branch.

        Parameters
        ----------
        u : float, optional
            Voltage; default ``U0`` (the state after a descent to U0, as after a characterisation).
            Outside the range the model sits on its extrapolation.
        branch : {"ascending", "descending"}
            Major branch the actuator is on (how ``u`` was approached).
        """
        if branch not in ("ascending", "descending"):
            raise ValueError(f"branch must be 'ascending' or 'descending', got {branch!r}")
        u = self.u_range[0] if u is None else self._check_u(u)
        self.state = self._major_state(u, branch == "ascending")
        return self.state

    def _major_state(self, u: float, rising: bool) -> HysteresisState:
        return HysteresisState(u=u, y=self._major(u, rising), rising=rising)

    def _check_u(self, u) -> float:
        return as_finite(u, "voltage")

    def forward(self, voltages) -> np.ndarray | float:
        """Commit voltage(s) in order and return the displacement(s) they produce (px).

        The memory (reversal points / play states) is updated, so a model used as the shadow of an
        axis must see every command sent to that axis. Voltages outside ``u_range`` are extrapolated,
        and the memory keeps their reversals too (an excursion beyond the range is remembered).
        """
        scalar = np.ndim(voltages) == 0
        out = []
        for u in np.atleast_1d(np.asarray(voltages, dtype=float)):
            self.state = self._advance(self.state, self._check_u(u))
            out.append(self.state.y)
        return out[0] if scalar else np.asarray(out)

    def displacement(self, u: float) -> float:
        """Displacement a move from the current state to ``u`` would produce, without committing it."""
        return self._advance(copy.deepcopy(self.state), self._check_u(u)).y

    def inverse(self, target: float) -> float:
        """Voltage that brings the displacement to ``target`` from the current state (not committed).

        Inside the characterised range the model's own inverse (eq. 11 by Newton-Raphson, or the
        analytic inverse PI operator); beyond it the extrapolation. Every finite target has an answer:
        whether the axis can apply it is for the caller to check against the axis limits.

        Raises
        ------
        ValueError
            If the target is not finite.
        """
        y_t = as_finite(target, "target displacement")
        lo_y, hi_y = self.displacement_range
        if abs(y_t - self.state.y) <= 1e-12 * max(1.0, hi_y - lo_y):  # rounding
            return self.state.u
        return self._inverse(self.state, y_t)

    def predict(self, voltages, *, reset: bool | tuple = True) -> np.ndarray:
        """Displacements for a voltage sequence, on a copy of the model (the model is untouched).

        Parameters
        ----------
        voltages : (N,) array_like
        reset : bool or (float, str)
            ``True`` starts from the reset state (U0 after a descent), ``False`` from the current state,
            a tuple ``(u, branch)`` from that major-branch state.
        """
        m = self.copy()
        if reset is True:
            m.reset()
        elif reset:
            m.reset(*reset)
        return np.atleast_1d(m.forward(np.atleast_1d(voltages)))

    def replay(self, characterisation: pd.DataFrame) -> np.ndarray:
        """Predicted displacement for each row of a characterisation (starting from U0 after a descent)."""
        return self.predict(characterisation["u"].to_numpy(float), reset=True)

    def copy(self) -> HysteresisModel:
        """A deep copy (its own memory)."""
        return copy.deepcopy(self)

    def check_axis(self, axis) -> None:
        """Raise ValueError if ``axis`` is not the axis this model was fitted on."""
        ident = axis_identity(axis)
        if ident != self.axis:
            raise ValueError(
                f"this {self.kind} hysteresis model was fitted on axis {self.axis!r}, not on {ident!r}; "
                "characterise this axis and fit a model for it"
            )

    def __repr__(self) -> str:
        lo, hi = self.displacement_range
        return (
            f"<{type(self).__name__} axis={self.axis!r} u={self.u_range[0]:.4g}..{self.u_range[1]:.4g} V "
            f"displacement={lo:.4g}..{hi:.4g} px direction=({self.direction[0]:.3f}, {self.direction[1]:.3f})>"
        )
