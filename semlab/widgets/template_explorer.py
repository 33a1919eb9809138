"""The template explorer: pick the ROI and tune the contour template and the Canny edges live
(paper, Figs. 1-3). The frame overview and its click-to-frame coordinates (:func:`overview_image`,
:func:`display_to_frame`) live in ``_common``, shared with the servo panel and the target picker;
they are importable from here as well."""

from __future__ import annotations

import html
import time

import numpy as np

from ..edges import adaptive_canny_thresholds, canny_edges
from ..plots import figure_png, show_edges, show_frame
from ..roi import as_gray_float, check_roi, find_motion_roi, roi_centre, roi_from_click
from ..template import identify_contour_template, to_uint8
from ..tracking import Tracker
from ..tracking.options import CANNY_SIGMA
from ._common import (
    _SLIDER_STYLE,
    CLICK_X_CLASS,
    CLICK_Y_CLASS,
    OVERVIEW_CLASS,
    READOUT_CLASS,
    THRESHOLD_CLASS,
    _layout,
    _png_figure,
    display_to_frame,  # noqa: F401 -- re-exported: it was defined here, and may be imported from here
    overview_click,
    overview_image,
)


def explore_template(frame, roi, *, sigma=2.0, threshold=None, morph_kernel=3, morph_iterations=1,
                     choose="central", canny_sigma=CANNY_SIGMA, canny_low=None, canny_high=None) -> dict:
    """Everything the template explorer shows for one set of parameters.

    Runs :func:`semlab.template.identify_contour_template` on the ROI (paper, Fig. 2) and
    :func:`semlab.edges.canny_edges` on it (Fig. 3; adaptive thresholds by eq. 10 unless both
    ``canny_low`` and ``canny_high`` are given). A threshold that leaves no contour is not an error
    here: the answer says ``ok=False`` with the reason.

    Parameters
    ----------
    frame : (M, N) array_like
    roi : (x, y, w, h)
    sigma, threshold, morph_kernel, morph_iterations, choose
        As :func:`semlab.template.identify_contour_template` (``threshold=None``: Otsu); ``choose``
        is ``"central"`` by default, as the default tracker has it (the paper's is ``"largest"``).
    canny_sigma, canny_low, canny_high
        As :func:`semlab.edges.canny_edges`.

    Returns
    -------
    dict
        ``roi``, ``patch`` (uint8 ROI), ``template`` (ContourTemplate or None), ``ok``, ``error``,
        ``threshold`` (the one used, gray levels), ``otsu`` (bool), ``area_px`` (px², NaN without a
        contour), ``length_px`` (contour pixels), ``edges`` (bool ROI edge map), ``canny`` (T_l, T_h),
        ``adaptive`` (bool), ``n_edges`` (edge pixels), ``attached`` (bool ROI mask: the particles the
        default tracker, ``semlab.Tracker`` with these parameters, cuts off the contour region and keeps
        its band clear of, :mod:`semlab.tracking.attached`; all False without a contour or a cut).
    """
    image = as_gray_float(frame)
    x, y, w, h = check_roi(roi, image.shape)
    raw = np.asarray(frame)[y:y + h, x:x + w]
    patch = to_uint8(raw)
    out = {"roi": (x, y, w, h), "patch": patch, "template": None, "ok": False, "error": "",
           "threshold": float("nan"), "otsu": threshold is None, "area_px": float("nan"), "length_px": 0}
    try:
        t = identify_contour_template(patch, sigma=sigma, threshold=threshold, morph_kernel=morph_kernel,
                                      morph_iterations=morph_iterations, choose=choose)
    except ValueError as err:
        out["error"] = str(err)
        if threshold is not None:
            out["threshold"] = float(threshold)
    else:
        out.update(template=t, ok=True, threshold=t.threshold, area_px=t.area, length_px=t.length)
    out["attached"] = np.zeros(patch.shape, bool)
    if out["ok"]:
        out["attached"] = _attached_pieces(frame, (x, y, w, h), sigma=sigma, threshold=threshold,
                                           morph_kernel=morph_kernel, morph_iterations=morph_iterations, choose=choose)
    adaptive = canny_low is None or canny_high is None
    thresholds = (adaptive_canny_thresholds(patch, sigma=canny_sigma) if adaptive
                  else (float(canny_low), float(canny_high)))
    edges = canny_edges(patch, low=thresholds[0], high=thresholds[1], sigma=canny_sigma)
    out.update(edges=edges, canny=tuple(float(v) for v in thresholds), adaptive=adaptive,
               n_edges=int(edges.sum()))
    return out


def _attached_pieces(frame, roi, **template_params) -> np.ndarray:
    """What the default tracker with these template parameters cuts off frame 0's contour region as
    attached particles (ROI-sized bool mask; all False where it cuts none or cannot start)."""
    tracker = Tracker(**template_params)
    try:
        tracker.init(frame, roi)
    except ValueError:
        return np.zeros((roi[3], roi[2]), bool)
    return np.zeros((roi[3], roi[2]), bool) if tracker.attached is None else tracker.attached


def _readout_html(r, pixel_size_nm, frame_label=None):
    s = pixel_size_nm
    parts = [f"<b>ROI</b> {r['roi']}"] + ([f"<b>on</b> {html.escape(frame_label)}"] if frame_label else [])
    th = f"{r['threshold']:.0f}" if np.isfinite(r["threshold"]) else "?"
    t = r["template"]
    how = "manual" if not r["otsu"] else ("Otsu, the brightest of 3 classes" if t is not None and t.otsu_classes == 3
                                          else "Otsu")
    parts.append(f"<b>threshold</b> {th} ({how})")
    if r["ok"]:
        area = f"<b>contour area</b> {r['area_px']:.0f} px²"
        length = f"<b>length</b> {r['length_px']} px"
        if s:
            area += f" ({r['area_px'] * s * s / 1e6:.3g} µm²)"
            length += f" ({r['length_px'] * s / 1e3:.3g} µm)"
        parts += [area, length]
        if r["attached"].any():
            cut = r["attached"]
            parts.append(f"<b>attached particles</b> {int(cut.sum())} px² cut (magenta; the tracker's band keeps clear)")
    else:
        parts.append(f"<b>no contour</b>: {html.escape(r['error'])}")
    lo, hi = r["canny"]
    parts.append(f"<b>Canny</b> T_l {lo:.0f} / T_h {hi:.0f} ({'adaptive, eq. 10' if r['adaptive'] else 'manual'})"
                 f", {r['n_edges']} edge px")
    return "<div>" + " · ".join(parts) + "</div>"


def render_template_figure(frame, r, *, pixel_size_nm=None, size=(14, 3.9), frame_label="frame"):
    """The explorer's figure: frame + ROI, ROI + contour, binary + contour, edge map. Returns a Figure."""
    axes = _png_figure(1, 4, size)[0]
    x, y = r["roi"][:2]
    contour = r["template"].points if r["ok"] else None
    show_frame(frame, axes[0], roi=r["roi"], contour=contour, contour_offset=(x, y),
               title=f"(a) {frame_label} and ROI")
    show_frame(r["patch"], axes[1], contour=contour, contour_offset=(x, y), origin=(x, y), title="(b) ROI, contour template")
    cut = r["attached"]
    if cut.any():
        h, w = cut.shape
        axes[1].contour(np.arange(w) + x, np.arange(h) + y, cut.astype(float), levels=[0.5], colors="m", linewidths=1.0)
    binary = r["template"].morphed if r["ok"] else np.zeros_like(r["patch"])
    show_frame(binary, axes[2], contour=contour, contour_offset=(x, y), origin=(x, y), title="(d, e) threshold, morphology")
    show_edges(r["edges"], axes[3], origin=(x, y), title="adaptive Canny" if r["adaptive"] else "fixed Canny")
    return axes[0].figure


class TemplateExplorer:
    """Pick the ROI and tune the contour template and Canny edges live (paper, Figs. 1-3).

    **Choosing the ROI by a click** (the paper's first method, Fig. 2b): click the overview -- the whole
    frame, top left, with the current ROI as a yellow box -- near the probe tip. The click becomes
    ``click_x, click_y`` (frame px, whatever size the overview is displayed at; :func:`display_to_frame`),
    a ``roi_size`` ROI is cut around it (:func:`semlab.roi.roi_from_click`, shifted to lie inside the frame)
    and the template, the edges and the readout are recomputed. The ``click x/y`` sliders do the same from
    the keyboard or from code (``explorer.controls["click_x"].value = 320``). The clickable overview needs
    the ``ipyevents`` package (and its JupyterLab extension); without it the overview is left out and the
    sliders alone move the ROI.

    Parameters
    ----------
    frame : (M, N) array_like
        The frame to take the template from.
    roi : (x, y, w, h), optional
        Initial ROI; default: ``roi_size`` around ``click`` (or the frame centre).
    click : (x, y), optional
        Initial click point near the probe tip, px (the paper's first ROI method).
    roi_size : int
        Side of the ROI a click makes (paper: 200 px at 3,000×).
    pixel_size_nm : float, optional
        Adds nm to the readout and the ROI axes.
    motion_frames : sequence of 2-D arrays, optional
        Frames of the probe stepping along x or y; enables the "ROI from motion" button (the paper's
        second ROI method, :func:`semlab.roi.find_motion_roi`). The ROI it finds holds the tip in the
        last motion frame used, so the explorer then shows and works on that frame (``frame``,
        ``frame_label``); a refusal (no motion) is shown in the readout.
    overview_width : int
        Width of the clickable overview, px (the frame is downscaled to it, never upscaled).
    **params
        Initial ``sigma, threshold, morph_kernel, morph_iterations, choose, canny_sigma, canny_low, canny_high``
        (as :func:`explore_template`).

    Attributes
    ----------
    result : dict
        The last :func:`explore_template` answer.
    params : dict
        The current parameters, ready for ``semlab.track(frames, explorer.roi, method="contour",
        **explorer.params)``.
    roi : (x, y, w, h)
        The current ROI, on ``frame``.
    frame : ndarray
        The frame the ROI and the template belong to: the frame given, or after *ROI from motion* the
        motion frame the ROI was found on.
    frame_label : str
        ``"frame"`` or ``"motion frame k"`` (shown in the readout and the figure).
    motion_index : int or None
        ``k`` when the ROI came from motion frame ``k``, None while it is on the frame given.
    motion_error : str
        Why the last *ROI from motion* was refused, '' otherwise.
    controls : dict of ipywidgets
        ``click_x, click_y, roi_size, motion, sigma, otsu, threshold, morph_kernel, morph_iterations,
        central, adaptive, canny_sigma, canny`` -- set their ``.value`` to drive the explorer from code.
    image, readout, ui : ipywidgets
        The rendered figure (PNG), the text readout and the whole panel.
    overview : ipywidgets.Image or None
        The clickable frame overview (``None`` without ipyevents).
    events : ipyevents.Event or None
        Watches ``click`` on ``overview``; its messages go to ``_on_overview_event``.
    """

    def __init__(self, frame, roi=None, *, click=None, roi_size=200, pixel_size_nm=None, motion_frames=None,
                 overview_width=440, sigma=2.0, threshold=None, morph_kernel=3, morph_iterations=1,
                 choose="central", canny_sigma=CANNY_SIGMA, canny_low=None, canny_high=None):
        import ipywidgets as w

        try:
            from ipyevents import Event
        except ImportError:   # the sliders alone still move the ROI
            Event = None

        self.frame = np.asarray(frame)
        self.frame_label = "frame"
        self.motion_index = None
        self.motion_error = ""
        image = as_gray_float(self.frame)
        rows, cols = image.shape
        self.pixel_size_nm = pixel_size_nm
        self.motion_frames = motion_frames
        if roi is not None:
            self._roi = check_roi(roi, image.shape)
            click = roi_centre(self._roi)
            roi_size = self._roi[2]
        else:
            click = ((cols - 1) / 2, (rows - 1) / 2) if click is None else click
            self._roi = roi_from_click(self.frame, click, size=min(int(roi_size), rows, cols))
        self._syncing = False
        self.render_ms = float("nan")

        def slider(cls, desc, value, lo, hi, step, **kw):
            return cls(value=value, min=lo, max=hi, step=step, description=desc, style=_SLIDER_STYLE,
                       layout=_layout(), continuous_update=False, **kw)

        c = {}
        c["click_x"] = slider(w.IntSlider, "click x (px)", round(click[0]), 0, cols - 1, 1)
        c["click_y"] = slider(w.IntSlider, "click y (px)", round(click[1]), 0, rows - 1, 1)
        c["click_x"].add_class(CLICK_X_CLASS)
        c["click_y"].add_class(CLICK_Y_CLASS)
        c["roi_size"] = slider(w.IntSlider, "ROI size (px)", int(roi_size), 16, min(rows, cols), 2)
        c["motion"] = w.Button(description="ROI from motion", disabled=motion_frames is None,
                               tooltip="background subtraction over frames of the probe stepping")
        c["sigma"] = slider(w.FloatSlider, "Gaussian σ (px)", float(sigma), 0.0, 8.0, 0.25)
        c["otsu"] = w.Checkbox(value=threshold is None, description="Otsu threshold (automatic)",
                               indent=False)
        c["threshold"] = slider(w.IntSlider, "threshold (gray)", 128 if threshold is None else int(threshold),
                                0, 255, 1)
        c["threshold"].add_class(THRESHOLD_CLASS)
        c["morph_kernel"] = slider(w.IntSlider, "morph. kernel (px)", int(morph_kernel), 1, 15, 2)
        c["morph_iterations"] = slider(w.IntSlider, "morph. iterations", int(morph_iterations), 0, 5, 1)
        c["central"] = w.Checkbox(value=choose == "central", indent=False,
                                  description="contour at the ROI's centre (else the paper's largest)")
        adaptive = canny_low is None or canny_high is None
        c["adaptive"] = w.Checkbox(value=adaptive, description="adaptive Canny thresholds (eq. 10)",
                                   indent=False)
        c["canny_sigma"] = slider(w.FloatSlider, "Canny σ (px)", float(canny_sigma), 0.0, 5.0, 0.25)
        c["canny"] = slider(w.FloatRangeSlider, "Canny T_l, T_h",
                            [20.0, 60.0] if adaptive else [float(canny_low), float(canny_high)],
                            0.0, 400.0, 1.0, readout_format=".0f")
        self.controls = c

        self.image = w.Image(format="png", layout=w.Layout(width="100%"))
        self.readout = w.HTML()
        self.readout.add_class(READOUT_CLASS)
        self._overview_width = int(overview_width)
        self._overview_drawn = None
        self.overview = self.events = None
        if Event is not None:
            self.overview = w.Image(format="jpeg", layout=w.Layout(width=f"{self._overview_width}px"))
            self.overview.add_class(OVERVIEW_CLASS)
            self.events = Event(source=self.overview, watched_events=["click"])
            self.events.on_dom_event(self._on_overview_event)
            heading = [w.HTML("<b>ROI</b>: click the frame near the probe tip"), self.overview]
        else:
            heading = [w.HTML("<b>ROI</b>: slide the click point near the probe tip")]
        left = w.VBox([*heading, c["click_x"], c["click_y"], c["roi_size"], c["motion"]])
        middle = w.VBox([w.HTML("<b>Contour template</b>"), c["sigma"], c["otsu"], c["threshold"],
                         c["morph_kernel"], c["morph_iterations"], c["central"]])
        right = w.VBox([w.HTML("<b>Canny edges</b>"), c["adaptive"], c["canny_sigma"], c["canny"]])
        self.ui = w.VBox([w.HBox([left, middle, right], layout=w.Layout(flex_flow="row wrap")),
                          self.readout, self.image])

        for name in ("click_x", "click_y", "roi_size"):
            c[name].observe(self._on_click, "value")
        for name in ("sigma", "otsu", "morph_kernel", "morph_iterations", "central", "adaptive", "canny_sigma"):
            c[name].observe(self._on_change, "value")
        c["threshold"].observe(self._on_threshold, "value")
        c["canny"].observe(self._on_canny, "value")
        c["motion"].on_click(self._on_motion)
        self.update()

    # -------------------------------------------------------------- state
    @property
    def roi(self) -> tuple[int, int, int, int]:
        return self._roi

    @property
    def params(self) -> dict:
        c = self.controls
        lo, hi = c["canny"].value
        adaptive = c["adaptive"].value
        return {
            "sigma": float(c["sigma"].value),
            "threshold": None if c["otsu"].value else float(c["threshold"].value),
            "morph_kernel": int(c["morph_kernel"].value),
            "morph_iterations": int(c["morph_iterations"].value),
            "choose": "central" if c["central"].value else "largest",
            "canny_sigma": float(c["canny_sigma"].value),
            "canny_low": None if adaptive else float(lo),
            "canny_high": None if adaptive else float(hi),
        }

    # -------------------------------------------------------------- events
    def _on_change(self, change=None):
        if not self._syncing:
            self.update()

    def _on_threshold(self, change):
        # Dragging the threshold means "manual threshold".
        self._manual("otsu")

    def _on_canny(self, change):
        # Dragging T_l, T_h means "manual Canny thresholds".
        self._manual("adaptive")

    def _manual(self, automatic: str) -> None:
        """A slider moved by hand: untick the checkbox that made it automatic, then recompute.

        Parameters
        ----------
        automatic : str
            The control that lets the explorer choose the slider's value (``"otsu"``, ``"adaptive"``);
            it is unticked without a recompute of its own. Nothing happens while the explorer itself
            is setting the controls.
        """
        if self._syncing:
            return
        with self._sync():
            self.controls[automatic].value = False
        self.update()

    def _on_overview_event(self, event):
        """An ipyevents message from the overview: a click there moves the click point and the ROI."""
        xy = overview_click(event, self.frame.shape)
        if xy is None:
            return   # not a click, or a message without usable geometry: nothing to do
        x, y = xy
        c = self.controls
        with self._sync():
            c["click_x"].value, c["click_y"].value = round(x), round(y)
        self._on_click()

    def _on_click(self, change=None):
        if self._syncing:
            return
        c = self.controls
        self._roi = roi_from_click(self.frame, (c["click_x"].value, c["click_y"].value),
                                   size=int(c["roi_size"].value))
        self.update()

    def _on_motion(self, button=None):
        """The paper's second ROI method: the ROI around the tip in the last motion frame, on that frame."""
        c = self.controls
        try:
            found = find_motion_roi(self.motion_frames, size=int(c["roi_size"].value))
        except ValueError as err:   # nothing moves: say so where the user looks, keep the ROI
            self.motion_error = str(err)
            self.readout.value = (f"<div><b>ROI from motion refused</b>: {html.escape(self.motion_error)}</div>"
                                  + _readout_html(self.result, self.pixel_size_nm, self.frame_label))
            return
        motion_frame = np.asarray(self.motion_frames[found.frame_index])
        if motion_frame.shape != self.frame.shape:
            self.motion_error = (f"the motion frames are {motion_frame.shape[1]}x{motion_frame.shape[0]} px, "
                                 f"the frame {self.frame.shape[1]}x{self.frame.shape[0]} px")
            self.readout.value = (f"<div><b>ROI from motion refused</b>: {html.escape(self.motion_error)}</div>"
                                  + _readout_html(self.result, self.pixel_size_nm, self.frame_label))
            return
        self.motion_error = ""
        # The probe moved while the frames were taken: the ROI holds the tip in the frame it was found on.
        self.frame = motion_frame
        self.frame_label = f"motion frame {found.frame_index}"
        self.motion_index = found.frame_index
        self._roi = found.roi
        cx, cy = roi_centre(self._roi)
        with self._sync():
            c["click_x"].value, c["click_y"].value = round(cx), round(cy)
        self.update()

    class _Sync:
        def __init__(self, owner):
            self.owner = owner

        def __enter__(self):
            self.previous = self.owner._syncing
            self.owner._syncing = True

        def __exit__(self, *exc):
            self.owner._syncing = self.previous

    def _sync(self):
        return self._Sync(self)

    # -------------------------------------------------------------- compute + show
    def update(self) -> dict:
        """Recompute with the current controls, refresh the figure and the readout; return ``result``."""
        self.result = explore_template(self.frame, self._roi, **self.params)
        c = self.controls
        # Show what the automatic choices picked, without turning them into manual ones.
        with self._sync():
            if c["otsu"].value and np.isfinite(self.result["threshold"]):
                c["threshold"].value = round(self.result["threshold"])
            if c["adaptive"].value:
                lo, hi = self.result["canny"]
                top = max(c["canny"].max, hi)
                c["canny"].max = float(np.ceil(top))
                c["canny"].value = [float(round(lo)), float(round(hi))]
        self.readout.value = _readout_html(self.result, self.pixel_size_nm, self.frame_label)
        self._draw_overview()
        t0 = time.perf_counter()
        fig = render_template_figure(self.frame, self.result, pixel_size_nm=self.pixel_size_nm,
                                     frame_label=self.frame_label)
        self.image.value = figure_png(fig)
        self.render_ms = 1e3 * (time.perf_counter() - t0)
        return self.result

    def _draw_overview(self):
        c = self.controls
        state = (self._roi, c["click_x"].value, c["click_y"].value, self.frame_label)
        if self.overview is None or state == self._overview_drawn:
            return
        self.overview.value = overview_image(self.frame, self._roi, state[1:3], max_width=self._overview_width)
        self._overview_drawn = state

    def _repr_mimebundle_(self, **kwargs):
        return self.ui._repr_mimebundle_(**kwargs)
