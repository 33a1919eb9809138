"""Choosing the region of interest around the probe tip (Ru et al. 2012, "Contour Template
Identification", step 1): by a click near the tip, or by motion differencing while the probe steps.

Every entry point of the tracker funnels its input through :func:`as_gray_float` and
:func:`check_roi`, so bad input fails here with a message that names the problem instead of
deep inside OpenCV.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

__all__ = ["MotionROI", "as_gray_float", "check_roi", "clip_window", "find_motion_roi", "motion_energy",
           "roi_centre", "roi_from_click", "roi_from_motion"]


def as_gray_float(frame, *, name: str = "frame") -> np.ndarray:
    """Return ``frame`` as a C-contiguous float32 2-D array, or raise a clear error.

    Parameters
    ----------
    frame : (M, N) array_like
        uint8, uint16, signed integer or float gray levels.
    name : str
        Used in error messages.

    Returns
    -------
    (M, N) ndarray of float32

    Raises
    ------
    TypeError
        Not an array of real numbers (bool, complex, object, str).
    ValueError
        Not 2-D (an RGB frame must be converted to gray first), empty, or holding NaN/inf.
    """
    arr = np.asarray(frame)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"{name} must hold real gray levels (uint8, uint16 or float), got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] in (3, 4):
        raise ValueError(f"{name} has shape {arr.shape}: an RGB(A) frame; convert it to gray first "
                         "(e.g. semlab.io.read_image does)")
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D gray image, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    out = np.ascontiguousarray(arr, dtype=np.float32)
    if not np.isfinite(out).all():
        raise ValueError(f"{name} holds NaN or infinite pixels")
    return out


def check_roi(roi, shape, *, min_size: int = 8, name: str = "roi") -> tuple[int, int, int, int]:
    """Validate an ROI ``(x, y, w, h)`` against an image of ``shape`` (rows, cols).

    Raises
    ------
    ValueError
        If the ROI is malformed, smaller than ``min_size`` px on a side, or not wholly
        inside the image.
    """
    try:
        x, y, w, h = (round(float(v)) for v in roi)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be four numbers (x, y, w, h), got {roi!r}") from None
    rows, cols = shape[:2]
    if w < min_size or h < min_size:
        raise ValueError(f"{name} {(x, y, w, h)} is smaller than {min_size}x{min_size} px: too small to hold a contour")
    if x < 0 or y < 0 or x + w > cols or y + h > rows:
        raise ValueError(f"{name} {(x, y, w, h)} is not wholly inside the {cols}x{rows} image")
    return x, y, w, h


def roi_centre(roi) -> tuple[float, float]:
    """Centre point of ``(x, y, w, h)`` with pixel centres at integer coordinates."""
    x, y, w, h = roi
    return x + (w - 1) / 2.0, y + (h - 1) / 2.0


def clip_window(cx: float, cy: float, w: int, h: int, shape) -> tuple[int, int, int, int]:
    """A ``w`` x ``h`` window centred near ``(cx, cy)``, shifted (not shrunk) to lie inside ``shape``.

    If the image is smaller than the window, the window is the whole image.
    """
    rows, cols = shape[:2]
    w, h = min(int(w), cols), min(int(h), rows)
    x0 = round(cx - (w - 1) / 2.0)
    y0 = round(cy - (h - 1) / 2.0)
    x0 = min(max(x0, 0), cols - w)
    y0 = min(max(y0, 0), rows - h)
    return x0, y0, w, h


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


class MotionROI(NamedTuple):
    """An ROI found by motion differencing, and the frame it belongs to.

    Attributes
    ----------
    roi : (x, y, w, h)
        Around the tip as it is in frame ``frame_index``: the probe has moved between the frames, so
        the ROI holds the tip in that frame only.
    frame_index : int
        Index, in the frames given, of the frame the ROI was found on (the last frame used).
    """

    roi: tuple[int, int, int, int]
    frame_index: int


def roi_from_motion(frames, size=200, *, sigma: float = 3.0, max_frames: int = 10) -> tuple[int, int, int, int]:
    """ROI around the tip of the moving probe in the last frame used (paper, step 1).

    The ROI belongs to ``frames[min(len(frames), max_frames) - 1]``: apply it to that frame, not to the
    first one, where the tip was elsewhere. :func:`find_motion_roi` returns the ROI with that index; this
    function returns the ROI alone (parameters, errors: as there).
    """
    return find_motion_roi(frames, size, sigma=sigma, max_frames=max_frames).roi


def find_motion_roi(frames, size=200, *, sigma: float = 3.0, max_frames: int = 10) -> MotionROI:
    """ROI around the tip of the moving probe, found by background subtraction (paper, step 1).

    The probe is stepped along x or y at a constant step while frames are grabbed; the
    unchanged background (the per-pixel median of the frames) is subtracted from the last frame,
    which leaves the ground the probe newly covers or uncovers: a band along its moving edges
    that reaches the image border where the probe enters, and a blob at its front. The tip is
    the point of that region farthest from where it touches the border (or, if it does not,
    its centroid). The paper finds the ROI "in less than 10 image frames": at most
    ``max_frames`` frames are used.

    Parameters
    ----------
    frames : sequence of (M, N) array_like
        At least 3 frames, the probe stepping between them.
    size : int or (int, int)
        ROI width and height.
    sigma : float
        Gaussian smoothing of the difference image, px.
    max_frames : int
        Frames used (the first ones).

    Returns
    -------
    MotionROI
        ``roi`` (x, y, w, h) around the tip in the last frame used, and that frame's index
        ``frame_index``.

    Raises
    ------
    ValueError
        Fewer than 3 frames, or nothing moves.
    """
    frames = list(frames)[:max_frames]
    stack = np.stack([as_gray_float(f, name=f"frame {i}") for i, f in enumerate(frames)])
    if len(stack) < 3:
        raise ValueError("motion differencing needs at least 3 frames")
    background = np.median(stack, axis=0)
    change = np.abs(stack[-1] - background)
    change = cv2.GaussianBlur(change, (0, 0), sigma) if sigma > 0 else change
    peak = float(change.max())
    if peak <= 1e-6 or peak < 5.0 * float(np.median(change)) + 1e-6:
        raise ValueError("no motion found in the frames: step the probe along x or y while grabbing")
    level = max(0.3 * peak, 3.0 * float(np.median(change)))
    mask = (change >= level).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    ys, xs = np.nonzero(labels == biggest)
    rows, cols = change.shape
    edge = (xs <= 1) | (ys <= 1) | (xs >= cols - 2) | (ys >= rows - 2)
    if edge.any():
        ex, ey = xs[edge].mean(), ys[edge].mean()
        k = int(np.argmax((xs - ex) ** 2 + (ys - ey) ** 2))
        cx, cy = float(xs[k]), float(ys[k])
    else:
        wts = change[ys, xs]
        cx, cy = float(xs @ wts / wts.sum()), float(ys @ wts / wts.sum())
    w, h = _size(size)
    return MotionROI(clip_window(cx, cy, w, h, change.shape), len(stack) - 1)
