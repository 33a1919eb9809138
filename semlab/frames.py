"""Frame and ROI checks; kept for importers of ``semlab.frames`` — they live in :mod:`semlab.roi`."""

from .roi import as_gray_float, check_roi, clip_window, roi_centre

__all__ = ["as_gray_float", "check_roi", "clip_window", "roi_centre"]
