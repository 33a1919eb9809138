"""A tracker's error budget: how much of its error each part of the scene makes.

On one sequence a tracker's error splits into the part every frame shares, its bias (frame 0's
own error, a static background's pull), and the frame-to-frame scatter about it. The same seeds run
with parts of the scene taken out (``without``, :data:`~semlab.evaluation.families.ABLATIONS`) and
put in units of the Cramér–Rao bound of the scene as drawn tell what each part costs. With the noise
taken out (``"noise"``) what is left is the tracker's systematic error (sampled edges interpolated,
the scene's model); the noise's own share of the scatter is then ``sqrt(scatter² − floor²)``.
An estimator at the bound scatters by 1 (and its bias, frame 0's error, is 1 too).

:func:`sequence_errors` reduces a per-frame table of :func:`~semlab.evaluation.evaluate` to bias and
scatter per sequence, :func:`error_budget` puts the runs of several conditions over their bound, and
:func:`budget_table` gives the median over seeds; ``benchmarks/bench_error_budget.py`` runs it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

__all__ = ["SKIP_FRAMES", "budget_table", "error_budget", "sequence_errors"]

#: Frames left out at the start of each sequence: the template is averaged over its first frames,
#: and their errors (a young template's) are not the steady state the budget describes.
SKIP_FRAMES = 5
#: A sequence needs this many ok frames for its scatter to mean something (a sample sd from
#: 10 values is within ±25 % of the truth at 1 sd).
MIN_FRAMES = 10
KEYS = ["family", "seed", "tracker"]


def sequence_errors(per_frame: pd.DataFrame, skip: int = SKIP_FRAMES) -> pd.DataFrame:
    """Bias and scatter of each sequence's errors.

    Parameters
    ----------
    per_frame : DataFrame
        :data:`~semlab.evaluation.PER_FRAME_COLUMNS` (``evaluate(..., per_frame=True)``).
    skip : int
        Frames ``< skip`` are left out (:data:`SKIP_FRAMES`).

    Returns
    -------
    DataFrame
        One row per ``family, seed, tracker``: ``n`` (ok, visible frames used), ``bias_x, bias_y``
        (their mean error, px) and ``scatter_x, scatter_y`` (the sd about it, px); NaN with fewer
        than :data:`MIN_FRAMES` frames.
    """
    used = per_frame[(per_frame["frame"] >= skip) & per_frame["ok"].astype(bool)
                     & per_frame["visible"].astype(bool)].dropna(subset=["ex", "ey"])
    rows = []
    for key, g in used.groupby(KEYS, sort=False):
        enough = len(g) >= MIN_FRAMES
        rows.append(dict(zip(KEYS, key), n=len(g),
                         bias_x=g["ex"].mean() if enough else np.nan, bias_y=g["ey"].mean() if enough else np.nan,
                         scatter_x=g["ex"].std(ddof=1) if enough else np.nan,
                         scatter_y=g["ey"].std(ddof=1) if enough else np.nan))
    return pd.DataFrame(rows, columns=[*KEYS, "n", "bias_x", "bias_y", "scatter_x", "scatter_y"])


def error_budget(runs: Mapping[str, pd.DataFrame], bound: pd.DataFrame, skip: int = SKIP_FRAMES) -> pd.DataFrame:
    """Each condition's bias and scatter over the bound of the scenes as drawn.

    Parameters
    ----------
    runs : mapping of str to DataFrame
        Condition name (e.g. ``"as drawn"``, ``"without noise"``) -> its per-frame table.
    bound : DataFrame
        ``family, seed, crb_x_px, crb_y_px``: the one-frame bound of the scenes as drawn (the rows of
        :func:`~semlab.evaluation.evaluate` without ablation). Every condition is put over this
        bound, so that the conditions compare in one unit.
    skip : int
        As :func:`sequence_errors`.

    Raises
    ------
    ValueError
        ``runs`` is empty.

    Returns
    -------
    DataFrame
        One row per condition and sequence: ``condition, family, seed, tracker, n``,
        ``scatter_over_crb`` and ``bias_over_crb`` (the RMS over the two axes of each axis's scatter
        or bias over its bound).
    """
    if not runs:
        raise ValueError("error_budget needs at least one run (a condition and its per-frame table)")
    crb = bound[["family", "seed", "crb_x_px", "crb_y_px"]].drop_duplicates(["family", "seed"])
    parts = []
    for condition, per_frame in runs.items():
        seq = sequence_errors(per_frame, skip).merge(crb, on=["family", "seed"], how="inner")
        seq.insert(0, "condition", condition)
        seq["scatter_over_crb"] = _rms_over(seq, "scatter")
        seq["bias_over_crb"] = _rms_over(seq, "bias")
        parts.append(seq[["condition", *KEYS, "n", "scatter_over_crb", "bias_over_crb"]])
    return pd.concat(parts, ignore_index=True)


def budget_table(budget: pd.DataFrame, floor: str | None = None) -> pd.DataFrame:
    """Medians over the seeds per family and condition (:func:`error_budget`'s rows).

    With ``floor`` (the condition without the noise), the column ``noise_share`` is the scatter's
    part the noise makes, ``sqrt(scatter² − floor²)`` of the medians (NaN where the floor is larger).
    """
    table = (budget.groupby(["family", "tracker", "condition"], sort=False)[["scatter_over_crb", "bias_over_crb"]]
             .median().reset_index())
    if floor is not None:
        floors = table[table["condition"] == floor].set_index(["family", "tracker"])["scatter_over_crb"]
        f = table.set_index(["family", "tracker"]).index.map(floors.get).astype(float)
        s = table["scatter_over_crb"].to_numpy()
        with np.errstate(invalid="ignore"):
            table["noise_share"] = np.where(s >= f, np.sqrt(s ** 2 - f ** 2), np.nan)
    return table


def _rms_over(seq: pd.DataFrame, part: str) -> pd.Series:
    return np.sqrt(0.5 * ((seq[f"{part}_x"] / seq["crb_x_px"]) ** 2 + (seq[f"{part}_y"] / seq["crb_y_px"]) ** 2))
