"""Frames as the tracker takes them: validation, float crops, and iteration over a sequence."""

from __future__ import annotations

import numpy as np

__all__ = ["GrayScale", "as_frame", "crop", "is_roi_list", "iter_frames"]

#: The gray scale every method works in: 0-255, the scale of an 8-bit SEM frame.
FULL_SCALE = 255.0
#: Float frames whose values all lie in [0, 1 + this] are taken as 0-1 encoded (``img_as_float``).
UNIT_RANGE_SLACK = 1e-6
#: Scaled gray levels within this of whole numbers are the whole numbers an 8-bit frame held.
INTEGRAL_TOLERANCE = 1e-3


class GrayScale:
    """The factor that brings a sequence's frames onto the 0-255 scale, fixed on frame 0.

    The same frames as uint8, uint16 (×257), float32 in 0-255 or float in 0-1 (what
    ``skimage.img_as_float`` gives) then give the tracker the same numbers, so the same answer: the
    noise model, the contrast checks and a manual threshold all read 0-255. Integer frames whose
    values exceed 255 are scaled by their type's full range, float frames in [0, 1] by 255; anything
    else keeps its values.
    """

    def __init__(self, factor: float = 1.0):
        self.factor = float(factor)

    @classmethod
    def of(cls, frame) -> GrayScale:
        arr = np.asarray(frame)
        if np.issubdtype(arr.dtype, np.integer):
            top = float(arr.max()) if arr.size else 0.0
            full = float(np.iinfo(arr.dtype).max)
            return cls(FULL_SCALE / full if top > FULL_SCALE else 1.0)
        if arr.size and float(np.nanmin(arr)) >= 0.0 and float(np.nanmax(arr)) <= 1.0 + UNIT_RANGE_SLACK:
            return cls(FULL_SCALE)
        return cls(1.0)

    def apply(self, arr: np.ndarray) -> np.ndarray:
        """``arr`` on the 0-255 scale (itself when the factor is 1)."""
        if self.factor == 1.0:
            return arr
        return (np.asarray(arr, np.float32) * np.float32(self.factor)).astype(np.float32)

    @staticmethod
    def as_8bit(arr: np.ndarray) -> np.ndarray:
        """``arr`` as uint8 when its values are the whole numbers 0-255 of an 8-bit frame (however
        encoded), else ``arr``: the contour identification then sees exactly the 8-bit frame."""
        if arr.dtype == np.uint8 or not arr.size:
            return arr
        values = np.asarray(arr, np.float64)
        if values.min() < 0 or values.max() > FULL_SCALE:
            return arr
        rounded = np.rint(values)
        if np.max(np.abs(values - rounded)) <= INTEGRAL_TOLERANCE:
            return rounded.astype(np.uint8)
        return arr


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
