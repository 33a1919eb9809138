"""Checking frames and regions of interest before any algorithm sees them.

Every entry point of the tracker funnels its input through :func:`as_gray_float` and
:func:`check_roi`, so bad input fails here with a message that names the problem instead of
deep inside OpenCV.
"""

from __future__ import annotations

import numpy as np

__all__ = ["as_gray_float", "check_roi", "clip_window", "roi_centre"]


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
