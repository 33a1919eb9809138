"""The tracking player: step or play through a tracked sequence (paper, Fig. 7)."""

from __future__ import annotations

import numpy as np

from ..plots import figure_png, plot_track_xy, show_frame
from ..roi import roi_centre
from ..template import identify_contour_template
from ._common import _SLIDER_STYLE, _layout, _png_figure


def player_state(tracks, frame, truth=None) -> dict:
    """The tracked (and true) position at ``frame``, and the displacement error there.

    The error follows the team's convention:
    ``(x_track - x_track[0]) - (x_true - x_true[0])`` (and y), NaN when the tracker lost the target.

    Parameters
    ----------
    tracks : DataFrame
        ``frame, x, y`` (and ``score``, ``ok``), from :func:`semlab.track`.
    frame : int
    truth : DataFrame, optional
        ``frame, x, y`` of the true tip.

    Returns
    -------
    dict
        ``frame, x, y, score, ok`` and with a truth ``x_true, y_true, err_x, err_y``.
    """
    t = tracks.set_index("frame")
    if frame not in t.index:
        raise ValueError(f"frame {frame} is not in the track (frames {t.index.min()}..{t.index.max()})")
    row = t.loc[frame]
    ok = bool(row["ok"]) if "ok" in t else True
    out = {"frame": int(frame), "x": float(row["x"]), "y": float(row["y"]),
           "score": float(row["score"]) if "score" in t else float("nan"), "ok": ok}
    if truth is not None:
        g = truth.set_index("frame")
        first = t.index.min()
        xt, yt = float(g.loc[frame, "x"]), float(g.loc[frame, "y"])
        out.update(x_true=xt, y_true=yt)
        if ok:
            out["err_x"] = (out["x"] - float(t.loc[first, "x"])) - (xt - float(g.loc[first, "x"]))
            out["err_y"] = (out["y"] - float(t.loc[first, "y"])) - (yt - float(g.loc[first, "y"]))
        else:
            out["err_x"] = out["err_y"] = float("nan")
    return out


class TrackingPlayer:
    """Step or play through a tracked sequence (paper, Fig. 7).

    Parameters
    ----------
    frames : (N, H, W) array_like or sequence of 2-D arrays
    tracks : DataFrame
        ``frame, x, y, score, ok`` from :func:`semlab.track` (one target).
    truth : DataFrame, optional
        ``frame, x, y`` of the true tip (simulation): drawn as a cyan ``+`` and a dashed path, and the
        displacement error is shown.
    roi : (x, y, w, h), optional
        The ROI the track started from; its box follows the tracked position.
    template : ContourTemplate, optional
        Its contour is drawn where the tracker put it; default: identified in ``roi`` of frame 0 with
        ``template_params`` (:func:`semlab.template.identify_contour_template`).
    template_params : dict, optional
    pixel_size_nm : float, optional
        Shown in the readout (error in nm).
    interval_ms : int
        Play speed (ms per frame).

    Attributes
    ----------
    shown : dict
        :func:`player_state` of the frame on screen.
    controls : dict of ipywidgets
        ``frame`` (IntSlider) and ``play`` (Play, linked to it in the browser).
    image, readout, ui : ipywidgets
    """

    def __init__(self, frames, tracks, truth=None, *, roi=None, template=None, template_params=None,
                 pixel_size_nm=None, interval_ms=200):
        import ipywidgets as w

        self.frames = frames
        if "target" in tracks and tracks["target"].nunique() > 1:
            raise ValueError("tracks holds several targets; pass one, e.g. tracks[tracks.target == 0]")
        self.tracks = tracks.reset_index(drop=True)
        self.truth = truth
        self.pixel_size_nm = pixel_size_nm
        self.roi = None if roi is None else tuple(int(v) for v in roi)
        if template is None and self.roi is not None:
            x, y, w_, h = self.roi
            try:
                template = identify_contour_template(np.asarray(frames[0])[y:y + h, x:x + w_],
                                                     **(template_params or {}))
            except ValueError:
                template = None
        self.template = template
        f0, f1 = int(self.tracks["frame"].min()), int(self.tracks["frame"].max())
        if f1 >= len(frames):
            raise ValueError(f"the track reaches frame {f1} but there are only {len(frames)} frames")
        self._first = f0
        slider = w.IntSlider(value=f0, min=f0, max=f1, step=1, description="frame", style=_SLIDER_STYLE,
                             layout=_layout("520px"), continuous_update=False)
        play = w.Play(value=f0, min=f0, max=f1, step=1, interval=int(interval_ms), description="play")
        w.jslink((play, "value"), (slider, "value"))
        self.controls = {"frame": slider, "play": play}
        self.image = w.Image(format="png", layout=w.Layout(width="720px"))
        self.readout = w.HTML()
        self.readout.add_class("semlab-player-readout")
        self.ui = w.VBox([w.HBox([play, slider]), self.readout, self.image])
        slider.observe(lambda ch: self.show(ch["new"]), "value")
        self.show(f0)

    def show(self, frame: int) -> dict:
        """Draw ``frame`` with the contour and the track so far; return :attr:`shown`."""
        st = player_state(self.tracks, int(frame), self.truth)
        self.shown = st
        ax = _png_figure(1, 1, (8, 6), left=0.08, bottom=0.08, top=0.95)[0, 0]
        kwargs = {}
        if st["ok"] and self.roi is not None:
            x0, y0, w_, h = self.roi
            cx, cy = roi_centre(self.roi)
            dx, dy = st["x"] - cx, st["y"] - cy
            kwargs["roi"] = (x0 + dx, y0 + dy, w_, h)
            if self.template is not None:
                kwargs["contour"] = self.template.points
                kwargs["contour_offset"] = (x0 + dx, y0 + dy)
        if self.truth is not None:
            kwargs["points"] = [(st["x_true"], st["y_true"])]
        show_frame(np.asarray(self.frames[st["frame"]]), ax, title=f"frame {st['frame']}", **kwargs)
        plot_track_xy(self.tracks, ax, upto=st["frame"], truth=self.truth)
        self.image.value = figure_png(ax.figure)
        self.readout.value = self._readout(st)
        return st

    def _readout(self, st):
        parts = [f"<b>frame</b> {st['frame']}"]
        if st["ok"]:
            parts.append(f"<b>x, y</b> {st['x']:.2f}, {st['y']:.2f} px")
        else:
            parts.append("<b>lost</b> (ok=False)")
        if np.isfinite(st["score"]):
            parts.append(f"<b>score</b> {st['score']:.2f}")
        if "err_x" in st and np.isfinite(st["err_x"]):
            e = f"<b>error</b> {st['err_x']:+.2f}, {st['err_y']:+.2f} px"
            if self.pixel_size_nm:
                s = self.pixel_size_nm
                e += f" ({st['err_x'] * s:+.0f}, {st['err_y'] * s:+.0f} nm)"
            parts.append(e)
        return "<div>" + " · ".join(parts) + "</div>"

    def _repr_mimebundle_(self, **kwargs):
        return self.ui._repr_mimebundle_(**kwargs)
