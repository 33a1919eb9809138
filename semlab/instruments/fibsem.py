"""A FIB/SEM through OpenFIBSEM (``fibsem`` on PyPI): one API over Thermo Fisher AutoScript, TESCAN,
Zeiss and Odemis microscopes, with an offline ``DemoMicroscope``.

- :class:`FibsemMicroscope`: the :class:`~semlab.protocols.Microscope` protocol (also
  :class:`~semlab.protocols.TimedMicroscope` and :class:`~semlab.protocols.ScaledMicroscope`) over a
  connected fibsem microscope: frames from ``acquire_image``, the pixel size from each image's
  metadata, the frame period from the image settings and then as measured between frames.
- :class:`FibsemManipulator`: the :class:`~semlab.protocols.Positioner` protocol over its manipulator,
  relative moves in its RAW coordinates (x, y seen by the electron beam; x, z by the ion beam).
- :func:`connect`: ``fibsem.utils.setup_session`` with semlab's defaults (the Demo by default).

``fibsem`` is an optional extra: ``pip install "semlab[fibsem]"``. This module imports without it;
using anything in it without it raises an ImportError that says so.
"""

from __future__ import annotations

import copy
import importlib
import math
import statistics
import tempfile
import time
from collections import deque

import numpy as np

from semlab.protocols import as_finite

__all__ = ["DEFAULT_RESOLUTION_NM", "FibsemManipulator", "FibsemMicroscope", "connect", "require_fibsem"]

_NM_PER_M = 1e9
#: Smallest relative move the adapter sends when the manipulator's resolution is not given. OpenFIBSEM
#: does not report one; closed-loop FIB/SEM needles (e.g. Thermo Fisher EasyLift, Kleindiek) resolve
#: a few nm, so 1 nm only suppresses numerically tiny commands. Set it from your datasheet.
DEFAULT_RESOLUTION_NM = 1.0
#: Frame intervals kept for the measured frame period (a median over the last ones).
PERIOD_WINDOW = 16


def require_fibsem():
    """The ``fibsem`` package, or an ImportError that names the extra to install."""
    try:
        return importlib.import_module("fibsem")
    except ImportError as err:
        raise ImportError('semlab.instruments.fibsem needs OpenFIBSEM: pip install "semlab[fibsem]" '
                          f"(or pip install fibsem); importing it failed: {err}") from err


def _structures():
    require_fibsem()
    return importlib.import_module("fibsem.structures")


def _beam_type(beam_type):
    BeamType = _structures().BeamType
    if isinstance(beam_type, BeamType):
        return beam_type
    try:
        return BeamType[str(beam_type).upper()]
    except KeyError:
        raise ValueError(f"beam_type must be one of {[b.name for b in BeamType]}, got {beam_type!r}") from None


def scan_time_s(image_settings) -> float:
    """Beam-on time (s) of one frame: dwell x pixels x line and frame integration passes."""
    width, height = image_settings.resolution
    passes = (image_settings.line_integration or 1) * (image_settings.frame_integration or 1)
    return float(image_settings.dwell_time) * int(width) * int(height) * passes


def connect(manufacturer: str = "Demo", ip_address: str | None = None, *, session_path=None,
            config_path=None, setup_logging: bool = False):
    """Connect to a microscope through ``fibsem.utils.setup_session``.

    Parameters
    ----------
    manufacturer : str
        ``"Demo"`` (offline), ``"Thermo"``, ``"Tescan"``, ... (fibsem's names).
    ip_address : str, optional
        The microscope PC; default from fibsem's configuration.
    session_path : path, optional
        Where fibsem writes its session files; default a new temporary folder (fibsem's own default
        is inside its installed package).
    config_path : path, optional
        A fibsem microscope configuration file.
    setup_logging : bool
        Let fibsem configure Python logging (it writes a log file in ``session_path``).

    Returns
    -------
    (microscope, settings)
        fibsem's ``FibsemMicroscope`` and ``MicroscopeSettings``.
    """
    require_fibsem()
    utils = importlib.import_module("fibsem.utils")
    if session_path is None:
        session_path = tempfile.mkdtemp(prefix="semlab-fibsem-")
    return utils.setup_session(session_path=str(session_path), config_path=config_path,
                               setup_logging=setup_logging, ip_address=ip_address,
                               manufacturer=manufacturer)


class FibsemMicroscope:
    """Frames from a connected fibsem microscope, through :class:`semlab.protocols.Microscope`.

    Parameters
    ----------
    microscope : fibsem.microscope.FibsemMicroscope
        Connected (e.g. from :func:`connect`).
    beam_type : {"ELECTRON", "ION"} or fibsem BeamType
        Which column images; it overrides ``image_settings.beam_type``.
    image_settings : fibsem.structures.ImageSettings, optional
        Resolution, dwell time, field width, ...; default: the microscope's current settings for the
        beam. Copied: later changes to the object passed in do not reach the adapter.

    Attributes
    ----------
    image_settings : ImageSettings
        What every :meth:`grab` asks for.
    last_image : fibsem.structures.FibsemImage or None
        The last frame with its metadata.
    last_frame_time : float or None
        The last frame's time stamp (the microscope state's, else the host's clock when it returned).
    nominal_frame_period : float
        The scan time the image settings imply (no fly-back or transfer).
    """

    def __init__(self, microscope, *, beam_type="ELECTRON", image_settings=None):
        self._beam = _beam_type(beam_type)
        if image_settings is None:
            image_settings = microscope.get_imaging_settings(beam_type=self._beam)
        settings = copy.deepcopy(image_settings)
        settings.beam_type = self._beam
        self.microscope = microscope
        self.image_settings = settings
        self.nominal_frame_period = scan_time_s(settings)
        if not self.nominal_frame_period > 0:
            raise ValueError(f"image settings imply a scan time of {self.nominal_frame_period} s "
                             "(dwell time and resolution must be > 0)")
        self.last_image = None
        self.last_frame_time = None
        self._intervals = deque(maxlen=PERIOD_WINDOW)
        self._pixel_size_nm = None

    @property
    def beam_type(self) -> str:
        return self._beam.name

    @property
    def frame_period(self) -> float:
        """Seconds per frame: the median interval between the last frames once two have been grabbed,
        else the scan time of the image settings."""
        if self._intervals:
            return float(statistics.median(self._intervals))
        return self.nominal_frame_period

    @property
    def pixel_size_nm(self) -> float | None:
        """nm per px from the last image's metadata (before any frame: field width / columns)."""
        if self._pixel_size_nm is not None:
            return self._pixel_size_nm
        hfw, cols = self.image_settings.hfw, self.image_settings.resolution[0]
        return float(hfw) * _NM_PER_M / int(cols) if hfw else None

    def grab(self) -> np.ndarray:
        """Acquire one frame (``acquire_image``) and return its pixels as a 2-D array.

        Raises whatever fibsem raises when the acquisition fails (a servo treats that as a frame it
        cannot see and holds).
        """
        image = self.microscope.acquire_image(image_settings=self.image_settings)
        data = np.asarray(image.data)
        meta = getattr(image, "metadata", None)
        stamp = getattr(getattr(meta, "microscope_state", None), "timestamp", None)
        stamp = float(stamp) if isinstance(stamp, (int, float)) and math.isfinite(stamp) else time.time()
        if self.last_frame_time is not None and stamp > self.last_frame_time:
            self._intervals.append(stamp - self.last_frame_time)
        self.last_frame_time = stamp
        ps = getattr(meta, "pixel_size", None)
        if ps is not None and ps.x and math.isfinite(ps.x) and ps.x > 0:
            self._pixel_size_nm = float(ps.x) * _NM_PER_M
        self.last_image = image
        return data

    def describe(self) -> dict:
        """The instrument and imaging conditions, JSON-ready (for provenance)."""
        info = getattr(getattr(self.microscope, "system", None), "info", None)
        s = self.image_settings
        return {"adapter": "semlab.instruments.fibsem.FibsemMicroscope",
                "fibsem_version": getattr(require_fibsem(), "__version__", "unknown"),
                "manufacturer": getattr(info, "manufacturer", None), "model": getattr(info, "model", None),
                "serial_number": getattr(info, "serial_number", None), "beam_type": self.beam_type,
                "resolution": list(s.resolution), "dwell_time_s": s.dwell_time, "hfw_m": s.hfw,
                "pixel_size_nm": self.pixel_size_nm, "nominal_frame_period_s": self.nominal_frame_period,
                "measured_frame_period_s": self.frame_period if self._intervals else None}


class FibsemManipulator:
    """A fibsem microscope's manipulator through :class:`semlab.protocols.Positioner`.

    Moves are relative, in the manipulator's RAW coordinates (metres in fibsem, nm here), along two
    of its axes: ``("x", "y")`` for the electron beam's view (fibsem's own convention), ``("x", "z")``
    for the ion beam's.

    Parameters
    ----------
    microscope : fibsem.microscope.FibsemMicroscope
        Connected, with the manipulator available (and inserted, to be seen).
    axes : (str, str)
        The two RAW axes driven by ``move_by(d0, d1)``.
    resolution_nm : float
        Smallest move the servo sends (:data:`DEFAULT_RESOLUTION_NM` unless told).
    limits : ((lo, hi), (lo, hi)) or None
        Travel in nm along ``axes`` in the encoder's RAW frame; moves that would leave it are refused.
    """

    def __init__(self, microscope, *, axes=("x", "y"), resolution_nm: float = DEFAULT_RESOLUTION_NM,
                 limits=None):
        require_fibsem()
        if not microscope.is_available("manipulator"):
            raise RuntimeError("this microscope's configuration has no manipulator enabled "
                               "(fibsem: system.manipulator.enabled)")
        axes = tuple(axes)
        if len(axes) != 2 or len(set(axes)) != 2 or not set(axes) <= {"x", "y", "z"}:
            raise ValueError(f"axes must be two different RAW axes of x, y, z; got {axes!r}")
        res = as_finite(resolution_nm, "resolution_nm")
        if res < 0:
            raise ValueError(f"resolution_nm must be >= 0, got {resolution_nm!r}")
        if limits is not None:
            limits = tuple(tuple(as_finite(v, "limit") for v in pair) for pair in limits)
            if len(limits) != 2 or any(len(p) != 2 or p[0] >= p[1] for p in limits):
                raise ValueError(f"limits must be ((lo, hi), (lo, hi)) nm with lo < hi, got {limits!r}")
        self.microscope = microscope
        self.axes = axes
        self.resolution_nm = res
        self.limits = limits

    @property
    def position_nm(self) -> tuple[float, float] | None:
        """The encoder reading along :attr:`axes` in nm; None when it is not in RAW coordinates."""
        pos = self.microscope.get_manipulator_position()
        if pos is None or str(getattr(pos, "coordinate_system", "RAW") or "RAW").upper() != "RAW":
            return None
        return tuple(float(getattr(pos, a)) * _NM_PER_M for a in self.axes)

    def move_by(self, dx_nm: float, dy_nm: float) -> None:
        """Relative move by ``(dx_nm, dy_nm)`` along :attr:`axes` (``move_manipulator_relative``, RAW).

        Raises
        ------
        ValueError
            NaN/inf, or a move that leaves :attr:`limits`.
        RuntimeError
            The driver reports a failure (some return the exception instead of raising it).
        """
        d = [as_finite(v, f"manipulator move along {a}", "refusing to drive blind")
             for v, a in zip((dx_nm, dy_nm), self.axes, strict=True)]
        if self.limits is not None:
            pos = self.position_nm
            if pos is None:
                raise ValueError("limits are set but the manipulator's position cannot be read in RAW "
                                 "coordinates: refusing to move without checking them")
            for a, p, v, (lo, hi) in zip(self.axes, pos, d, self.limits, strict=True):
                if not lo <= p + v <= hi:
                    raise ValueError(f"moving {a} by {v:.4g} nm from {p:.6g} nm leaves the travel "
                                     f"[{lo:.6g}, {hi:.6g}] nm")
        structures = _structures()
        move = structures.FibsemManipulatorPosition(coordinate_system="RAW",
                                                    **{a: v / _NM_PER_M for a, v in zip(self.axes, d, strict=True)})
        result = self.microscope.move_manipulator_relative(move)
        if isinstance(result, BaseException):
            raise RuntimeError(f"the manipulator move {move} failed: {result}") from result  # noqa: TRY004

    def describe(self) -> dict:
        return {"adapter": "semlab.instruments.fibsem.FibsemManipulator", "axes": list(self.axes),
                "coordinate_system": "RAW", "resolution_nm": self.resolution_nm,
                "limits_nm": None if self.limits is None else [list(p) for p in self.limits]}
