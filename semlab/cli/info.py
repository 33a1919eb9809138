"""``semlab info``: what semlab reads from image files (size, dtype, frames, pixel size)."""

from __future__ import annotations

import json

from semlab.cli._common import EXIT_OK, _fmt_ps, _read

INFO_DESCRIPTION = """\
Print what semlab reads from image files: format, number of frames, size, pixel type, grey-level
range and the pixel size in nm with where it came from (FEI/Thermo Fisher or Zeiss TIFF metadata,
ImageJ calibration), or 'unknown'. FILE may be a file, a folder or a quoted glob pattern; a folder
or pattern is described as one sequence.
"""


def _cmd_info(args) -> int:
    import numpy as np

    reports = []
    for item in args.files:
        seq = _read([item])
        n, h, w = seq.frames.shape
        formats = sorted(set(seq.meta["format"].values()))
        ps = seq.pixel_size_nm
        report = {
            "input": item,
            "files": len(seq.files),
            "format": ", ".join(formats),
            "vendor": seq.meta.get("vendor"),
            "frames": n,
            "width_px": w,
            "height_px": h,
            "dtype": str(seq.frames.dtype),
            "min": float(np.min(seq.frames)),
            "max": float(np.max(seq.frames)),
            "pixel_size_nm": ps,
            "pixel_size_source": seq.pixel_size_source,
            "field_of_view_um": None if ps is None else [w * ps / 1e3, h * ps / 1e3],
        }
        if seq.meta.get("converted"):
            report["converted"] = seq.meta["converted"]
        if seq.meta.get("fps"):
            report["fps"] = seq.meta["fps"]
        reports.append(report)
    if args.json:
        print(json.dumps(reports if len(reports) > 1 else reports[0], indent=1))
        return EXIT_OK
    for r in reports:
        fmt = r["format"] + (f" ({r['vendor']} metadata)" if r["vendor"] else "")
        lines = [
            r["input"],
            f"  format      {fmt}" + (f", {r['files']} files" if r["files"] > 1 else ""),
            f"  frames      {r['frames']}" + (f" at {r['fps']:.4g} fps" if r.get("fps") else ""),
            f"  size        {r['width_px']} x {r['height_px']} px (width x height)",
            f"  dtype       {r['dtype']} (grey levels {r['min']:g} to {r['max']:g})",
            f"  pixel size  {_fmt_ps(r['pixel_size_nm'], r['pixel_size_source'])}",
        ]
        if r["field_of_view_um"]:
            fw, fh = r["field_of_view_um"]
            lines.append(f"  field       {fw:.4g} x {fh:.4g} um")
        if r.get("converted"):
            lines.append(f"  converted   {r['converted']}")
        print("\n".join(lines))
    return EXIT_OK
