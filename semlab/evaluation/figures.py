"""The corpus's figure: RMSE / Cramér–Rao bound per family, semlab beside each peer, on a log scale."""

from __future__ import annotations

import numpy as np

from .summary import summarise

__all__ = ["plot_corpus", "plot_family_frames"]

#: Ratios are drawn clipped to this range (a lost track can be 1000x the bound); an infinite median
#: (no position on most seeds) is a triangle at the top.
_YLIM = (0.5, 3000.0)


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
        raw = s["rmse_over_crb_median"].to_numpy(float)
        med = np.clip(raw, lo, hi)
        p90 = np.clip(s["rmse_over_crb_p90"].to_numpy(float), lo, hi)
        ax.vlines(x, med, p90, color=f"C{j}", lw=2, alpha=0.6)
        shown = np.isfinite(raw)
        (markers[trk],) = ax.plot(x[shown], med[shown], "o" if trk == "semlab" else "s", color=f"C{j}",
                                  ms=6 if trk == "semlab" else 4, ls="none", label=trk)
        # a median that is infinite: the tracker refused or never gave a position on most seeds
        ax.plot(x[~shown], np.full((~shown).sum(), hi), "v", color=f"C{j}", ms=7, ls="none")
    ax.axhline(1.0, color="k", lw=1)
    for t in targets:
        ax.axhline(t, color="k", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_ylim(*_YLIM)
    ax.set_xticks(np.arange(len(families)))
    ax.set_xticklabels(families, rotation=30, ha="right")
    ax.set_ylabel("RMSE / Cramér–Rao bound\n(median, bar to p90; ▼ never started)")
    ax.legend(ncol=len(trackers), fontsize="small", loc="upper left")
    return {"ax": ax, "markers": markers}


def plot_family_frames(sequences: dict, axes=None, frame: int = 0):
    """One frame of every family with its ROI (rectangle) and the ground-truth point (cross).

    Parameters
    ----------
    sequences : dict
        family name -> :class:`semlab.sim.Sequence` (e.g. from
        :func:`semlab.evaluation.make_family_sequence`).
    axes : sequence of matplotlib Axes or None
        One per family (a new figure with a grid of 4 columns when None).
    frame : int
        Which frame to show.

    Returns
    -------
    list of Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    names = list(sequences)
    if axes is None:
        rows = -(-len(names) // 4)
        _, grid = plt.subplots(rows, 4, figsize=(14, 2.9 * rows), layout="constrained")
        axes = list(np.ravel(grid))
        for ax in axes[len(names):]:
            ax.axis("off")
    for ax, name in zip(axes, names):
        seq = sequences[name]
        img = np.asarray(seq.frames[frame], float)
        lo, hi = np.percentile(img, [0.5, 99.5])  # float frames (semi-real) are not bounded by 255
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
        x, y, w, h = seq.roi
        ax.add_patch(Rectangle((x - 0.5, y - 0.5), w, h, fill=False, color="C1", lw=1))
        t = seq.truth.loc[frame]
        ax.plot(t["x"], t["y"], "+", color="C3", ms=8)
        ax.set_title(f"{name} (seed {seq.meta.get('seed', '?')})", fontsize="small")
        ax.set_xticks([])
        ax.set_yticks([])
    return list(axes[: len(names)])
