"""Ground-truth piezo actuator: Preisach hysteresis, logarithmic creep, lag and a DAC.

The controller in :mod:`semlab.hysteresis` fits 4th-order polynomial branches (the
paper's Eq. 11 model) and Prandtl-Ishlinskii operators; the ground truth here comes
from a different family on purpose, a *continuous Preisach model* whose weight
depends on the position along the Preisach plane's diagonal (so it is asymmetric and
not a Prandtl-Ishlinskii model, whose weight would depend on ``alpha - beta`` only).

Signal chain of one nano axis: command -> DAC quantisation -> first-order lag (the
amplifier and the piezo's capacitance, time constant of a few ms) -> rate-independent
hysteresis -> logarithmic creep -> displacement in nm.

An independently built alternative, for benchmarks on a piezo whose hysteresis is not the
family any model assumes: :class:`PrandtlIshlinskiiHysteresis`, play operators of uneven
thresholds followed by a static output nonlinearity (so neither the polynomial model, nor
semlab's PI model, whose shaping acts on the input, contains it), with
:class:`ExponentialCreep` (a chain of Kelvin-Voigt relaxations, not the log law the
controller's creep model assumes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import exprel

__all__ = ["DAC", "ExponentialCreep", "LogCreep", "PiezoAxis", "PiezoParameters", "PrandtlIshlinskiiHysteresis",
           "PreisachHysteresis"]


class PreisachHysteresis:
    """Continuous Preisach model with a closed-form Everett function.

    Input ``v`` and output ``y`` are normalised: ``v`` in [0, 1] (command range), ``y``
    in [0, 1] (full travel reached at ``v = 1`` from the demagnetised state at 0).

    The Preisach weight over the half-plane ``0 <= beta <= alpha <= 1`` (relays switch
    up at ``alpha`` and down at ``beta``) is::

        mu(alpha, beta) = exp(kappa * beta) * sum_i c_i lam_i exp(-lam_i (alpha - beta))

    i.e. a mixture of exponential distributions of the switching width modulated along
    the diagonal (``kappa != 0`` makes the loop asymmetric and the gain voltage
    dependent), plus a reversible (single-valued) part ``r (v + nu v^2) / (1 + nu)``.
    The Everett function ``E(a, b)`` (the weight of the triangle ``b <= beta <= alpha
    <= a``) is available in closed form, so the output of any input history is a finite
    sum over the reversal points kept in a wiping-out memory stack: the output is
    continuous, and minor loops close (return-point memory).

    Parameters
    ----------
    lambdas : sequence of float
        Decay rates of the switching-width distributions (per unit normalised input).
    weights : sequence of float
        Their relative weights.
    kappa : float
        Modulation along the diagonal (asymmetry).
    reversible : float
        Fraction of the travel that is reversible (no hysteresis).
    nu : float
        Quadratic nonlinearity of the reversible part.
    """

    def __init__(self, lambdas=(3.0, 14.0), weights=(0.45, 0.55), kappa=0.7,
                 reversible=0.22, nu=0.4):
        lam = np.asarray(lambdas, float)
        wts = np.asarray(weights, float)
        if lam.shape != wts.shape or lam.ndim != 1 or lam.size == 0:
            raise ValueError("lambdas and weights must be 1-D sequences of equal length")
        if np.any(lam <= 0) or np.any(wts < 0) or not np.all(np.isfinite(lam)):
            raise ValueError("lambdas must be > 0 and weights >= 0")
        if not 0 <= reversible < 1:
            raise ValueError(f"reversible must lie in [0, 1), got {reversible}")
        if nu < 0:
            raise ValueError("nu must be >= 0 (monotone reversible part)")
        self.lambdas, self.kappa, self.nu = lam, float(kappa), float(nu)
        self._c = wts.copy()
        self.reversible = float(reversible)
        # normalise the hysteretic part so that E(1, 0) = 1 - reversible
        e10 = self._everett_raw(1.0, 0.0)
        self._c *= (1.0 - self.reversible) / e10
        self.reset()

    def _everett_raw(self, a: float, b: float) -> float:
        if a <= b:
            return 0.0
        k = self.kappa
        d = a - b
        first = math.exp(k * b) * d * float(exprel(k * d))
        total = 0.0
        for c, lam in zip(self._c, self.lambdas):
            total += c * (first - (math.exp(k * a) - math.exp(k * b - lam * d)) / (k + lam))
        return total

    def everett(self, a: float, b: float) -> float:
        """Weight of the Preisach triangle ``b <= beta <= alpha <= a`` (0 if ``a <= b``)."""
        return self._everett_raw(a, b)

    def reset(self) -> None:
        """Negative saturation: all relays down, input at 0."""
        self._stack = [0.0]
        self._v = 0.0

    @property
    def input(self) -> float:
        """Current normalised input."""
        return self._v

    @property
    def memory(self) -> tuple:
        """Reversal points kept by the wiping-out rule (the first is the lower bound 0)."""
        return tuple(self._stack)

    def update(self, v: float) -> float:
        """Move the input monotonically to ``v`` (in [0, 1]) and return the output."""
        v = float(v)
        if not (0.0 <= v <= 1.0) or not math.isfinite(v):
            raise ValueError(f"Preisach input must lie in [0, 1], got {v}")
        st = self._stack
        increasing = len(st) % 2 == 1  # the last reversal is a minimum
        if v > self._v:
            if not increasing:
                st.append(self._v)  # the previous input was a maximum
            # wiping-out: a larger maximum erases the smaller (max, min) pairs
            while len(st) >= 3 and v >= st[-2]:
                del st[-2:]
        elif v < self._v:
            if increasing:
                st.append(self._v)
            while len(st) >= 2 and v <= st[-2]:
                del st[-2:]
            if not st:
                st.append(0.0)
        self._v = v
        return self.output()

    def output(self) -> float:
        """Output for the current memory stack and input (finite sum of Everett terms)."""
        pts = self._stack + [self._v]
        y = 0.0
        for j in range(1, len(pts), 2):
            upper = pts[j + 1] if j + 1 < len(pts) else pts[j]
            y += self.everett(pts[j], pts[j - 1]) - self.everett(pts[j], upper)
        v = self._v
        y += self.reversible * (v + self.nu * v * v) / (1.0 + self.nu)
        return y

    def branch(self, v_path) -> np.ndarray:
        """Outputs along an input path (stateful: the model ends at the last input)."""
        return np.array([self.update(v) for v in v_path])


class PrandtlIshlinskiiHysteresis:
    """Prandtl-Ishlinskii hysteresis with a static output nonlinearity (a generalised PI model).

    Input ``v`` and output ``y`` normalised as for :class:`PreisachHysteresis` (``y`` = 1 at
    ``v`` = 1 from the relaxed state). With play operators ``F_r`` (backlash of half-width
    ``r``)::

        p = sum_j w_j (F_{r_j}[v] - r_j) / sum_j w_j (1 - 2 r_j),   y = g(p) = (p + a p^2 + b p^3) / (1 + a + b)

    Thresholds ``r_j = r_max (j / (n - 1))^1.5`` (denser at narrow widths) and weights
    ``w_j = exp(-decay r_j)``, except ``w_0`` (``r_0 = 0``, the reversible part), set so that it
    carries the fraction ``reversible`` of ``p``'s travel. A PI operator
    alone gives a point-symmetric major loop with congruent minor loops; the output
    nonlinearity ``g`` (monotone for ``a, b >= 0``) breaks both, as a real piezo's loop does.
    The plays give wiping-out and return-point memory, so minor loops close.

    Parameters
    ----------
    n_plays : int
        Number of play operators.
    max_threshold : float
        ``r_max``, the widest play's half-width (normalised input).
    decay : float
        Decay of the weights with the threshold.
    reversible : float
        Share of the reversible (threshold 0) play in the travel of ``p``, in [0, 1).
    quadratic, cubic : float
        ``a`` and ``b`` of the output nonlinearity (>= 0).
    """

    def __init__(self, n_plays=12, max_threshold=0.2, decay=4.0, reversible=0.25, quadratic=0.45, cubic=0.2):
        if int(n_plays) != n_plays or n_plays < 1:
            raise ValueError(f"n_plays must be a positive integer, got {n_plays!r}")
        if not 0.0 <= max_threshold < 0.5:
            raise ValueError(f"max_threshold must lie in [0, 0.5), got {max_threshold}")
        if quadratic < 0 or cubic < 0:
            raise ValueError("quadratic and cubic must be >= 0 (a monotone output nonlinearity)")
        if not 0.0 <= reversible < 1.0 or (int(n_plays) == 1 and reversible == 0.0):
            raise ValueError(f"reversible must lie in [0, 1) (and > 0 with one play), got {reversible}")
        j = np.arange(int(n_plays))
        self.thresholds = float(max_threshold) * (j / max(int(n_plays) - 1, 1)) ** 1.5
        self.weights = np.exp(-float(decay) * self.thresholds)
        rest = float(self.weights[1:] @ (1.0 - 2.0 * self.thresholds[1:]))
        self.weights[0] = 1.0 if rest == 0.0 else reversible * rest / (1.0 - reversible)
        self._norm = float(self.weights @ (1.0 - 2.0 * self.thresholds))
        self.quadratic, self.cubic = float(quadratic), float(cubic)
        self.reset()

    def reset(self) -> None:
        """Relaxed: after a descent to 0, every play sits at its threshold."""
        self._z = self.thresholds.copy()
        self._v = 0.0

    @property
    def input(self) -> float:
        return self._v

    def operator_output(self) -> float:
        """``p``, the normalised PI operator output before the static nonlinearity."""
        return float(self.weights @ (self._z - self.thresholds)) / self._norm

    def update(self, v: float) -> float:
        """Move the input to ``v`` (in [0, 1]) and return the output."""
        v = float(v)
        if not (0.0 <= v <= 1.0) or not math.isfinite(v):
            raise ValueError(f"PI input must lie in [0, 1], got {v}")
        self._z = np.maximum(v - self.thresholds, np.minimum(v + self.thresholds, self._z))
        self._v = v
        return self.output()

    def output(self) -> float:
        p = self.operator_output()
        a, b = self.quadratic, self.cubic
        return (p + a * p * p + b * p**3) / (1.0 + a + b)

    def branch(self, v_path) -> np.ndarray:
        """Outputs along an input path (stateful: the model ends at the last input)."""
        return np.array([self.update(v) for v in v_path])


class ExponentialCreep:
    """Creep as a chain of Kelvin-Voigt relaxations: each displacement step ``D`` made at ``t_j``
    adds ``D * sum_k c_k (1 - exp(-(t - t_j) / tau_k))``.

    A different law from :class:`LogCreep` (and from the log law of the controller's creep model):
    it saturates at ``D * sum c_k`` instead of growing per decade for ever. The sums over past steps
    are kept exactly by recursion (no memory limit).

    Parameters
    ----------
    fractions : sequence of float
        ``c_k``, the creep of each relaxation as a fraction of the step (>= 0).
    time_constants : sequence of float
        ``tau_k`` in s (> 0).
    """

    def __init__(self, fractions=(0.008, 0.012, 0.015), time_constants=(0.3, 3.0, 30.0)):
        c = np.asarray(fractions, float)
        tau = np.asarray(time_constants, float)
        if c.shape != tau.shape or c.ndim != 1 or np.any(c < 0) or np.any(tau <= 0):
            raise ValueError("ExponentialCreep needs matching fractions >= 0 and time constants > 0")
        self.fractions, self.time_constants = c, tau
        self.reset()

    def reset(self) -> None:
        self._total = 0.0  # sum of all steps
        self._decaying = np.zeros_like(self.fractions)  # sum_j D_j exp(-(t_ref - t_j) / tau_k)
        self._t_ref = 0.0

    def add_step(self, t: float, step: float) -> None:
        """Register a displacement ``step`` that started at time ``t``."""
        if step == 0.0:
            return
        t = float(t)
        if t > self._t_ref:
            self._decaying *= np.exp(-(t - self._t_ref) / self.time_constants)
            self._t_ref = t
        self._decaying += step * np.exp(-(self._t_ref - t) / self.time_constants)
        self._total += step

    def value(self, t: float) -> float:
        """Creep displacement at time ``t`` (not before the last step)."""
        if t < self._t_ref:
            raise ValueError(f"creep asked at t={t} s, before its last step at {self._t_ref} s")
        decayed = self._decaying * np.exp(-(t - self._t_ref) / self.time_constants)
        return float(self.fractions @ (self._total - decayed))


class LogCreep:
    """Logarithmic creep superposed per step (the usual piezo creep law).

    A displacement step ``D`` made at time ``t_j`` keeps growing as
    ``D * gamma * log10(1 + (t - t_j) / t0)``; every step contributes its own term.
    Only the last ``memory`` steps keep growing; older ones are frozen at their value
    (their growth rate is below ``gamma D / (t ln 10)`` anyway).

    Parameters
    ----------
    gamma : float
        Creep per time decade as a fraction of the step (0.015 = 1.5 %/decade).
    t0 : float
        Reference time in s (creep counts decades after ``t0``).
    memory : int
        Number of steps tracked.
    """

    def __init__(self, gamma=0.015, t0=0.1, memory=64):
        if gamma < 0 or t0 <= 0 or memory < 1:
            raise ValueError("LogCreep needs gamma >= 0, t0 > 0, memory >= 1")
        self.gamma, self.t0, self.memory = float(gamma), float(t0), int(memory)
        self.reset()

    def reset(self) -> None:
        """Forget all steps."""
        self._events = []  # [t_j, D_j]
        self._frozen = 0.0

    def add_step(self, t: float, step: float) -> None:
        """Register a displacement ``step`` that started at time ``t``."""
        if step == 0.0 or self.gamma == 0.0:
            return
        if self._events and self._events[-1][0] == t:
            self._events[-1][1] += step
            return
        self._events.append([t, step])
        if len(self._events) > self.memory:
            t_old, d_old = self._events.pop(0)
            self._frozen += d_old * self.gamma * math.log10(1.0 + max(t - t_old, 0.0) / self.t0)

    def value(self, t: float) -> float:
        """Creep displacement at time ``t``."""
        s = self._frozen
        for tj, dj in self._events:
            if t > tj:
                s += dj * self.gamma * math.log10(1.0 + (t - tj) / self.t0)
        return s


class DAC:
    """An ideal N-bit DAC over ``[u0, un]``: LSB = (un - u0) / 2**bits.

    Codes run from 0 to ``2**bits - 1``, so the top of the range is ``un - LSB`` (as on
    a real converter whose full scale is ``un``).
    """

    def __init__(self, bits: int, u0: float, un: float):
        if int(bits) != bits or not 1 <= bits <= 24:
            raise ValueError(f"DAC bits must be an integer in [1, 24], got {bits!r}")
        if not un > u0:
            raise ValueError("DAC range needs un > u0")
        self.bits, self.u0, self.un = int(bits), float(u0), float(un)
        self.lsb = (self.un - self.u0) / 2**self.bits

    def code(self, volts: float) -> int:
        """Nearest code for ``volts`` (clipped to the code range)."""
        c = round((volts - self.u0) / self.lsb)
        return min(max(c, 0), 2**self.bits - 1)

    def quantise(self, volts: float) -> float:
        """Output voltage of the DAC for a requested ``volts``."""
        return self.u0 + self.code(volts) * self.lsb


@dataclass(frozen=True)
class PiezoParameters:
    """Dynamics of a nano axis (all effects switchable: 0 = off).

    Parameters
    ----------
    lag_s : float
        First-order lag time constant (amplifier + piezo capacitance); 2 ms, i.e. the
        step is complete within 3 % of a 13 Hz frame.
    creep_per_decade : float
        Logarithmic creep as a fraction of each step per time decade.
    creep_t0_s : float
        Creep reference time.
    hysteresis : bool
        ``False`` replaces the Preisach model by the line ``y = v``.
    position_noise_nm : float
        Standard deviation of the piezo's position noise (amplifier noise, vibration),
        drawn independently per frame and axis; 1 nm rms ~ the 5 nm peak-to-peak
        "nominal resolution" of the Zyvex nano stage. It is part of the ground truth.
    """

    lag_s: float = 0.002
    creep_per_decade: float = 0.015
    creep_t0_s: float = 0.1
    hysteresis: bool = True
    position_noise_nm: float = 1.0

    def __post_init__(self):
        if self.lag_s < 0 or self.creep_per_decade < 0 or self.creep_t0_s <= 0:
            raise ValueError("PiezoParameters: lag_s, creep_per_decade >= 0 and creep_t0_s > 0")
        if not (math.isfinite(self.position_noise_nm) and self.position_noise_nm >= 0):
            raise ValueError("PiezoParameters: position_noise_nm must be finite and >= 0")


class PiezoAxis:
    """Ground truth of one piezo axis: volts in, nm out, with lag, hysteresis and creep.

    Parameters
    ----------
    travel_nm : float
        Displacement at full command from the relaxed state.
    u0, un : float
        Command range in volts.
    params : PiezoParameters
        Lag/creep settings.
    hysteresis : PreisachHysteresis, PrandtlIshlinskiiHysteresis or None
        The hysteresis model (a fresh default Preisach one if ``None``).
    creep : LogCreep, ExponentialCreep or None
        The creep law (default: ``LogCreep`` from ``params``).
    """

    def __init__(self, travel_nm, u0, un, params: PiezoParameters | None = None,
                 hysteresis: PreisachHysteresis | None = None, creep=None):
        self.travel_nm, self.u0, self.un = float(travel_nm), float(u0), float(un)
        self.params = PiezoParameters() if params is None else params
        self.hyst = PreisachHysteresis() if hysteresis is None else hysteresis
        self.creep = LogCreep(self.params.creep_per_decade, self.params.creep_t0_s) if creep is None else creep
        self.reset()

    def reset(self, t: float = 0.0) -> None:
        """Relaxed state at ``u0``, time ``t``."""
        self.hyst.reset()
        self.creep.reset()
        self._t = float(t)
        self._u = self.u0
        self._target = self.u0
        self._t_cmd = float(t)
        self._y = 0.0

    def _normalise(self, u):
        return min(max((u - self.u0) / (self.un - self.u0), 0.0), 1.0)

    def set_target(self, volts: float, t: float) -> None:
        """The (already quantised) drive voltage changes to ``volts`` at time ``t``."""
        self.advance(t)
        if volts != self._target:
            self._target = float(volts)
            self._t_cmd = float(t)

    def advance(self, t: float) -> None:
        """Let time run to ``t``: the lagged voltage moves monotonically towards the target."""
        dt = t - self._t
        if dt < 0:
            raise ValueError("time cannot run backwards")
        if dt == 0:
            return
        tau = self.params.lag_s
        if tau > 0:
            self._u = self._target + (self._u - self._target) * math.exp(-dt / tau)
        else:
            self._u = self._target
        v = self._normalise(self._u)
        y = self.hyst.update(v) if self.params.hysteresis else v
        self.creep.add_step(self._t_cmd, (y - self._y) * self.travel_nm)
        self._y = y
        self._t = float(t)

    @property
    def voltage(self) -> float:
        """The lagged voltage across the piezo."""
        return self._u

    def position_nm(self, t: float | None = None) -> float:
        """Displacement in nm at time ``t`` (advances the state to ``t``)."""
        if t is not None:
            self.advance(t)
        return self._y * self.travel_nm + self.creep.value(self._t)
