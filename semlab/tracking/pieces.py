"""Pieces of frame 0's object that do not move with it: the frames say which, and they are cut.

The geometric cut (:mod:`semlab.tracking.attached`) judges a piece the morphological openings shave
off the contour region by its shape and level alone, in frame 0. Where it judges wrong — a particle
sunk into the flank with a square-ish cap as bright as the probe, taken for a gripper jaw's end; a
particle on the flank within the openings' apex clearance — the particle stays in the template, and
along the shaft, where only the apex tells the position, it holds the track back by a pixel and more
while every fit says ``ok`` (the corpus's clutter family with its texture and occluder taken out,
spare seed 270: 10 px by frame 10; ``tests/test_track_attached.py``).

The frames can tell what frame 0 cannot: a piece of the probe moves with the probe, a particle does
not. While the template is young (the averaging's first frames, when a pull sets in), each accepted
frame is registered again without each such piece that the geometric cut left (:func:`loose_pieces`:
shaved by an opening, particle-sized, more than :data:`APEX_CLEARANCE_PX` from the apex), from the
frame's answer. When leaving a piece out moves the answer by more than :data:`MIN_PULL_PX`, and
significantly under the refit's own covariance (χ² above :data:`PULL_CHI2`, 2 degrees of freedom),
the piece was pulling: it does not move with the rest of the object. It is cut off the contour's region
and the band is re-drawn clear of it, as frame 0's cut does (only weighing its band pixels 0 is not
enough: the particle then slides along the flank's band in template coordinates, which reads as the flank
moving out, and an analytic wedge drifted 2.7 px forward), and the frame is refitted from the refit's
answer. A piece of the probe, left out, leaves the answer where it was, within the noise: it stays.
A piece the openings shave together with the tip's end (a particle at the apex) is not reached.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .attached import (
    BAND_CLEARANCE_PX,
    OPENINGS,
    _apex,
    _body,
    _disc,
    _distance_to_apex,
    _particle_sized,
    clear_band,
    cut_off,
)
from .band import MIN_BAND_PIXELS, registration_band
from .consistency import INFLUENCE_CHI2, MIN_QUADRANT_PIXELS

__all__ = ["APEX_CLEARANCE_PX", "MIN_PULL_PX", "PULL_CHI2", "LoosePieces", "band_masks", "loose_pieces", "pulls"]

#: A shaved piece this near (px) the apex is the probe's end (a thin tip's end is what every opening
#: shaves first): never tested, never cut.
APEX_CLEARANCE_PX = 3.0
#: Leaving a piece out must move the answer by more than this (px) to cut it: a material pull (the
#: particle of the clutter spare scene above moved it 0.37 px at frame 2, with the answer 1.2 px back)...
MIN_PULL_PX = 0.3
#: ... and significantly: χ² of the move under the refit's covariance (as the band's quadrants are
#: judged, :data:`~semlab.tracking.consistency.INFLUENCE_CHI2`).
PULL_CHI2 = INFLUENCE_CHI2
#: A piece is tested only when at least this many band pixels lie near it, and at most this fraction of
#: the band (a piece that holds a quarter of the band is the object's own).
MIN_PIECE_BAND_PIXELS = MIN_QUADRANT_PIXELS
MAX_PIECE_BAND_FRACTION = 0.25


def loose_pieces(region) -> list[np.ndarray]:
    """The pieces of ``region`` the openings of :mod:`~semlab.tracking.attached` shave off, of a
    particle's size, more than :data:`APEX_CLEARANCE_PX` from the apex: what a particle touching the
    probe may be, whatever its shape and level (ROI-sized bool masks; they may overlap).

    Parameters
    ----------
    region : (h, w) array_like of bool
        The contour template's region after the geometric cut.
    """
    region = np.asarray(region, bool)
    to_apex = _distance_to_apex(region, _apex(region))
    pieces = []
    for opening in OPENINGS:
        shaved = (region & ~_body(region, opening.radius)).astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(shaved, connectivity=4)
        for i in range(1, n):
            if not _particle_sized(stats[i], opening.min_area, region.shape):
                continue
            piece = labels == i
            if to_apex is None or float(to_apex[piece].min()) > APEX_CLEARANCE_PX:
                pieces.append(piece)
    return pieces


def band_masks(points, pieces) -> list[np.ndarray]:
    """For each piece (of :func:`loose_pieces`) the band pixels within
    :data:`~semlab.tracking.attached.BAND_CLEARANCE_PX` of it, when they are enough to judge it
    (:data:`MIN_PIECE_BAND_PIXELS`) and not a large part of the band (:data:`MAX_PIECE_BAND_FRACTION`).

    Parameters
    ----------
    points : (K, 2) array_like
        The band's pixel coordinates ``(x, y)`` in the ROI.
    pieces : list of (h, w) bool arrays

    Returns
    -------
    list of (K,) bool arrays or None
        One per piece; None where the piece cannot be judged.
    """
    pts = np.rint(np.asarray(points, float)).astype(np.intp)
    masks = []
    for piece in pieces:
        near = cv2.dilate(piece.astype(np.uint8), _disc(BAND_CLEARANCE_PX)).astype(bool)
        h, w = near.shape
        inside = (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)
        mask = np.zeros(len(pts), bool)
        mask[inside] = near[pts[inside, 1], pts[inside, 0]]
        masks.append(mask if MIN_PIECE_BAND_PIXELS <= mask.sum() and mask.mean() < MAX_PIECE_BAND_FRACTION else None)
    return masks


def pulls(shift, rest_shift, rest_covariance) -> bool:
    """Whether the answer ``shift`` moves to ``rest_shift`` when a piece is left out by more than
    :data:`MIN_PULL_PX`, significantly under ``rest_covariance`` (px², the refit's): χ² above
    :data:`PULL_CHI2`."""
    d = np.asarray(rest_shift, float) - np.asarray(shift, float)
    cov = np.asarray(rest_covariance, float)
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(cov))) or math.hypot(*d) <= MIN_PULL_PX:
        return False
    try:
        chi2 = float(d @ np.linalg.solve(cov, d))
    except np.linalg.LinAlgError:
        return False
    return chi2 > PULL_CHI2


class LoosePieces:
    """One track's loose pieces: those still to be judged, and those the frames cut.

    Parameters
    ----------
    pending : list of (h, w) bool arrays
        :func:`loose_pieces` of frame 0's region (empty: nothing to judge).
    attached : (h, w) bool array or None
        What frame 0's geometric cut took (:mod:`semlab.tracking.attached`): a re-drawn band keeps clear of it too.
    """

    def __init__(self, pending, attached=None):
        self.pending = list(pending)
        self.attached = attached
        #: The pieces the frames cut (ROI-sized bool mask; None: none).
        self.cut = None
        self._masks = None  # (points, masks) of the band they were taken on

    def judged(self, points):
        """``(piece, band mask)`` of each pending piece that can be judged on the band ``points``
        (:func:`band_masks`, computed once per band)."""
        if self._masks is None or self._masks[0] is not points:
            self._masks = (points, band_masks(points, self.pending))
        return [(piece, mask) for piece, mask in zip(self.pending, self._masks[1]) if mask is not None]

    def cut_off(self, contour, piece, widths, *, choose: str = "central"):
        """``(contour, band)``: ``contour`` without ``piece`` and the band re-drawn clear of it, of the pieces cut
        before and of frame 0's (:func:`~semlab.tracking.attached.cut_off`, :func:`~semlab.tracking.attached.
        clear_band`), the piece then counted cut; None (nothing recorded) when too little would remain."""
        cut_contour = cut_off(contour, piece, choose=choose)
        if cut_contour is None:
            return None
        cut = piece if self.cut is None else self.cut | piece
        band = clear_band(registration_band(cut_contour, widths), cut if self.attached is None else cut | self.attached,
                          cut_contour.region)
        if band.sum() < MIN_BAND_PIXELS:
            return None
        self.cut = cut
        self.pending = [p for p in self.pending if p is not piece]
        self._masks = None
        return cut_contour, band

    def forget(self) -> None:
        """Judge no more pieces (the band was re-drawn from another contour: the masks were the old band's)."""
        self.pending, self._masks = [], None
