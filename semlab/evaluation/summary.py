"""The corpus's summary: per family and tracker, the spread over seeds of RMSE / bound and the failure rates.

Order statistics over the sequences (seeds) of one family: the median, the 90th percentile
(linear interpolation) and the worst of ``rmse_over_crb``; a sequence on which a tracker never gave
a position counts as infinitely bad there. Rates are means over the sequences (a family's
sequences have equal length, so this is also the rate over its frames).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = ["SUMMARY_COLUMNS", "summarise", "summary_markdown"]

SUMMARY_COLUMNS = ["family", "tracker", "n_sequences", "rmse_over_crb_median", "rmse_over_crb_p90",
                   "rmse_over_crb_worst", "std_over_crb_median", "lost_fraction", "silent_fraction",
                   "silent_sequences", "flagged_fraction", "coverage95", "ms_per_frame", "n_errors"]


def _ratios(s: pd.Series) -> np.ndarray:
    v = s.to_numpy(float)
    return np.where(np.isfinite(v), v, np.inf)


def _p90(r: np.ndarray) -> float:
    """90th percentile (linear interpolation, as ``np.percentile``), infinite values included as
    infinitely large: infinite as soon as the interpolation gives an infinite value any weight."""
    v = np.sort(np.asarray(r, float))
    if v.size == 0:
        return math.nan
    position = 0.9 * (v.size - 1)
    lo, hi = math.floor(position), math.ceil(position)
    weight = position - lo
    if math.isinf(v[lo]) or (weight > 0 and math.isinf(v[hi])):
        return math.inf
    return float(v[lo] + weight * (v[hi] - v[lo]))


def summarise(results: pd.DataFrame) -> pd.DataFrame:
    """One row per family x tracker of :func:`semlab.evaluate`'s output (families and trackers in its order).

    Columns: ``family, tracker, n_sequences``, ``rmse_over_crb_median / _p90 / _worst``,
    ``std_over_crb_median`` (the still probe's figure), ``lost_fraction``, ``silent_fraction``
    (means over the sequences), ``silent_sequences`` (fraction of the sequences with any silent
    frame), ``flagged_fraction``, ``coverage95`` (mean, NaN without sigmas), ``ms_per_frame``
    (median) and ``n_errors`` (runs cut short by a tracker error).
    """
    rows = []
    families = list(dict.fromkeys(results["family"]))
    trackers = list(dict.fromkeys(results["tracker"]))
    for fam in families:
        for trk in trackers:
            g = results[(results["family"] == fam) & (results["tracker"] == trk)]
            if g.empty:
                continue
            r = _ratios(g["rmse_over_crb"])
            s = _ratios(g["std_over_crb"])
            rows.append({
                "family": fam, "tracker": trk, "n_sequences": len(g),
                "rmse_over_crb_median": float(np.median(r)),
                "rmse_over_crb_p90": _p90(r),
                "rmse_over_crb_worst": float(np.max(r)),
                "std_over_crb_median": float(np.median(s)),
                "lost_fraction": float(g["lost_fraction"].mean()),
                "silent_fraction": float(g["silent_fraction"].mean()),
                "silent_sequences": float((g["silent_fraction"] > 0).mean()),
                "flagged_fraction": float(g["flagged_fraction"].mean()),
                "coverage95": float(g["coverage95"].mean()) if g["coverage95"].notna().any() else float("nan"),
                "ms_per_frame": float(g["ms_per_frame"].median()),
                "n_errors": int((g["error"].fillna("") != "").sum()) if "error" in g else 0,
            })
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


def _f(v, fmt="{:.2f}"):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return fmt.format(v)


def summary_markdown(summary: pd.DataFrame) -> str:
    """The summary as a Markdown table: semlab beside each peer, family by family."""
    head = ("| family | tracker | RMSE/CRB median | p90 | worst | std/CRB median | lost | silent | "
            "seqs with silent | ms/frame |")
    lines = [head, "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for _, r in summary.iterrows():
        lines.append(
            f"| {r.family} | {r.tracker} | {_f(r.rmse_over_crb_median)} | {_f(r.rmse_over_crb_p90)} | "
            f"{_f(r.rmse_over_crb_worst)} | {_f(r.std_over_crb_median)} | {_f(100 * r.lost_fraction, '{:.1f} %')} | "
            f"{_f(100 * r.silent_fraction, '{:.1f} %')} | {_f(100 * r.silent_sequences, '{:.0f} %')} | "
            f"{_f(r.ms_per_frame, '{:.1f}')} |")
    return "\n".join(lines)
