"""What the widgets share: the layout and slider style, the off-screen matplotlib figure, the CSS
classes the widgets put on themselves, and the clickable frame overview (the image, its
click-to-frame coordinates and the click messages ipyevents sends from it)."""

from __future__ import annotations

import cv2
import numpy as np

from ..template import to_uint8

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


def overview_click(event, frame_shape) -> tuple[float, float] | None:
    """Frame coordinates of a click on a frame overview, from the ipyevents message it sent.

    Parameters
    ----------
    event : dict
        An ipyevents message from the overview (``on_dom_event``).
    frame_shape : (rows, cols)
        Shape of the frame the overview shows.

    Returns
    -------
    (x, y) : (float, float) or None
        Frame px (:func:`display_to_frame`); None for a message that is not a click, or one without
        usable geometry (e.g. the image was hidden), which the widgets ignore.
    """
    if event.get("event") != "click":
        return None
    try:
        return display_to_frame((event["relativeX"], event["relativeY"]),
                                (event["boundingRectWidth"], event["boundingRectHeight"]), frame_shape)
    except (KeyError, TypeError, ValueError):
        return None
