"""Live widgets for the workbench: thin ipywidgets shells over plain semlab functions.

* :class:`TemplateExplorer` -- pick the ROI (a mouse click on an overview of the frame, or click sliders,
  and a size; or motion differencing), tune the contour-template identification (Gaussian σ, Otsu or manual
  threshold, morphology) and the Canny edge detector (adaptive, eq. 10, or manual T_l/T_h); shows the ROI,
  the binary image with the contour and the edge map live (the paper's Figs. 1-3). ``explorer.params`` goes
  straight into :func:`semlab.track`.
* :class:`TrackingPlayer` -- a frame slider and a Play button over a tracked sequence, with the contour
  template drawn where the tracker put it and the track so far (the paper's Fig. 7).
* :class:`ServoPanel` -- click on the frame where the tip should go (:func:`semlab.move_probe_to`, all
  axes at once: error vs time, path in the image), or step size, feed-forward on/off, PID gains and a Run
  button for :func:`semlab.step_response`, with the response plot and :func:`semlab.step_metrics` (Fig. 9).

Each widget recomputes through a plain function (:func:`explore_template`, :func:`player_state`,
:func:`semlab.control.step_response`, :func:`semlab.move_probe_to`) and keeps the last answer as an attribute
(``.result``, ``.shown``, ``.response``/``.metrics``, ``.point_response``) so tests can read it without a browser. Figures are rendered
off-screen by matplotlib's Agg canvas into an :class:`ipywidgets.Image`, so the widgets need no
interactive matplotlib backend. Display a widget by leaving it last in a cell or with ``display(w)``.
"""

from __future__ import annotations

import html
import time

import cv2
import numpy as np

from .edges import adaptive_canny_thresholds, canny_edges
from .plots import figure_png, plot_step_response, plot_track_xy, show_edges, show_frame
from .roi import as_gray_float, check_roi, clip_window, find_motion_roi, roi_centre, roi_from_click
from .template import identify_contour_template, to_uint8
from .tracking.options import CANNY_SIGMA

__all__ = ["ServoPanel", "TemplateExplorer", "TrackingPlayer", "display_to_frame", "explore_template",
           "overview_image", "player_state"]

#: CSS classes put on the widgets (``add_class``), for the browser test and for styling.
THRESHOLD_CLASS = "semlab-threshold"
READOUT_CLASS = "semlab-readout"
OVERVIEW_CLASS = "semlab-overview"
CLICK_X_CLASS, CLICK_Y_CLASS = "semlab-click-x", "semlab-click-y"

_SLIDER_STYLE = {"description_width": "150px"}


def _layout(width="460px"):
    import ipywidgets as w

    return w.Layout(width=width)


def _png_figure(nrows, ncols, size, **adjust):
    """A matplotlib Figure outside pyplot (never shown twice by the inline backend).

    Fixed margins instead of constrained layout: the layout solver doubles the render time.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=size)
    fig.subplots_adjust(**{"left": 0.06, "right": 0.98, "bottom": 0.13, "top": 0.9, "wspace": 0.3, **adjust})
    return fig.subplots(nrows, ncols, squeeze=False)


# ---------------------------------------------------------------------------------------------
# Template explorer
# ---------------------------------------------------------------------------------------------

def explore_template(frame, roi, *, sigma=2.0, threshold=None, morph_kernel=3, morph_iterations=1,
                     canny_sigma=CANNY_SIGMA, canny_low=None, canny_high=None) -> dict:
    """Everything the template explorer shows for one set of parameters.

    Runs :func:`semlab.template.identify_contour_template` on the ROI (paper, Fig. 2) and
    :func:`semlab.edges.canny_edges` on it (Fig. 3; adaptive thresholds by eq. 10 unless both
    ``canny_low`` and ``canny_high`` are given). A threshold that leaves no contour is not an error
    here: the answer says ``ok=False`` with the reason.

    Parameters
    ----------
    frame : (M, N) array_like
    roi : (x, y, w, h)
    sigma, threshold, morph_kernel, morph_iterations
        As :func:`semlab.template.identify_contour_template` (``threshold=None``: Otsu).
    canny_sigma, canny_low, canny_high
        As :func:`semlab.edges.canny_edges`.

    Returns
    -------
    dict
        ``roi``, ``patch`` (uint8 ROI), ``template`` (ContourTemplate or None), ``ok``, ``error``,
        ``threshold`` (the one used, gray levels), ``otsu`` (bool), ``area_px`` (px², NaN without a
        contour), ``length_px`` (contour pixels), ``edges`` (bool ROI edge map), ``canny`` (T_l, T_h),
        ``adaptive`` (bool), ``n_edges`` (edge pixels).
    """
    image = as_gray_float(frame)
    x, y, w, h = check_roi(roi, image.shape)
    raw = np.asarray(frame)[y:y + h, x:x + w]
    patch = to_uint8(raw)
    out = {"roi": (x, y, w, h), "patch": patch, "template": None, "ok": False, "error": "",
           "threshold": float("nan"), "otsu": threshold is None, "area_px": float("nan"), "length_px": 0}
    try:
        t = identify_contour_template(patch, sigma=sigma, threshold=threshold, morph_kernel=morph_kernel,
                                      morph_iterations=morph_iterations)
    except ValueError as err:
        out["error"] = str(err)
        if threshold is not None:
            out["threshold"] = float(threshold)
    else:
        out.update(template=t, ok=True, threshold=t.threshold, area_px=t.area, length_px=t.length)
    adaptive = canny_low is None or canny_high is None
    thresholds = (adaptive_canny_thresholds(patch, sigma=canny_sigma) if adaptive
                  else (float(canny_low), float(canny_high)))
    edges = canny_edges(patch, low=thresholds[0], high=thresholds[1], sigma=canny_sigma)
    out.update(edges=edges, canny=tuple(float(v) for v in thresholds), adaptive=adaptive,
               n_edges=int(edges.sum()))
    return out


def _readout_html(r, pixel_size_nm, frame_label=None):
    s = pixel_size_nm
    parts = [f"<b>ROI</b> {r['roi']}"] + ([f"<b>on</b> {html.escape(frame_label)}"] if frame_label else [])
    th = f"{r['threshold']:.0f}" if np.isfinite(r["threshold"]) else "?"
    parts.append(f"<b>threshold</b> {th} ({'Otsu' if r['otsu'] else 'manual'})")
    if r["ok"]:
        area = f"<b>contour area</b> {r['area_px']:.0f} px²"
        length = f"<b>length</b> {r['length_px']} px"
        if s:
            area += f" ({r['area_px'] * s * s / 1e6:.3g} µm²)"
            length += f" ({r['length_px'] * s / 1e3:.3g} µm)"
        parts += [area, length]
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
    binary = r["template"].morphed if r["ok"] else np.zeros_like(r["patch"])
    show_frame(binary, axes[2], contour=contour, contour_offset=(x, y), origin=(x, y), title="(d, e) threshold, morphology")
    show_edges(r["edges"], axes[3], origin=(x, y), title="adaptive Canny" if r["adaptive"] else "fixed Canny")
    return axes[0].figure


def display_to_frame(display_xy, display_size, frame_shape) -> tuple[float, float]:
    """Frame coordinates of a mouse position on a displayed image of the whole frame.

    The image may be downscaled when it is encoded and scaled again by CSS: only its size *as displayed*
    matters. The displayed image spans the frame from pixel edge to pixel edge (frame x from -0.5 to
    ``cols - 0.5``), and a mouse position ``k`` (whole CSS px, as the browser reports it) stands for the
    CSS pixel ``[k, k + 1)``, whose centre is taken; so at 1:1 display CSS pixel ``k`` is frame pixel ``k``.
    x and y are scaled separately, so a stretched display converts correctly too.

    Parameters
    ----------
    display_xy : (float, float)
        Mouse position from the displayed image's top-left corner, CSS px: ipyevents' ``relativeX,
        relativeY`` (or ``offsetX, offsetY`` for an image without border and padding).
    display_size : (float, float)
        Width and height of the image as displayed, CSS px: ipyevents' ``boundingRectWidth,
        boundingRectHeight``.
    frame_shape : (rows, cols)

    Returns
    -------
    (x, y) : (float, float)
        Frame px, clipped into ``[0, cols - 1] x [0, rows - 1]`` (a click on the image's last CSS pixel
        may land half a frame pixel outside).

    Raises
    ------
    ValueError
        A display size that is not positive, or a position that is not finite.

    Examples
    --------
    A 640x480 frame shown 320x240 px: CSS pixel (10, 0) covers frame pixels x 20 and 21, y 0 and 1.

    >>> display_to_frame((10, 0), (320, 240), (480, 640))
    (20.5, 0.5)
    """
    rows, cols = (int(v) for v in frame_shape[:2])
    dx, dy = (float(v) for v in display_xy)
    width, height = (float(v) for v in display_size)
    if not (width > 0 and height > 0 and np.isfinite(width) and np.isfinite(height)):
        raise ValueError(f"display size {display_size!r} must be positive (is the image hidden?)")
    if not (np.isfinite(dx) and np.isfinite(dy)):
        raise ValueError(f"display position {display_xy!r} is not finite")
    x = (dx + 0.5) * cols / width - 0.5
    y = (dy + 0.5) * rows / height - 0.5
    return float(np.clip(x, 0, cols - 1)), float(np.clip(y, 0, rows - 1))


def overview_image(frame, roi, click=None, *, max_width=440, quality=85) -> bytes:
    """The whole frame as a JPEG, at most ``max_width`` px wide, with the ROI as a yellow box.

    Drawn with OpenCV rather than matplotlib: no axes or margins, so the image's pixels map linearly onto
    the frame (:func:`display_to_frame`), and it renders in a few milliseconds. JPEG, because a noisy SEM
    frame makes a PNG ten times larger, and the image travels to the browser on every click.

    Parameters
    ----------
    frame : (M, N) array_like
    roi : (x, y, w, h)
    click : (x, y), optional
        Drawn as a small cyan cross, px.
    max_width : int
        The frame is downscaled (never upscaled) to this width.
    quality : int
        JPEG quality, 0-100.
    """
    gray = to_uint8(frame)
    rows, cols = gray.shape
    scale = min(1.0, max_width / cols)
    size = (max(1, round(cols * scale)), max(1, round(rows * scale)))
    small = cv2.resize(gray, size, interpolation=cv2.INTER_AREA) if scale < 1 else gray
    rgb = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
    sx, sy = size[0] / cols, size[1] / rows
    x, y, w, h = roi
    # Frame px edges x - 0.5 .. x + w - 0.5 become display edges x*s .. (x + w)*s.
    cv2.rectangle(rgb, (round(x * sx), round(y * sy)), (round((x + w) * sx) - 1, round((y + h) * sy) - 1),
                  (0, 215, 255), 2)
    if click is not None:
        cx, cy = (round((float(v) + 0.5) * s - 0.5) for v, s in zip(click, (sx, sy), strict=True))
        cv2.drawMarker(rgb, (cx, cy), (255, 255, 0), cv2.MARKER_CROSS, 9, 1)
    _, jpeg = cv2.imencode(".jpg", rgb, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    return jpeg.tobytes()


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
        Initial ``sigma, threshold, morph_kernel, morph_iterations, canny_sigma, canny_low, canny_high``
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
        adaptive, canny_sigma, canny`` -- set their ``.value`` to drive the explorer from code.
    image, readout, ui : ipywidgets
        The rendered figure (PNG), the text readout and the whole panel.
    overview : ipywidgets.Image or None
        The clickable frame overview (``None`` without ipyevents).
    events : ipyevents.Event or None
        Watches ``click`` on ``overview``; its messages go to ``_on_overview_event``.
    """

    def __init__(self, frame, roi=None, *, click=None, roi_size=200, pixel_size_nm=None, motion_frames=None,
                 overview_width=440, sigma=2.0, threshold=None, morph_kernel=3, morph_iterations=1,
                 canny_sigma=CANNY_SIGMA, canny_low=None, canny_high=None):
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
                         c["morph_kernel"], c["morph_iterations"]])
        right = w.VBox([w.HTML("<b>Canny edges</b>"), c["adaptive"], c["canny_sigma"], c["canny"]])
        self.ui = w.VBox([w.HBox([left, middle, right], layout=w.Layout(flex_flow="row wrap")),
                          self.readout, self.image])

        for name in ("click_x", "click_y", "roi_size"):
            c[name].observe(self._on_click, "value")
        for name in ("sigma", "otsu", "morph_kernel", "morph_iterations", "adaptive", "canny_sigma"):
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
        if self._syncing:
            return
        with self._sync():
            self.controls["otsu"].value = False
        self.update()

    def _on_canny(self, change):
        if self._syncing:
            return
        with self._sync():
            self.controls["adaptive"].value = False
        self.update()

    def _on_overview_event(self, event):
        """An ipyevents message from the overview: a click there moves the click point and the ROI."""
        if event.get("event") != "click":
            return
        try:
            x, y = display_to_frame((event["relativeX"], event["relativeY"]),
                                    (event["boundingRectWidth"], event["boundingRectHeight"]),
                                    self.frame.shape)
        except (KeyError, TypeError, ValueError):
            return   # a message without usable geometry (e.g. the image was hidden): nothing to do
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


# ---------------------------------------------------------------------------------------------
# Tracking player
# ---------------------------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------------------------
# Servo panel
# ---------------------------------------------------------------------------------------------

#: Runs overlaid in the servo panel's figures (older ones are kept in ``runs``/``moves``, not drawn).
SERVO_RUNS_SHOWN = 6
#: Half-height (px) of the "near the target" panel: the error of every run, the ±0.5 and ±1 px bands.
SERVO_ZOOM_PX = 3.0
SERVO_OVERVIEW_CLASS = "semlab-servo-overview"


def _hidden_image(width):
    """An Image that takes no room until it has content (an empty Image shows a broken-image icon)."""
    import ipywidgets as w

    return w.Image(format="png", layout=w.Layout(width=width, display="none"))


def _show_png(image, fig):
    image.value = figure_png(fig)
    image.layout.display = None


def _hide(image):
    image.layout.display = "none"
    image.value = b""


def _final_frames(resp) -> int:
    """Frames at the end of a panel run for its final figures: a third of it, 2 to 30 (the paper's 30)."""
    return min(30, max(2, len(resp) // 3))


def _servo_readout(label, parts):
    return "<div>" + " · ".join([f"<b>{html.escape(label)}</b>", *parts]) + "</div>"


def _plot_point_moves(moves, frame, axes):
    """(a) distance to the target against time, (b) the tracked paths in the image (servo to a point)."""
    ax_err, ax_path = axes
    ends = []
    for i, (label, resp, _) in enumerate(moves):
        ok = resp["ok"].to_numpy(bool)
        t = resp["t"] - resp["t"].iloc[0]
        err = np.where(ok, resp["error_px"].to_numpy(float), np.nan)
        color = f"C{i % 10}"
        ax_err.semilogy(t, np.maximum(err, 1e-2), ".-", color=color, markersize=3, linewidth=1, label=label)
        ax_path.plot(resp["x"][ok], resp["y"][ok], ".-", color=color, markersize=2, linewidth=1)
        ax_path.plot(resp["x"].iloc[0], resp["y"].iloc[0], "o", color=color, markersize=5, fillstyle="none")
        ax_path.plot(resp["target_x"].iloc[-1], resp["target_y"].iloc[-1], "x", color=color, markersize=8)
        ends += [resp[["x", "y"]].to_numpy(float)[ok], resp[["target_x", "target_y"]].to_numpy(float)[-1:]]
    ax_err.axhspan(1e-2, 0.5, color="g", alpha=0.1, label="±0.5 px")
    ax_err.set(xlabel="time (s)", ylabel="distance to the target (px)", title="error vs time")
    ax_err.legend(loc="upper right", fontsize=8)
    pts = np.vstack(ends)
    lo, hi = pts.min(axis=0) - 30, pts.max(axis=0) + 30
    show_frame(frame, ax_path, title="path in the image (o start, x target)")
    ax_path.set_xlim(max(lo[0], -0.5), min(hi[0], frame.shape[1] - 0.5))
    ax_path.set_ylim(min(hi[1], frame.shape[0] - 0.5), max(lo[1], -0.5))


class ServoPanel:
    """Visual servo in the workbench: click where the tip should go, or run the paper's 1-D step
    (Figs. 8a and 9).

    **Click on the frame** (the overview, top left; needs ``ipyevents``) where the probe's tip should
    go: the click becomes frame px (:func:`display_to_frame`, whatever size the overview is shown at),
    and :func:`semlab.move_probe_to` moves the ROI's centre point there with all the axes at once
    (feed-forward on or off, as ticked). The figure shows the distance to the target against time and
    the path in the image; :meth:`go_to` does the same from code. **Run step** makes the paper's step
    of ``step (px)`` along one axis (:func:`semlab.step_response`), with the response and the approach
    to the target enlarged (the error of every run drawn, so all the runs the legend lists show).

    Parameters
    ----------
    microscope : Microscope
    axis : Axis or sequence of Axis
        One axis (steps only) or the manipulator's axes (steps along a chosen one, and clicks).
    roi : (x, y, w, h) or callable
        The probe's ROI in the current frame. After each run the panel re-centres it on the last tracked
        position, since the probe ends each run somewhere else. A callable ``roi(microscope)`` is
        called before every run instead.
    model : HysteresisModel or sequence of HysteresisModel
        Fitted on ``axis`` (one per axis, :func:`semlab.fit_hysteresis`); each model's memory follows its
        axis through every run, as it must.
    step_px : float
        Initial step.
    n_frames : int
        Frames per run.
    pid_factory : callable, optional
        ``pid_factory(kp, ki, kd) -> PID``; default :class:`semlab.control.PID` with those gains, used
        when "my PID gains" is ticked (otherwise the servo's own default PID).
    pixel_size_nm : float, optional
    overview_width : int
        Width of the clickable frame overview, px.
    **params
        More :func:`semlab.step_response` / :func:`semlab.move_probe_to` parameters (``max_slew_v``, ...).

    Attributes
    ----------
    response, metrics : DataFrame, Series or None
        The last step's :func:`semlab.step_response` and :func:`semlab.step_metrics`.
    point_response, point_metrics : DataFrame, Series or None
        The last click's :func:`semlab.move_probe_to` and :func:`semlab.point_metrics`.
    runs, moves : list of (label, response, metrics)
        Every step / every move to a point so far (the figures overlay the last few).
    frame : ndarray
        The frame the overview shows (grabbed after every run).
    controls : dict of ipywidgets
        ``step_px, step_axis, feedforward, custom_pid, kp, ki, kd, n_frames, run, clear``.
    overview, events : ipywidgets.Image, ipyevents.Event or None
        The clickable overview and its click watcher (None without ipyevents, or with one axis).
    image, point_image, readout, ui : ipywidgets
        The step figure, the point figure (each hidden until it has something to show), the text readout
        and the whole panel.
    step_figure, point_figure : matplotlib Figure or None
        The figures last rendered into ``image`` and ``point_image``.
    error : str
        The message of the last run that raised (e.g. a move out of reach), '' otherwise.
    """

    def __init__(self, microscope, axis, roi, model, *, step_px=100.0, n_frames=40, pid_factory=None,
                 pixel_size_nm=None, kp=None, ki=None, kd=None, overview_width=440, **params):
        import ipywidgets as w

        try:
            from ipyevents import Event
        except ImportError:  # the step experiment still works; clicks need ipyevents
            Event = None

        self.microscope = microscope
        self.axes = list(axis) if isinstance(axis, (list, tuple)) else [axis]
        self.models = list(model) if isinstance(model, (list, tuple)) else [model]
        if len(self.axes) != len(self.models):
            raise ValueError(f"{len(self.axes)} axes but {len(self.models)} models: one fitted model per axis")
        self._roi = roi if callable(roi) else tuple(int(v) for v in roi)
        self.params = params
        self.pixel_size_nm = pixel_size_nm
        self.pid_factory = pid_factory
        self.response = self.metrics = self.point_response = self.point_metrics = None
        self.runs, self.moves = [], []
        self.step_figure = self.point_figure = None
        self.error = ""
        c = self._controls(w, step_px, n_frames, kp, ki, kd)
        self.controls = c
        self.image = _hidden_image("760px")
        self.point_image = _hidden_image("760px")
        self.readout = w.HTML("press <b>Run step</b>" + (", or click where the tip should go" if
                                                           len(self.axes) > 1 and Event is not None else ""))
        self.readout.add_class("semlab-servo-readout")
        self._overview_width = int(overview_width)
        self.overview = self.events = None
        self.frame = np.asarray(microscope.grab())
        left = [w.VBox([c["step_px"], c["step_axis"], c["n_frames"], c["feedforward"]]),
                w.VBox([c["custom_pid"], c["kp"], c["ki"], c["kd"]])]
        if Event is not None and len(self.axes) > 1:
            self.overview = w.Image(format="jpeg", layout=w.Layout(width=f"{self._overview_width}px"))
            self.overview.add_class(SERVO_OVERVIEW_CLASS)
            self.events = Event(source=self.overview, watched_events=["click"])
            self.events.on_dom_event(self._on_overview_event)
            left = [w.VBox([w.HTML("<b>click where the tip should go</b>"), self.overview]), *left]
            self._draw_overview()
        self.ui = w.VBox([w.HBox(left, layout=w.Layout(flex_flow="row wrap")), w.HBox([c["run"], c["clear"]]),
                          self.readout, self.point_image, self.image])
        c["run"].on_click(lambda b: self.run())
        c["clear"].on_click(lambda b: self.clear())

    def _controls(self, w, step_px, n_frames, kp, ki, kd):
        default = self._default_gains()
        c = {}
        c["step_px"] = w.FloatSlider(value=float(step_px), min=-200.0, max=200.0, step=1.0,
                                     description="step (px)", style=_SLIDER_STYLE, layout=_layout(),
                                     continuous_update=False)
        c["step_px"].add_class("semlab-step")
        c["step_axis"] = w.Dropdown(options=[(m.axis, i) for i, m in enumerate(self.models)], value=0,
                                    description="step along", style=_SLIDER_STYLE, layout=_layout(),
                                    disabled=len(self.models) == 1)
        c["feedforward"] = w.Checkbox(value=True, description="feed-forward (inverse hysteresis model)",
                                      indent=False)
        c["custom_pid"] = w.Checkbox(value=kp is not None, description="my PID gains (else the servo's own)",
                                     indent=False)
        for key, label, given, dflt in (("kp", "K_p", kp, default[0]), ("ki", "K_i (per frame)", ki, default[1]),
                                        ("kd", "K_d (frames)", kd, default[2])):
            c[key] = w.FloatText(value=dflt if given is None else given, description=label,
                                 style=_SLIDER_STYLE, layout=_layout("300px"))
        c["n_frames"] = w.IntSlider(value=int(n_frames), min=5, max=200, step=1, description="frames",
                                    style=_SLIDER_STYLE, layout=_layout(), continuous_update=False)
        c["run"] = w.Button(description="Run step", button_style="primary")
        c["run"].add_class("semlab-run")
        c["clear"] = w.Button(description="Clear plot")
        return c

    @staticmethod
    def _default_gains():
        from .control import PID

        pid = PID()
        return float(pid.kp), float(pid.ki), float(pid.kd)

    def roi(self):
        """The ROI for the next run."""
        return self._roi(self.microscope) if callable(self._roi) else self._roi

    def _run_params(self):
        from .control import PID

        c = self.controls
        params = dict(self.params)
        if c["custom_pid"].value:
            kp, ki, kd = float(c["kp"].value), float(c["ki"].value), float(c["kd"].value)
            params["pid"] = self.pid_factory(kp, ki, kd) if self.pid_factory else PID(kp=kp, ki=ki, kd=kd)
        return params

    def _label(self, what):
        c = self.controls
        gains = f", K=({c['kp'].value:g}, {c['ki'].value:g}, {c['kd'].value:g})" if c["custom_pid"].value else ""
        return f"{'FF+PID' if c['feedforward'].value else 'PID only'}, {what}{gains}"

    def _attempt(self, busy: str, run):
        """Run one servo call; its response, or None when it was refused (the reason shown)."""
        self.readout.value = busy
        try:
            resp = run()
        except (ValueError, TypeError, RuntimeError) as err:
            self._refused(err)
            return None
        self.error = ""
        self._follow(resp)
        return resp

    def _refused(self, err):
        self.error = str(err)
        self.readout.value = f"<b>refused</b>: {html.escape(self.error)}"

    # -------------------------------------------------------------- the paper's step
    def run(self):
        """Run one step response with the current controls; return it (None if it raised)."""
        from .control import step_metrics, step_response

        c = self.controls
        k = int(c["step_axis"].value)
        resp = self._attempt("running…", lambda: step_response(
            self.microscope, self.axes[k], self.roi(), float(c["step_px"].value), model=self.models[k],
            feedforward=bool(c["feedforward"].value), n_frames=int(c["n_frames"].value), **self._run_params()))
        if resp is None:
            return None
        self.response = resp
        self.metrics = step_metrics(resp, final_frames=_final_frames(resp))
        along = f" along {self.models[k].axis}" if len(self.models) > 1 else ""
        label = self._label(f"{c['step_px'].value:+.0f} px{along}")
        self.runs.append((label, resp, self.metrics))
        self._draw()
        self.readout.value = self._readout(label, self.metrics)
        return resp

    # -------------------------------------------------------------- servo to a point
    def go_to(self, target_xy):
        """Move the ROI's centre point to ``target_xy`` (frame px) with all the axes at once
        (:func:`semlab.move_probe_to`); return the response (None if it was refused)."""
        from .pointing import move_probe_to, point_metrics

        c = self.controls

        def run():
            if len(self.axes) < 2:
                raise ValueError("a point in the image needs two axes; this panel drives one (steps only)")
            return move_probe_to(self.microscope, self.axes, self.roi(), target_xy, model=self.models,
                                 n_frames=int(c["n_frames"].value), feedforward=bool(c["feedforward"].value),
                                 **self._run_params())

        resp = self._attempt("moving…", run)
        if resp is None:
            return None
        self.point_response = resp
        self.point_metrics = point_metrics(resp, final_frames=_final_frames(resp))
        label = self._label(f"to ({float(target_xy[0]):.0f}, {float(target_xy[1]):.0f})")
        self.moves.append((label, resp, self.point_metrics))
        self._draw_points()
        self.readout.value = self._point_readout(label, self.point_metrics)
        return resp

    def _on_overview_event(self, event):
        """An ipyevents message from the overview: a click there is where the tip should go."""
        if event.get("event") != "click":
            return
        try:
            xy = display_to_frame((event["relativeX"], event["relativeY"]),
                                  (event["boundingRectWidth"], event["boundingRectHeight"]), self.frame.shape)
        except (KeyError, TypeError, ValueError):
            return  # a message without usable geometry (e.g. the image was hidden): nothing to do
        self.go_to(xy)

    # -------------------------------------------------------------- state after a run
    def _follow(self, resp):
        """Grab the frame that shows where the probe ended; re-centre a fixed ROI on its last tracked
        position (the tracker's ROI centre moved there)."""
        self.frame = np.asarray(self.microscope.grab())
        if not callable(self._roi):
            ok = resp["ok"].to_numpy(bool) & np.isfinite(resp["x"].to_numpy(float))
            if ok.any():
                last = resp[ok].iloc[-1]
                w, h = self._roi[2:]
                self._roi = clip_window(float(last["x"]), float(last["y"]), w, h, self.frame.shape)
        self._draw_overview()

    def _draw_overview(self):
        if self.overview is None:
            return
        click = None
        if self.moves:
            last = self.moves[-1][1]
            click = (float(last["target_x"].iloc[-1]), float(last["target_y"].iloc[-1]))
        # a callable ROI is asked for only before a run (it may grab frames): no box then
        roi = self._roi if not callable(self._roi) else (-10, -10, 1, 1)
        self.overview.value = overview_image(self.frame, roi, click, max_width=self._overview_width)

    def clear(self):
        self.runs, self.moves = [], []
        _hide(self.image)
        _hide(self.point_image)
        self._draw_overview()
        self.readout.value = "cleared"

    # -------------------------------------------------------------- readouts and figures
    @staticmethod
    def _fmt(m, key, unit, fmt=".2f"):
        v = m.get(key, np.nan)
        return "—" if not np.isfinite(v) else f"{v:{fmt}} {unit}"

    def _readout(self, label, m):
        f = self._fmt
        return _servo_readout(label, [
            f"<b>response time (±1 px)</b> {f(m, 'response_time_1px_s', 's')}",
            f"<b>(±0.5 px)</b> {f(m, 'response_time_0p5px_s', 's')}",
            f"<b>overshoot</b> {f(m, 'overshoot_px', 'px')}",
            f"<b>final</b> {f(m, 'final_mean_px', 'px', '.3f')} ± {f(m, 'final_std_px', 'px', '.3f')}",
            f"<b>lost frames</b> {int(m.get('n_lost', 0))}"])

    def _point_readout(self, label, m):
        f = self._fmt
        return _servo_readout(label, [
            f"<b>distance</b> {f(m, 'distance_px', 'px', '.1f')}",
            f"<b>response time (±0.5 px)</b> {f(m, 'response_time_s', 's')}",
            f"<b>overshoot</b> {f(m, 'overshoot_px', 'px')}",
            f"<b>final error</b> {f(m, 'final_error_px', 'px', '.3f')} ± {f(m, 'final_std_px', 'px', '.3f')}",
            f"<b>lost frames</b> {int(m.get('n_lost', 0))} (measured by the tracker)"])

    def _draw(self):
        axes = _png_figure(1, 2, (12, 4), left=0.07, wspace=0.25)[0]
        for label, resp, _ in self.runs[-SERVO_RUNS_SHOWN:]:
            line = plot_step_response(resp, axes[0], label=label, pixel_size_nm=None)["response"]
            ok = resp["ok"].to_numpy(bool)
            err = np.where(ok, resp["displacement"] - resp["target"], np.nan)
            axes[1].plot(resp["t"] - resp["t"].iloc[0], err, ".-", markersize=3, linewidth=1, color=line.get_color())
        axes[0].set_title("step responses (Fig. 9a/b)")
        axes[1].axhspan(-1, 1, color="g", alpha=0.08)
        axes[1].axhspan(-0.5, 0.5, color="g", alpha=0.12)
        axes[1].axhline(0.0, color="k", linestyle=":", linewidth=1)
        axes[1].set(ylim=(-SERVO_ZOOM_PX, SERVO_ZOOM_PX), xlabel="time (s)", ylabel="displacement - target (px)",
                    title="near the target (Fig. 9c): every run's error")
        self.step_figure = axes[0].figure
        _show_png(self.image, self.step_figure)

    def _draw_points(self):
        axes = _png_figure(1, 2, (12, 4.4), left=0.07, wspace=0.25)[0]
        _plot_point_moves(self.moves[-SERVO_RUNS_SHOWN:], self.frame, axes)
        self.point_figure = axes[0].figure
        _show_png(self.point_image, self.point_figure)

    def _repr_mimebundle_(self, **kwargs):
        return self.ui._repr_mimebundle_(**kwargs)
