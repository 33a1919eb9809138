"""Frames as the tracker takes them: validation, float crops, and iteration over a sequence."""

from __future__ import annotations

import numpy as np

__all__ = ["as_frame", "crop", "is_roi_list", "iter_frames"]


def as_frame(frame) -> np.ndarray:
    """Validate dtype and dimensions without copying (the hot path converts only crops)."""
    arr = np.asarray(frame)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"frame must hold real gray levels (uint8, uint16 or float), got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise ValueError(f"frame must be a 2-D gray image, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError("frame is empty")
    return arr


def crop(arr, x0, y0, x1, y1) -> np.ndarray:
    """float32 copy of ``arr[y0:y1, x0:x1]``; ValueError if it holds NaN/inf."""
    out = np.asarray(arr[y0:y1, x0:x1], np.float32)
    if np.issubdtype(arr.dtype, np.floating) and not np.isfinite(out).all():
        raise ValueError("NaN or infinite pixels where the target is searched")
    return out


def iter_frames(frames):
    """``(iterator, n)`` over a (N, H, W) array or an iterable of 2-D frames (``n`` None if unknown).

    Raises
    ------
    TypeError, ValueError
        A single 2-D image, an array that is not 3-D, a path, or something not iterable.
    """
    if isinstance(frames, np.ndarray):
        if frames.ndim == 2:
            raise ValueError("frames is a single 2-D image; pass a sequence of frames or a 3-D array")
        if frames.ndim != 3:
            raise ValueError(f"a frame array must be 3-D (N, H, W), got shape {frames.shape}")
        return iter(frames), len(frames)
    if isinstance(frames, (str, bytes)):
        raise TypeError("frames must be arrays, not a path; read them with semlab.io.read_frames")
    try:
        n = len(frames)
    except TypeError:
        n = None
    try:
        return iter(frames), n
    except TypeError:
        raise TypeError(f"frames must be an iterable of 2-D arrays or a 3-D array, got {type(frames).__name__}") from None


def is_roi_list(roi) -> bool:
    """Whether ``roi`` is a list of ROIs (several targets) rather than one ``(x, y, w, h)``."""
    try:
        first = roi[0]
    except (TypeError, IndexError, KeyError):
        return False
    return not np.isscalar(first)
