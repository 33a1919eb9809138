"""The corpus's figure: RMSE / Cramér–Rao bound per family, semlab beside each peer, on a log scale."""

from __future__ import annotations

import numpy as np

from .summary import summarise

__all__ = ["plot_corpus"]

#: Ratios are drawn clipped to this range (a lost track can be 1000x the bound).
_YLIM = (0.5, 300.0)


def plot_corpus(results, ax=None, *, targets=(2.0,)):
    """Median RMSE / bound per family and tracker, with a bar from the median to the 90th percentile.

    Parameters
    ----------
    results : pandas.DataFrame
        :func:`semlab.evaluate`'s output (or :func:`semlab.evaluation.summarise`'s).
    ax : matplotlib Axes or None
        Drawn on (the current axes when None).
    targets : tuple of float
        Dashed horizontal lines (the issue's 2x target); the bound itself is the line at 1.

    Returns
    -------
    dict
        ``{"ax": ax, "markers": {tracker: Line2D}}``.
    """
    import matplotlib.pyplot as plt

    ax = plt.gca() if ax is None else ax
    summary = results if "rmse_over_crb_median" in results else summarise(results)
    families = list(dict.fromkeys(summary["family"]))
    trackers = list(dict.fromkeys(summary["tracker"]))
    width = 0.8 / max(len(trackers), 1)
    markers = {}
    lo, hi = _YLIM
    for j, trk in enumerate(trackers):
        s = summary[summary["tracker"] == trk].set_index("family").reindex(families)
        x = np.arange(len(families)) - 0.4 + width * (j + 0.5)
        med = np.clip(s["rmse_over_crb_median"].to_numpy(float), lo, hi)
        p90 = np.clip(s["rmse_over_crb_p90"].to_numpy(float), lo, hi)
        ax.vlines(x, med, p90, color=f"C{j}", lw=2, alpha=0.6)
        (markers[trk],) = ax.plot(x, med, "o" if trk == "semlab" else "s", color=f"C{j}", ms=6 if trk == "semlab" else 4,
                                  ls="none", label=trk)
    ax.axhline(1.0, color="k", lw=1)
    for t in targets:
        ax.axhline(t, color="k", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_ylim(*_YLIM)
    ax.set_xticks(np.arange(len(families)))
    ax.set_xticklabels(families, rotation=30, ha="right")
    ax.set_ylabel("RMSE / Cramér–Rao bound (median, bar to p90)")
    ax.legend(ncol=len(trackers), fontsize="small", loc="upper left")
    return {"ax": ax, "markers": markers}
