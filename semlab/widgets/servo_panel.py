"""The servo panel: click where the tip should go, or run the paper's 1-D step (Figs. 8a and 9)."""

from __future__ import annotations

import html

import numpy as np

from ..plots import figure_png, plot_step_response, show_frame
from ..roi import clip_window
from ._common import (
    _SLIDER_STYLE,
    SERVO_OVERVIEW_CLASS,
    _layout,
    _png_figure,
    overview_click,
    overview_image,
)

#: Runs overlaid in the servo panel's figures (older ones are kept in ``runs``/``moves``, not drawn).
SERVO_RUNS_SHOWN = 6
#: Half-height (px) of the "near the target" panel: the error of every run, the ±0.5 and ±1 px bands.
SERVO_ZOOM_PX = 3.0


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
        from ..control import PID

        pid = PID()
        return float(pid.kp), float(pid.ki), float(pid.kd)

    def roi(self):
        """The ROI for the next run."""
        return self._roi(self.microscope) if callable(self._roi) else self._roi

    def _run_params(self):
        from ..control import PID

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

    def _record(self, history, what, resp, metrics, draw, readout):
        """Keep a finished run, redraw its figure and show its readout.

        Parameters
        ----------
        history : list
            ``runs`` or ``moves``; ``(label, resp, metrics)`` is appended to it.
        what : str
            What the run did, for its label (:meth:`_label` adds the controller and the gains).
        resp : DataFrame
            The run's response.
        metrics : Series
            Its metrics.
        draw : callable
            Redraws the figure that overlays ``history``.
        readout : callable
            ``readout(label, metrics)``: the readout's HTML.

        Returns
        -------
        DataFrame
            ``resp``.
        """
        label = self._label(what)
        history.append((label, resp, metrics))
        draw()
        self.readout.value = readout(label, metrics)
        return resp

    # -------------------------------------------------------------- the paper's step
    def run(self):
        """Run one step response with the current controls; return it (None if it raised)."""
        from ..control import step_metrics, step_response

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
        return self._record(self.runs, f"{c['step_px'].value:+.0f} px{along}", resp, self.metrics,
                            self._draw, self._readout)

    # -------------------------------------------------------------- servo to a point
    def go_to(self, target_xy):
        """Move the ROI's centre point to ``target_xy`` (frame px) with all the axes at once
        (:func:`semlab.move_probe_to`); return the response (None if it was refused)."""
        from ..pointing import move_probe_to, point_metrics

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
        return self._record(self.moves, f"to ({float(target_xy[0]):.0f}, {float(target_xy[1]):.0f})", resp,
                            self.point_metrics, self._draw_points, self._point_readout)

    def _on_overview_event(self, event):
        """An ipyevents message from the overview: a click there is where the tip should go."""
        xy = overview_click(event, self.frame.shape)
        if xy is not None:  # not a click, or a message without usable geometry: nothing to do
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
