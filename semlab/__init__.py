"""semlab: sub-pixel visual tracking and visual servoing in a scanning electron microscope.

The handful of calls a notebook or a script needs, after Ru et al. (2012),
"An Improved Visual Tracking Method in Scanning Electron Microscope":

- tracking: :func:`track`, :class:`Tracker`, :func:`roi_from_click`, :func:`roi_from_motion`,
  :func:`identify_contour_template`, :func:`adaptive_canny_thresholds`
- control: :func:`characterise_hysteresis`, :func:`fit_hysteresis`, :func:`step_response`,
  :func:`step_metrics`, :func:`move_probe_to` (a point of the image, several axes at once)
- evaluation: :func:`evaluate` (the scene-family corpus, :mod:`semlab.evaluation`)
- data: :func:`read_frames`, :func:`read_image`, :func:`load_sample` (the samples in ``data/``)
- widgets: :class:`TemplateExplorer`, :class:`TrackingPlayer`, :class:`ServoPanel`; figures in :mod:`semlab.plots`
- the simulated rig lives in :mod:`semlab.sim`, the hardware protocols in :mod:`semlab.protocols`.

Names are imported lazily, so ``import semlab`` stays fast and a notebook pays only for what it uses.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    # tracking (paper: template identification, matching, sub-pixel refinement)
    "track": "semlab.tracking",
    "Tracker": "semlab.tracking",
    "TrackResult": "semlab.tracking",
    "ContourTemplate": "semlab.template",
    "canny_edges": "semlab.edges",
    "gradient_subpixel_shift": "semlab.subpixel",
    "tracking_errors": "semlab.metrics",
    # the scene-family corpus every tracking figure is measured on
    "evaluate": "semlab.evaluation",
    "MatchTemplatePeer": "semlab.peers",
    "ECCPeer": "semlab.peers",
    "PhaseCorrelationPeer": "semlab.peers",
    "roi_from_click": "semlab.roi",
    "roi_from_motion": "semlab.roi",
    "identify_contour_template": "semlab.template",
    "adaptive_canny_thresholds": "semlab.edges",
    # hysteresis and visual servo
    "characterise_hysteresis": "semlab.experiments",
    "fit_hysteresis": "semlab.hysteresis",
    "step_response": "semlab.control",
    "step_metrics": "semlab.control",
    "move_to": "semlab.control",
    "drive_voltages": "semlab.experiments",
    "characterise_creep": "semlab.experiments",
    "fit_creep": "semlab.creep",
    "CreepModel": "semlab.creep",
    "PolynomialHysteresis": "semlab.hysteresis",
    "PIHysteresis": "semlab.hysteresis",
    "PID": "semlab.control",
    "VisualServo": "semlab.control",
    # servo to a point: several axes at once, several probes from one frame stream
    "move_probe_to": "semlab.pointing",
    "move_probes_to": "semlab.pointing",
    "ProbeMove": "semlab.pointing",
    "point_metrics": "semlab.pointing",
    # data in and out
    "read_frames": "semlab.io",
    "read_image": "semlab.io",
    "FrameSequence": "semlab.io",
    "FrameReadError": "semlab.io",
    "load_sample": "semlab.io",
    "list_samples": "semlab.io",
    "data_path": "semlab.io",
    # the workbench's widgets
    "TemplateExplorer": "semlab.widgets",
    "TrackingPlayer": "semlab.widgets",
    "ServoPanel": "semlab.widgets",
    "display_to_frame": "semlab.widgets",
    # protocols
    "Microscope": "semlab.protocols",
    "Axis": "semlab.protocols",
    # closed-loop positioners (FIB/SEM manipulators, semlab.instruments)
    "Positioner": "semlab.protocols",
    "calibrate_positioner": "semlab.positioning",
}

__all__ = sorted(_EXPORTS) + ["__version__"]  # noqa: PLE0605 (built from the lazy export table)


def __getattr__(name: str):
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'semlab' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
