"""What the widgets share: the layout and slider style, the off-screen matplotlib figure, and the
CSS classes the widgets put on themselves."""

from __future__ import annotations

#: CSS classes put on the widgets (``add_class``), for the browser test and for styling.
THRESHOLD_CLASS = "semlab-threshold"
READOUT_CLASS = "semlab-readout"
OVERVIEW_CLASS = "semlab-overview"
CLICK_X_CLASS, CLICK_Y_CLASS = "semlab-click-x", "semlab-click-y"
SERVO_OVERVIEW_CLASS = "semlab-servo-overview"

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
