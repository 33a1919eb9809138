"""semlab: sub-pixel visual tracking and visual servoing in a scanning electron microscope."""

__version__ = "0.1.0"
