"""SEM optics: pixel size from magnification and the beam blur.

The paper's rig (Hitachi S-4000, Matrox frame grabber, 640x480 at 13 Hz) images
66 nm/px at 3,000x and 6.6 nm/px at 30,000x ("Tracking Performance" and Fig. 1).
"""

from __future__ import annotations

import math

__all__ = ["REFERENCE_FIELD_NM", "beam_blur_sigma_px", "pixel_size_from_magnification"]

#: Field of view width (nm) times magnification for the paper's 640-px-wide frame:
#: 66 nm/px * 640 px * 3,000 = 126.72 mm, i.e. a 12.672 cm reference display width.
REFERENCE_FIELD_NM = 66.0 * 640 * 3000.0


def pixel_size_from_magnification(magnification: float, width_px: int = 640) -> float:
    """Pixel size of an SEM frame from the nominal magnification.

    Parameters
    ----------
    magnification : float
        Nominal SEM magnification (e.g. ``3000`` for 3,000x). Must be > 0.
    width_px : int, optional
        Frame width in pixels; the field of view is fixed by the magnification, so a
        wider frame has smaller pixels. Default 640 (the paper's frame).

    Returns
    -------
    float
        Pixel size in nm/px: 66.0 at 3,000x and 6.6 at 30,000x for 640 px.

    Raises
    ------
    ValueError
        If ``magnification`` or ``width_px`` is not a positive finite number.

    Examples
    --------
    >>> pixel_size_from_magnification(3000)
    66.0
    """
    mag = float(magnification)
    if not math.isfinite(mag) or mag <= 0:
        raise ValueError(f"magnification must be a positive finite number, got {magnification!r}")
    if int(width_px) != width_px or width_px <= 0:
        raise ValueError(f"width_px must be a positive integer, got {width_px!r}")
    return REFERENCE_FIELD_NM / (mag * int(width_px))


def beam_blur_sigma_px(pixel_size_nm: float, spot_sigma_nm: float = 10.0,
                       scan_sigma_px: float = 0.5) -> float:
    """Standard deviation of the Gaussian point-spread function, in pixels.

    The blur combines the electron probe (a Gaussian of ``spot_sigma_nm``) with the
    integration of the signal while the beam sweeps one pixel and the detector's
    bandwidth (together ``scan_sigma_px``), added in quadrature.

    Parameters
    ----------
    pixel_size_nm : float
        Pixel size in nm/px (> 0).
    spot_sigma_nm : float, optional
        Beam spot standard deviation in nm; 10 nm suits a field-emission SEM at video rate.
    scan_sigma_px : float, optional
        Blur from pixel integration/bandwidth in px.

    Returns
    -------
    float
        Blur sigma in px (0.52 px at 66 nm/px, 1.6 px at 6.6 nm/px with the defaults).
    """
    if not pixel_size_nm > 0:
        raise ValueError(f"pixel_size_nm must be > 0, got {pixel_size_nm!r}")
    if spot_sigma_nm < 0 or scan_sigma_px < 0:
        raise ValueError("spot_sigma_nm and scan_sigma_px must be >= 0")
    return math.hypot(spot_sigma_nm / pixel_size_nm, scan_sigma_px)
