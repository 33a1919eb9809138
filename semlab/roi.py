"""Choosing the region of interest around the probe tip (Ru et al. 2012, "Contour Template
Identification", step 1): by a click near the tip, or by motion differencing while the probe steps.
"""

from __future__ import annotations

import cv2
import numpy as np

from .frames import as_gray_float, clip_window

__all__ = ["motion_energy", "roi_from_click", "roi_from_motion"]


def _size(size) -> tuple[int, int]:
    w, h = (size, size) if np.isscalar(size) else size
    w, h = int(w), int(h)
    if w < 8 or h < 8:
        raise ValueError(f"ROI size {(w, h)} is too small (at least 8x8 px)")
    return w, h


def roi_from_click(frame, click_xy, size=200) -> tuple[int, int, int, int]:
    """A ``size`` ROI centred on a click near the tip, shifted to lie inside the frame.

    The paper takes 200×200 px at 3,000× (Fig. 2b); scale ``size`` with the magnification.

    Parameters
    ----------
    frame : (M, N) array_like
    click_xy : (float, float)
        The click, ``(x, y)`` px.
    size : int or (int, int)
        ROI width and height.

    Returns
    -------
    (x, y, w, h)

    Raises
    ------
    ValueError
        If the click lies outside the frame or the frame is smaller than the ROI.
    """
    rows, cols = np.shape(frame)[:2]
    w, h = _size(size)
    cx, cy = (float(v) for v in click_xy)
    if not (np.isfinite(cx) and np.isfinite(cy)) or not (-0.5 <= cx <= cols - 0.5 and -0.5 <= cy <= rows - 0.5):
        raise ValueError(f"click {click_xy!r} lies outside the {cols}x{rows} frame")
    if w > cols or h > rows:
        raise ValueError(f"a {w}x{h} ROI does not fit in the {cols}x{rows} frame")
    return clip_window(cx, cy, w, h, (rows, cols))


def motion_energy(frames, *, sigma: float = 3.0) -> np.ndarray:
    """Where the scene changes: the mean absolute difference from the static background.

    The background is the per-pixel median of the frames, which a probe stepping across them
    does not occupy for long; subtracting it leaves the moving probe (paper, step 1).
    """
    stack = np.stack([as_gray_float(f, name=f"frame {i}") for i, f in enumerate(frames)])
    if len(stack) < 3:
        raise ValueError("motion differencing needs at least 3 frames")
    background = np.median(stack, axis=0)
    energy = np.mean(np.abs(stack - background), axis=0).astype(np.float32)
    return cv2.GaussianBlur(energy, (0, 0), sigma) if sigma > 0 else energy


def roi_from_motion(frames, size=200, *, sigma: float = 3.0, max_frames: int = 10) -> tuple[int, int, int, int]:
    """ROI around the moving probe found by background subtraction within ``max_frames`` frames.

    The probe is stepped along x or y at a constant step (paper, step 1); the centre of the
    strongest motion energy — where the tip sweeps new ground — centres the ROI.

    Raises
    ------
    ValueError
        Fewer than 3 frames, or nothing moves.
    """
    frames = list(frames)[:max_frames]
    energy = motion_energy(frames, sigma=sigma)
    peak = float(energy.max())
    if peak <= 1e-6 or peak < 5.0 * float(np.median(energy)) + 1e-6:
        raise ValueError("no motion found in the frames: step the probe along x or y while grabbing")
    weights = np.where(energy >= 0.5 * peak, energy, 0.0)
    ys, xs = np.nonzero(weights)
    wsum = weights[ys, xs].sum()
    cx, cy = float((xs * weights[ys, xs]).sum() / wsum), float((ys * weights[ys, xs]).sum() / wsum)
    w, h = _size(size)
    return clip_window(cx, cy, w, h, energy.shape)
