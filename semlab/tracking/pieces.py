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

A particle fused with a thin tip's end is shaved together with it by every opening; what the frames can
judge of it is its part outside the wedge of the tip's flanks (:func:`~semlab.tracking.attached.apex_pieces`,
smaller and less round than the geometric cut takes). Left out, it takes the band beside the apex with it,
and the rest hardly fixes the position along the shaft: no single frame's move is significant (the corpus's
clutter development seed 106: χ² 0.3-5 a frame, the probe held back by up to 2 px later with ``ok=True``), and
one frame's refit there scatters along the shaft more than its covariance says (wander spare seed 204: a tip's own
end cut on one frame's move of 0.9 px). So every piece's moves are also judged together (:class:`PullEvidence`):
a piece whose moves agree over :data:`MIN_EVIDENCE_FRAMES` frames and more, :data:`MIN_MEAN_PULL_PX` on average,
with their sum significant both under the sum of the refits' covariances and under the moves' own scatter, is
cut; a piece outside the wedge only so. Such a piece may also lie further along a flank (:data:`FLANK_REACH_PX`):
a low, broad cap that no opening shaves.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
from scipy.stats import f as f_distribution

from .attached import (
    BAND_CLEARANCE_PX,
    BUMP_REACH_PX,
    OPENINGS,
    _apex,
    _body,
    _disc,
    _distance_to_apex,
    _particle_sized,
    apex_pieces,
    clear_band,
    cut_off,
)
from .band import MIN_BAND_PIXELS, registration_band
from .consistency import INFLUENCE_CHI2, MIN_QUADRANT_PIXELS

__all__ = ["APEX_CLEARANCE_PX", "FLANK_REACH_PX", "MIN_EVIDENCE_FRAMES", "MIN_MEAN_PULL_PX", "MIN_PULL_PX", "PULL_CHI2",
           "PULL_T2_LEVEL", "LoosePieces", "Piece", "PullEvidence", "band_masks", "loose_pieces", "pulls"]

#: A shaved piece this near (px) the apex is the probe's end (a thin tip's end is what every opening
#: shaves first): never tested, never cut.
APEX_CLEARANCE_PX = 3.0
#: Leaving a piece out must move the answer by more than this (px) to cut it: a material pull (the
#: particle of the clutter spare scene above moved it 0.37 px at frame 2, with the answer 1.2 px back)...
MIN_PULL_PX = 0.3
#: ... and significantly: χ² of the move under the refit's covariance (as the band's quadrants are
#: judged, :data:`~semlab.tracking.consistency.INFLUENCE_CHI2`).
PULL_CHI2 = INFLUENCE_CHI2
#: The moves' own scatter must make their mean significant at this level too (Hotelling's T²): a guard
#: against refits that scatter along the shaft more than their covariances say, not the test of the pull
#: itself, which the summed covariances' χ² makes at :data:`PULL_CHI2`'s rate (a tip's own end whose refits
#: scattered, wander spare seed 204: p 0.12; a particle on a charging probe's apex whose moves agreed,
#: gray_charging spare seed 231: p 7e-5).
PULL_T2_LEVEL = 1e-3
#: A piece is tested only when at least this many band pixels lie near it, and at most this fraction of
#: the band (a piece that holds a quarter of the band is the object's own).
MIN_PIECE_BAND_PIXELS = MIN_QUADRANT_PIXELS
MAX_PIECE_BAND_FRACTION = 0.25
#: A thin tip's region outside the wedge of its flanks near the apex is a piece to judge from this many px²
#: and this fraction of its enclosing circle (:func:`~semlab.tracking.attached.apex_pieces`): the part of a
#: particle fused with the apex outside the wedge (clutter development seed 106: 8 px², 0.39) and not a
#: sliver along a flank that the wedge's fit leaves out (the probe's own edge: substrates development seed
#: 116, 29 px², 0.09, which, cut, took that probe 1.8 → 3.5 times the bound; a low dose's outline noise
#: 0.09-0.14).
MIN_APEX_PIECE_PX = 4
MIN_APEX_PIECE_ROUNDNESS = 0.2
#: Beyond the apex (:data:`~semlab.tracking.attached.BUMP_REACH_PX`), the wedge's flanks are followed this far
#: (px from the apex) for such pieces too: a low, broad cap on a flank that no opening shaves, its part outside
#: the wedge judged like an apex piece (clutter spare seed 277: 12 px² of a particle 37-51 px from the apex
#: held the probe back by up to 1.2 px along its shaft).
FLANK_REACH_PX = 60.0
#: The frames' moves of a piece are judged together (:class:`PullEvidence`) from this many frames: fewer
#: are one frame's say...
MIN_EVIDENCE_FRAMES = 3
#: ... when they move the answer by this much (px) on average. Far under :data:`MIN_PULL_PX`: leaving out only a
#: piece's part outside the wedge understates its pull, as its part inside still holds the answer (clutter
#: spare seed 266 without noise: 0.06-0.09 px a frame, the same way every frame, with the track 0.5-1 px back;
#: development seed 106: 0.2 px); the moves' own scatter (Hotelling's T²) keeps a refit's noise from being
#: taken for a pull.
MIN_MEAN_PULL_PX = 0.05


class Piece(NamedTuple):
    """A loose piece: its pixels (ROI-sized bool mask) and whether it is the part of a thin tip's region
    outside the wedge of its flanks (:func:`~semlab.tracking.attached.apex_pieces`, at the apex or along a
    flank), which only the frames' moves together judge (:class:`PullEvidence`)."""

    mask: np.ndarray
    outside_wedge: bool = False


def loose_pieces(region) -> list[Piece]:
    """The pieces of ``region`` the openings of :mod:`~semlab.tracking.attached` shave off, of a
    particle's size, more than :data:`APEX_CLEARANCE_PX` from the apex: what a particle touching the
    probe may be, whatever its shape and level; and, of a thin tip, what lies outside the wedge of its
    flanks (:data:`MIN_APEX_PIECE_PX`, :data:`MIN_APEX_PIECE_ROUNDNESS`) at its apex and along its flanks
    (:data:`FLANK_REACH_PX`). They may overlap.

    Parameters
    ----------
    region : (h, w) array_like of bool
        The contour template's region after the geometric cut.
    """
    region = np.asarray(region, bool)
    apex = _apex(region)
    to_apex = _distance_to_apex(region, apex)
    pieces = []
    for opening in OPENINGS:
        shaved = (region & ~_body(region, opening.radius)).astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(shaved, connectivity=4)
        for i in range(1, n):
            if not _particle_sized(stats[i], opening.min_area, region.shape):
                continue
            piece = labels == i
            if to_apex is None or float(to_apex[piece].min()) > APEX_CLEARANCE_PX:
                pieces.append(Piece(piece))
    if apex is not None:
        sized = {"min_area": MIN_APEX_PIECE_PX, "min_roundness": MIN_APEX_PIECE_ROUNDNESS}
        pieces += [Piece(bump, outside_wedge=True) for bump in apex_pieces(region, apex, **sized)]
        yy, xx = np.mgrid[:region.shape[0], :region.shape[1]]
        from_apex = np.hypot(xx - apex[0], yy - apex[1])
        along_flanks = apex_pieces(region, apex, **sized, reach=FLANK_REACH_PX)
        pieces += [Piece(bump, outside_wedge=True) for bump in along_flanks
                   if float(from_apex[bump].min()) > BUMP_REACH_PX]  # those nearer are the apex's
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


class PullEvidence:
    """One piece's moves of the answer over the frames (:func:`pulls`' ``rest_shift − shift``) and the sum of the
    refits' covariances."""

    def __init__(self):
        self.moves: list[np.ndarray] = []
        self.covariance = np.zeros((2, 2))

    @property
    def frames(self) -> int:
        return len(self.moves)

    def add(self, move, covariance) -> None:
        """One frame's move (px) and its refit's covariance (px²); a frame with either not finite is not counted."""
        move, covariance = np.asarray(move, float), np.asarray(covariance, float)
        if np.all(np.isfinite(move)) and np.all(np.isfinite(covariance)):
            self.moves.append(move)
            self.covariance += covariance

    def pulls(self) -> bool:
        """Whether the frames' moves say the piece pulls: at least :data:`MIN_EVIDENCE_FRAMES` of them,
        :data:`MIN_MEAN_PULL_PX` on average, and their sum significant both under the sum of the refits'
        covariances (χ² above :data:`PULL_CHI2`) and under the moves' own scatter (Hotelling's T², at
        :data:`PULL_T2_LEVEL`): the refits' covariances alone understate how a refit that has lost the band
        beside the apex scatters along the shaft."""
        n = self.frames
        if n < MIN_EVIDENCE_FRAMES:
            return False
        moves = np.array(self.moves)
        total = moves.sum(axis=0)
        if math.hypot(*total) <= MIN_MEAN_PULL_PX * n:
            return False
        try:
            if float(total @ np.linalg.solve(self.covariance, total)) <= PULL_CHI2:
                return False
            t2 = float(n * (total / n) @ np.linalg.solve(np.cov(moves.T), total / n))
        except np.linalg.LinAlgError:
            return False
        # T² (2 dimensions, n frames) is 2 (n − 1) / (n − 2) times an F(2, n − 2) variable.
        return float(f_distribution.sf(t2 * (n - 2) / (2.0 * (n - 1)), 2, n - 2)) < PULL_T2_LEVEL


class LoosePieces:
    """One track's loose pieces: those still to be judged, and those the frames cut.

    Parameters
    ----------
    pending : list of Piece
        :func:`loose_pieces` of frame 0's region (empty: nothing to judge).
    attached : (h, w) bool array or None
        What frame 0's geometric cut took (:mod:`semlab.tracking.attached`): a re-drawn band keeps clear of it too.
    """

    def __init__(self, pending, attached=None):
        #: The pieces still judged, each with its frames' moves (:class:`PullEvidence`).
        self.pending = [(piece, PullEvidence()) for piece in pending]
        self.attached = attached
        #: The pieces the frames cut (ROI-sized bool mask; None: none).
        self.cut = None
        self._masks = None  # (points, masks) of the band they were taken on

    def judged(self, points):
        """``(index, band mask)`` of each pending piece that can be judged on the band ``points``
        (:func:`band_masks`, computed once per band)."""
        if self._masks is None or self._masks[0] is not points:
            self._masks = (points, band_masks(points, [piece.mask for piece, _ in self.pending]))
        return [(i, mask) for i, mask in enumerate(self._masks[1]) if mask is not None]

    def pulling_pieces(self, points, shift, refit_without):
        """``(index, refit)`` of each pending piece, judged on the band ``points``, that pulls the answer ``shift``
        (:meth:`pulling`): ``refit_without(band mask)`` registers the frame without the piece's band pixels (a
        :class:`~semlab.tracking.registration.FitResult`; a refit that fails or does not converge judges nothing).
        A generator: the frame's remaining pieces are judged only when the caller asks for the next."""
        for index, mask in self.judged(points):
            try:
                rest = refit_without(mask)
            except (ValueError, np.linalg.LinAlgError):
                continue
            if rest.converged and self.pulling(index, shift, rest.shift, rest.covariance()):
                yield index, rest

    def pulling(self, index, shift, rest_shift, rest_covariance) -> bool:
        """Whether pending piece ``index`` pulls the answer: leaving it out moved this frame's ``shift`` to
        ``rest_shift`` (:func:`pulls`, with ``rest_covariance``; not for a piece outside the wedge: at the apex
        it takes the band that fixes the position along the shaft with it), or the frames' moves so far say so
        (:class:`PullEvidence`)."""
        piece, evidence = self.pending[index]
        evidence.add(np.asarray(rest_shift, float) - np.asarray(shift, float), rest_covariance)
        return (not piece.outside_wedge and pulls(shift, rest_shift, rest_covariance)) or evidence.pulls()

    def cut_off(self, contour, index, widths, *, choose: str = "central"):
        """``(contour, band)``: ``contour`` without pending piece ``index`` and the band re-drawn clear of it, of
        the pieces cut before and of frame 0's (:func:`~semlab.tracking.attached.cut_off`,
        :func:`~semlab.tracking.attached.clear_band`), the piece then counted cut; None (nothing recorded) when
        too little would remain."""
        piece = self.pending[index][0].mask
        cut_contour = cut_off(contour, piece, choose=choose)
        if cut_contour is None:
            return None
        cut = piece if self.cut is None else self.cut | piece
        band = clear_band(registration_band(cut_contour, widths), cut if self.attached is None else cut | self.attached,
                          cut_contour.region)
        if band.sum() < MIN_BAND_PIXELS:
            return None
        self.cut = cut
        del self.pending[index]
        self._masks = None
        return cut_contour, band

    def forget(self) -> None:
        """Judge no more pieces (the band was re-drawn from another contour: the masks were the old band's)."""
        self.pending, self._masks = [], None
