"""Fakes for the servo tests: a 'microscope' holding probes whose two piezo axes move the tip along
image directions that are rotated and not orthogonal, each axis an independent hysteresis (weighted play
operators on a leaning input, cubic output: in neither model family), with one frame of latency, and a
fake tracker per probe that reports the true position (plus optional noise / lost frames)."""

from __future__ import annotations

import math

import numpy as np

from semlab.hysteresis import characterise_hysteresis, fit_hysteresis

FRAME_PERIOD = 1 / 13
RS = np.array([0.0, 0.05, 0.1, 0.2, 0.3])
WS = np.array([100.0, 70.0, 60.0, 60.0, 40.0]) / 330.0


class FakePiezo:
    """One axis: displacement (px along its direction) = gain * h(u), h a hysteresis of its own."""

    def __init__(self, stage, name, gain_px, direction_deg, limits=(0.0, 100.0)):
        self.stage, self.name, self.limits, self.gain = stage, name, limits, gain_px
        th = math.radians(direction_deg)
        self.d = np.array([math.cos(th), math.sin(th)])
        self.u, self.pending, self.sent = limits[0], None, []
        self.z = RS.copy()
        self.disp = 0.0

    def apply(self, volts):
        from semlab.protocols import check_command

        self.sent.append(check_command(volts, self.limits, self.name))
        self.pending = self.sent[-1]

    @property
    def command(self):
        return self.pending if self.pending is not None else self.u

    def _latch(self):
        if self.pending is None:
            return
        self.u, self.pending = self.pending, None
        v = (self.u - self.limits[0]) / (self.limits[1] - self.limits[0])
        v = v + 0.15 * v * (1 - v)
        self.z = np.maximum(v - RS, np.minimum(v + RS, self.z))
        h = float(WS @ self.z) - float(WS @ RS)
        self.disp = self.gain * (h + 0.1 * h**3)


class FakeStage:
    """Probes of two axes each in one 'microscope'; ``grab`` counts frames. A frame is a
    ``frame_shape`` array filled with its index (the fake tracker reads it)."""

    # (origin, (gain_x, angle_x), (gain_y, angle_y)): axes 75 deg and 105 deg apart, rotated
    PROBES = (((150.0, 250.0), (300.0, 20.0), (200.0, 95.0)),
              ((500.0, 150.0), (250.0, 200.0), (220.0, 285.0)))

    def __init__(self, n_probes=2, frame_shape=(480, 640)):
        self.frame_period = FRAME_PERIOD
        self.frame_shape = tuple(frame_shape)
        self.frame, self.grabs = -1, 0
        self.probes = []
        for k, (origin, (gx, ax), (gy, ay)) in enumerate(self.PROBES[:n_probes]):
            self.probes.append({"origin": np.array(origin), "axes": [FakePiezo(self, f"probe {k} x", gx, ax),
                                                                      FakePiezo(self, f"probe {k} y", gy, ay)]})

    def grab(self):
        self.frame += 1
        self.grabs += 1
        for p in self.probes:
            for a in p["axes"]:
                a._latch()
        return np.full(self.frame_shape, self.frame, dtype=np.int32)  # the frame 'shows' its index

    def position(self, k):
        p = self.probes[k]
        return p["origin"] + sum(a.disp * a.d for a in p["axes"])

    def axes(self, k):
        return self.probes[k]["axes"]


class FakeTracker:
    """Reports ``position()`` (the truth) moved onto the ROI's centre, plus optional noise; frames whose
    index is in ``lose`` are lost, in ``nan_ok`` reported valid with a NaN position (a broken tracker).

    ``FakeTracker(stage, probe)`` follows a probe of a :class:`FakeStage`; ``FakeTracker(position=f)``
    follows any ``f() -> (x, y)``."""

    def __init__(self, stage=None, probe=0, noise_px=0.0, lose=(), nan_ok=(), seed=0, *, position=None):
        self.position = position if position is not None else (lambda: stage.position(probe))
        self.noise = noise_px
        self.lose, self.nan_ok = set(lose), set(nan_ok)
        self.rng = np.random.default_rng(seed)
        self.updates = 0

    def init(self, frame, roi):
        x, y, w, h = roi
        self.centre = np.array([x + (w - 1) / 2, y + (h - 1) / 2])
        self.ref = np.array(self.position(), float)

    def update(self, frame):
        self.updates += 1
        k = int(frame[0, 0])
        if k in self.nan_ok:
            return (float("nan"), float("nan"), 1.0, True)
        if k in self.lose:
            return (float("nan"), float("nan"), 0.0, False)
        p = self.centre + np.array(self.position(), float) - self.ref + self.rng.normal(0, self.noise, 2)
        return (float(p[0]), float(p[1]), 1.0, True)


def roi_at(stage, k, size=101):
    x, y = stage.position(k)
    return (x - (size - 1) / 2, y - (size - 1) / 2, size, size)


def characterise(stage, k, u_range=(0.0, 100.0)):
    models = []
    for axis in stage.axes(k):
        char = characterise_hysteresis(stage, axis, roi_at(stage, k), u_min=u_range[0], u_max=u_range[1],
                                       n_steps=30, tracker=FakeTracker(stage, k))
        models.append(fit_hysteresis(char, kind="pi"))
    return models


def set_voltages(stage, k, models, volts):
    """Move probe ``k``'s axes (and their shadow models) to ``volts`` in 5-V increments."""
    for axis, model, v in zip(stage.axes(k), models, volts):
        for u in np.linspace(axis.command, v, 1 + int(abs(v - axis.command) // 5) + 1)[1:]:
            axis.apply(u)
            model.forward(u)
            stage.grab()
