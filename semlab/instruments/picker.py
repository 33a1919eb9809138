"""Click where the tip should go: a frame overview (ipyevents, like :class:`semlab.TemplateExplorer`'s)
that records a target point.
"""

from __future__ import annotations

import numpy as np

from semlab.widgets import OVERVIEW_CLASS, overview_click, overview_image

__all__ = ["TargetPicker"]


class TargetPicker:
    """The whole frame with the ROI (yellow) and the target (cyan cross); a click sets the target.

    Parameters
    ----------
    frame : (M, N) array_like
    roi : (x, y, w, h)
        Drawn as a box (the tracked point is its centre).
    target : (x, y), optional
        Initial target, px (a script's or a test's; a click replaces it).
    width : int
        Displayed width of the overview, CSS px.

    Attributes
    ----------
    target : (float, float) or None
        The last click (frame px) or the initial target.
    ui : ipywidgets.VBox
    events : ipyevents.Event or None
        None without ipyevents (the target then comes only from ``target=`` or :meth:`set_target`).
    """

    def __init__(self, frame, roi, *, target=None, width: int = 440):
        import ipywidgets as w

        self.frame = np.asarray(frame)
        self.roi = tuple(roi)
        self.width = int(width)
        self.target = None
        self.image = w.Image(format="jpeg", layout=w.Layout(width=f"{self.width}px"))
        self.image.add_class(OVERVIEW_CLASS)
        self.readout = w.HTML()
        try:
            from ipyevents import Event
        except ImportError:
            self.events = None
        else:
            self.events = Event(source=self.image, watched_events=["click"])
            self.events.on_dom_event(self._on_event)
        self.ui = w.VBox([w.HTML("<b>Target</b>: click where the tip should go"), self.image, self.readout])
        self.set_target(target)

    def set_target(self, target) -> None:
        """Set (or with None clear) the target, px; redraws."""
        if target is not None:
            rows, cols = self.frame.shape[:2]
            x, y = (float(v) for v in target)
            if not (np.isfinite(x) and np.isfinite(y) and 0 <= x <= cols - 1 and 0 <= y <= rows - 1):
                raise ValueError(f"target {target!r} is not a point of the {cols}x{rows} frame")
            target = (x, y)
        self.target = target
        self.image.value = overview_image(self.frame, self.roi, target, max_width=self.width)
        self.readout.value = ("no target yet" if target is None
                              else f"target ({target[0]:.1f}, {target[1]:.1f}) px")

    def _on_event(self, event):
        xy = overview_click(event, self.frame.shape)
        if xy is not None:  # not a click, or a message without usable geometry (the image hidden)
            self.set_target(xy)

    def _repr_mimebundle_(self, **kwargs):
        return self.ui._repr_mimebundle_(**kwargs)
