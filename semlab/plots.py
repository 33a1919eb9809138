"""Thin matplotlib helpers for the paper's figures.

Every function draws on ``ax`` (or the current axes when ``ax is None``), never calls ``plt.show()``,
and returns a dict of the artists it made so a caller can restyle them. Image axes are in px with
pixel centres at integer coordinates (``frame[y, x]``, x to the right, y down); where a pixel size is
known a second axis or a label gives nm.

The maths lives elsewhere (:mod:`semlab.template`, :mod:`semlab.edges`, :mod:`semlab.tracking`,
:mod:`semlab.hysteresis`, :mod:`semlab.control`); this module only shows its results.
"""

from __future__ import annotations

import io

import numpy as np

__all__ = [
    "OUTLIER_FENCE",
    "add_nm_axes",
    "error_histogram",
    "figure_png",
    "mark_missing",
    "outlier_fences",
    "plot_hysteresis",
    "plot_step_response",
    "plot_track",
    "plot_track_xy",
    "robust_ylim",
    "show_edges",
    "show_frame",
    "template_steps",
]


def _ax(ax):
    if ax is None:
        import matplotlib.pyplot as plt

        ax = plt.gca()
    return ax


#: Tukey's "far out" fence: a value more than this many interquartile ranges beyond the quartiles is an
#: outlier (Tukey 1977). 3 rather than the usual 1.5 keeps a skewed but genuine spread on the axes.
OUTLIER_FENCE = 3.0


def outlier_fences(values, *, k: float = OUTLIER_FENCE, log: bool = False) -> tuple[float, float]:
    """Tukey's fences ``(Q1 - k IQR, Q3 + k IQR)`` of the finite values (of their log10 when ``log``).

    Returns the fences in the values' own units; ``(nan, nan)`` without finite (positive, for ``log``)
    values.
    """
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v) & (v > 0)] if log else v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    if log:
        v = np.log10(v)
    q1, q3 = np.percentile(v, [25, 75])
    lo, hi = q1 - k * (q3 - q1), q3 + k * (q3 - q1)
    return (float(10**lo), float(10**hi)) if log else (float(lo), float(hi))


def _xy(line):
    """A line's x, y as floats (categorical x, e.g. level names, as the positions matplotlib gave them)."""
    xy = np.asarray(line.get_xydata(), float).reshape(-1, 2)
    return xy[:, 0], xy[:, 1]


def _line_data(ax):
    """x, y of every data line on ``ax`` (not the marker lines the helpers below add)."""
    for line in ax.get_lines():
        if line.get_gid() in ("semlab-outlier", "semlab-missing"):
            continue
        x, y = _xy(line)
        if x.size:
            yield line, x, y


def robust_ylim(ax=None, *, k: float = OUTLIER_FENCE, pad: float = 0.08, include=(), unit: str = "",
                max_labels: int = 6):
    """Y limits from the lines' inliers, with every outlier marked at the edge it lies beyond.

    A few wild values (a tracker that jumped 300 px) would otherwise stretch the axis until the others
    are flat. The limits span the values inside :func:`outlier_fences` of all lines on ``ax`` (and
    ``include``, e.g. a reference level that must stay visible), padded by ``pad`` of the span; each
    value beyond them is drawn as a triangle on that edge, in its line's colour, labelled with its value.

    Parameters
    ----------
    ax : matplotlib Axes, optional
    k : float
        Fence in interquartile ranges (:data:`OUTLIER_FENCE`).
    pad : float
        Margin, as a fraction of the inliers' span (of decades on a log axis).
    include : sequence of float
        Values the limits must contain.
    unit : str
        Appended to the outliers' labels.
    max_labels : int
        Per line, only the ``max_labels`` values farthest out are labelled (every outlier gets its marker).

    Returns
    -------
    dict
        ``limits`` (lo, hi), ``outliers`` (list of (x, y) beyond them), ``markers`` (the artists).
    """
    ax = _ax(ax)
    log = ax.get_yscale() == "log"
    data = list(_line_data(ax))
    ys = np.concatenate([y for _, _, y in data] + [np.asarray(include, float)]) if data else np.asarray(include, float)
    f_lo, f_hi = outlier_fences(ys, k=k, log=log)
    if not np.isfinite(f_lo):
        return {"limits": ax.get_ylim(), "outliers": [], "markers": []}
    keep = ys[np.isfinite(ys) & (ys >= f_lo) & (ys <= f_hi) & ((ys > 0) if log else True)]
    keep = np.concatenate([keep, np.asarray(include, float)])
    lo, hi = float(np.min(keep)), float(np.max(keep))
    if log:
        a, b = np.log10(lo), np.log10(hi)
        m = pad * max(b - a, 0.3)
        lo, hi = 10 ** (a - m), 10 ** (b + m)
    else:
        m = pad * max(hi - lo, 1e-9 + 0.05 * max(abs(lo), abs(hi), 1.0))
        lo, hi = lo - m, hi + m
    ax.set_ylim(lo, hi)
    out = {"limits": (lo, hi), "outliers": [], "markers": []}
    for line, x, y in data:
        beyond = np.isfinite(y) & ((y < lo) | (y > hi))
        if not beyond.any():
            continue
        xo, yo = x[beyond], y[beyond]
        above = yo > hi
        edges = np.where(above, hi, lo)
        for mark, side in (("^", above), ("v", ~above)):
            if side.any():
                (marker,) = ax.plot(xo[side], edges[side], mark, color=line.get_color(), markersize=8,
                                    linestyle="none", clip_on=False, gid="semlab-outlier", zorder=5)
                out["markers"].append(marker)
        distance = np.maximum(yo - hi, lo - yo)
        for j in np.argsort(-distance)[:max_labels]:
            out["markers"].append(ax.annotate(
                f"{yo[j]:.3g}{unit}", (xo[j], edges[j]), textcoords="offset points",
                xytext=(4, -10 if above[j] else 4), fontsize="x-small", color=line.get_color()))
        out["outliers"] += [(float(a), float(b)) for a, b in zip(xo, yo)]
    return out


def mark_missing(ax=None, *, label: str = "no value", lines=None):
    """Mark the points a line has no value at (NaN) with a cross on the bottom edge, in the line's colour.

    matplotlib silently leaves NaN out of a line: a tracker that lost every frame at one dose simply
    vanishes from a sweep. Each NaN point of ``lines`` (default: every data line on ``ax``) is drawn as
    an ``x`` at the bottom of the axes, at its own x, and the first one carries ``label`` in the legend.

    Returns
    -------
    dict
        ``missing`` (list of (line label, x)) and ``markers``.
    """
    ax = _ax(ax)
    import matplotlib.transforms as mtransforms

    trans = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
    out = {"missing": [], "markers": []}
    chosen = list(_line_data(ax)) if lines is None else [(ln, *_xy(ln)) for ln in lines]
    first = True
    for line, x, y in chosen:
        gone = np.isfinite(x) & ~np.isfinite(y)
        if not gone.any():
            continue
        (marker,) = ax.plot(x[gone], np.full(gone.sum(), 0.03), "x", color=line.get_color(), markersize=9,
                            markeredgewidth=2, transform=trans, clip_on=False, gid="semlab-missing",
                            label=label if first else None, zorder=5)
        first = False
        out["missing"] += [(line.get_label(), float(v)) for v in x[gone]]
        out["markers"].append(marker)
    return out


def _extent(shape, origin=(0, 0)):
    """imshow extent putting pixel (i, j)'s centre at (origin_x + j, origin_y + i)."""
    h, w = shape[:2]
    x0, y0 = origin
    return (x0 - 0.5, x0 + w - 0.5, y0 + h - 0.5, y0 - 0.5)


def add_nm_axes(ax, pixel_size_nm, *, which="both"):
    """Secondary axes in nm on an image in px (top for x, right for y).

    Parameters
    ----------
    ax : matplotlib Axes
    pixel_size_nm : float or None
        nm per px; ``None`` adds nothing.
    which : {"both", "x", "y"}

    Returns
    -------
    dict
        ``{"x": secondary x axis, "y": secondary y axis}`` (those made).
    """
    out = {}
    if not pixel_size_nm:
        return out
    s = float(pixel_size_nm)
    fwd, inv = (lambda v: v * s), (lambda v: v / s)
    if which in ("both", "x"):
        out["x"] = ax.secondary_xaxis("top", functions=(fwd, inv))
        out["x"].set_xlabel("x (nm)")
    if which in ("both", "y"):
        out["y"] = ax.secondary_yaxis("right", functions=(fwd, inv))
        out["y"].set_ylabel("y (nm)")
    return out


def show_frame(frame, ax=None, *, roi=None, contour=None, contour_offset=(0.0, 0.0), points=None,
               origin=(0, 0), pixel_size_nm=None, title=None, cmap="gray", roi_color="y",
               contour_color="r", vmin=None, vmax=None):
    """A frame (or crop) with an ROI box and a contour overlay (the paper's Figs. 1-2).

    Parameters
    ----------
    frame : (M, N) array_like
    ax : matplotlib Axes, optional
    roi : (x, y, w, h), optional
        Drawn as a box around the pixels it holds.
    contour : (K, 2) array_like, optional
        Contour points ``(x, y)``; ``contour_offset`` is added (e.g. the ROI's top-left corner to
        go from ROI to frame coordinates).
    points : (P, 2) array_like, optional
        Marked with ``+`` (e.g. true tip positions).
    origin : (x, y)
        Frame coordinates of ``frame[0, 0]`` when ``frame`` is a crop.
    pixel_size_nm : float, optional
        Adds nm axes (top/right).
    title : str, optional
    cmap, roi_color, contour_color, vmin, vmax
        Styling.

    Returns
    -------
    dict
        ``image`` and, if drawn, ``roi``, ``contour``, ``points``, ``nm_axes``.
    """
    import matplotlib.patches as mpatches

    ax = _ax(ax)
    img = np.asarray(frame)
    out = {"image": ax.imshow(img, cmap=cmap, extent=_extent(img.shape, origin), vmin=vmin, vmax=vmax,
                              interpolation="nearest")}
    if roi is not None:
        x, y, w, h = roi
        out["roi"] = ax.add_patch(mpatches.Rectangle((x - 0.5, y - 0.5), w, h, fill=False,
                                                     edgecolor=roi_color, linewidth=1.2))
    if contour is not None and len(contour):
        c = np.asarray(contour, float).reshape(-1, 2) + np.asarray(contour_offset, float)
        c = np.vstack([c, c[:1]])
        (out["contour"],) = ax.plot(c[:, 0], c[:, 1], "-", color=contour_color, linewidth=1.0)
    if points is not None:
        p = np.asarray(points, float).reshape(-1, 2)
        (out["points"],) = ax.plot(p[:, 0], p[:, 1], "c+", markersize=10, markeredgewidth=1.5)
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    if title:
        ax.set_title(title)
    nm = add_nm_axes(ax, pixel_size_nm)
    if nm:
        out["nm_axes"] = nm
    return out


def show_edges(edges, ax=None, *, origin=(0, 0), title=None, thresholds=None):
    """A binary edge map (the paper's Fig. 3), with its edge-pixel count in the title.

    Parameters
    ----------
    edges : (M, N) array_like of bool
    thresholds : (T_l, T_h), optional
        Shown in the title.

    Returns
    -------
    dict
        ``image``.
    """
    ax = _ax(ax)
    e = np.asarray(edges, bool)
    out = {"image": ax.imshow(e, cmap="gray", extent=_extent(e.shape, origin), interpolation="nearest")}
    label = title or "Canny edges"
    label += f" ({int(e.sum())} px"
    if thresholds is not None:
        label += f", T_l={thresholds[0]:.0f}, T_h={thresholds[1]:.0f}"
    ax.set_title(label + ")")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    return out


def template_steps(roi_image, template, axes=None, *, origin=(0, 0)):
    """The contour-template identification steps side by side (the paper's Fig. 2b-f).

    Parameters
    ----------
    roi_image : (h, w) array_like
        The ROI.
    template : semlab.template.ContourTemplate
        From :func:`semlab.template.identify_contour_template` on ``roi_image``.
    axes : sequence of 5 Axes, optional
        Default: a new 1x5 figure.
    origin : (x, y)
        Frame coordinates of the ROI's top-left pixel (so the axes read in frame px).

    Returns
    -------
    dict
        ``axes`` and ``images``.
    """
    if axes is None:
        import matplotlib.pyplot as plt

        _, axes = plt.subplots(1, 5, figsize=(16, 3.6), constrained_layout=True)
    panels = [(roi_image, "(b) ROI"), (template.smoothed, "(c) Gaussian smoothed"),
              (template.binary, f"(d) threshold {template.threshold:.0f}"),
              (template.morphed, "(e) eroded + dilated"), (template.mask, "(f) contour template")]
    images = []
    for ax, (img, title) in zip(axes, panels):
        images.append(ax.imshow(np.asarray(img), cmap="gray", extent=_extent(np.shape(img), origin),
                                interpolation="nearest"))
        ax.set_title(title)
        ax.set_xlabel("x (px)")
    axes[0].set_ylabel("y (px)")
    c = np.vstack([template.points, template.points[:1]]) + np.asarray(origin)
    axes[0].plot(c[:, 0], c[:, 1], "r-", linewidth=1.0)
    return {"axes": list(axes), "images": images}


def plot_track(track, truth=None, ax=None, *, coord="x", frame_period=None, pixel_size_nm=None,
               label="tracked", truth_label="truth"):
    """Tracked displacement along one coordinate against frame (or time), beside the truth (Fig. 7).

    Parameters
    ----------
    track : DataFrame
        ``frame, x, y`` (and ``ok``).
    truth : DataFrame, optional
        ``frame, x, y`` of the true tip; drawn as a displacement from its first row.
    coord : {"x", "y"}
    frame_period : float, optional
        Seconds per frame: the abscissa becomes time.
    pixel_size_nm : float, optional
        Adds an nm axis on the right.

    Returns
    -------
    dict
        ``track``, ``truth`` (if given), ``nm_axis``.
    """
    ax = _ax(ax)
    d = track.reset_index(drop=True)
    ok = d["ok"].to_numpy(bool) if "ok" in d else np.ones(len(d), bool)
    s = np.where(ok, d[coord] - d[coord].iloc[0], np.nan)
    t = d["frame"].to_numpy(float) * (frame_period or 1.0)
    out = {}
    (out["track"],) = ax.plot(t, s, ".-", markersize=3, linewidth=1, label=label)
    if truth is not None:
        g = truth.reset_index(drop=True)
        (out["truth"],) = ax.plot(g["frame"].to_numpy(float) * (frame_period or 1.0),
                                  g[coord] - g[coord].iloc[0], "k--", linewidth=1, label=truth_label)
    ax.set_xlabel("time (s)" if frame_period else "frame")
    ax.set_ylabel(f"{coord} displacement (px)")
    if pixel_size_nm:
        s_nm = float(pixel_size_nm)
        out["nm_axis"] = ax.secondary_yaxis("right", functions=(lambda v: v * s_nm, lambda v: v / s_nm))
        out["nm_axis"].set_ylabel(f"{coord} displacement (nm)")
    ax.legend(loc="best")
    return out


def plot_track_xy(track, ax=None, *, upto=None, truth=None, color="orange", **kwargs):
    """The track so far as a path in the image plane (px).

    Parameters
    ----------
    track : DataFrame
        ``frame, x, y`` (and ``ok``).
    upto : int, optional
        Draw only frames ``<= upto``.
    truth : DataFrame, optional
        ``frame, x, y``: drawn as a dashed path over the same frames.

    Returns
    -------
    dict
        ``path`` and ``current`` (the last point), ``truth`` if given.
    """
    ax = _ax(ax)
    d = track if upto is None else track[track["frame"] <= upto]
    if "ok" in d:
        d = d[d["ok"].astype(bool)]
    out = {}
    (out["path"],) = ax.plot(d["x"], d["y"], "-", color=color, linewidth=1.2, **kwargs)
    (out["current"],) = ax.plot(d["x"].iloc[-1:], d["y"].iloc[-1:], "o", color=color, markersize=6,
                                markerfacecolor="none")
    if truth is not None:
        g = truth if upto is None else truth[truth["frame"] <= upto]
        (out["truth"],) = ax.plot(g["x"], g["y"], "c--", linewidth=0.8)
    return out


def error_histogram(errors, ax=None, *, bins=30, crb=None, paper_std=None, label=None,
                    pixel_size_nm=None):
    """Histogram of tracking errors (px) with the Cramér–Rao bound and the paper's figure marked.

    Parameters
    ----------
    errors : array_like
        Errors in px (NaN ignored).
    crb : float, optional
        Cramér–Rao bound (1σ, px): ±crb drawn as dotted lines.
    paper_std : float, optional
        The paper's standard deviation (px): ±paper_std drawn as dashed lines.
    pixel_size_nm : float, optional
        Adds an nm axis on top.

    Returns
    -------
    dict
        ``bars`` and the lines drawn.
    """
    ax = _ax(ax)
    e = np.asarray(errors, float)
    e = e[np.isfinite(e)]
    out = {"bars": ax.hist(e, bins=bins, alpha=0.6, label=label or f"σ = {np.std(e, ddof=1):.3f} px")[2]}
    if crb is not None:
        out["crb"] = [ax.axvline(v, color="g", linestyle=":", label="± CRB" if v > 0 else None)
                      for v in (-crb, crb)]
    if paper_std is not None:
        out["paper"] = [ax.axvline(v, color="r", linestyle="--", label="± paper σ" if v > 0 else None)
                        for v in (-paper_std, paper_std)]
    ax.set_xlabel("error (px)")
    ax.set_ylabel("frames")
    if pixel_size_nm:
        s = float(pixel_size_nm)
        out["nm_axis"] = ax.secondary_xaxis("top", functions=(lambda v: v * s, lambda v: v / s))
        out["nm_axis"].set_xlabel("error (nm)")
    ax.legend(loc="best")
    return out


def plot_hysteresis(characterisation, ax=None, *, model=None, pixel_size_nm=None):
    """Displacement against voltage by branch (the paper's Fig. 8b), with a model's branches.

    Parameters
    ----------
    characterisation : DataFrame
        ``u, displacement`` and optionally ``branch`` (from :func:`semlab.characterise_hysteresis`).
    model : object, optional
        With ``ascending(u)`` / ``descending(u)`` (a polynomial model) or ``predict(voltages)``:
        the fitted major loop is drawn over the data.
    pixel_size_nm : float, optional
        Adds an nm axis on the right.

    Returns
    -------
    dict
        ``data`` (one line per branch) and ``model`` lines.
    """
    ax = _ax(ax)
    c = characterisation
    out = {"data": [], "model": []}
    groups = c.groupby("branch", sort=False) if "branch" in c else [("measured", c)]
    for name, g in groups:
        (line,) = ax.plot(g["u"], g["displacement"], ".", markersize=4, label=str(name))
        out["data"].append(line)
    if model is not None:
        lo, hi = float(c["u"].min()), float(c["u"].max())
        u = np.linspace(lo, hi, 200)
        if hasattr(model, "ascending") and hasattr(model, "descending"):
            out["model"].append(ax.plot(u, model.ascending(u), "k-", linewidth=1, label="Pn(u) fit")[0])
            out["model"].append(ax.plot(u, model.descending(u), "k--", linewidth=1, label="Dn(u) fit")[0])
        elif hasattr(model, "predict"):
            loop = np.concatenate([u, u[::-1]])
            out["model"].append(ax.plot(loop, model.predict(loop), "k-", linewidth=1, label="model")[0])
    ax.set_xlabel("applied voltage u (V)")
    ax.set_ylabel("displacement (px)")
    if pixel_size_nm:
        s = float(pixel_size_nm)
        out["nm_axis"] = ax.secondary_yaxis("right", functions=(lambda v: v * s, lambda v: v / s))
        out["nm_axis"].set_ylabel("displacement (nm)")
    ax.legend(loc="best", fontsize="small")
    return out


def plot_step_response(response, ax=None, *, label=None, time=True, pixel_size_nm=None, target=True,
                       **kwargs):
    """A visual-servo step response (the paper's Fig. 9): displacement against time, with the target.

    Parameters
    ----------
    response : DataFrame
        ``frame, t, displacement, target`` (and ``ok``), from :func:`semlab.step_response`.
    label : str, optional
    time : bool
        Abscissa in seconds (else frames).
    pixel_size_nm : float, optional
        Adds an nm axis on the right.
    target : bool
        Draw the target as a dotted step.

    Returns
    -------
    dict
        ``response`` and ``target`` lines.
    """
    ax = _ax(ax)
    r = response.reset_index(drop=True)
    xs = (r["t"] - r["t"].iloc[0]) if time else r["frame"]
    d = r["displacement"].to_numpy(float)
    if "ok" in r:
        d = np.where(r["ok"].to_numpy(bool), d, np.nan)
    out = {}
    (out["response"],) = ax.plot(xs, d, ".-", markersize=3, linewidth=1, label=label, **kwargs)
    if target:
        (out["target"],) = ax.step(xs, r["target"], "k:", where="post", linewidth=1)
    ax.set_xlabel("time (s)" if time else "frame")
    ax.set_ylabel("displacement (px)")
    if pixel_size_nm:
        s = float(pixel_size_nm)
        out["nm_axis"] = ax.secondary_yaxis("right", functions=(lambda v: v * s, lambda v: v / s))
        out["nm_axis"].set_ylabel("displacement (nm)")
    if label:
        ax.legend(loc="best")
    return out


def figure_png(fig, *, dpi=72) -> bytes:
    """Render a figure to PNG bytes with the Agg canvas (no pyplot state, safe in any backend)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
