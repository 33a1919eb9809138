"""A recording played back through :class:`semlab.protocols.Microscope`.

:class:`ReplayMicroscope` hands out the frames of a recorded sequence (anything
:func:`semlab.read_frames` reads, or an array of frames) one :meth:`~ReplayMicroscope.grab` at a
time, stamped at the recording's frame period, so the tracker, the widgets and the evaluation run on
a user's own recordings through the same protocol as on a live instrument.
"""

from __future__ import annotations

import math
import time

import numpy as np

from semlab.protocols import as_finite

__all__ = ["RecordingExhausted", "ReplayMicroscope"]


class RecordingExhausted(EOFError):
    """Every frame of the recording has been played (and ``loop`` is off)."""


class ReplayMicroscope:
    """Play a recorded sequence as a microscope.

    Parameters
    ----------
    source : FrameSequence, (N, H, W) array_like, or what :func:`semlab.read_frames` reads
        The recording (files, a folder, a glob pattern, a list of these).
    frame_period : float, optional
        Seconds between frames; default from the recording's metadata (``meta["frame_period"]``, or
        ``meta["sim_meta"]["frame_period"]`` of a synthetic sample), else a ValueError asks for it.
    pixel_size_nm : float, optional
        Overrides the recording's pixel size.
    loop : bool
        Start again after the last frame instead of raising :class:`RecordingExhausted`.
    realtime : bool
        Pace :meth:`grab` to the frame period on the host's clock (a live-looking stream for widgets);
        off, frames come as fast as they are asked for and only the time stamps follow the period.

    Attributes
    ----------
    frame_index : int
        Frames grabbed so far.
    last_frame_time : float or None
        Recording time (s) of the last grabbed frame, ``index * frame_period``.
    """

    def __init__(self, source, *, frame_period: float | None = None, pixel_size_nm: float | None = None,
                 loop: bool = False, realtime: bool = False):
        frames, meta, ps = _load(source)
        if frames.ndim != 3 or frames.shape[0] == 0:
            raise ValueError(f"a recording must hold at least one 2-D frame, got shape {frames.shape}")
        if frame_period is None:  # read_frames' metadata, or a synthetic sample's simulator record
            frame_period = meta.get("frame_period", meta.get("sim_meta", {}).get("frame_period"))
        if frame_period is None:
            raise ValueError("the recording does not say its frame period: give frame_period (s)")
        period = as_finite(frame_period, "frame_period")
        if not period > 0:
            raise ValueError(f"frame_period must be > 0 s, got {frame_period!r}")
        if pixel_size_nm is not None:
            ps = as_finite(pixel_size_nm, "pixel_size_nm")
            if not ps > 0:
                raise ValueError(f"pixel_size_nm must be > 0, got {pixel_size_nm!r}")
        self.frames = frames
        self.meta = meta
        self.frame_period = period
        self.pixel_size_nm = ps
        self.loop = bool(loop)
        self.realtime = bool(realtime)
        self.frame_index = 0
        self.last_frame_time = None
        self._start = None

    def __len__(self) -> int:
        return int(self.frames.shape[0])

    def grab(self) -> np.ndarray:
        """The next recorded frame (a read-only view).

        Raises
        ------
        RecordingExhausted
            After the last frame, unless ``loop``.
        """
        k = self.frame_index
        n = len(self)
        if k >= n and not self.loop:
            raise RecordingExhausted(f"the recording has {n} frames and all have been played")
        if self.realtime:
            now = time.monotonic()
            if self._start is None:
                self._start = now
            wait = self._start + k * self.frame_period - now
            if wait > 0:
                time.sleep(wait)
        frame = self.frames[k % n].view()
        frame.flags.writeable = False
        self.frame_index = k + 1
        self.last_frame_time = k * self.frame_period
        return frame

    def __iter__(self):
        """The frames still to be played (so ``semlab.track(replay, roi)`` reads through the protocol);
        endless with ``loop``."""
        while self.loop or self.frame_index < len(self):
            yield self.grab()

    def rewind(self) -> None:
        """Play from the first frame again."""
        self.frame_index = 0
        self.last_frame_time = None
        self._start = None


def _load(source):
    """(frames, meta, pixel_size_nm) from a FrameSequence, an array or read_frames' inputs."""
    from semlab.io import FrameSequence, read_frames

    if isinstance(source, np.ndarray):  # one frame or a stack; other shapes are refused by the caller
        arr = source[None] if source.ndim == 2 else source
        return arr, {}, None
    if not isinstance(source, FrameSequence):
        source = read_frames(source)
    ps = source.pixel_size_nm
    ps = float(ps) if ps is not None and math.isfinite(ps) else None
    return np.asarray(source.frames), dict(source.meta), ps
