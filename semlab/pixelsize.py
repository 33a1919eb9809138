"""The pixel size of an SEM image from its vendor TIFF metadata (read through :mod:`tifffile`).

* FEI / Thermo Fisher (tags 34680/34682, ``TiffFile.fei_metadata``): ``[Scan] PixelWidth`` in metres;
  then ``[EScan]``/``[IScan] PixelWidth``; then the horizontal field width (``[Scan] HorFieldsize`` or
  ``[EBeam]``/``[IBeam]``/``[Beam] HFW``) divided by ``[Image] ResolutionX`` (or the image width).
* Zeiss (``CZ_SEM`` tag 34118, ``TiffFile.sem_metadata``): ``ap_image_pixel_size`` (or
  ``ap_pixel_size``) with its unit; then the field width ``ap_width`` divided by the image width.
* ImageJ-calibrated TIFFs (``unit`` nm/um/micron with ``XResolution``) as a last resort.
"""

from __future__ import annotations

import math
import re

__all__ = ["tiff_pixel_size"]


def _num(v) -> float | None:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) and x > 0 else None


_UNIT_TO_NM = {"pm": 1e-3, "nm": 1.0, "um": 1e3, "mm": 1e6, "m": 1e9, "cm": 1e7}


def _unit_scale(unit: str) -> float | None:
    u = unit.strip().lower().replace("µ", "u").replace("μ", "u").replace("micron", "um")
    if u.endswith("um") or (len(u) >= 2 and u.endswith("m") and not u[-2].isascii()):
        return 1e3  # micro sign, possibly mis-decoded (e.g. 'Âµm')
    return _UNIT_TO_NM.get(u)


def _zeiss_length_nm(entry) -> float | None:
    """A CZ_SEM entry ``(label, value, unit)`` or ``(label, 'value unit')`` → nm."""
    if not isinstance(entry, tuple) or len(entry) < 2:
        return None
    value = entry[1]
    unit = entry[2] if len(entry) > 2 else None
    if unit is None:
        m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*(\S+)\s*", str(value))
        if not m:
            return None
        value, unit = m.group(1), m.group(2)
    v = _num(value)
    scale = _unit_scale(str(unit))
    if v is None or scale is None:
        return None
    return v * scale


def _fei_pixel_size(md: dict, width_px: int) -> tuple[float | None, str]:
    for section in ("Scan", "EScan", "IScan"):
        v = _num((md.get(section) or {}).get("PixelWidth"))
        if v is not None:
            return v * 1e9, f"FEI metadata [{section}] PixelWidth"
    hfw = None
    where = ""
    for section, key in (
        ("Scan", "HorFieldsize"),
        ("EBeam", "HFW"),
        ("IBeam", "HFW"),
        ("Beam", "HFW"),
    ):
        hfw = _num((md.get(section) or {}).get(key))
        if hfw is not None:
            where = f"[{section}] {key}"
            break
    if hfw is not None:
        res = _num((md.get("Image") or {}).get("ResolutionX"))
        if res is not None:
            return hfw * 1e9 / res, f"FEI metadata {where} / [Image] ResolutionX"
        return hfw * 1e9 / width_px, f"FEI metadata {where} / image width"
    return None, "FEI metadata without PixelWidth or HFW"


def _zeiss_pixel_size(md: dict, width_px: int) -> tuple[float | None, str]:
    for key in ("ap_image_pixel_size", "ap_pixel_size"):
        v = _zeiss_length_nm(md.get(key))
        if v is not None and v > 0:
            return v, f"Zeiss CZ_SEM metadata {key}"
    w = _zeiss_length_nm(md.get("ap_width"))
    if w is not None and w > 0:
        return w / width_px, "Zeiss CZ_SEM metadata ap_width / image width"
    return None, "Zeiss CZ_SEM metadata without pixel size or field width"


def _imagej_pixel_size(tif, page) -> tuple[float | None, str]:
    ij = tif.imagej_metadata or {}
    unit = ij.get("unit")
    if not unit:
        return None, ""
    scale = _unit_scale(str(unit).replace("\\u00B5", "u"))
    tag = page.tags.get("XResolution")
    if scale is None or tag is None:
        return None, ""
    num, den = tag.value
    px_per_unit = _num(num / den if den else None)
    if px_per_unit is None:
        return None, ""
    return scale / px_per_unit, "ImageJ calibration (unit, XResolution)"


def tiff_pixel_size(tif, page, width_px: int) -> tuple[float | None, str, dict]:
    """The pixel size (nm) a TIFF's vendor metadata gives, where it was read, and the metadata.

    Parameters
    ----------
    tif : tifffile.TiffFile
        The open file.
    page : tifffile.TiffPage
        Its first page (the ImageJ calibration's ``XResolution``).
    width_px : int
        The image width, for a field width without a resolution.

    Returns
    -------
    (float or None, str, dict)
        The pixel size in nm (None: not in the metadata), a sentence naming its source (or why
        there is none), and ``vendor`` plus the vendor's metadata dict for ``FrameSequence.meta``.
    """
    if tif.is_fei:
        md = tif.fei_metadata or {}
        ps, src = _fei_pixel_size(md, width_px)
        return ps, src, {"vendor": "FEI/Thermo Fisher", "fei_metadata": md}
    if tif.is_sem:
        md = tif.sem_metadata or {}
        ps, src = _zeiss_pixel_size(md, width_px)
        return ps, src, {"vendor": "Zeiss", "sem_metadata": md}
    if tif.is_imagej:
        ps, src = _imagej_pixel_size(tif, page)
        if ps is not None:
            return ps, src, {"vendor": "ImageJ"}
    return None, "no pixel size in the TIFF metadata", {}
