"""Contour template identification (Ru et al. 2012, "Contour Template Identification", steps 2-5).

ROI → Gaussian smoothing → Otsu threshold → erosion/dilation → contours organised in a two-level
hierarchy → the largest external contour is the template (the paper's Fig. 2), or, with
``choose="central"``, the one at the ROI's centre.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from skimage.filters import threshold_multiotsu

from .roi import as_gray_float

__all__ = ["CONTOUR_CHOICES", "ContourTemplate", "brightest_of_three", "edge_strength", "identify_contour_template",
           "to_uint8"]

#: Which external contour is the object (step 5): ``"largest"``, the paper's (Fig. 2), or
#: ``"central"``, the one holding the ROI's centre (where the user clicked), else the nearest to it.
CONTOUR_CHOICES = ("largest", "central")
#: ``"central"`` weighs only contours of at least this fraction of the largest's area: smaller ones
#: are specks of noise or clutter left by the opening, not the object, even when nearer the centre.
MIN_CENTRAL_AREA_FRACTION = 0.1
#: A probe whose end is at the ROI's centre lies behind it: its region covers at most about half the
#: ROI. With ``"central"`` and Otsu's threshold, a region over more than this holds part of the
#: substrate too (a bright surface the probe reaches over, merged with it at Otsu's level), and the
#: brightest of three Otsu classes is taken instead (:func:`skimage.filters.threshold_multiotsu`).
MAX_CENTRAL_REGION_FRACTION = 0.5
#: The edge strength of a contour is read this many px inside the ROI (where the object leaves the ROI
#: its contour runs along the border, on no edge).
EDGE_READ_MARGIN_PX = 3


@dataclass
class ContourTemplate:
    """The result of :func:`identify_contour_template`.

    Attributes
    ----------
    points : (K, 2) ndarray of int
        The chosen external contour, ``(x, y)`` in ROI coordinates.
    mask : (h, w) ndarray of bool
        The contour's pixels (1 px wide): the paper's contour template (Fig. 1c).
    region : (h, w) ndarray of bool
        The filled contour (the object).
    hierarchy : (n, 4) ndarray of int
        OpenCV's ``[next, previous, first_child, parent]`` for every contour found
        (``RETR_CCOMP``: two levels, external boundaries and the holes inside them).
    contours : list of ndarray
        All contours, as OpenCV returns them.
    smoothed, binary, morphed : (h, w) ndarray of uint8
        The intermediate images (Fig. 2c, 2d, 2e).
    threshold : float
        The threshold used on the smoothed image (Otsu's unless given), gray levels 0-255.
    area : float
        Area enclosed by the template contour, px².
    otsu_classes : int or None
        How the threshold was found: 2 (Otsu's), 3 (the brightest of three Otsu classes: see
        :func:`identify_contour_template`'s ``choose``), None (given).
    """

    points: np.ndarray
    mask: np.ndarray
    region: np.ndarray
    hierarchy: np.ndarray
    contours: list = field(repr=False)
    smoothed: np.ndarray = field(repr=False)
    binary: np.ndarray = field(repr=False)
    morphed: np.ndarray = field(repr=False)
    threshold: float = 0.0
    area: float = 0.0
    otsu_classes: int | None = None

    @property
    def length(self) -> int:
        """Number of contour pixels."""
        return int(self.mask.sum())


def to_uint8(image) -> np.ndarray:
    """Stretch an image's gray levels linearly onto 0-255 (uint8 passes through unchanged)."""
    arr = np.asarray(image)
    if arr.dtype == np.uint8:
        return arr
    img = as_gray_float(arr, name="image")
    lo, hi = float(img.min()), float(img.max())
    if hi <= lo:
        return np.zeros(img.shape, np.uint8)
    return np.clip((img - lo) * (255.0 / (hi - lo)) + 0.5, 0, 255).astype(np.uint8)


def identify_contour_template(image, *, sigma: float = 2.0, threshold: float | None = None,
                              morph_kernel: int = 3, morph_iterations: int = 1,
                              bright_object: bool = True, choose: str = "largest") -> ContourTemplate:
    """Identify the contour template in an ROI image (paper, Fig. 2).

    Parameters
    ----------
    image : (h, w) array_like
        The ROI (uint8, uint16 or float); other dtypes are stretched to 0-255 first.
    sigma : float
        Standard deviation of the Gaussian smoothing, px (step 2). 0 disables it.
    threshold : float or None
        Gray level (0-255, on the smoothed image) separating object and background; ``None``
        takes Otsu's threshold (step 3; Otsu 1979).
    morph_kernel : int
        Side of the elliptical structuring element of the erosion/dilation (step 4); 0 or 1
        disables the morphology.
    morph_iterations : int
        How often erosion and then dilation are applied (an opening that removes specks).
    bright_object : bool
        The probe is brighter than the substrate in an SE image; set False for a dark object.
    choose : {"largest", "central"}
        Which external contour is the template (step 5). ``"largest"`` is the paper's. ``"central"``
        departs from it: among the contours of at least :data:`MIN_CENTRAL_AREA_FRACTION` of the
        largest's area, the one that holds the ROI's centre (the tip the user clicked), else the one
        nearest to it; the largest contour of an ROI centred on a tip can be a bright blob of the
        substrate beside it, and a tracker that follows the blob says ``ok`` on every frame. With
        Otsu's threshold, a central region over :data:`MAX_CENTRAL_REGION_FRACTION` of the ROI is
        the probe merged with a bright part of the substrate (a probe ending at the centre lies
        behind it): the brightest of three Otsu classes (Liao et al. 2001) separates them, and its
        central contour is taken when it has one.

    Returns
    -------
    ContourTemplate

    Raises
    ------
    ValueError
        If the image is constant, no contour survives (step 5 finds nothing) or ``choose`` is
        not one of :data:`CONTOUR_CHOICES`.

    Examples
    --------
    >>> import numpy as np
    >>> yy, xx = np.mgrid[:60, :60]
    >>> disc = np.where((xx - 30) ** 2 + (yy - 30) ** 2 < 15 ** 2, 200, 50).astype(np.uint8)
    >>> t = identify_contour_template(disc)
    >>> 650 < t.area < 760
    True
    """
    if choose not in CONTOUR_CHOICES:
        raise ValueError(f"choose must be one of {CONTOUR_CHOICES}, got {choose!r}")
    gray = to_uint8(image)
    if gray.ndim != 2 or gray.size == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {gray.shape}")
    if int(gray.max()) == int(gray.min()):
        raise ValueError("the ROI is constant: there is no object to take a contour from")
    smoothed = cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else gray.copy()
    if threshold is not None and not np.isfinite(threshold):
        raise ValueError(f"threshold must be finite, got {threshold}")
    found = _segment(smoothed, threshold, bright_object, morph_kernel, morph_iterations, choose)
    if threshold is None:
        found.otsu_classes = 2
    if threshold is None and choose == "central" and found.region.mean() > MAX_CENTRAL_REGION_FRACTION:
        found = brightest_of_three(smoothed, bright_object, morph_kernel, morph_iterations) or found
    if found.area < 4.0:
        raise ValueError(f"the {choose} contour in the ROI encloses less than 4 px²: no usable template")
    return found


def _segment(smoothed, threshold, bright_object: bool, morph_kernel: int, morph_iterations: int,
             choose: str) -> ContourTemplate:
    """Steps 3-5 of :func:`identify_contour_template` on the smoothed ROI (Otsu's threshold when
    ``threshold`` is None)."""
    mode = cv2.THRESH_BINARY if bright_object else cv2.THRESH_BINARY_INV
    if threshold is None:
        t, binary = cv2.threshold(smoothed, 0, 255, mode | cv2.THRESH_OTSU)
    else:
        t, binary = cv2.threshold(smoothed, float(threshold), 255, mode)
    morphed = binary
    if morph_kernel > 1 and morph_iterations > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (int(morph_kernel), int(morph_kernel)))
        morphed = cv2.erode(binary, kernel, iterations=int(morph_iterations))
        morphed = cv2.dilate(morphed, kernel, iterations=int(morph_iterations))
    contours, hierarchy = cv2.findContours(morphed, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None or not contours:
        raise ValueError("no contour in the ROI: the threshold leaves no object "
                         f"(threshold {t:.1f}); adjust sigma/threshold or move the ROI")
    hierarchy = hierarchy.reshape(-1, 4)
    external = [i for i in range(len(contours)) if hierarchy[i, 3] < 0]
    best = _chosen_contour(contours, external, smoothed.shape, choose)
    mask = np.zeros(smoothed.shape, np.uint8)
    cv2.drawContours(mask, contours, best, 1, thickness=1)
    region = np.zeros(smoothed.shape, np.uint8)
    cv2.drawContours(region, contours, best, 1, thickness=cv2.FILLED)
    return ContourTemplate(points=contours[best].reshape(-1, 2), mask=mask.astype(bool),
                           region=region.astype(bool), hierarchy=hierarchy, contours=list(contours),
                           smoothed=smoothed, binary=binary, morphed=morphed, threshold=float(t),
                           area=float(cv2.contourArea(contours[best])))


def brightest_of_three(smoothed, bright_object: bool, morph_kernel: int,
                       morph_iterations: int) -> ContourTemplate | None:
    """The central contour at the level between the brightest of three Otsu classes and the rest
    (the darkest's, for a dark object); None when there are no three levels or no contour of at
    least 4 px² at that level."""
    try:
        low, high = threshold_multiotsu(smoothed, classes=3)
        found = _segment(smoothed, float(high if bright_object else low), bright_object, morph_kernel,
                         morph_iterations, "central")
    except ValueError:
        return None
    found.otsu_classes = 3
    return found if found.area >= 4.0 else None


def edge_strength(smoothed, mask) -> float:
    """Mean gradient magnitude (gray levels per px) of ``smoothed`` along the contour ``mask``, the
    largest within a pixel of each contour pixel (a threshold's contour is not the steepest point of
    the edge), read :data:`EDGE_READ_MARGIN_PX` inside the ROI; 0 when no contour pixel is there."""
    img = np.asarray(smoothed, np.float32)
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    steepest = cv2.dilate(np.hypot(gx, gy), np.ones((3, 3), np.uint8))
    m = EDGE_READ_MARGIN_PX
    read = np.zeros(img.shape, bool)
    read[m:-m, m:-m] = np.asarray(mask, bool)[m:-m, m:-m]
    return float(steepest[read].mean()) if read.any() else 0.0


def _chosen_contour(contours, external, shape, choose: str) -> int:
    """The index of the template among the ``external`` contours of an ROI of ``shape`` (see
    :func:`identify_contour_template`'s ``choose``)."""
    areas = {i: cv2.contourArea(contours[i]) for i in external}
    largest = max(external, key=areas.get)
    if choose == "largest":
        return largest
    centre = ((shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0)
    sizeable = [i for i in external if areas[i] >= MIN_CENTRAL_AREA_FRACTION * areas[largest]]
    # Signed distance: positive inside the contour, so the one holding the centre deepest wins.
    return max(sizeable, key=lambda i: cv2.pointPolygonTest(contours[i], centre, True))
