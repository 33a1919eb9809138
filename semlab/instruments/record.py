"""A servo run saved with its provenance: the table as CSV and a JSON sidecar beside it.

Like ``semlab track``'s sidecar: what ran (semlab and fibsem versions, the command's parameters), on
what (the instrument's own description, the calibration), and the CSV's SHA-256, so a result can be
traced back and checked years later.
"""

from __future__ import annotations

import hashlib
import json
import os
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd

from semlab.environment import describe as describe_environment

__all__ = ["save_run"]


def _describe(obj) -> dict:
    """An instrument's own ``describe()`` when it has one, else its class."""
    describe = getattr(obj, "describe", None)
    if callable(describe):
        return describe()
    return {"class": f"{type(obj).__module__}.{type(obj).__qualname__}"}


def save_run(table: pd.DataFrame, out, *, microscope=None, positioner=None, calibration=None, roi=None,
             target=None, params=None, **extra) -> Path:
    """Write ``table`` to ``out`` (CSV) and ``out.json`` (its provenance); returns the sidecar's path.

    Parameters
    ----------
    table : DataFrame
        E.g. :func:`semlab.positioning.move_positioner_to`'s result.
    out : path
        The CSV; its folder is created.
    microscope, positioner
        Described by their ``describe()`` (the fibsem adapters have one) or their class.
    calibration : PositionerCalibration, optional
    roi, target, params
        What the run was asked to do.
    **extra
        More JSON-ready entries (e.g. ``ground_truth`` on the Demo).
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False, float_format="%.6f", lineterminator="\n")
    record = {
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "cwd": os.getcwd(),
        "csv": out.name,
        "sha256": hashlib.sha256(out.read_bytes()).hexdigest(),
        "columns": list(table.columns),
        "n_rows": len(table),
        "n_ok": int(table["ok"].sum()) if "ok" in table else None,
        "roi": None if roi is None else [float(v) for v in roi],
        "target_px": None if target is None else [float(v) for v in target],
        "params": params or {},
        "table_attrs": dict(table.attrs),
        "microscope": None if microscope is None else _describe(microscope),
        "positioner": None if positioner is None else _describe(positioner),
        "calibration": None if calibration is None else calibration.as_dict(),
        "conventions": "x, y: the ROI centre point, frame px (pixel centres at integer coordinates, x "
                       "right, y down); dx_nm, dy_nm: the relative move sent after the frame, in the "
                       "positioner's own axes",
        "environment": describe_environment(extra=("semlab", "fibsem")),
        **extra,
    }
    sidecar = out.with_name(out.name + ".json")
    sidecar.write_text(json.dumps(record, indent=1, default=str) + "\n")
    return sidecar
