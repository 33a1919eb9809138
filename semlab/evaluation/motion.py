"""Probe paths of the corpus: where the ground-truth point is in each frame, relative to frame 0.

Each function returns an ``(n_frames, 2)`` array of displacements ``(dx, dy)`` px from the start,
row 0 being ``(0, 0)``, drawn from the generator it is given (so a family's sequence is a
deterministic function of its seed).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ab_moves", "jumps", "still", "wander"]


def still(n_frames: int) -> np.ndarray:
    """No motion: the paper's repeatability test."""
    return np.zeros((n_frames, 2))


def wander(n_frames: int, rng: np.random.Generator, *, speed_px: float, persistence: float,
           radius_px: float, along=None, along_fraction: float = 0.5) -> np.ndarray:
    """Smooth random wander: a velocity that is an AR(1) process, kept within ``radius_px``.

    Parameters
    ----------
    n_frames : int
    rng : numpy.random.Generator
    speed_px : float
        RMS speed in px per frame.
    persistence : float
        Frame-to-frame correlation of the velocity, in [0, 1).
    radius_px : float
        The path is pushed back (the outward velocity reversed) when it leaves this disc.
    along : (float, float) or None
        A direction in the image that gets ``along_fraction`` of the velocity variance (e.g. a
        probe's shaft); None: isotropic.
    along_fraction : float
        With ``along``, the share of the velocity variance along it (0.9: mostly along).

    Returns
    -------
    (n_frames, 2) ndarray
    """
    if not 0 <= persistence < 1:
        raise ValueError(f"persistence must lie in [0, 1), got {persistence!r}")
    if along is None:
        scale = np.array([1.0, 1.0]) * speed_px / math.sqrt(2.0)
        basis = np.eye(2)
    else:
        u = np.asarray(along, float) / np.hypot(*along)
        basis = np.array([u, [-u[1], u[0]]])
        scale = speed_px * np.sqrt([along_fraction, 1.0 - along_fraction])
    innov = math.sqrt(1.0 - persistence**2)
    path = np.zeros((n_frames, 2))
    v = scale * rng.standard_normal(2)
    for k in range(1, n_frames):
        v = persistence * v + innov * scale * rng.standard_normal(2)
        step = v @ basis  # image coordinates (the basis is orthonormal: v = step @ basis.T)
        p = path[k - 1] + step
        r = np.hypot(*p)
        if r > radius_px:  # reflect the outward part of the motion at the edge of the disc
            n = p / r
            step = step - 2.0 * max(float(step @ n), 0.0) * n
            p = path[k - 1] + step
            v = step @ basis.T
        path[k] = p
    return path


def ab_moves(step_px: float, direction_rad: float, *, n_cycles: int, ramp_frames: int,
             dwell_frames: int, smooth: bool) -> np.ndarray:
    """The paper's A -> B -> A moves: dwell at A, ramp to B, dwell, ramp back, ``n_cycles`` times.

    Parameters
    ----------
    step_px : float
        Distance A -> B (the paper: 200 px).
    direction_rad : float
        Direction of A -> B in the image.
    n_cycles, ramp_frames, dwell_frames : int
    smooth : bool
        A raised-cosine ramp (a servo's smooth move) instead of a linear one.

    Returns
    -------
    (dwell + n_cycles * 2 * (ramp + dwell), 2) ndarray
    """
    k = np.arange(1, ramp_frames + 1) / ramp_frames
    ramp = 0.5 - 0.5 * np.cos(np.pi * k) if smooth else k
    out = list(np.zeros(dwell_frames))
    for _ in range(n_cycles):
        out += list(ramp) + [1.0] * dwell_frames + list(1.0 - ramp) + [0.0] * dwell_frames
    s = np.asarray(out)
    d = np.array([math.cos(direction_rad), math.sin(direction_rad)])
    return step_px * s[:, None] * d[None, :]


def jumps(n_frames: int, rng: np.random.Generator, *, jump_px: tuple[float, float],
          dwell_frames: tuple[int, int], half_extent) -> tuple[np.ndarray, list[float]]:
    """Fast jumps between two frames, then a dwell: a feed-forward servo step seen by a tracker.

    Parameters
    ----------
    n_frames : int
    rng : numpy.random.Generator
    jump_px : (float, float)
        Range of each jump's length (uniform).
    dwell_frames : (int, int)
        Range (inclusive) of the number of frames between jumps.
    half_extent : (float, float)
        The path stays within ``|dx| <= half_extent[0]``, ``|dy| <= half_extent[1]``.

    Returns
    -------
    (path, lengths, dwells) : ((n_frames, 2) ndarray, list of float, list of int)
        The displacements, the length of every jump made and the dwells drawn.
    """
    hx, hy = half_extent
    path = np.zeros((n_frames, 2))
    lengths = []
    p = np.zeros(2)
    k = int(rng.integers(dwell_frames[0], dwell_frames[1] + 1))
    dwells = [k]
    path[:k] = p
    while k < n_frames:
        length = float(rng.uniform(*jump_px))
        for _ in range(50):
            ang = rng.uniform(0, 2 * math.pi)
            q = p + length * np.array([math.cos(ang), math.sin(ang)])
            if abs(q[0]) <= hx and abs(q[1]) <= hy:
                break
        else:  # no direction keeps it inside: jump back towards the start
            q = p - length * p / max(np.hypot(*p), 1e-9)
        q = np.clip(q, [-hx, -hy], [hx, hy])
        lengths.append(float(np.hypot(*(q - p))))
        p = q
        dwell = int(rng.integers(dwell_frames[0], dwell_frames[1] + 1))
        dwells.append(dwell)
        path[k:k + dwell] = p
        k += dwell
    return path, lengths, dwells
