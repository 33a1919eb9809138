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

Modules
-------
``_common``
    What the widgets share: the layout and slider style, the off-screen figure, the CSS classes; the
    frame overview (:func:`overview_image`) and its click-to-frame coordinates (:func:`display_to_frame`),
    which the template explorer, the servo panel and :class:`semlab.instruments.picker.TargetPicker` show.
``template_explorer``
    :class:`TemplateExplorer`, :func:`explore_template`, :func:`render_template_figure`.
``player``
    :class:`TrackingPlayer`, :func:`player_state`.
``servo_panel``
    :class:`ServoPanel` and its figures and readouts.
"""

from __future__ import annotations

from ._common import CLICK_X_CLASS as CLICK_X_CLASS
from ._common import CLICK_Y_CLASS as CLICK_Y_CLASS
from ._common import OVERVIEW_CLASS as OVERVIEW_CLASS
from ._common import READOUT_CLASS as READOUT_CLASS
from ._common import SERVO_OVERVIEW_CLASS as SERVO_OVERVIEW_CLASS
from ._common import THRESHOLD_CLASS as THRESHOLD_CLASS
from ._common import display_to_frame, overview_click, overview_image
from .player import TrackingPlayer, player_state
from .servo_panel import SERVO_RUNS_SHOWN as SERVO_RUNS_SHOWN
from .servo_panel import SERVO_ZOOM_PX as SERVO_ZOOM_PX
from .servo_panel import ServoPanel
from .template_explorer import TemplateExplorer, explore_template
from .template_explorer import render_template_figure as render_template_figure

__all__ = ["ServoPanel", "TemplateExplorer", "TrackingPlayer", "display_to_frame", "explore_template",
           "overview_click", "overview_image", "player_state"]
